//! Training tests on data simulated from the paper's chemostat (spec section 4).

mod jitter;
mod mechanism;
mod nonnegative;
mod outputs;
mod recipe;
mod records;
mod start;
mod stopping;
mod substeps;
mod windows;

use super::evaluate::{online_error, simulate, Feed};
use super::fixtures::{chemostat, normalise, options, record, track, train_one};
use super::stepping::Stepping;
use super::*;
use crate::data::Dataset;
use crate::engine::graph::Network;
use crate::engine::pairs::{stage_fractions, PairTable};
use crate::trained::{artifacts, predict};

#[test]
fn short_training_on_chemostat_data_cuts_the_validation_error() {
    let (data, _) = chemostat::data(700, (0.002, 0.02), 1);
    let trained = train_one(
        &chemostat::grey_box(),
        &data,
        None,
        &options(15, 500),
        &Recipe::default(),
    )
    .unwrap();
    let metrics = &trained.report.metrics;
    let before = metrics.initial_offline.as_ref().unwrap().overall;
    let after = metrics.offline.as_ref().unwrap().overall;
    assert!(after < before / 20.0, "offline error {before} -> {after}");
    let online_before = metrics.initial_online.as_ref().unwrap().overall;
    let online = metrics.online.as_ref().unwrap().overall;
    assert!(
        online < online_before / 2.0,
        "online error {online_before} -> {online}"
    );
    assert!(trained.report.warnings.is_empty());
}

/// The paper's comparison (section 3.1) in miniature: the grey-box model, knowing the
/// dilution term, predicts one step far better than the black-box map `next S = n(z_e)`.
#[test]
fn grey_box_beats_the_black_box_map_offline() {
    let (data, _) = chemostat::data(700, (0.002, 0.02), 1);
    let offline = |model: &ir::Model| {
        let trained = train_one(model, &data, None, &options(15, 500), &Recipe::default()).unwrap();
        trained.report.metrics.offline.unwrap().overall
    };
    let (grey, black) = (
        offline(&chemostat::grey_box()),
        offline(&chemostat::black_box()),
    );
    assert!(grey * 10.0 < black, "grey-box {grey}, black-box {black}");
}

#[test]
fn the_same_seed_gives_the_same_result_and_another_seed_does_not() {
    let (data, _) = chemostat::data(200, (0.002, 0.02), 2);
    let run = |seed| {
        let options = TrainOptions {
            seed,
            ..options(2, 100)
        };
        let trained = train_one(
            &chemostat::grey_box(),
            &data,
            None,
            &options,
            &Recipe::default(),
        )
        .unwrap();
        (trained.report.losses, trained.network.weights())
    };
    let (losses, weights) = run(5);
    assert_eq!(run(5), (losses.clone(), weights));
    assert_ne!(run(6).0, losses);
}

#[test]
fn divergence_stops_training_naming_the_epoch() {
    let (data, _) = chemostat::data(200, (0.002, 0.02), 2);
    let options = TrainOptions {
        learning_rate: 1e12,
        ..options(5, 100)
    };
    let mut epochs_done = 0;
    let train_records = [record(&chemostat::grey_box(), &data)];
    let training = TrainingData {
        train: &train_records,
        validation: &[],
        part: Part::FirstPairs(options.train_points),
    };
    let result = train(&chemostat::grey_box(), &training, &options, &mut |event| {
        if let Event::Epoch { .. } = event {
            epochs_done += 1;
        }
    });
    match result {
        Err(TrainError::Diverged { epoch, what }) => {
            assert!(
                what.contains("loss became") || what.contains("after the epoch"),
                "{what}"
            );
            assert_eq!(epoch, epochs_done + 1);
        }
        Err(other) => panic!("expected divergence, found {other}"),
        Ok(_) => panic!("expected divergence, found a trained network"),
    }
}

#[test]
fn hidden_states_are_run_in_and_a_rate_constant_is_learned() {
    let (data, _) = chemostat::data(400, (0.002, 0.02), 4);
    let options = TrainOptions {
        learning_rate: 0.02,
        precision: Precision::F64,
        ..options(15, 300)
    };
    // Starting at half the true kcat; the hidden enzyme starts at 0, not its steady state,
    // and is integrated along the record.
    // The paper's recipe: a polish would fit kcat to the early rows, where the enzyme
    // estimate is still far from the truth, as faithfully as to the rest.
    let model = chemostat::exact_law(chemostat::KCAT / 2.0);
    let trained = train_one(&model, &data, None, &options, &Recipe::paper()).unwrap();
    let (name, kcat) = &trained.report.params[0];
    assert_eq!(name, "kcat");
    assert!((kcat / chemostat::KCAT - 1.0).abs() < 0.05, "kcat {kcat}");
}

