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

#[test]
fn zz_oracle_probe() {
    let data = record("models/bioreactor/truth.gbm", &["steps(hold=5..40, seed=3)"], 800.0, 1.0, 0.01, 11);
    let path = root().join("models/diagnose/burden/model.gbm");
    let source = crate::driver::read_source(&path).unwrap();
    let compiled = crate::driver::compile("m", &source, &["burden"]).unwrap();
    let base = crate::driver::compile("m", &source, &[]).unwrap();
    let options = Options::default();
    let problem = Problem { name: "m", source: &source, checked: &base.checked, model: &base.model, train: &data, test: None };
    let context = context(&problem, &options).unwrap();
    let sim = Simulator::new(&compiled.model, None, tolerances()).unwrap();
    eprintln!("{:?}", compiled.model.params.iter().map(|p| &p.name).collect::<Vec<_>>());
    for params in [[0.22, 0.272, 0.5], [0.22, 0.435, 0.5], [0.137, 0.272, 1e9]] {
        let (gap, run) = effects::held_out(&context, &sim, &params);
        let errors = evaluate::state_errors(run.as_ref().unwrap(), &context.split.test, context.split.test_rows.clone(), &context.normalisation);
        eprintln!("{params:?}: {gap} {errors:?}");
    }
}

#[test]
fn zz_probe_correction() {
    let data = record("models/bioreactor/truth.gbm", &["steps(hold=5..40, seed=3)"], 800.0, 1.0, 0.01, 11);
    let path = root().join("models/diagnose/burden/model.gbm");
    let source = crate::driver::read_source(&path).unwrap();
    let base = crate::driver::compile("m", &source, &[]).unwrap();
    let options = Options::default();
    let problem = Problem { name: "m", source: &source, checked: &base.checked, model: &base.model, train: &data, test: None };
    let context = context(&problem, &options).unwrap();
    let params = [0.13692618458710532, 0.27208907912839364];
    let target = locus::Target { name: "mu".into(), kind: LocusKind::Let };
    let mut corrected = locus::synthesise(&context, &target, &params).unwrap().unwrap();
    let theta = correction::theta_of(&corrected.constraints, &params);
    let pass = correction::one_step_pass(&mut corrected, &theta, &context.split.train, context.split.train_rows.end).unwrap();
    let map = locus::feature_map(&context, &pass, None);
    let solution = correction::fit(&mut corrected, &pass, &map, &context.split.train, &context.normalisation).unwrap();
    let fitted = correction::values_along(&pass, &map, &context.split.train, &solution.weights);
    // oracle: E_B is present index 1 + 4 + 1 = 6 (u, X, A, B, S, E_A, E_B, ...)
    let oracle: Vec<f64> = (0..pass.rows).map(|i| pass.locus[i] * (0.22 / params[0] * (-2.0 * pass.present[i][6]).exp() - 1.0)).collect();
    let mean = oracle.iter().sum::<f64>() / oracle.len() as f64;
    let ss: f64 = oracle.iter().map(|o| (o - mean).powi(2)).sum();
    let res: f64 = oracle.iter().zip(&fitted).map(|(o, f)| (o - f).powi(2)).sum();
    eprintln!("R2 of fitted vs oracle {} ; rms oracle {}", 1.0 - res / ss, (ss / oracle.len() as f64).sqrt());
    for i in (0..pass.rows).step_by(40) { eprintln!("{i}: oracle {:.5} fitted {:.5} sens {:?} r {:?}", oracle[i], fitted[i], pass.sensitivity[i], pass.residual[i]); }
}
