//! Tests of the split: its parts, starts and overrides.

use super::*;

fn record(name: &str, rows: usize) -> Record {
    Record::complete(
        name,
        (0..rows).map(|k| k as f64).collect(),
        vec![vec![0.5; rows]],
        vec![(0..rows).map(|k| k as f64).collect()],
    )
}

fn model() -> Model {
    let source = "model m\ninput u\nstate X = 1\nparam k = 1\nder X = -k * X + u\n";
    crate::driver::compile("m", source, &[]).unwrap().model
}

#[test]
fn a_tail_split_scores_the_last_rows_and_normalises_on_the_rest() {
    let split = Split::new(
        &model(),
        vec![record("a", 100)],
        vec![],
        (Holdout::Tail(0.3), false),
    )
    .unwrap();
    assert_eq!(
        split.parts[0],
        Part {
            train: 0..70,
            test: 70..100
        }
    );
    // 0..70: mean 34.5, population variance (70^2 - 1) / 12.
    let norm = &split.normalisation;
    assert!((norm.state_mean[0] - 34.5).abs() < 1e-12);
    assert!((norm.state_std[0] - ((4900.0f64 - 1.0) / 12.0).sqrt()).abs() < 1e-12);
    assert_eq!(split.measured_rows(), (70, 30));
}

#[test]
fn a_tail_counts_measured_rows_not_rows() {
    // Rows 0..20, the state measured at even rows only: 10 measured rows, 3 held out.
    let mut thin = record("a", 20);
    for (row, cell) in thin.states[0].iter_mut().enumerate() {
        if row % 2 == 1 {
            *cell = None;
        }
    }
    let other = record("b", 30);
    let split = Split::new(
        &model(),
        vec![thin, other],
        vec![],
        (Holdout::Tail(0.3), false),
    )
    .unwrap();
    assert_eq!(
        split.parts[0],
        Part {
            train: 0..14,
            test: 14..20
        }
    );
    assert_eq!(split.measured_rows(), (7 + 21, 3 + 9));
}

#[test]
fn held_out_experiments_are_scored_after_their_start_row() {
    let split = Split::new(
        &model(),
        vec![record("a", 12)],
        vec![record("b", 11)],
        (Holdout::Experiments, false),
    )
    .unwrap();
    assert_eq!(split.training().count(), 1);
    assert_eq!(
        split.scored().map(|(i, _, r)| (i, r)).collect::<Vec<_>>(),
        vec![(1, 1..11)]
    );
}

#[test]
fn too_small_parts_say_what_each_needs_and_got() {
    // A sparse held-out experiment is scored: 5 rows after its start.
    let sparse = Split::new(
        &model(),
        vec![record("a", 34)],
        vec![record("b", 6)],
        (Holdout::Experiments, false),
    )
    .unwrap();
    assert_eq!(sparse.measured_rows(), (34, 5));
    // One with nothing after its start is not, nor a training part under 10 rows.
    let error = Split::new(
        &model(),
        vec![record("a", 9)],
        vec![record("b", 1)],
        (Holdout::Experiments, false),
    )
    .unwrap_err();
    assert_eq!(
        error.to_string(),
        "expected at least 10 measured rows in the training part and one in the held-out \
         part, found 9 and 0 (experiment `b` held out)"
    );
    let error = Split::new(
        &model(),
        vec![record("a", 3)],
        vec![],
        (Holdout::Tail(0.1), false),
    )
    .unwrap_err();
    assert!(
        matches!(
            error,
            FitError::TailTooSmall {
                train: 3,
                test: 0,
                ..
            }
        ),
        "{error}"
    );
}

#[test]
fn starts_come_from_cells_declarations_fits_or_first_values() {
    let source = "model m\ninput u\nstate X = 1\nstate Y\nparam k = 1\n\
                  der X = -k * X + u\nder Y = X - Y\n";
    let model = crate::driver::compile("m", source, &[]).unwrap().model;
    let gapped = |name: &str| {
        let mut r = Record::complete(
            name,
            (0..12).map(|k| k as f64).collect(),
            vec![vec![0.5; 12]],
            vec![(0..12).map(|k| k as f64).collect(), vec![2.0; 12]],
        );
        r.states[0][0] = None;
        r.states[1][0] = None;
        r.states[1][1] = None;
        r
    };
    let split = Split::new(
        &model,
        vec![gapped("a")],
        vec![gapped("b")],
        (Holdout::Experiments, false),
    )
    .unwrap();
    assert_eq!(split.starts[0], vec![Start::Declared, Start::Fitted(0)]);
    assert_eq!(split.starts[1], vec![Start::Declared, Start::Fixed(2.0)]);
    assert_eq!(split.fitted_starts, vec![(0, 1)]);
    assert_eq!(split.overrides(0, &[7.0], 0), vec![None, Some(7.0)]);
    assert_eq!(split.overrides(1, &[7.0], 0), vec![None, Some(2.0)]);
    // Hidden starts fitted: one per hidden state of each training record, after the
    // measured ones; a record that is only scored keeps the declared values.
    let mut with_hidden = split.clone();
    with_hidden.fit_hidden = true;
    assert_eq!(with_hidden.fitted_count(2), 1 + 2);
    assert_eq!(
        with_hidden.overrides(0, &[7.0, 8.0, 9.0], 2),
        vec![None, Some(7.0), Some(8.0), Some(9.0)]
    );
    assert_eq!(
        with_hidden.overrides(1, &[7.0, 8.0, 9.0], 2),
        vec![None, Some(2.0), None, None]
    );
}

/// The diagnosis's default starts: a training experiment's measured first cell is fitted
/// within 3 standard deviations of its declared noise at that cell; a state whose noise is
/// not known to be above zero (undeclared, and the data a line with no scatter) keeps its
/// exact start, and a held-out experiment starts at its cells.
#[test]
fn uncertain_first_cells_are_fitted_within_their_noise() {
    let source = "model m\ninput u\nstate X = 1\nstate Y = 1\nparam k = 1\n\
                  noise X = 10 %\nder X = -k * X + u\nder Y = X - Y\n";
    let model = crate::driver::compile("m", source, &[]).unwrap().model;
    let complete = |name: &str| {
        Record::complete(
            name,
            (0..12).map(|k| k as f64).collect(),
            vec![vec![0.5; 12]],
            vec![
                (0..12).map(|k| 2.0 + k as f64).collect(),
                (0..12).map(|k| k as f64).collect(),
            ],
        )
    };
    let mut split = Split::new(
        &model,
        vec![complete("a")],
        vec![complete("b")],
        (Holdout::Experiments, false),
    )
    .unwrap();
    split.declare_noise(&model.noise);
    crate::solve::fit::noise::fit_uncertain_starts(&mut split, &model);
    assert_eq!(split.starts[0], vec![Start::CellFitted(0), Start::Cell]);
    assert_eq!(split.starts[1], vec![Start::Cell, Start::Cell]);
    assert_eq!(split.fitted_starts, vec![(0, 0)]);
    // X's first cell is 2: 10 % noise is 0.2, the bound 3 of them either side.
    let (lo, hi) = split.start_bounds[0].unwrap();
    assert!(
        (lo - 1.4).abs() < 1e-12 && (hi - 2.6).abs() < 1e-12,
        "{lo} {hi}"
    );
}
