//! What-if runs against online predictions and against one step built by hand.

use super::*;
use crate::engine::graph::{Batch, Precision};
use crate::train::fixtures::{chemostat, options, record, train_one};
use crate::train::{History, Recipe, TrainOptions, Trained};
use crate::trained::predict::{predict_in_range, Mode};

fn trained() -> (ir::Model, Trained, crate::data::Dataset) {
    let (data, _) = chemostat::data(120, (0.002, 0.02), 4);
    let model = chemostat::grey_box();
    let options = TrainOptions {
        precision: Precision::F64,
        ..options(1, 60)
    };
    let trained = train_one(&model, &data, None, &options, &Recipe::default()).unwrap();
    (model, trained, data)
}

/// The signal holding `values` from `times`.
fn held(times: &[f64], values: &[f64]) -> Signal {
    Signal::new(times.to_vec(), values.to_vec()).unwrap()
}

#[test]
fn a_run_along_a_records_own_inputs_from_its_history_is_its_online_prediction() {
    let (model, trained, data) = trained();
    let data_record = record(&model, &data);
    let how = (Mode::Online, History::Measured, None);
    let online =
        predict_in_range(&model, &trained.network, &trained.setup, &data_record, how).unwrap();
    let start = online.columns[0][0];
    assert_eq!(
        start, 40.0,
        "the first row with a full embedding (4 delays of 10)"
    );
    let signals = [held(&data_record.times, &data_record.inputs[0])];
    let what = WhatIf {
        signals: &signals,
        t_start: start,
        t_end: *data_record.times.last().unwrap(),
        dt: 1.0,
        initial: Vec::new(),
        history: Some(&data_record),
    };
    let run = what_if(&model, (&trained.network, &trained.setup), &what, None).unwrap();
    assert_eq!(run.header, ["t", "E0", "S", "r"]);
    assert_eq!(run.columns[0], online.columns[0]);
    assert_eq!(run.columns[1], data_record.inputs[0][40..].to_vec());
    for (ours, theirs) in run.columns[2..].iter().zip(&online.columns[1..]) {
        for (a, b) in ours.iter().zip(theirs) {
            assert!((a - b).abs() <= 1e-9 * b.abs().max(1e-12), "{a} vs {b}");
        }
    }
}

#[test]
fn a_run_from_a_held_initial_state_takes_its_first_step_from_a_held_embedding() {
    let (model, trained, _) = trained();
    let (s0, e0) = (0.012, 0.008);
    let signals = [Signal::constant(0.0, e0)];
    let what = WhatIf {
        signals: &signals,
        t_start: 0.0,
        t_end: 5.0,
        dt: 1.0,
        initial: vec![Some(s0)],
        history: None,
    };
    let run = what_if(&model, (&trained.network, &trained.setup), &what, None).unwrap();
    assert_eq!(run.columns[0], [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
    assert_eq!(run.columns[1], [e0; 6]);
    assert_eq!(run.columns[2][0], s0);
    // One step by hand: every lag of the embedding reads the held initial values.
    let width = model.closures[0].embedding.width();
    let row: Vec<f64> = (0..width)
        .map(|k| if k % 2 == 0 { s0 } else { e0 })
        .collect();
    let batch = Batch {
        rows: 1,
        states: vec![s0],
        inputs: vec![e0],
        embeddings: vec![vec![row; 3]],
        ..Batch::default()
    };
    let step = trained.network.predict(&batch).unwrap();
    assert_eq!(run.columns[2][1], step.next_states[0]);
    assert_eq!(run.columns[3][0], step.closure_outputs[0]);
}

#[test]
fn a_run_needs_an_initial_value_a_start_in_its_history_and_a_grid() {
    let (model, trained, data) = trained();
    let signals = [Signal::constant(0.0, 0.01)];
    let mut what = WhatIf {
        signals: &signals,
        t_start: 0.0,
        t_end: 5.0,
        dt: 1.0,
        initial: Vec::new(),
        history: None,
    };
    let run = |what: &WhatIf| what_if(&model, (&trained.network, &trained.setup), what, None);
    assert!(matches!(run(&what), Err(WhatIfError::NoInitialValue { state }) if state == "S"));
    what.initial = vec![Some(0.01)];
    what.dt = 0.0;
    assert!(matches!(run(&what), Err(WhatIfError::BadTimes { .. })));
    let data_record = record(&model, &data);
    what.dt = 1.0;
    what.history = Some(&data_record);
    what.t_start = 40.5;
    what.t_end = 100.0;
    assert!(matches!(
        run(&what),
        Err(WhatIfError::StartOutsideHistory { .. })
    ));
}