#[test]
fn default_magnitude_of_a_rate_is_its_typical_size() {
    let (data, enzyme) = chemostat::data(600, (0.002, 0.02), 6);
    let model = chemostat::grey_box();
    let track = track(&model, &data);
    let rows: Vec<usize> = (40..500).collect();
    let pairs: Vec<(usize, usize)> = rows.iter().map(|&r| (0, r)).collect();
    let scales =
        analysis::closure_scales(&model, std::slice::from_ref(&track), &pairs, &[]).unwrap();
    let substrate = &track.states[0];
    let rms = (rows.iter())
        .map(|&r| chemostat::rate(&[substrate[r], enzyme[r]]).powi(2))
        .sum::<f64>()
        / rows.len() as f64;
    let ratio = scales[0][0] / rms.sqrt();
    assert!(
        (0.8..1.25).contains(&ratio),
        "scale {} vs rms {}",
        scales[0][0],
        rms.sqrt()
    );
}

/// With `E0` up to 1 the substrate balance has eigenvalues near -9 at 1 s sampling.
#[test]
fn stiff_data_warns_and_substeps_make_the_free_run_stable() {
    let (calm, _) = chemostat::data(300, (0.002, 0.02), 7);
    let (stiff, _) = chemostat::data(300, (0.002, 1.0), 7);
    let model = chemostat::grey_box();
    let warnings = |data: &Dataset, substeps: usize| {
        let tracks = [track(&model, data)];
        let pairs: Vec<(usize, usize)> = (40..299).map(|r| (0, r)).collect();
        analysis::stiffness(&model, (&tracks, &pairs), &[], substeps).unwrap()
    };
    assert!(warnings(&calm, 1).is_empty());
    let found = warnings(&stiff, 1);
    assert_eq!(found.len(), 1);
    let warning = &found[0];
    assert_eq!(warning.balance, "S");
    assert!((-12.0..-6.0).contains(&warning.eigenvalue), "{warning}");
    assert!(warnings(&stiff, warning.substeps_needed).is_empty());
    // The exact rate law itself blows up at the sampling step and runs stably with the
    // recommended sub-steps.
    let exact = chemostat::exact_law(chemostat::KCAT);
    let free_run_error = |substeps: usize, stepping: Stepping| {
        let setup = Setup {
            step: 1.0,
            substeps,
            precision: Precision::F64,
            seed: 0,
            normalisation: normalise(&record(&exact, &stiff), 300),
            scales: vec![],
        };
        let network = Network::build(&exact, &setup).unwrap();
        let record = track(&exact, &stiff);
        let fractions = stage_fractions(exact.dynamics, substeps);
        let (_, enzyme) = chemostat::data(300, (0.002, 1.0), 7);
        let run = simulate(
            &network,
            &exact,
            &record,
            &fractions,
            (0, 298),
            &[enzyme[0]],
            (Feed::Own, None, stepping),
        )
        .unwrap();
        let errors = online_error(&exact, &record, &run, (&setup.normalisation, f64::MIN));
        errors.finish().unwrap().overall
    };
    let unstable = free_run_error(1, Stepping::Fixed);
    assert!(
        unstable.is_nan() || unstable > 1e3,
        "free run without sub-steps: {unstable}"
    );
    let stable = free_run_error(warning.substeps_needed, Stepping::Fixed);
    assert!(stable < 1e-3, "free run with sub-steps: {stable}");
    // A free run that controls its steps needs no sub-steps from the user.
    let controlled = free_run_error(1, Stepping::Controlled);
    assert!(
        controlled < 1e-3,
        "free run with controlled steps: {controlled}"
    );
    let mut heard = Vec::new();
    let stiff_records = [record(&model, &stiff)];
    let training = TrainingData {
        train: &stiff_records,
        validation: &[],
        part: Part::FirstPairs(Some(200)),
    };
    // `train` takes the sub-steps the estimate names and tells its caller; no warning is
    // left to give.
    let mut took = Vec::new();
    let trained = train(
        &model,
        &training,
        &options(1, 200),
        &mut |event| match event {
            Event::Warning(warning) => heard.push(warning.to_string()),
            Event::Substeps(substeps) => took.push(substeps),
            _ => {}
        },
    )
    .unwrap();
    assert!(heard.is_empty(), "{heard:?}");
    assert!(trained.report.warnings.is_empty());
    assert_eq!(took, vec![warning.substeps_needed]);
    assert_eq!(trained.setup.substeps, warning.substeps_needed);
}

