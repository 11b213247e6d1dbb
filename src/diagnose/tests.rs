//! The withheld-effect cases of models/diagnose/ (README there): "real" data simulated from
//! a truth model with relative noise, diagnosed with a model that lacks one mechanism.
//!
//! Independent references: the truth's own parameter values, and the noise actually
//! injected (a perfect model's held-out gap is the mean squared normalised noise on the
//! held-out rows, computed here from the clean and noisy records without any fitting).

use super::*;
use crate::data::Column;
use crate::sim::SimOptions;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::path::PathBuf;

/// A simulated record with its noise-free measured states.
struct Simulated {
    data: Dataset,
    clean: Vec<Vec<f64>>,
}

impl Simulated {
    /// The held-out gap of a perfect model: the injected noise, normalised by the training
    /// part's std, averaged over the last 30 % of rows and the measured states.
    fn noise_gap(&self) -> f64 {
        let rows = self.data.len();
        let first = rows - (rows as f64 * 0.3).round() as usize;
        let noisy = &self.data.columns[self.data.columns.len() - self.clean.len()..];
        let mut total = 0.0;
        for (column, clean) in noisy.iter().zip(&self.clean) {
            let (_, std) = crate::numeric::mean_std(&column.values[..first]);
            total += (first..rows)
                .map(|i| ((column.values[i] - clean[i]) / std).powi(2))
                .sum::<f64>()
                / (rows - first) as f64;
        }
        total / self.clean.len() as f64
    }
}

