use super::*;
use crate::engine::fixtures::{ClosureSpec, ModelBuilder, OutputSpec};
use crate::ir::Activation;
use crate::record::{GridOptions, Record};

/// A closure observing a state and an input with a delay of 3 time units.
fn model() -> ir::Model {
    ModelBuilder::new("m")
        .input("u")
        .state("x")
        .closure(ClosureSpec {
            name: "c",
            outputs: vec![OutputSpec {
                name: "o",
                scale: Some(1.0),
                prior: None,
            }],
            observe: &["x", "u"],
            delay: 3.0,
            dim: 3,
            hidden: vec![2],
            activation: Activation::Tanh,
        })
        .der("x", "o")
        .build()
}

fn lay(record: &Record, max_step: f64) -> Track {
    let options = GridOptions {
        max_step,
        gap_limits: vec![3.0],
        subdivide: true,
    };
    Track::lay(record, &options, &[])
}

/// Every RK4 stage time against values worked out by hand on a uniform record.
#[test]
fn embedding_at_stage_times_matches_hand_computed_values() {
    let model = model();
    // h = 2, so the delay is 1.5 samples and the embedding needs 3 samples of history.
    let record = Record::complete(
        "r",
        (0..8).map(|i| 2.0 * i as f64).collect(),
        vec![vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]],
        vec![vec![0.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0]],
    );
    let track = lay(&record, 2.0);
    assert_eq!(track.uniform, Some(2.0));
    assert_eq!(first_pair_row(&model, 2.0), 3);
    let fractions = stage_fractions(model.dynamics, 1);
    assert_eq!(fractions, vec![0.0, 0.5, 1.0]);
    let closure = &model.closures[0];
    // Layout: [x(t), u(t), x(t-3), u(t-3), x(t-6), u(t-6)], step from knot 4 (t = 8).
    // Stage t = 8: x at samples 4, 2.5, 1 -> 80, 30, 10; u held at 4, 2.5, 1 -> 4, 2, 1.
    let start = embedding_row(closure, &track, 4, 0.0);
    assert_eq!(start, vec![80.0, 4.0, 30.0, 2.0, 10.0, 1.0]);
    // Stage t = 9: samples 4.5, 3, 1.5 -> x 120, 40, 15; u 4, 3 (switched at 3), 1.
    let middle = embedding_row(closure, &track, 4, 0.5);
    assert_eq!(middle, vec![120.0, 4.0, 40.0, 3.0, 15.0, 1.0]);
    // Stage t = 10: samples 5, 3.5, 2 -> x 160, 60, 20; u 4 (left limit: held over the
    // step), 3, 1 (left limit at 2).
    let end = embedding_row(closure, &track, 4, 1.0);
    assert_eq!(end, vec![160.0, 4.0, 60.0, 3.0, 20.0, 1.0]);
    let tracks = [track];
    let table = PairTable::build(&model, &tracks, &[(0, 4), (0, 6)], &[], &fractions);
    let batch = table.batch(&[1, 0]);
    assert_eq!(batch.states, vec![320.0, 80.0]);
    assert_eq!(batch.inputs, vec![6.0, 4.0]);
    assert_eq!(batch.targets, vec![640.0, 160.0]);
    assert_eq!(batch.step_sizes, vec![2.0, 2.0]);
    assert_eq!(batch.weights, vec![1.0, 1.0]);
    assert_eq!(&batch.embeddings[0][2][6..], &end[..]);
    // History before the first row: the pair at knot 2 reaches back to t = -2.
    assert!(!measured_history(&model, &tracks[0], 2, &fractions));
    assert!(measured_history(&model, &tracks[0], 3, &fractions));
}

/// On irregular rows with a missing cell and a long interval, the grid cuts the interval,
/// the reference interpolates the state's own measurements, and embeddings read it at
/// stage times.
#[test]
fn irregular_records_are_read_at_stage_times_from_their_own_measurements() {
    let model = model();
    let record = Record {
        name: "r".into(),
        source: "r".into(),
        times: vec![0.0, 1.0, 3.0, 4.0, 8.0, 9.0],
        inputs: vec![vec![1.0, 1.0, 2.0, 2.0, 5.0, 5.0]],
        states: vec![vec![
            Some(0.0),
            Some(1.0),
            None,
            Some(4.0),
            Some(12.0),
            Some(14.0),
        ]],
        observables: Vec::new(),
    };
    let track = lay(&record, 2.0);
    // The 4-unit interval from t = 4 to 8 is cut in two.
    assert_eq!(track.times, vec![0.0, 1.0, 3.0, 4.0, 6.0, 8.0, 9.0]);
    assert_eq!(track.rows[4], None);
    assert_eq!(track.uniform, None);
    assert_eq!(track.steps, vec![1.0, 2.0, 1.0, 2.0, 2.0, 1.0, 0.0]);
    // x: cells at 0, 1, 4, 8, 9; at 3 (no cell) the interpolant of 1 @ 1 and 4 @ 4 is 3,
    // known (gap 3 <= delay 3); at 6 that of 4 @ 4 and 12 @ 8 is 8, not known (gap 4).
    assert_eq!(track.states[0], vec![0.0, 1.0, 3.0, 4.0, 8.0, 12.0, 14.0]);
    assert_eq!(
        track.known[0],
        vec![true, true, true, true, false, true, true]
    );
    assert_eq!(
        track.measured[0],
        vec![true, true, false, true, false, true, true]
    );
    assert_eq!(track.inputs[0], vec![1.0, 1.0, 2.0, 2.0, 2.0, 5.0, 5.0]);
    let closure = &model.closures[0];
    let fractions = stage_fractions(model.dynamics, 1);
    // Step from knot 5 (t = 8, h = 1), stage t = 8.5: x(8.5) = 13 (stage: ignored, then
    // x(5.5) = 7 and x(2.5) = 2.5; u held at 8.5 -> 5, at 5.5 -> 2, at 2.5 -> 1.
    let middle = embedding_row(closure, &track, 5, 0.5);
    assert_eq!(middle, vec![13.0, 5.0, 7.0, 2.0, 2.5, 1.0]);
    // That step's lagged read at t = 5.5 falls in the unknown stretch: no measured history.
    assert!(!measured_history(&model, &track, 5, &fractions));
    // The step from knot 3 (t = 4 to 6) has no target cell at t = 6; from 4 (6 to 8) has.
    assert!(!has_target(&track, 3));
    assert!(has_target(&track, 4));
    let tracks = [track];
    let table = PairTable::build(&model, &tracks, &[(0, 1), (0, 2)], &[], &fractions);
    let batch = table.batch(&[0, 1]);
    assert_eq!(batch.step_sizes, vec![2.0, 1.0]);
    // Knot 2 (t = 3) has no cell: the pair from knot 1 has weight 0 on its target.
    assert_eq!(batch.weights, vec![0.0, 1.0]);
}