/// A fresh directory under the system's temporary directory.
fn scratch_directory(name: &str) -> std::path::PathBuf {
    let directory = std::env::temp_dir().join(format!("gbc-train-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&directory);
    directory
}

#[test]
fn saved_weights_reload_to_the_same_predictions_and_refuse_a_changed_structure() {
    let (data, _) = chemostat::data(150, (0.002, 0.02), 8);
    let model = chemostat::grey_box();
    let options = options(2, 80);
    let trained = train_one(&model, &data, None, &options, &Recipe::default()).unwrap();
    let source = "model chemostat_gb  # the text the hash is taken of\n";
    let info = artifacts::run_info(&model, ("gb.gbm", source), "memory.csv", &options, &trained);
    let directory = scratch_directory("roundtrip");
    artifacts::save(&directory, &info, &trained.network).unwrap();
    let (network, setup, reloaded) = artifacts::restore(&model, source, &directory).unwrap();
    // JSON numbers read back to within an ulp (serde_json without `float_roundtrip`).
    let json_round_trip: artifacts::RunInfo =
        serde_json::from_str(&serde_json::to_string(&info).unwrap()).unwrap();
    assert_eq!(reloaded, json_round_trip);
    assert_eq!(network.weights(), trained.network.weights());
    let data_record = record(&model, &data);
    let offline = |net: &Network, setup: &Setup| {
        let how = (predict::Mode::Offline, History::Measured);
        predict::predict(&model, net, setup, &data_record, how).unwrap()
    };
    let (again, original) = (
        offline(&network, &setup),
        offline(&trained.network, &trained.setup),
    );
    assert_eq!(again.header, original.header);
    for (a, b) in again
        .columns
        .iter()
        .flatten()
        .zip(original.columns.iter().flatten())
    {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1e-12), "{a} vs {b}");
    }
    // Another text of the same structure is accepted, with a note; another structure is not.
    let edited =
        artifacts::restore_with_notes(&model, "model chemostat_gb  # edited\n", &directory);
    assert!(edited.unwrap().notes[0].contains("structure is the same"));
    let mut wider = model.clone();
    wider.closures[0].network.hidden[0] += 1;
    match artifacts::restore(&wider, source, &directory) {
        Err(TrainError::ModelChanged { changes, .. }) => {
            assert_eq!(changes.len(), 1, "{changes:?}");
            assert!(
                changes[0].contains("network: expected `hidden [20"),
                "{changes:?}"
            );
        }
        _ => panic!("a wider network must be refused"),
    }
    std::fs::remove_dir_all(&directory).unwrap();
}

#[test]
fn offline_predictions_are_one_step_and_online_ones_a_free_run() {
    let (data, _) = chemostat::data(120, (0.002, 0.02), 9);
    let model = chemostat::grey_box();
    let trained = train_one(&model, &data, None, &options(1, 60), &Recipe::default()).unwrap();
    let data_record = record(&model, &data);
    let table = |mode| {
        let how = (mode, History::Measured);
        predict::predict(&model, &trained.network, &trained.setup, &data_record, how)
    };
    let (offline, online) = (
        table(predict::Mode::Offline).unwrap(),
        table(predict::Mode::Online).unwrap(),
    );
    assert_eq!(offline.header, vec!["t", "S", "r"]);
    let first = crate::engine::pairs::first_pair_row(&model, 1.0);
    assert_eq!(offline.columns[0][0], first as f64);
    let measured = data.column("S").unwrap();
    // Both start from the data; offline row k + 1 is the step from the true state at k.
    assert_eq!(offline.columns[1][0], measured[first]);
    assert_eq!(online.columns[1][0], measured[first]);
    let tracks = [track(&model, &data)];
    let fractions = stage_fractions(model.dynamics, 1);
    let table_row = PairTable::build(&model, &tracks, &[(0, first + 5)], &[], &fractions);
    let step = trained.network.predict(&table_row.batch(&[0])).unwrap();
    assert_eq!(offline.columns[1][6], step.next_states[0]);
    assert_eq!(offline.columns[2][5], step.closure_outputs[0]);
    // The free run drifts away from the one-step predictions.
    assert_ne!(online.columns[1][40], offline.columns[1][40]);
}

