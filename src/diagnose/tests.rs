//! The withheld-effect cases of models/diagnose/ (README there) on their full records: "real"
//! data simulated from a truth model with relative noise, diagnosed with a model that lacks
//! one mechanism (two in the two-effect case). `tests_sets.rs` runs the same cases split
//! into experiments and thinned.
//!
//! Independent references: the truth's own parameter values, and the noise actually
//! injected (a perfect model's held-out gap is the mean squared normalised noise at the
//! held-out cells, computed from the clean and noisy records without any fitting).

use super::*;
use crate::record::Record;
use crate::solve::fit::split::{Holdout, Split};
use crate::solve::fit::FitError;
use crate::solve::ode::SimOptions;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::path::PathBuf;

/// A simulated experiment: the noisy record and its clean measured states at each row.
#[derive(Debug, Clone)]
pub(super) struct Simulated {
    pub record: Record,
    pub clean: Vec<Vec<f64>>,
}

/// The truth model `truth` under one input program per input, measured states perturbed
/// by `y (1 + 0.01 z)`, `z` standard normal (as `gbc simulate --noise 0.01`).
pub(super) fn simulate(truth: &str, program: &str, t_end: f64, seed: u64) -> Simulated {
    let model = crate::driver::compile_file(&root().join(truth), &[])
        .unwrap()
        .model;
    let signals: Vec<_> = (model.inputs.iter())
        .map(|input| {
            let program = crate::signal::parse_program(program).unwrap();
            program.generate(input, 0.0, t_end, 1.0).unwrap()
        })
        .collect();
    let trajectory =
        crate::solve::ode::simulate(&model, &signals, &SimOptions::new(t_end, 1.0)).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noisy = (trajectory.states.iter())
        .map(|values| {
            (values.iter())
                .map(|v| {
                    let z: f64 = StandardNormal.sample(&mut rng);
                    v * (1.0 + 0.01 * z)
                })
                .collect()
        })
        .collect();
    let record = Record::complete(truth, trajectory.times, trajectory.inputs, noisy);
    Simulated {
        record,
        clean: trajectory.states,
    }
}

pub(super) fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The chemostat cases: 1200 s at 1 s, enzyme steps held 10-60 s.
pub(super) fn chemostat(truth: &str) -> Simulated {
    let truth = format!("models/diagnose/chemostat/{truth}");
    simulate(&truth, "steps(hold=10..60, seed=4)", 1200.0, 7)
}

/// The bioreactor cases: 800 h at 1 h, light steps held 5-40 h.
pub(super) fn bioreactor(truth: &str) -> Simulated {
    simulate(truth, "steps(hold=5..40, seed=3)", 800.0, 11)
}

/// The expression case: 800 h at 1 h, light steps held 5-40 h.
pub(super) fn expression() -> Simulated {
    let truth = "models/diagnose/expression/truth.gbm";
    simulate(truth, "steps(hold=5..40, seed=3)", 800.0, 11)
}

/// Diagnoses the model file `model` on the experiments `sets` (tails of 30 % held out).
pub(super) fn run(model: &str, sets: &[Simulated], options: &Options) -> Report {
    try_run(model, sets, options).unwrap()
}

pub(super) fn try_run(
    model: &str,
    sets: &[Simulated],
    options: &Options,
) -> Result<Report, DiagnoseError> {
    let source = crate::driver::read_source(&root().join(model)).unwrap();
    let compiled = crate::driver::compile(model, &source, &[]).unwrap();
    let records: Vec<Record> = sets.iter().map(|s| s.record.clone()).collect();
    let problem = Problem {
        name: model,
        source: &source,
        checked: &compiled.checked,
        model: &compiled.model,
        records: &records,
        held_out: &[],
    };
    diagnose(&problem, options, &|_| {})
}

