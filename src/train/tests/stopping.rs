//! A stop asked inside an epoch (Ctrl-C, SIGTERM, a caller's flag): the run ends before
//! the epoch's next batch with the checkpoint of its last whole epoch, and resumed it ends
//! bit for bit where an uninterrupted run ends.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use super::super::fixtures::{chemostat, options, record};
use super::super::*;

#[test]
fn a_stop_inside_an_epoch_keeps_the_last_whole_epoch_and_resumes_bit_for_bit() {
    let (data, _) = chemostat::data(200, (0.002, 0.02), 2);
    let model = chemostat::grey_box();
    let records = [record(&model, &data)];
    let training = TrainingData {
        train: &records,
        validation: &[],
        part: Part::FirstPairs(Some(100)),
    };
    let settings = TrainOptions {
        learning_rate: 0.01,
        batch_size: 10,
        ..options(5, 100)
    };
    let how = (&settings, &Recipe::paper());
    let whole = train_run(&model, &training, how, &RunControl::default(), &mut |_| {}).unwrap();

    let scratch = crate::io::ScratchDir::new("train-stopped-inside").unwrap();
    let flag = Arc::new(AtomicBool::new(false));
    let stopping = RunControl {
        directory: Some(scratch.path.clone()),
        stop: Some(Arc::clone(&flag)),
        ..RunControl::default()
    };
    let mut batches_after = 0;
    let mut listen = |event: Event| {
        if let Event::Batch { epoch: 3, done, .. } = event {
            batches_after = done;
            if done == 2 {
                flag.store(true, Ordering::SeqCst);
            }
        }
    };
    let stopped = train_run(&model, &training, how, &stopping, &mut listen);
    assert!(
        matches!(stopped, Err(TrainError::Interrupted { epoch: 2, .. })),
        "{:?}",
        stopped.err()
    );
    assert_eq!(batches_after, 2, "no batch runs after the stop");
    let checkpoint = Checkpoint::load(&scratch.path).unwrap();
    assert_eq!((checkpoint.epoch, checkpoint.log.len()), (2, 2));

    let resumed = RunControl {
        resume: Some(checkpoint),
        ..RunControl::default()
    };
    let resumed = train_run(&model, &training, how, &resumed, &mut |_| {}).unwrap();
    assert_eq!(resumed.network.weights(), whole.network.weights());
    assert_eq!(resumed.report.losses, whole.report.losses);
}
