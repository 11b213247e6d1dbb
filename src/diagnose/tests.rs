//! Withheld-effect cases (models/diagnose/): "real" data simulated from a truth model with
//! noise, diagnosed with the model that lacks the mechanism.

use super::*;
use crate::data::Column;
use crate::sim::SimOptions;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::path::{Path, PathBuf};

/// A simulated record of `truth` under `program` (one per input), with relative noise.
fn record(truth: &str, programs: &[&str], t_end: f64, dt: f64, noise: f64, seed: u64) -> Dataset {
    let model = crate::driver::compile_file(&root().join(truth), &[])
        .unwrap_or_else(|e| panic!("{truth}: {e:?}"))
        .model;
    let signals: Vec<_> = (model.inputs.iter().zip(programs))
        .map(|(input, text)| {
            crate::signal::parse_program(text)
                .unwrap()
                .generate(input, 0.0, t_end, dt)
                .unwrap()
        })
        .collect();
    let trajectory = crate::sim::simulate(&model, &signals, &SimOptions::new(t_end, dt)).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut columns: Vec<Column> = (model.inputs.iter().map(|i| &i.name))
        .zip(&trajectory.inputs)
        .map(|(name, values)| Column {
            name: name.clone(),
            values: values.clone(),
        })
        .collect();
    for (state, values) in model.states.iter().zip(&trajectory.states) {
        let noisy = values
            .iter()
            .map(|v| {
                let z: f64 = StandardNormal.sample(&mut rng);
                v * (1.0 + noise * z)
            })
            .collect();
        columns.push(Column {
            name: state.name.clone(),
            values: noisy,
        });
    }
    Dataset {
        path: PathBuf::from(format!("{truth}.csv")),
        step: dt,
        times: trajectory.times,
        columns,
    }
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Diagnoses the model file `model` on `data`.
fn run(model: &str, data: &Dataset, options: &Options) -> Report {
    let path = root().join(model);
    let source = crate::driver::read_source(Path::new(&path)).unwrap();
    let compiled = crate::driver::compile(model, &source, &[]).unwrap();
    let problem = Problem {
        name: model,
        source: &source,
        checked: &compiled.checked,
        model: &compiled.model,
        train: data,
        test: None,
    };
    let start = std::time::Instant::now();
    diagnose(&problem, options, &|p| {
        if let Progress::Stage { name, .. } = p {
            eprintln!("{:>8.2?} {name}", start.elapsed())
        }
    })
    .unwrap()
}

#[test]
fn enzyme_lag_case() {
    let data = record(
        "models/diagnose/enzyme_lag/truth.gbm",
        &["steps(hold=10..60, seed=4)"],
        1200.0,
        1.0,
        0.01,
        7,
    );
    let start = std::time::Instant::now();
    let report = run("models/diagnose/enzyme_lag/model.gbm", &data, &Options::default());
    eprintln!("{:.2?}", start.elapsed());
    eprintln!("{}", serde_json::to_string_pretty(&report).unwrap());
    assert_eq!(report.credited.as_deref(), Some("enzyme_holdup"));
}

#[test]
fn burden_case() {
    let data = record("models/bioreactor/truth.gbm", &["steps(hold=5..40, seed=3)"], 800.0, 1.0, 0.01, 11);
    let start = std::time::Instant::now();
    let report = run("models/diagnose/burden/model.gbm", &data, &Options::default());
    eprintln!("{:.2?}", start.elapsed());
    eprintln!("{}", serde_json::to_string_pretty(&report).unwrap());
    assert_eq!(report.credited.as_deref(), Some("burden"));
}

#[test]
fn death_case() {
    let data = record("models/diagnose/death/truth.gbm", &["steps(hold=5..40, seed=3)"], 800.0, 1.0, 0.01, 11);
    let start = std::time::Instant::now();
    let report = run("models/diagnose/death/model.gbm", &data, &Options::default());
    eprintln!("{:.2?}", start.elapsed());
    eprintln!("{}", serde_json::to_string_pretty(&report).unwrap());
    assert_eq!(report.credited.as_deref(), Some("death"));
}