/// The held-out gap of a perfect model on `sets` split as the diagnosis splits them (the
/// last 30 % of each experiment's measured rows): the injected noise at the scored cells,
/// normalised by the training cells' standard deviation.
pub(super) fn noise_gap(model: &str, sets: &[Simulated]) -> f64 {
    let model = crate::driver::compile_file(&root().join(model), &[])
        .unwrap()
        .model;
    let records = sets.iter().map(|s| s.record.clone()).collect();
    let split = Split::new(
        &model,
        records,
        vec![],
        (Holdout::Tail(DEFAULT_TAIL), false),
    )
    .unwrap();
    let (mut sum, mut count) = (0.0, 0);
    for (index, record, rows) in split.scored() {
        for row in rows {
            for (k, cells) in record.states.iter().enumerate() {
                if let Some(value) = cells[row] {
                    let noise = value - sets[index].clean[k][row];
                    sum += (noise / split.normalisation.state_std[k]).powi(2);
                    count += 1;
                }
            }
        }
    }
    sum / count as f64
}

pub(super) fn param(report: &Report, name: &str) -> f64 {
    report.effects[0].params[name]
}

/// The answers every case with a gap must get right: a significant gap, the withheld
/// effects credited in order (the first also best alone and told apart from the rest), the
/// credited set's held-out gap within `tolerance` of the injected noise (what a fit of the
/// truth achieves).
pub(super) fn check_credited(report: &Report, noise: f64, effects: &[&str], tolerance: f64) {
    let text = render::text(report);
    assert!(report.significant, "{text}");
    // A refitted constant may fit better alone than any one effect (the ranking says so);
    // the best effect alone is the first credited, told apart from the rest when it leads.
    let best_effect = (report.effects.iter())
        .find(|e| super::candidates::refitted(&e.name).is_none())
        .unwrap();
    assert_eq!(best_effect.name, effects[0], "{text}");
    assert_eq!(report.credited.as_deref(), Some(effects[0]), "{text}");
    assert_eq!(report.selection.credited, effects, "{text}");
    if report.effects[0].name == effects[0] {
        assert!(report.confidence.separated, "{text}");
    }
    let after = report.selection.gap_after;
    assert!(
        (after / noise - 1.0).abs() < tolerance,
        "gap after {after}, injected noise {noise}\n{text}"
    );
}

/// The noise floor estimated from the data alone within 30 % of the injected noise.
fn check_floor(report: &Report, noise: f64) {
    assert!(
        (report.noise_floor / noise - 1.0).abs() < 0.3,
        "floor {} noise {noise}",
        report.noise_floor
    );
}

pub(super) fn locus(report: &Report) -> (&str, LocusKind) {
    (&report.locus[0].name, report.locus[0].kind)
}

/// The names of the loci tied with the best.
pub(super) fn tied(report: &Report) -> Vec<&str> {
    (report.locus.iter())
        .filter(|l| l.tied)
        .map(|l| l.name.as_str())
        .collect()
}

const CHEMOSTAT_MODEL: &str = "models/diagnose/chemostat/model.gbm";

#[test]
fn a_missing_hidden_lag_is_found_and_needs_history() {
    let sets = [chemostat("truth.gbm")];
    let model = "models/diagnose/chemostat/nolag.gbm";
    let report = run(model, &sets, &Options::default());
    check_credited(&report, noise_gap(model, &sets), &["enzyme_holdup"], 0.1);
    check_floor(&report, noise_gap(model, &sets));
    // Truth: the enzyme lags its inlet with the residence time, 20 s; kcat = 0.14 1/s.
    assert!((param(&report, "tau_E") / 20.0 - 1.0).abs() < 0.05);
    assert!((param(&report, "kcat") / 0.14 - 1.0).abs() < 0.05);
    assert_eq!(locus(&report), ("rate", LocusKind::Let));
    assert!(report.memory.probe, "{}", render::text(&report));
    assert!(report.history_dependent);
    assert_eq!(report.effects[0].adds_hidden, vec!["E".to_string()]);
    assert!(report.locus[0].bound_history < 0.5 * report.locus[0].bound_present);
}

