//! Every file gbc writes, it reads back: run directories, experiment results and study
//! records, diagnosis reports and cross-validation results holding infinities, NaNs and
//! unidentified params (written by name, `"inf"`, `"nan"`; see `src/json.rs`).

use std::path::Path;

use gbc::api::artifacts::{self, BalanceFit, Divergence, ErrorSet, ParamEstimate};
use gbc::api::experiment::results::{self, Measure};
use gbc::api::experiment::{RunResult, RunStatus, Study, StudyRecord};
use gbc::api::{CrossValidation, CvFold as Fold};

use crate::cli::{gbc, scratch};

/// The JSON text of a value: equal texts mean equal values, NaNs included.
fn text<T: serde::Serialize>(value: &T) -> String {
    serde_json::to_string_pretty(value).unwrap()
}

/// A diverged error set, as a free run that left the physical range gives.
fn diverged(state: &str) -> ErrorSet {
    ErrorSet {
        per_state: vec![(state.to_string(), f64::INFINITY)],
        overall: f64::INFINITY,
        rows: 12,
        cells: 12,
        divergence: Some(Divergence {
            experiment: "steps".into(),
            row: 13,
            time: 58.0,
            state: state.into(),
            value: f64::NAN,
            range: (f64::NEG_INFINITY, 4.5),
        }),
    }
}

/// A param the data do not determine.
fn unidentified(name: &str) -> ParamEstimate {
    ParamEstimate {
        name: name.into(),
        value: 0.5,
        std_error: Some(f64::INFINITY),
        relative_error: Some(f64::INFINITY),
        identified: false,
        held: false,
    }
}

#[test]
fn a_run_with_unidentified_params_and_a_diverged_free_run_reads_back_and_predicts() {
    let dir = scratch("artifacts-run");
    let (model_path, data) = (
        "models/bioreactor/gb1.gbm",
        "models/bioreactor/data/steps.csv",
    );
    let run = dir.join("run");
    let run_text = run.display().to_string();
    let trained = gbc(&[
        "train",
        model_path,
        data,
        "--epochs",
        "1",
        "--objective",
        "one-step",
        "--train-points",
        "100",
        "-o",
        &run_text,
    ]);
    assert!(
        trained.status.success(),
        "{}",
        String::from_utf8_lossy(&trained.stderr)
    );
    let model = gbc::api::Model::from_file(Path::new(model_path)).unwrap();
    let source = std::fs::read_to_string(model_path).unwrap();
    let (network, _, mut info) = artifacts::restore(model.ir(), &source, &run).unwrap();
    info.estimates = vec![
        unidentified("Y_X"),
        unidentified("Y_A"),
        unidentified("Y_B"),
    ];
    info.balance_fit = Some(BalanceFit {
        intervals: 90,
        steps: 4,
        rms_residual: f64::NAN,
        estimates: info.estimates.clone(),
        raw: Vec::new(),
    });
    info.metrics.online = Some(diverged("X"));
    info.metrics.initial_online = Some(diverged("S"));
    info.training.final_loss = Some(f64::NAN);
    info.model.source = source;
    artifacts::save(&run, &info, &network).unwrap();
    let written = std::fs::read_to_string(run.join("run.json")).unwrap();
    for expected in [
        "\"std_error\": \"inf\"",
        "\"rms_residual\": \"nan\"",
        "\"overall\": \"inf\"",
        "\"value\": \"nan\"",
        "\"-inf\"",
        "\"final_loss\": \"nan\"",
    ] {
        assert!(written.contains(expected), "{expected} not in {written}");
    }
    let (again, _) = artifacts::load(&run).unwrap();
    assert_eq!(text(&again), text(&info));
    assert_eq!(again.estimates[0].std_error, Some(f64::INFINITY));
    let online = again.metrics.online.unwrap();
    assert!(online.divergence.unwrap().value.is_nan());
    // The user's view: the run predicts.
    let out = dir.join("offline.csv").display().to_string();
    let predicted = gbc(&[
        "predict",
        model_path,
        data,
        "--weights",
        &run_text,
        "-o",
        &out,
    ]);
    assert!(
        predicted.status.success(),
        "{}",
        String::from_utf8_lossy(&predicted.stderr)
    );
}

