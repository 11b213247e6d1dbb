//! Time stamps that jitter (issue 24): a plate reader's times scatter by about `1e-7` h
//! around a uniform grid. Such a record trains on the same pairs, windows and targets as
//! its rounded version; a genuinely irregular record stays irregular; steps with a target
//! that do not train are counted and reported.

use crate::engine::pairs::{stage_fractions, PairTable};
use crate::ir::Activation;
use crate::record::Record;
use crate::train::fixtures::{ClosureSpec, ModelBuilder, OutputSpec};
use crate::train::prepare::Layout;
use crate::train::*;

/// The grid step: ten minutes in hours.
const STEP: f64 = 1.0 / 6.0;
/// Rows of the records.
const ROWS: usize = 600;

/// A closure that looks back at `x` and `u` (delay 3 steps), and a state `y` that no
/// embedding reads (its gap limit is the grid's longest step).
fn model() -> ir::Model {
    ModelBuilder::new("jitter")
        .input("u")
        .state("x")
        .state("y")
        .closure(ClosureSpec {
            name: "c",
            outputs: vec![OutputSpec {
                name: "o",
                scale: Some(0.5),
                prior: None,
            }],
            observe: &["x", "u"],
            delay: 0.5,
            dim: 3,
            hidden: vec![4],
            activation: Activation::Tanh,
        })
        .der("x", "o - 0.1 * x")
        .der("y", "u - 0.2 * y")
        .build()
}

/// A jitter of `size` for row `i`, of alternating sign and 0.8 to 1 of `size` (a fixed
/// scrambling of `i`), so that steps scatter by up to about twice `size`.
fn jitter(i: usize, size: f64) -> f64 {
    let scrambled = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
    let share = 0.8 + 0.2 * scrambled as f64 / (1u64 << 53) as f64;
    let sign = if i.is_multiple_of(2) { 1.0 } else { -1.0 };
    sign * size * share
}

/// The record at `times`: `u` switching every 17 rows, `x` and `y` smooth; `y` measured
/// only at every `y_every`-th row.
fn record(times: Vec<f64>, y_every: usize) -> Record {
    let rows = times.len();
    let mut record = Record::complete(
        "plate",
        times,
        vec![(0..rows).map(|i| ((i / 17) % 3) as f64 * 0.5).collect()],
        vec![
            (0..rows).map(|i| 1.0 + (0.05 * i as f64).sin()).collect(),
            (0..rows).map(|i| (0.03 * i as f64).cos()).collect(),
        ],
    );
    for (row, cell) in record.states[1].iter_mut().enumerate() {
        if row % y_every != 0 {
            *cell = None;
        }
    }
    record
}

/// The grid's times, exact (the rounded export).
fn rounded() -> Vec<f64> {
    (0..ROWS).map(|i| i as f64 * STEP).collect()
}

/// The grid's times with a jitter of up to `1e-7`, printed with nine decimals.
fn jittered() -> Vec<f64> {
    (0..ROWS)
        .map(|i| format!("{:.9}", i as f64 * STEP + jitter(i, 1e-7)))
        .map(|text| text.parse().unwrap())
        .collect()
}

/// The layout of one record that trains on every row.
fn layout(model: &ir::Model, record: &Record) -> Layout {
    let train = [record.clone()];
    let data = TrainingData {
        train: &train,
        validation: &[],
        part: Part::All,
    };
    Layout::new(model, &data, &TrainOptions::default()).unwrap()
}

#[test]
fn a_jittered_record_trains_on_the_pairs_of_its_rounded_version() {
    let model = model();
    let times = jittered();
    // The jitter is more than the relative 1e-6 of the step that once made a grid uniform.
    let widest = (times.windows(2))
        .map(|w| (w[1] - w[0] - STEP).abs())
        .fold(0.0, f64::max);
    assert!(widest > 1e-6 * STEP, "{widest}");
    let (exact, shaken) = (record(rounded(), 1), record(times, 1));
    let (a, b) = (layout(&model, &exact), layout(&model, &shaken));
    for layout in [&a, &b] {
        assert!(layout.tracks[0].uniform.is_some());
        // One knot per row (no interval cut), and every step trains: 600 rows, 599 steps.
        assert_eq!(layout.tracks[0].len(), ROWS);
        assert_eq!(layout.pairs.len(), ROWS - 1);
        assert_eq!(layout.dropped, None);
    }
    assert_eq!(a.pairs, b.pairs);
    // The windows of the multi-step objective tile the same training knots.
    assert_eq!(a.trainings, b.trainings);
    let fractions = stage_fractions(model.dynamics, 1);
    let all: Vec<usize> = (0..a.pairs.len()).collect();
    let batch = |layout: &Layout| {
        PairTable::build(&model, &layout.tracks, &layout.pairs, &[], &fractions).batch(&all)
    };
    let (one, other) = (batch(&a), batch(&b));
    assert_eq!(one.targets, other.targets);
    assert_eq!(one.inputs, other.inputs);
    assert_eq!(one.embeddings, other.embeddings);
    let steps = one.step_sizes.iter().zip(&other.step_sizes);
    assert!(steps.into_iter().all(|(p, q)| (p - q).abs() < 1e-8 * STEP));
}

