//! A model without closures is fitted by `gbc train` with the diagnosis's fitter: the same
//! params as `gbc diagnose` on the same split and seed, a training cost at or below scipy's
//! multi-start reference (`bench/diagnose/overflow_reference.json`), and no epoch.

use std::path::PathBuf;

use crate::data::MinRows;
use crate::record::{bind, request, Record};
use crate::train::fixtures::quiet;
use crate::train::*;

const MODEL: &str = "models/diagnose/overflow/monod.gbm";
const DATA: &str = "models/diagnose/overflow/data/overflow.csv";

/// The overflow case's model, its training batches and the held-out batch `B4`.
fn overflow() -> (crate::driver::Compiled, String, Vec<Record>, Vec<Record>) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let source = crate::driver::read_source(&root.join(MODEL)).unwrap();
    let compiled = crate::driver::compile(MODEL, &source, &[]).unwrap();
    let request = request(&compiled.model, &[], MinRows::new(2, "one step"));
    let set = crate::data::read_set(&[root.join(DATA)], &request).unwrap();
    let records = bind(&compiled.model, &set).unwrap();
    let (held, train) = (records.into_iter()).partition(|r: &Record| r.name == "B4");
    (compiled, source, train, held)
}

/// scipy's best training gap of the base model (`least_squares`, 12 starts, LSODA).
fn scipy_training_gap() -> f64 {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("bench/diagnose/overflow_reference.json");
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    (reference["training_gap"].as_array().unwrap().iter())
        .find(|fit| fit["fit"] == "base")
        .and_then(|fit| fit["train_gap_scipy"].as_f64())
        .unwrap()
}

#[test]
fn a_model_without_closures_is_fitted_as_gbc_diagnose_fits_it() {
    let (compiled, source, train, held) = overflow();
    let model = &compiled.model;
    let data = TrainingData {
        train: &train,
        validation: &held,
        part: Part::FirstPairs(None),
    };
    let options = TrainOptions {
        epochs: 50,
        seed: 1,
        ..TrainOptions::default()
    };
    let trained = train_with(model, &data, &options, &Recipe::default(), &mut quiet).unwrap();
    let fit = trained
        .report
        .mechanism_fit
        .as_ref()
        .expect("fitted by free runs");
    assert!(trained.report.losses.is_empty(), "no epoch runs");
    // The diagnosis of the model alone (its effects are not what is compared).
    let mut alone = model.clone();
    alone.effects.clear();
    let problem = crate::diagnose::Problem {
        name: MODEL,
        source: &source,
        checked: &compiled.checked,
        model: &alone,
        records: &train,
        held_out: &held,
    };
    // `gbc train` starts its free runs at the measured first cells (the records spec); the
    // diagnosis does so with `--exact-starts` (by default it fits them within their noise).
    let settings = crate::diagnose::Options {
        seed: 1,
        locate: false,
        fit_starts: false,
        ..crate::diagnose::Options::default()
    };
    let diagnosis = crate::diagnose::diagnose(&problem, &settings, &|_| {}).unwrap();
    // The same optimum: equal costs, and params equal up to the fit's convergence along
    // its flattest direction (K_S is poorly identified here).
    let (ours, theirs) = (fit.gap_train, diagnosis.base_fit.gap_train);
    assert!(
        (ours - theirs).abs() <= 1e-9 * theirs,
        "gaps {ours} vs {theirs}"
    );
    for (name, value) in &trained.report.params {
        let diagnosed = diagnosis.fitted_params[name];
        assert!(
            (value - diagnosed).abs() <= 1e-5 * diagnosed.abs(),
            "{name}: train {value}, diagnose {diagnosed}"
        );
    }
    let scipy = scipy_training_gap();
    assert!(
        fit.gap_train <= scipy * (1.0 + 1e-6),
        "train's fit {} above scipy's {scipy}",
        fit.gap_train
    );
    // The held-out free run: glucose runs out under the feed and its balance turns stiff
    // (an explicit step of the record's ~1 h is unstable there); the controlled steps
    // follow the diagnosis's implicit integrator, and the two report one error.
    let online = trained.report.metrics.online.as_ref().unwrap();
    assert!(online.divergence.is_none(), "{:?}", online.divergence);
    let exact = diagnosis.gap_before_per_state;
    assert!(
        (online.overall - exact).abs() <= 1e-3 * exact,
        "train's held-out error {} against the diagnosis's {exact}",
        online.overall
    );
    // Standard errors come with the params, as in the diagnosis.
    assert_eq!(trained.report.estimates.len(), model.params.len());
    assert!(trained
        .report
        .estimates
        .iter()
        .all(|e| e.std_error.is_some_and(f64::is_finite)));
}

#[test]
fn params_train_keeps_adam_for_a_model_without_closures() {
    let (compiled, _, train, held) = overflow();
    let data = TrainingData {
        train: &train,
        validation: &held,
        part: Part::FirstPairs(None),
    };
    let recipe = Recipe {
        params: ParamSource::Train,
        ..Recipe::default()
    };
    let options = TrainOptions {
        epochs: 3,
        ..TrainOptions::default()
    };
    let trained = train_with(&compiled.model, &data, &options, &recipe, &mut quiet).unwrap();
    assert!(trained.report.mechanism_fit.is_none());
    assert_eq!(trained.report.losses.len(), 3);
}

/// A grey box on the sparse overflow record starts from its mechanism: the params the
/// model without the closure gets (`bench/training/overflow_greybox.gbm` is `monod.gbm`
/// with a learned acetate exchange, which no other balance reads), held in training.
#[test]
fn a_grey_box_on_a_sparse_record_starts_from_its_fitted_mechanism() {
    let (compiled, _, train, held) = overflow();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("bench/training/overflow_greybox.gbm");
    let source = crate::driver::read_source(&path).unwrap();
    let grey = crate::driver::compile("overflow_greybox.gbm", &source, &[])
        .unwrap()
        .model;
    let data = TrainingData {
        train: &train,
        validation: &held,
        part: Part::FirstPairs(None),
    };
    // One (one-step) epoch: the rollouts on this stiff record are the open case of
    // docs/training.md.
    let options = TrainOptions {
        epochs: 1,
        seed: 1,
        toward_mechanism: crate::train::TowardMechanism::Strength(0.0),
        ..TrainOptions::default()
    };
    let plain = train_with(
        &compiled.model,
        &data,
        &options,
        &Recipe::default(),
        &mut quiet,
    );
    let boxed = train_with(&grey, &data, &options, &Recipe::default(), &mut quiet).unwrap();
    assert!(boxed.report.mechanism_fit.is_some());
    assert_eq!(boxed.report.losses.len(), 1, "the networks still train");
    for ((name, ours), (_, theirs)) in boxed
        .report
        .params
        .iter()
        .zip(&plain.unwrap().report.params)
    {
        assert!(
            (ours - theirs).abs() <= 1e-5 * theirs.abs(),
            "{name}: {ours} vs {theirs}"
        );
    }
}