/// The data and split of the divergence tests: 100 one-step pairs of the chemostat.
fn diverging_data() -> (ir::Model, crate::record::Record) {
    let (data, _) = chemostat::data(200, (0.002, 0.02), 2);
    let model = chemostat::grey_box();
    let record = record(&model, &data);
    (model, record)
}

/// The user's case: in f32 an Adam step overflows every weight (a learning rate beyond
/// f32's range) while the loss, computed before the step, stays finite. One batch per
/// epoch, so no later loss sees the weights: they are checked themselves.
#[test]
fn weights_that_overflow_with_a_finite_loss_are_a_divergence() {
    let (model, record) = diverging_data();
    let records = [record];
    let training = TrainingData {
        train: &records,
        validation: &[],
        part: Part::FirstPairs(Some(100)),
    };
    let options = TrainOptions {
        learning_rate: 1e39,
        precision: Precision::F32,
        batch_size: 128,
        ..options(1, 100)
    };
    let result = train_with(&model, &training, &options, &Recipe::paper(), &mut |_| {});
    match result {
        Err(TrainError::Diverged { epoch, what }) => {
            assert_eq!(epoch, 1);
            assert!(what.contains("after the epoch"), "{what}");
        }
        Err(other) => panic!("expected divergence, found {other}"),
        Ok(_) => panic!("expected divergence, found a trained network"),
    }
    let control = RunControl {
        keep_last_finite: true,
        ..RunControl::default()
    };
    let kept = train_run(
        &model,
        &training,
        (&options, &Recipe::paper()),
        &control,
        &mut |_| {},
    )
    .unwrap();
    let diverged = kept.report.diverged.unwrap();
    assert_eq!((diverged.epoch, diverged.kept_epoch), (1, 0));
    assert!(kept.report.losses.is_empty());
    let initial = Network::build(&model, &kept.setup).unwrap().weights();
    assert_eq!(
        kept.network.weights(),
        initial,
        "the initial weights are kept"
    );
    let params = kept.report.params.iter().map(|(_, value)| *value);
    assert!(params
        .chain(initial.iter().flat_map(|t| t.values.clone()))
        .all(f64::is_finite));
}

/// A run that diverges after finite epochs keeps the last of them, bit for bit: two epochs
/// at a sane learning rate (stopped with a checkpoint), then the third with an absurd one.
#[test]
fn a_run_that_diverges_keeps_its_last_finite_epoch() {
    let (model, record) = diverging_data();
    let records = [record];
    let training = TrainingData {
        train: &records,
        validation: &[],
        part: Part::FirstPairs(Some(100)),
    };
    let scratch = crate::io::ScratchDir::new("train-diverged").unwrap();
    let sane = TrainOptions {
        learning_rate: 0.01,
        ..options(5, 100)
    };
    let stopping = RunControl {
        directory: Some(scratch.path.clone()),
        stop_after: Some(2),
        ..RunControl::default()
    };
    let stopped = train_run(
        &model,
        &training,
        (&sane, &Recipe::paper()),
        &stopping,
        &mut |_| {},
    );
    assert!(matches!(
        stopped,
        Err(TrainError::Interrupted { epoch: 2, .. })
    ));
    let checkpoint = Checkpoint::load(&scratch.path).unwrap();
    let absurd = TrainOptions {
        learning_rate: 1e12,
        ..sane
    };
    let resumed = RunControl {
        resume: Some(checkpoint.clone()),
        keep_last_finite: true,
        ..RunControl::default()
    };
    let kept = train_run(
        &model,
        &training,
        (&absurd, &Recipe::paper()),
        &resumed,
        &mut |_| {},
    )
    .unwrap();
    let diverged = kept.report.diverged.clone().unwrap();
    assert_eq!(
        (diverged.epoch, diverged.kept_epoch),
        (3, 2),
        "{diverged:?}"
    );
    assert!(diverged.what.contains("became"), "{diverged:?}");
    assert_eq!(kept.network.weights(), checkpoint.weights);
    assert_eq!(kept.report.losses.len(), 2);
}
