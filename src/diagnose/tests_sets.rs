//! The withheld-effect cases on data sets: each full record split into 3 experiments and
//! thinned to 30 % of its cells (irregular times, missing cells), which must credit the
//! same effects as the full record; and the behaviour of the diagnosis on data sets (starts
//! not measured, held-out experiments, bad input).

use super::tests::*;
use super::*;
use crate::record::Record;
use crate::solve::fit::FitError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Cuts `full` into `experiments` contiguous pieces of (nearly) equal length named `e1`,
/// `e2`, ... Each keeps its first row whole (an experiment starts with a full assay); at
/// every later row each state cell is kept with probability `keep`, and a row is kept only
/// if it keeps a cell or an input changes there (inputs are logged at every change). The
/// clean values follow the rows kept. Deterministic for a `seed`; `scripts/split_thin.py`
/// does the same on CSV files.
pub(super) fn split_and_thin(
    full: &Simulated,
    experiments: usize,
    keep: f64,
    seed: u64,
) -> Vec<Simulated> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let record = &full.record;
    let rows = record.len();
    (0..experiments)
        .map(|e| {
            let (start, end) = (e * rows / experiments, (e + 1) * rows / experiments);
            let mut kept: Vec<usize> = Vec::new();
            let mut cells: Vec<Vec<Option<f64>>> = vec![Vec::new(); record.states.len()];
            for row in start..end {
                let first = row == start;
                let drawn: Vec<Option<f64>> = (record.states.iter())
                    .map(|column| column[row].filter(|_| first || rng.gen::<f64>() < keep))
                    .collect();
                let changed =
                    !first && (record.inputs.iter()).any(|column| column[row] != column[row - 1]);
                if first || changed || drawn.iter().any(Option::is_some) {
                    kept.push(row);
                    for (column, cell) in cells.iter_mut().zip(drawn) {
                        column.push(cell);
                    }
                }
            }
            let pick = |column: &Vec<f64>| kept.iter().map(|&r| column[r]).collect::<Vec<f64>>();
            let mut thinned = Record::complete(
                &format!("e{}", e + 1),
                pick(&record.times),
                record.inputs.iter().map(pick).collect(),
                Vec::new(),
            );
            thinned.states = cells;
            Simulated {
                record: thinned,
                clean: full.clean.iter().map(pick).collect(),
            }
        })
        .collect()
}

/// 3 experiments, 30 % of the cells.
fn thinned(full: &Simulated) -> Vec<Simulated> {
    split_and_thin(full, 3, 0.3, 17)
}

const CHEMOSTAT_MODEL: &str = "models/diagnose/chemostat/model.gbm";

#[test]
fn splitting_and_thinning_keeps_starts_inputs_and_a_share_of_cells() {
    let full = chemostat("truth_decay.gbm");
    let sets = thinned(&full);
    assert_eq!(sets.len(), 3);
    let cells: usize = sets.iter().map(|s| s.record.measured_cells()).sum();
    let share = cells as f64 / full.record.measured_cells() as f64;
    assert!((share - 0.3).abs() < 0.03, "{share}");
    for set in &sets {
        let record = &set.record;
        assert!(record.uniform_step().is_none(), "irregular times");
        assert!(
            record.states.iter().all(|c| c[0].is_some()),
            "first row whole"
        );
        // The held inputs are the full record's at every kept time.
        for (row, &t) in record.times.iter().enumerate() {
            let original = t as usize;
            assert_eq!(record.inputs[0][row], full.record.inputs[0][original]);
            assert_eq!(set.clean[0][row], full.clean[0][original]);
        }
    }
}

/// Diagnoses the split and thinned records, checks that the credited effects are those of
/// the full record and that the credited set leaves a gap within `tolerance` of the noise.
fn check_thinned(model: &str, full: &Simulated, effects: &[&str], options: &Options) -> Report {
    let sets = thinned(full);
    let report = run(model, &sets, options);
    check_credited(&report, noise_gap(model, &sets), effects, 0.5);
    assert_eq!(report.split.train_experiments, vec!["e1", "e2", "e3"]);
    report
}

#[test]
fn thinned_a_missing_hidden_lag_is_still_found_with_history() {
    let model = "models/diagnose/chemostat/nolag.gbm";
    let report = check_thinned(
        model,
        &chemostat("truth.gbm"),
        &["enzyme_holdup"],
        &mid_run_starts(),
    );
    assert!((param(&report, "tau_E") / 20.0 - 1.0).abs() < 0.1);
    assert!(report.history_dependent, "{}", render::text(&report));
}

/// Experiments cut from one run start mid-run: the hidden enzyme of `e2` and `e3` is not
/// at its declared start (`E_ref`), so its starts are unknowns (`--fit-initial`). Held at
/// the declared value, the wrong starts leave a training gap that a refitted residence
/// time (`refit theta`) absorbs.
fn mid_run_starts() -> Options {
    Options {
        fit_initial: true,
        ..Options::default()
    }
}

