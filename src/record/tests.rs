use super::grid::{hold, interpolate};
use super::*;

fn irregular() -> Record {
    Record {
        name: "batch".into(),
        source: "batch.csv".into(),
        times: vec![2.0, 3.0, 5.0, 11.0, 12.0],
        inputs: vec![vec![0.5, 0.5, 1.0, 1.0, 0.0]],
        states: vec![
            vec![None, Some(2.0), Some(4.0), None, Some(10.0)],
            vec![Some(1.0), None, Some(3.0), Some(9.0), Some(7.0)],
        ],
        observables: Vec::new(),
    }
}

/// Statistics are over measured cells only, pooled over the parts given.
#[test]
fn normalisation_is_taken_over_measured_cells_of_every_part() {
    let record = irregular();
    let other = Record::complete(
        "b",
        vec![0.0, 1.0],
        vec![vec![2.0, 4.0]],
        vec![vec![6.0, 8.0], vec![5.0, 5.0]],
    );
    let norm = Normalisation::over(&[(&record, 0..5), (&other, 0..2)], 2, 1);
    // State 0: 2, 4, 10, 6, 8 -> mean 6, population variance 8.
    assert!((norm.state_mean[0] - 6.0).abs() < 1e-12);
    assert!((norm.state_std[0] - 8.0_f64.sqrt()).abs() < 1e-12);
    assert_eq!((norm.state_min[0], norm.state_max[0]), (2.0, 10.0));
    // State 1 over the first three rows only of the first record: 1, 3 and 5, 5.
    let head = Normalisation::over(&[(&record, 0..3), (&other, 0..2)], 2, 1);
    assert!((head.state_mean[1] - 3.5).abs() < 1e-12);
    // Inputs over every row of the parts: 0.5, 0.5, 1, 1, 0, 2, 4.
    assert!((norm.input_mean[0] - 9.0 / 7.0).abs() < 1e-12);
    // A column measured once is constant: its std is 1.
    let single = Record::complete("c", vec![0.0], vec![vec![1.0]], vec![vec![3.0], vec![3.0]]);
    let norm = Normalisation::over(&[(&single, 0..1)], 2, 1);
    assert_eq!(norm.state_std, vec![1.0, 1.0]);
}

#[test]
fn uniform_steps_are_recognised_and_irregular_ones_are_not() {
    let times: Vec<f64> = (0..100).map(|i| 0.1 * i as f64).collect();
    let step = uniform_step(&times).unwrap();
    assert!((step - 0.1).abs() < 1e-12);
    assert_eq!(uniform_step(&[0.0, 1.0, 2.5]), None);
    assert_eq!(uniform_step(&[0.0]), None);
    assert_eq!(irregular().uniform_step(), None);
    assert!(!irregular().is_complete());
    assert_eq!(irregular().measured_cells(), 7);
    let head = irregular().rows(1..3);
    assert_eq!(head.times, vec![3.0, 5.0]);
    assert_eq!(head.states[1], vec![None, Some(3.0)]);
}

/// The grid cuts long intervals, holds inputs, interpolates each state's own cells where
/// they are close enough, and starts an unmeasured state at its initial value.
#[test]
fn a_record_is_laid_on_its_grid() {
    let options = GridOptions {
        max_step: 2.5,
        gap_limits: vec![3.0, 10.0],
        subdivide: true,
    };
    let track = Track::lay(&irregular(), &options, &[1.5, 0.0]);
    // 5 -> 11 is cut into three steps of 2.
    assert_eq!(track.times, vec![2.0, 3.0, 5.0, 7.0, 9.0, 11.0, 12.0]);
    assert_eq!(
        track.rows,
        vec![Some(0), Some(1), Some(2), None, None, Some(3), Some(4)]
    );
    assert_eq!(track.steps, vec![1.0, 2.0, 2.0, 2.0, 2.0, 1.0, 0.0]);
    assert_eq!(track.inputs[0], vec![0.5, 0.5, 1.0, 1.0, 1.0, 1.0, 0.0]);
    // State 0 starts at its initial value 1.5 (no cell at the first row, not known); its
    // cells 4 @ 5 and 10 @ 12 are 7 apart, beyond its gap limit 3: the cut knots hold the
    // provisional interpolant, not known.
    assert_eq!(track.states[0][0], 1.5);
    assert_eq!(
        track.known[0],
        vec![false, true, true, false, false, false, true]
    );
    assert_eq!(
        track.measured[0],
        vec![false, true, true, false, false, false, true]
    );
    assert!((track.states[0][3] - (4.0 + 6.0 * 2.0 / 7.0)).abs() < 1e-12);
    // State 1: 3 @ 5 and 9 @ 11 are 6 apart, within its limit 10: interpolated, known.
    let expected = [1.0, 5.0 / 3.0, 3.0, 5.0, 7.0, 9.0, 7.0];
    for (found, wanted) in track.states[1].iter().zip(expected) {
        assert!((found - wanted).abs() < 1e-12, "{:?}", track.states[1]);
    }
    assert!(track.known[1].iter().all(|&k| k));
    assert!(!track.fully_known());
    // The model's fill replaces only unknown knots.
    let mut filled = track.clone();
    filled.fill(0, &[9.0; 7]);
    assert_eq!(filled.states[0], vec![9.0, 2.0, 4.0, 9.0, 9.0, 9.0, 10.0]);
}

#[test]
fn positions_map_times_onto_knots() {
    let options = GridOptions {
        max_step: 10.0,
        gap_limits: vec![10.0, 10.0],
        subdivide: true,
    };
    let track = Track::lay(&irregular(), &options, &[2.0, 0.0]);
    assert_eq!(track.position(2.0), 0.0);
    assert_eq!(track.position(4.0), 1.5);
    assert_eq!(track.position(8.0), 2.5);
    assert_eq!(track.position(-5.0), 0.0);
    assert_eq!(track.position(50.0), 4.0);
    // Half-way through the step from knot 2 (5 -> 11), three units back: time 5.
    assert_eq!(track.stage_position(2, 0.5, (1, 3.0)), 2.0);
    // Before the record: a negative position (held history there).
    assert!(track.stage_position(0, 0.0, (1, 1.0)) < 0.0);
    assert!((interpolate(&track.states[1], 1.5) - (5.0 / 3.0 + 3.0) / 2.0).abs() < 1e-12);
    assert_eq!(hold(&track.inputs[0], 1.5, false), 0.5);
    assert_eq!(hold(&track.inputs[0], 2.0, true), 0.5);
    assert!(track.known_between(1, 0.5, 3.5));
}

/// A uniform record on a grid of its own step: knots are rows, positions are arithmetic.
#[test]
fn a_uniform_complete_record_is_its_own_grid() {
    let times: Vec<f64> = (0..10).map(|i| 0.5 * i as f64).collect();
    let values: Vec<f64> = times.iter().map(|t| t * t).collect();
    let record = Record::complete(
        "u",
        times.clone(),
        vec![vec![0.0; 10]],
        vec![values.clone()],
    );
    let options = GridOptions {
        max_step: 0.5,
        gap_limits: vec![0.5],
        subdivide: true,
    };
    let track = Track::lay(&record, &options, &[]);
    assert_eq!(track.times, times);
    assert_eq!(track.uniform, Some(0.5));
    assert_eq!(track.states[0], values);
    assert!(track.fully_known());
    assert_eq!(track.stage_position(6, 0.5, (2, 1.0)), 2.5);
}