/// The truth model `truth` under one input program per input, measured states perturbed
/// by `y (1 + noise z)`, `z` standard normal (as `gbc simulate --noise`).
fn simulate(truth: &str, program: &str, t_end: f64, dt: f64, seed: u64) -> Simulated {
    let model = crate::driver::compile_file(&root().join(truth), &[])
        .unwrap()
        .model;
    let signals: Vec<_> = (model.inputs.iter())
        .map(|input| {
            let program = crate::signal::parse_program(program).unwrap();
            program.generate(input, 0.0, t_end, dt).unwrap()
        })
        .collect();
    let options = SimOptions::new(t_end, dt);
    let trajectory = crate::sim::simulate(&model, &signals, &options).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut columns: Vec<Column> = (model.inputs.iter().zip(&trajectory.inputs))
        .map(|(input, values)| Column {
            name: input.name.clone(),
            values: values.clone(),
        })
        .collect();
    for (state, values) in model.states.iter().zip(&trajectory.states) {
        let noisy = values
            .iter()
            .map(|v| {
                let z: f64 = StandardNormal.sample(&mut rng);
                v * (1.0 + 0.01 * z)
            })
            .collect();
        columns.push(Column {
            name: state.name.clone(),
            values: noisy,
        });
    }
    let data = Dataset {
        path: PathBuf::from(format!("{truth}.csv")),
        step: dt,
        times: trajectory.times,
        columns,
    };
    Simulated {
        data,
        clean: trajectory.states,
    }
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn chemostat(truth: &str) -> Simulated {
    simulate(
        &format!("models/diagnose/chemostat/{truth}"),
        "steps(hold=10..60, seed=4)",
        1200.0,
        1.0,
        7,
    )
}

fn bioreactor(truth: &str) -> Simulated {
    simulate(truth, "steps(hold=5..40, seed=3)", 800.0, 1.0, 11)
}

/// Diagnoses the model file `model` on `data`.
fn run(model: &str, data: &Dataset) -> Report {
    try_run(model, data).unwrap()
}

fn try_run(model: &str, data: &Dataset) -> Result<Report, DiagnoseError> {
    let source = crate::driver::read_source(&root().join(model)).unwrap();
    let compiled = crate::driver::compile(model, &source, &[]).unwrap();
    let problem = Problem {
        name: model,
        source: &source,
        checked: &compiled.checked,
        model: &compiled.model,
        train: data,
        test: None,
    };
    diagnose(&problem, &Options::default(), &|_| {})
}

fn param(report: &Report, name: &str) -> f64 {
    report.effects[0].params[name]
}

/// The answers every case with a gap must get right: a significant gap, the withheld
/// effect first and credited, stable over the halves, its gap after at the injected noise
/// level (what a direct fit of the truth achieves), and the noise floor estimated well.
fn check_credited(report: &Report, simulated: &Simulated, effect: &str) {
    let noise = simulated.noise_gap();
    assert!(report.significant, "{}", render::text(report));
    assert_eq!(report.effects[0].name, effect, "{}", render::text(report));
    assert_eq!(report.credited.as_deref(), Some(effect));
    assert!(report.confidence.stable);
    let after = report.effects[0].gap_after;
    assert!(
        (after / noise - 1.0).abs() < 0.1,
        "gap after {after}, injected noise {noise}"
    );
    let shrink = 1.0 - noise / report.gap_before;
    assert!((report.effects[0].shrink - shrink).abs() < 0.1 * (1.0 - shrink) + 1e-3);
    assert!(
        (report.noise_floor / noise - 1.0).abs() < 0.3,
        "floor {} noise {noise}",
        report.noise_floor
    );
}

fn locus(report: &Report) -> (&str, LocusKind) {
    (&report.locus[0].name, report.locus[0].kind)
}

#[test]
fn a_missing_hidden_lag_is_found_and_needs_history() {
    let simulated = chemostat("truth.gbm");
    let report = run("models/diagnose/chemostat/nolag.gbm", &simulated.data);
    check_credited(&report, &simulated, "enzyme_holdup");
    // Truth: the enzyme lags its inlet with the residence time, 20 s; kcat = 0.14 1/s.
    assert!((param(&report, "tau_E") / 20.0 - 1.0).abs() < 0.05);
    assert!((param(&report, "kcat") / 0.14 - 1.0).abs() < 0.05);
    assert_eq!(locus(&report), ("rate", LocusKind::Let));
    assert!(report.history_dependent, "{}", render::text(&report));
    assert!(report.locus[0].bound_history < 0.5 * report.locus[0].bound_present);
}

#[test]
fn a_missing_factor_is_found_in_its_rate_and_regime() {
    let simulated = chemostat("truth_inhibition.gbm");
    let report = run("models/diagnose/chemostat/model.gbm", &simulated.data);
    check_credited(&report, &simulated, "product_inhibition");
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
    let simulated = chemostat("truth_decay.gbm");
    let report = run("models/diagnose/chemostat/model.gbm", &simulated.data);
    check_credited(&report, &simulated, "product_decay");
    assert!((param(&report, "k_P") / 0.01 - 1.0).abs() < 0.1);
    assert_eq!(locus(&report), ("P", LocusKind::Balance));
    assert!(!report.locus[1].tied, "{:?}", report.locus);
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
    let simulated = chemostat("truth.gbm");
    let report = run("models/diagnose/chemostat/model.gbm", &simulated.data);
    assert!(!report.significant, "{}", render::text(&report));
    assert_eq!(report.credited, None);
    assert!((report.gap_before / simulated.noise_gap() - 1.0).abs() < 0.1);
    assert!(report.effects.iter().all(|e| e.shrink < 0.1));
    assert!(render::text(&report).contains("credited: none (no significant gap)"));
}

#[test]
fn the_burden_of_enzyme_b_is_found_in_the_growth_of_x() {
    let simulated = bioreactor("models/bioreactor/truth.gbm");
    let report = run("models/diagnose/bioreactor/noburden.gbm", &simulated.data);
    check_credited(&report, &simulated, "burden");
    // Truth (paper table 2): K_EB = 0.5, mu0 = 0.22, Y_X = 0.435.
    assert!((param(&report, "K_EB") / 0.5 - 1.0).abs() < 0.05);
    assert!((param(&report, "mu0") / 0.22 - 1.0).abs() < 0.05);
    assert!((param(&report, "Y_X") / 0.435 - 1.0).abs() < 0.05);
    // The growth rate or the biomass balance it feeds; only the weakly excited substrate
    // could tell them apart, so both must be among the loci tied with the best.
    let tied: Vec<&str> = report
        .locus
        .iter()
        .filter(|l| l.tied)
        .map(|l| l.name.as_str())
        .collect();
    assert!(
        ["mu", "X"].contains(&report.locus[0].name.as_str()),
        "{:?}",
        report.locus
    );
    assert!(
        tied.contains(&"mu") && tied.contains(&"X"),
        "{:?}",
        report.locus
    );
    assert!(!report.history_dependent);
}

#[test]
fn cell_death_is_found_in_the_biomass_balance() {
    let simulated = bioreactor("models/diagnose/bioreactor/truth_death.gbm");
    let report = run("models/diagnose/bioreactor/nodeath.gbm", &simulated.data);
    check_credited(&report, &simulated, "death");
    assert!((param(&report, "k_d") / 0.006 - 1.0).abs() < 0.1);
    assert_eq!(locus(&report), ("X", LocusKind::Balance));
    assert!(
        report
            .hints
            .iter()
            .any(|h| h.text.ends_with("* X") && h.terms == 1),
        "{:?}",
        report.hints
    );
}

#[test]
fn the_same_seed_gives_the_same_report() {
    let simulated = chemostat("truth_inhibition.gbm");
    let first = run("models/diagnose/chemostat/model.gbm", &simulated.data);
    let second = run("models/diagnose/chemostat/model.gbm", &simulated.data);
    assert_eq!(first, second);
}

#[test]
fn models_with_closures_or_too_little_data_are_refused() {
    let simulated = chemostat("truth.gbm");
    let refused = try_run("models/mm_chemostat/greybox.gbm", &simulated.data);
    assert!(matches!(refused, Err(DiagnoseError::HasClosures { .. })));
    let mut short = simulated.data.clone();
    short.times.truncate(15);
    short.columns.iter_mut().for_each(|c| c.values.truncate(15));
    let refused = try_run("models/diagnose/chemostat/model.gbm", &short);
    assert!(matches!(
        refused,
        Err(DiagnoseError::TooFewRows { rows: 15, .. })
    ));
}

#[test]
fn the_json_has_the_spec_fields_and_the_html_its_plots() {
    let simulated = chemostat("truth_decay.gbm");
    let report = run("models/diagnose/chemostat/model.gbm", &simulated.data);
    let json = serde_json::to_value(&report).unwrap();
    for key in [
        "gap_before",
        "noise_floor",
        "significant",
        "states",
        "locus",
        "history_dependent",
    ] {
        assert!(json.get(key).is_some(), "{key}");
    }
    for key in ["windows", "regime", "effects", "credited"] {
        assert!(json.get(key).is_some(), "{key}");
    }
    assert_eq!(json["credited"], "product_decay");
    assert_eq!(json["locus"][0]["kind"], "balance");
    assert!(json["locus"][0]["bound_after"].as_f64().is_some());
    assert!(json["effects"][0]["params"]["k_P"].as_f64().is_some());
    assert_eq!(json["regime"][0]["range"].as_array().map(Vec::len), Some(2));
    let shares: f64 = (json["states"].as_array().unwrap().iter())
        .map(|s| s["share"].as_f64().unwrap())
        .sum();
    assert!((shares - 1.0).abs() < 1e-9);
    let page = html::page(&report);
    // One plot per measured state, the error over time and the bars.
    assert_eq!(page.matches("<svg").count(), 2 + 2);
    assert!(page.contains("after product_decay") && page.contains("</html>"));
}