#[test]
fn an_irregular_record_stays_irregular() {
    let model = model();
    let times: Vec<f64> = (0..ROWS)
        .map(|i| i as f64 * STEP + 0.25 * STEP * (1.3 * i as f64).sin())
        .collect();
    let irregular = record(times, 1);
    assert_eq!(irregular.uniform_step(), None);
    // Its tolerance is capped at 1 % of its median step (within a few per cent of STEP).
    assert!(irregular.time_tolerance() <= 0.011 * STEP);
    let layout = layout(&model, &irregular);
    assert_eq!(layout.tracks[0].uniform, None);
    // A jittered record with a missing row is irregular too.
    let mut gap = jittered();
    gap.remove(300);
    assert_eq!(record(gap, 1).uniform_step(), None);
}

/// `y`, which no embedding reads, measured at every third row: its interpolant across
/// three steps is longer than its gap limit (one step), so only the steps that start at
/// one of its cells train, and the run says how many do not and why.
#[test]
fn steps_that_do_not_train_are_counted_and_reported() {
    let model = model();
    let sparse = record(jittered(), 3);
    let layout = layout(&model, &sparse);
    // Steps 0..599 all have a target (`x` at every row); those from rows 0, 3, ..., 597
    // train: 200 of them.
    assert_eq!(layout.pairs.len(), 200);
    let dropped = layout.dropped.clone().unwrap();
    assert_eq!((dropped.with_target, dropped.dropped), (599, 399));
    assert_eq!(dropped.causes.len(), 1);
    assert_eq!(
        (dropped.causes[0].state.as_str(), dropped.causes[0].steps),
        ("y", 399)
    );
    assert!(
        (dropped.causes[0].gap_limit - STEP).abs() < 1e-6,
        "{dropped:?}"
    );
    // One-step training tells its caller and keeps the warning in its report, which reads
    // back (the multi-step objective trains those steps in windows and says so instead).
    let mut heard = Vec::new();
    let one_step = Recipe {
        objective: Objective::OneStep,
        ..Recipe::default()
    };
    let options = TrainOptions {
        epochs: 1,
        seed: 3,
        ..Default::default()
    };
    let train = [sparse];
    let data = TrainingData {
        train: &train,
        validation: &[],
        part: Part::All,
    };
    let trained = crate::train::train_with(&model, &data, &options, &one_step, &mut |event| {
        if let Event::Warning(warning) = event {
            heard.push(warning.to_string());
        }
    })
    .unwrap();
    assert_eq!(heard.len(), 1);
    assert!(heard[0].starts_with("399 of 599 steps"), "{}", heard[0]);
    assert!(heard[0].contains("`y` at 399"), "{}", heard[0]);
    assert_eq!(trained.report.train_pairs, 200);
    let warnings = &trained.report.warnings;
    assert_eq!(warnings, &vec![Warning::DroppedPairs(dropped)]);
    let json = serde_json::to_string(warnings).unwrap();
    let back: Vec<Warning> = serde_json::from_str(&json).unwrap();
    assert_eq!(&back, warnings);
}

/// A stiffness warning saved before dropped steps were reported reads back as one.
#[test]
fn saved_stiffness_warnings_read_back() {
    let saved = r#"[{"balance":"S","eigenvalue":-40.0,"step":1.0,"substeps":1,
        "stable_step":0.0696,"substeps_needed":15}]"#;
    let warnings: Vec<Warning> = serde_json::from_str(saved).unwrap();
    assert!(matches!(&warnings[0], Warning::Stiffness(w) if w.substeps_needed == 15));
}