#[test]
fn experiment_results_and_study_records_read_back() {
    let dir = scratch("artifacts-experiment");
    std::fs::create_dir_all(dir.join(results::RUNS_DIR)).unwrap();
    let result = RunResult {
        id: "greybox-n100-r0".into(),
        model: "greybox".into(),
        size: 100,
        replicate: 0,
        seed: 1,
        epochs: 3,
        status: RunStatus::Ok,
        error: None,
        offline_mse: Some(0.25),
        online_mse: Some(f64::INFINITY),
        offline_per_state: vec![Measure {
            name: "S".into(),
            value: Some(f64::NAN),
        }],
        online_per_state: vec![Measure {
            name: "S".into(),
            value: None,
        }],
        generalisation: vec![Measure {
            name: "chirp.csv".into(),
            value: Some(f64::NEG_INFINITY),
        }],
        params: vec![Measure::new("Y_X", f64::INFINITY)],
        final_loss: Some(f64::NAN),
        train_pairs: 100,
        validation_pairs: 40,
        wall_seconds: 1.5,
        warnings: Vec::new(),
        left_range: Some("the free run left the physical range".into()),
    };
    results::write_result(&dir, &result).unwrap();
    let again = results::read_result(&dir, &result.id).expect("the result reads back");
    assert_eq!(text(&again), text(&result));
    assert_eq!(again.online_mse, Some(f64::INFINITY));
    let mut study = Study::chemostat_demo();
    study.settings.learning_rate = f64::INFINITY;
    let record = StudyRecord {
        gbc_version: "0".into(),
        study,
        files: Vec::new(),
    };
    std::fs::write(dir.join(results::STUDY_FILE), text(&record)).unwrap();
    let again = results::read_study_record(&dir).unwrap().unwrap();
    assert_eq!(text(&again), text(&record));
}

#[test]
fn cross_validations_read_back() {
    let folds = CrossValidation {
        folds: vec![Fold {
            held_out: "run2".into(),
            offline: None,
            online: Some(diverged("X")),
            seconds: 2.0,
            run: Some("cv/fold-01-run2".into()),
            diverged: None,
            nothing_validates: Some("its training failed".into()),
        }],
        pooled_offline: None,
        pooled_online: Some(diverged("X")),
        median_offline: None,
        median_online: Some(f64::INFINITY),
    };
    let again: CrossValidation = serde_json::from_str(&text(&folds)).unwrap();
    assert_eq!(text(&again), text(&folds));
}

/// Every float in `value` replaced by a non-finite number's name (`"inf"`, `"nan"`,
/// `"-inf"` in turn); returns how many.
fn name_every_float(value: &mut serde_json::Value, count: &mut usize) {
    match value {
        serde_json::Value::Number(number) if number.is_f64() => {
            *value = ["inf", "nan", "-inf"][*count % 3].into();
            *count += 1;
        }
        serde_json::Value::Array(items) => {
            (items.iter_mut()).for_each(|item| name_every_float(item, count));
        }
        serde_json::Value::Object(map) => {
            (map.values_mut()).for_each(|item| name_every_float(item, count));
        }
        _ => {}
    }
}

/// A diagnosis JSON written by `gbc diagnose` (200 s of the two-effect chemostat case, one
/// start per fit) reads back into the report it was written from: written again, it is the
/// same text. The same file with every float turned infinite or NaN by name reads back
/// too, and writes those names again.
#[test]
fn a_diagnosis_json_reads_back_into_its_report() {
    let dir = scratch("artifacts-diagnosis");
    let (data, json) = (dir.join("two.csv"), dir.join("diagnosis.json"));
    crate::diagnose::simulate_chemostat("truth_two", "200", &data);
    let (data, json) = (data.display().to_string(), json.display().to_string());
    let model = "models/diagnose/chemostat/model.gbm";
    let options = ["--json", &json, "--restarts", "0", "--jobs", "1"];
    let diagnosed = gbc(&[&["diagnose", model, &data][..], &options[..]].concat());
    assert!(
        diagnosed.status.success(),
        "{}",
        String::from_utf8_lossy(&diagnosed.stderr)
    );
    let written = std::fs::read_to_string(&json).unwrap();
    let report: gbc::api::DiagnosisReport = serde_json::from_str(&written).unwrap();
    assert!(!report.effects.is_empty() && !report.locus.is_empty());
    assert_eq!(format!("{}\n", text(&report)), written);

    let mut value: serde_json::Value = serde_json::from_str(&written).unwrap();
    let mut count = 0;
    name_every_float(&mut value, &mut count);
    assert!(count > 100, "{count} floats");
    let named: gbc::api::DiagnosisReport = serde_json::from_value(value.clone()).unwrap();
    // Which name each float gets depends on the fields' (sorted) order: both are named.
    assert!(!named.gap_before.is_finite() && !named.noise_floor.is_finite());
    assert_eq!(serde_json::to_value(&named).unwrap(), value);
}