#[test]
fn a_missing_factor_is_found_in_its_rate_and_regime() {
    let sets = [chemostat("truth_inhibition.gbm")];
    let report = run(CHEMOSTAT_MODEL, &sets, &Options::default());
    let noise = noise_gap(CHEMOSTAT_MODEL, &sets);
    check_credited(&report, noise, &["product_inhibition"], 0.1);
    check_floor(&report, noise);
    assert!((param(&report, "K_P") / 0.02 - 1.0).abs() < 0.1);
    assert_eq!(locus(&report), ("rate", LocusKind::Let));
    assert!(!report.history_dependent, "{}", render::text(&report));
    // Inhibition by the product bites where the product is high (the substrate low).
    let top = &report.regime[0];
    let high_product = (top.variable == "P" && top.highest) || (top.variable == "S" && top.lowest);
    assert!(high_product, "{:?}", report.regime);
}

#[test]
fn a_missing_balance_term_is_found_in_its_balance() {
    let sets = [chemostat("truth_decay.gbm")];
    let report = run(CHEMOSTAT_MODEL, &sets, &Options::default());
    let noise = noise_gap(CHEMOSTAT_MODEL, &sets);
    check_credited(&report, noise, &["product_decay"], 0.1);
    check_floor(&report, noise);
    assert!((param(&report, "k_P") / 0.01 - 1.0).abs() < 0.1);
    // No rate explains it: the balance comes first, alone.
    assert_eq!(locus(&report), ("P", LocusKind::Balance));
    assert_eq!(tied(&report), vec!["P"], "{:?}", report.locus);
    assert!(!report.history_dependent);
    // The learned correction of dP/dt is proportional to -P.
    let hint = &report.hints[0];
    assert!(
        hint.text.starts_with('-') && hint.text.ends_with("* P") && hint.r2 > 0.9,
        "{:?}",
        report.hints
    );
}

#[test]
fn without_a_gap_nothing_is_credited() {
    let sets = [chemostat("truth.gbm")];
    let report = run(CHEMOSTAT_MODEL, &sets, &Options::default());
    let text = render::text(&report);
    assert!(!report.significant, "{text}");
    assert_eq!(report.credited, None);
    assert!(report.selection.credited.is_empty());
    assert!((report.gap_before / noise_gap(CHEMOSTAT_MODEL, &sets) - 1.0).abs() < 0.1);
    assert!(report.effects.iter().all(|e| e.shrink < 0.1));
    assert!(
        text.contains("credited: none (no significant gap)"),
        "{text}"
    );
}

#[test]
fn two_withheld_effects_are_credited_in_order() {
    let sets = [chemostat("truth_two.gbm")];
    let report = run(CHEMOSTAT_MODEL, &sets, &Options::default());
    let noise = noise_gap(CHEMOSTAT_MODEL, &sets);
    // The decay alone explains more than the inhibition alone: it comes first. The pair's
    // gap is within 1.5x of the truth's (the injected noise).
    check_credited(
        &report,
        noise,
        &["product_decay", "product_inhibition"],
        0.5,
    );
    // Chosen among sets on the training BIC: the pair is the one accepted step and it beats
    // each of its members alone by the evidence needed; it leaves no significant training
    // gap, so no triple is tried.
    let steps = &report.selection.steps;
    let accepted: Vec<_> = steps.iter().filter(|s| s.accepted).collect();
    assert_eq!(accepted.len(), 1, "{steps:?}");
    let pair = accepted[0];
    for single in steps.iter().filter(|s| s.effects.len() == 1) {
        if pair.effects.contains(&single.effects[0]) {
            assert!(
                pair.bic <= single.bic - super::selection::EVIDENCE,
                "{steps:?}"
            );
        }
    }
    assert!(pair.gap_train <= super::SIGNIFICANCE * report.noise_floor);
    assert!(steps.iter().all(|s| s.effects.len() <= 2));
    assert!(report
        .selection
        .combinations
        .contains(&"product_decay + product_inhibition".to_string()));
    assert!(report.selection.undecided.is_empty());
}