#[test]
fn thinned_a_missing_factor_is_still_found() {
    let full = chemostat("truth_inhibition.gbm");
    let report = check_thinned(
        CHEMOSTAT_MODEL,
        &full,
        &["product_inhibition"],
        &mid_run_starts(),
    );
    assert!((param(&report, "K_P") / 0.02 - 1.0).abs() < 0.2);
}

#[test]
fn thinned_a_missing_balance_term_is_still_found() {
    let full = chemostat("truth_decay.gbm");
    let report = check_thinned(
        CHEMOSTAT_MODEL,
        &full,
        &["product_decay"],
        &Options::default(),
    );
    assert_eq!(tests::locus(&report), ("P", LocusKind::Balance));
}

#[test]
fn thinned_without_a_gap_nothing_is_credited() {
    let sets = thinned(&chemostat("truth.gbm"));
    let report = run(CHEMOSTAT_MODEL, &sets, &Options::default());
    assert!(!report.significant, "{}", render::text(&report));
    assert_eq!(report.credited, None);
}

#[test]
fn thinned_two_withheld_effects_are_still_credited_in_order() {
    let full = chemostat("truth_two.gbm");
    let sets = thinned(&full);
    let report = run(CHEMOSTAT_MODEL, &sets, &Options::default());
    // The pair's gap within 1.5x of the truth's.
    check_credited(
        &report,
        noise_gap(CHEMOSTAT_MODEL, &sets),
        &["product_decay", "product_inhibition"],
        0.5,
    );
}

/// The effects only: the locus search (most of the cost) is skipped, and says so.
fn effects_only() -> Options {
    Options {
        locate: false,
        ..Options::default()
    }
}

#[test]
fn thinned_the_burden_is_still_found() {
    let model = "models/diagnose/bioreactor/noburden.gbm";
    let full = bioreactor("models/bioreactor/truth.gbm");
    let report = check_thinned(model, &full, &["burden"], &effects_only());
    assert!((param(&report, "K_EB") / 0.5 - 1.0).abs() < 0.1);
    assert!(report.locus.is_empty() && !report.memory.history_needed);
    let text = render::text(&report);
    assert!(
        text.contains("not probed: the free corrections were not tried"),
        "{text}"
    );
}

#[test]
fn thinned_cell_death_is_still_found() {
    let model = "models/diagnose/bioreactor/nodeath.gbm";
    let full = bioreactor("models/diagnose/bioreactor/truth_death.gbm");
    let report = check_thinned(model, &full, &["death"], &effects_only());
    assert!((param(&report, "k_d") / 0.006 - 1.0).abs() < 0.2);
}

/// Records cut from one long run start with the enzyme's mRNA and level away from their
/// declared values: with `--fit-initial` they are fitted per experiment.
#[test]
fn thinned_the_slow_expression_lag_is_still_found_with_fitted_hidden_starts() {
    let model = "models/diagnose/expression/nolag.gbm";
    let options = Options {
        fit_initial: true,
        ..Options::default()
    };
    let report = check_thinned(model, &expression(), &["expression_lag"], &options);
    assert!(report.memory.history_needed, "{}", render::text(&report));
    assert!(
        report.locus[0].kind != LocusKind::Balance,
        "{:?}",
        report.locus
    );
    // The base model has no hidden state: the fitted starts are the effect's.
    let names: Vec<&str> = (report.effects[0].fit.estimates.iter())
        .map(|e| e.name.as_str())
        .collect();
    assert!(
        names.contains(&"M@e2") && names.contains(&"E@e3"),
        "{names:?}"
    );
}

/// A measured state with no cell at an experiment's first row and no declared initial value
/// starts from a value fitted with the params; the fit recovers the truth's start.
#[test]
fn an_unmeasured_start_without_declaration_is_fitted() {
    let source = "model decay\ninput u\nstate X\nparam k = 0.5 positive\nder X = -k * X + u\n";
    let compiled = crate::driver::compile("decay", source, &[]).unwrap();
    // X(t) = 2 e^{-0.1 t} under u = 0, measured from t = 3 on (no cell at t = 0).
    let times: Vec<f64> = (0..60).map(|k| k as f64).collect();
    let states = vec![times.iter().map(|t| 2.0 * (-0.1 * t).exp()).collect()];
    let mut record = Record::complete("a", times.clone(), vec![vec![0.0; 60]], states);
    for cell in &mut record.states[0][..3] {
        *cell = None;
    }
    let problem = Problem {
        name: "decay",
        source,
        checked: &compiled.checked,
        model: &compiled.model,
        records: &[record],
        held_out: &[],
    };
    let report = diagnose(&problem, &Options::default(), &|_| {}).unwrap();
    let start = &report.initial_states[0];
    assert_eq!(
        (start.state.as_str(), start.origin.as_str()),
        ("X", "fitted")
    );
    assert!((start.value - 2.0).abs() < 1e-6, "{start:?}");
    assert!((report.fitted_params["k"] - 0.1).abs() < 1e-6);
    let estimate = report
        .base_fit
        .estimates
        .iter()
        .find(|e| e.name == "X@a")
        .unwrap();
    assert!(estimate.identified, "{estimate:?}");
}