#[test]
fn the_burden_of_enzyme_b_is_found_in_the_growth_of_x() {
    let sets = [bioreactor("models/bioreactor/truth.gbm")];
    let model = "models/diagnose/bioreactor/noburden.gbm";
    let report = run(model, &sets, &Options::default());
    let noise = noise_gap(model, &sets);
    check_credited(&report, noise, &["burden"], 0.2);
    check_floor(&report, noise);
    // Truth (paper table 2): K_EB = 0.5, mu0 = 0.22, Y_X = 0.435.
    assert!((param(&report, "K_EB") / 0.5 - 1.0).abs() < 0.05);
    assert!((param(&report, "mu0") / 0.22 - 1.0).abs() < 0.05);
    assert!((param(&report, "Y_X") / 0.435 - 1.0).abs() < 0.05);
    // The growth rate or the biomass balance it feeds; only the weakly excited substrate
    // could tell them apart: both are tied, the rate (more specific) first.
    assert_eq!(locus(&report), ("mu", LocusKind::Let), "{:?}", report.locus);
    let tied = tied(&report);
    assert!(
        tied.contains(&"mu") && tied.contains(&"X"),
        "{:?}",
        report.locus
    );
    assert!(!report.history_dependent);
    // Every fitted param of the credited effect carries a standard error (the fitted starts,
    // `STATE@EXPERIMENT`, are the other unknowns).
    let estimates: Vec<_> = (report.effects[0].fit.estimates.iter())
        .filter(|e| !e.name.contains('@'))
        .collect();
    assert_eq!(estimates.len(), 3);
    assert!(
        estimates
            .iter()
            .all(|e| e.std_error > Some(0.0) && e.identified),
        "{estimates:?}"
    );
}

#[test]
fn cell_death_is_found_in_the_biomass_balance() {
    let sets = [bioreactor("models/diagnose/bioreactor/truth_death.gbm")];
    let model = "models/diagnose/bioreactor/nodeath.gbm";
    let report = run(model, &sets, &Options::default());
    let noise = noise_gap(model, &sets);
    check_credited(&report, noise, &["death"], 0.2);
    assert!((param(&report, "k_d") / 0.006 - 1.0).abs() < 0.1);
    // A death term in the biomass balance and a lower growth rate differ only in the
    // weakly excited substrate: the biomass balance first, or the growth rate tied with it
    // (then first, as the more specific place).
    let tied = tied(&report);
    let first = locus(&report);
    assert!(
        first == ("X", LocusKind::Balance) || (first.0 == "mu" && tied.contains(&"X")),
        "{:?}",
        report.locus
    );
}

#[test]
fn a_slow_expression_lag_on_two_rates_needs_history_at_the_lagging_let() {
    let sets = [expression()];
    let model = "models/diagnose/expression/nolag.gbm";
    let report = run(model, &sets, &Options::default());
    let text = render::text(&report);
    check_credited(&report, noise_gap(model, &sets), &["expression_lag"], 0.2);
    // The truth's time constants, 3 h and 5 h (the two lags are interchangeable).
    let (a, b) = (param(&report, "tau_M"), param(&report, "tau_E"));
    let (short, long) = (a.min(b), a.max(b));
    assert!(
        (short / 3.0 - 1.0).abs() < 0.15 && (long / 5.0 - 1.0).abs() < 0.15,
        "{text}"
    );
    // The one-stage lag is second, told apart.
    assert_eq!(report.effects[1].name, "single_lag");
    // History needed, from the probe and from the credited effect's hidden states.
    assert!(report.memory.probe && report.history_dependent, "{text}");
    assert!(text.contains("adds hidden states (M, E)"), "{text}");
    // The locus: the lagging induction level, or the group of the two rates it drives;
    // never a balance first.
    let first = &report.locus[0];
    assert!(
        first.name == "E_ss" || (first.kind == LocusKind::Group && first.members == ["r_P", "r_Q"]),
        "{:?}",
        report.locus
    );
    let group = report
        .locus
        .iter()
        .find(|l| l.kind == LocusKind::Group)
        .unwrap();
    assert_eq!(group.name, "r_P + r_Q");
}

#[test]
fn the_same_seed_gives_the_same_report() {
    let sets = [chemostat("truth_decay.gbm")];
    let options = Options {
        restarts: 1,
        ..Options::default()
    };
    let mut first = run(CHEMOSTAT_MODEL, &sets, &options);
    let mut second = run(CHEMOSTAT_MODEL, &sets, &options);
    for report in [&mut first, &mut second] {
        report.timing = Timing::default();
        report.base_fit.seconds = 0.0;
        report.effects.iter_mut().for_each(|e| e.fit.seconds = 0.0);
        report.locus.iter_mut().for_each(|l| l.seconds = 0.0);
        (report.selection.steps.iter_mut())
            .filter_map(|s| s.fit.as_mut())
            .for_each(|f| f.seconds = 0.0);
    }
    assert_eq!(first, second);
}

#[test]
fn models_with_closures_or_too_little_data_are_refused() {
    let sets = [chemostat("truth.gbm")];
    let refused = try_run(
        "models/mm_chemostat/greybox.gbm",
        &sets,
        &Options::default(),
    );
    assert!(matches!(
        refused,
        Err(DiagnoseError::Fit(FitError::HasClosures { .. }))
    ));
    let mut short = sets[0].clone();
    short.record = short.record.rows(0..12);
    let refused = try_run(CHEMOSTAT_MODEL, &[short], &Options::default()).unwrap_err();
    // 12 measured rows: 8 train, 4 held out; the training part is too small to fit.
    assert_eq!(
        refused.to_string(),
        "expected at least 10 measured rows in the training part and one in the held-out part, \
         found 8 and 4 (the last 30 % of each experiment held out)"
    );
}

/// A held-out part of a few rows is scored, not refused: the report says how few.
#[test]
fn a_sparse_held_out_part_is_scored_and_said_to_be_few_rows() {
    let mut short = chemostat("truth.gbm");
    short.record = short.record.rows(0..20);
    let options = Options {
        locate: false,
        ..Options::default()
    };
    // 20 measured rows: 14 train, 6 held out (fewer than the 10 of --min-rows).
    let report = run(CHEMOSTAT_MODEL, &[short], &options);
    assert_eq!((report.split.train_rows, report.split.test_rows), (14, 6));
    assert!(report.split.sparse());
    assert!(report.gap_before.is_finite() && report.gap_before > 0.0);
    let text = render::text(&report);
    assert!(
        text.contains("fewer than 10 rows: the held-out score is noisy"),
        "{text}"
    );
}

#[test]
fn the_json_has_the_spec_fields_and_the_html_its_figures() {
    let sets = [chemostat("truth_decay.gbm")];
    let report = run(CHEMOSTAT_MODEL, &sets, &Options::default());
    let json = serde_json::to_value(&report).unwrap();
    for key in [
        "gap_before",
        "noise_floor",
        "significant",
        "states",
        "locus",
        "history_dependent",
        "windows",
        "regime",
        "effects",
        "credited",
        "selection",
        "timing",
    ] {
        assert!(json.get(key).is_some(), "{key}");
    }
    assert_eq!(json["credited"], "product_decay");
    assert_eq!(json["locus"][0]["kind"], "balance");
    assert!(json["locus"][0]["bound_after"].as_f64().is_some());
    assert!(json["effects"][0]["params"]["k_P"].as_f64().is_some());
    assert!(json["effects"][0]["fit"]["estimates"][0]["std_error"]
        .as_f64()
        .is_some());
    assert_eq!(json["regime"][0]["range"].as_array().map(Vec::len), Some(2));
    let shares: f64 = (json["states"].as_array().unwrap().iter())
        .map(|s| s["share"].as_f64().unwrap())
        .sum();
    assert!((shares - 1.0).abs() < 1e-9);
    let page = html::page(&report);
    // The bars, the loci, the selection, one plot per measured state and the error.
    assert_eq!(page.matches("<svg").count(), 3 + 2 + 1);
    assert!(page.contains("after product_decay") && page.contains("</html>"));
    assert!(page.contains("P [mol/L]") && page.contains(">time [s]</text>"));
    assert!(page.contains(">held-out part starts</text>"));
    assert_eq!(html::figures(&report).len(), 3 + 2 + 1);
}