/// Whole experiments held out: scored after their first row (the run's start), never
/// fitted.
#[test]
fn held_out_experiments_are_scored_after_their_start() {
    let full = chemostat("truth_decay.gbm");
    let sets = thinned(&full);
    let source = crate::driver::read_source(&root().join(CHEMOSTAT_MODEL)).unwrap();
    let compiled = crate::driver::compile(CHEMOSTAT_MODEL, &source, &[]).unwrap();
    let records: Vec<Record> = sets.iter().map(|s| s.record.clone()).collect();
    let problem = Problem {
        name: CHEMOSTAT_MODEL,
        source: &source,
        checked: &compiled.checked,
        model: &compiled.model,
        records: &records[..2],
        held_out: &records[2..],
    };
    let options = Options {
        restarts: 1,
        ..Options::default()
    };
    let report = diagnose(&problem, &options, &|_| {}).unwrap();
    assert_eq!(report.split.holdout, "experiments");
    assert_eq!(report.split.train_experiments, vec!["e1", "e2"]);
    assert_eq!(report.split.scored.len(), 1);
    assert_eq!(report.split.scored[0].experiment, "e3");
    assert_eq!(report.split.scored[0].t_start, records[2].times[1]);
    assert_eq!(report.credited.as_deref(), Some("product_decay"));
    // Offline errors only where the previous row measured the same state.
    assert!(report
        .states
        .iter()
        .all(|s| s.offline.is_some_and(f64::is_finite)));
}

#[test]
fn bad_options_and_data_are_refused_with_their_codes() {
    let sets = thinned(&chemostat("truth_decay.gbm"));
    let code = |result: Result<Report, DiagnoseError>| {
        let error = result.unwrap_err();
        miette::Diagnostic::code(&error).map(|c| c.to_string())
    };
    let with = |options: Options| try_run(CHEMOSTAT_MODEL, &sets, &options);
    let fraction = Options {
        val_fraction: Some(1.5),
        ..Options::default()
    };
    assert_eq!(code(with(fraction)).as_deref(), Some("gbm::E0805"));
    let span = Options {
        span: Some(-1.0),
        ..Options::default()
    };
    assert_eq!(code(with(span)).as_deref(), Some("gbm::E0805"));
    // A tail that leaves an experiment without a held-out measured row.
    let mut short = sets.clone();
    short[0].record = short[0].record.rows(0..3);
    let tiny = Options {
        val_fraction: Some(0.1),
        ..Options::default()
    };
    let error = try_run(CHEMOSTAT_MODEL, &short, &tiny).unwrap_err();
    assert!(
        matches!(
            error,
            DiagnoseError::Fit(FitError::TailTooSmall {
                train: 3,
                test: 0,
                ..
            })
        ),
        "{error}"
    );
}

/// The product read only through an absorbance, `A = 2 P + 0.01` (an `output` named as the
/// data's column, records spec 4): the diagnosis fits and scores it like the state and
/// credits the missing decay, as it does with P measured (thinned, one experiment from the
/// run's start, whose declared P is the truth's).
#[test]
fn a_gap_read_through_a_measured_output_is_found_as_through_its_state() {
    let sets = split_and_thin(&chemostat("truth_decay.gbm"), 1, 0.3, 17);
    let source = crate::driver::read_source(&root().join(CHEMOSTAT_MODEL)).unwrap();
    let source =
        format!("{source}\n## Absorbance of the product.\noutput A [mol/L] = 2 * P + 0.01\n");
    let compiled = crate::driver::compile("observed", &source, &[]).unwrap();
    let mut record = sets[0].record.clone();
    let rows = record.len();
    let p = std::mem::replace(&mut record.states[1], vec![None; rows]);
    record.observables = vec![crate::record::Observable {
        output: 0,
        name: "A".into(),
        cells: p.iter().map(|cell| cell.map(|v| 2.0 * v + 0.01)).collect(),
    }];
    let problem = Problem {
        name: "observed",
        source: &source,
        checked: &compiled.checked,
        model: &compiled.model,
        records: &[record],
        held_out: &[],
    };
    let report = diagnose(&problem, &Options::default(), &|_| {}).unwrap();
    let text = render::text(&report);
    assert!(report.significant, "{text}");
    assert_eq!(report.selection.credited, ["product_decay"], "{text}");
    let cells = |name: &str| {
        report
            .states
            .iter()
            .find(|s| s.name == name)
            .map(|s| s.cells)
    };
    assert_eq!(report.states.len(), 3, "{text}");
    assert_eq!(cells("P"), Some(0), "P is not measured: {text}");
    let p = report.states.iter().find(|s| s.name == "P").unwrap();
    assert!(p.noise_estimate.starts_with("not measured"), "{text}");
    assert!(cells("A").is_some_and(|c| c > 0), "{text}");
    assert!(
        report
            .states
            .iter()
            .all(|s| s.online.is_none_or(f64::is_finite)),
        "{text}"
    );
    let k_p = param(&report, "k_P");
    assert!((k_p / 0.01 - 1.0).abs() < 0.2, "k_P {k_p}\n{text}");
}
