//! Results on disk and their summaries.
//!
//! Layout of an experiment directory:
//! ```text
//! DIR/study.json            the study and the sha256 of every file it reads (StudyRecord)
//! DIR/runs/<id>.json        one finished run (RunResult), written atomically, last
//! DIR/runs/<id>/            its weights and run.json (as `gbc train -o`), for the figures
//! DIR/results.csv, .json    every run, one row each (written by a full run or `merge`)
//! DIR/summary.csv           median, min and max per model and size
//! DIR/figures/*.svg, DIR/report.html
//! ```
//! A run counts as finished when its `<id>.json` reads back; a re-run skips it.
//!
//! Errors are mean squared errors of the measured states z-scored with the mean and
//! standard deviation of the *validation window* (the same scale for every model and size;
//! `gbc train` reports them z-scored with each run's own training split instead), averaged
//! over states. An error that is not finite (a free run that diverged) is stored as `null`
//! and counts as infinite in medians.

use std::path::{Path, PathBuf};

use super::grid::RunSpec;
use super::{ExperimentError, Study};
use crate::io::IoError;

/// Folder of the per-run files inside an experiment directory.
pub const RUNS_DIR: &str = "runs";
/// The study record inside an experiment directory.
pub const STUDY_FILE: &str = "study.json";

/// A file a study reads, with its hash (runs are reused only while every file is unchanged).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fingerprint {
    /// The path as given.
    pub path: String,
    /// sha256 of its bytes, lowercase hex.
    pub sha256: String,
}

/// `DIR/study.json`: the study and the fingerprints of its files.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StudyRecord {
    /// Version of gbc that wrote it.
    pub gbc_version: String,
    /// The study.
    pub study: Study,
    /// Every model, data, truth and generalisation file, in that order.
    pub files: Vec<Fingerprint>,
}

impl StudyRecord {
    /// Whether runs of `other` compute the same thing as runs of `self`.
    pub fn same_identity(&self, other: &StudyRecord) -> bool {
        self.study.identity() == other.study.identity() && self.files == other.files
    }
}

/// A name with a value that may be missing or not finite (`null` in JSON).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Measure {
    /// Name (a state, a param, a data file).
    pub name: String,
    /// The value; `None` when it was not finite.
    #[serde(with = "crate::json")]
    pub value: Option<f64>,
}

impl Measure {
    /// A measure, `None` for a non-finite value.
    pub fn new(name: &str, value: f64) -> Self {
        Measure {
            name: name.to_string(),
            value: finite(value),
        }
    }
}

/// `Some(value)` when finite.
pub fn finite(value: f64) -> Option<f64> {
    value.is_finite().then_some(value)
}

/// Whether a run finished training.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunStatus {
    /// Trained and evaluated.
    Ok,
    /// Training failed (e.g. diverged); `error` says why.
    Failed,
}

/// One finished run: `DIR/runs/<id>.json` and a row of `results.csv`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunResult {
    /// Stable id (see [`RunSpec`]).
    pub id: String,
    /// The model's label.
    pub model: String,
    /// Training pairs asked for.
    pub size: usize,
    /// Replicate number.
    pub replicate: usize,
    /// Seed.
    pub seed: u64,
    /// Epochs trained.
    pub epochs: usize,
    /// Whether it trained.
    pub status: RunStatus,
    /// Why it failed.
    pub error: Option<String>,
    /// Offline validation MSE (one step from the true history), mean over states.
    #[serde(with = "crate::json")]
    pub offline_mse: Option<f64>,
    /// Online validation MSE (one free run over the whole validation window, never stopped),
    /// mean over states.
    #[serde(with = "crate::json")]
    pub online_mse: Option<f64>,
    /// Offline MSE per measured state.
    pub offline_per_state: Vec<Measure>,
    /// Online MSE per measured state.
    pub online_per_state: Vec<Measure>,
    /// Online MSE of a free run over each generalisation record (z-scored with that
    /// record's own statistics), named by file.
    pub generalisation: Vec<Measure>,
    /// Trained param values.
    pub params: Vec<Measure>,
    /// Mean training loss of the last epoch.
    #[serde(with = "crate::json")]
    pub final_loss: Option<f64>,
    /// Training pairs used.
    pub train_pairs: usize,
    /// Validation pairs.
    pub validation_pairs: usize,
    /// Wall time of training and evaluation, seconds.
    #[serde(with = "crate::json")]
    pub wall_seconds: f64,
    /// Stiffness warnings issued before training.
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Where the free run over the validation window first left the training module's
    /// physical range (10 times the training extremes; a tenth of its maximum below zero
    /// for a state never negative in training), if it did. The online error ignores this
    /// and covers the whole run.
    #[serde(default)]
    pub left_range: Option<String>,
}

impl RunResult {
    /// A failed run.
    pub fn failed(spec: &RunSpec, label: &str, epochs: usize, error: String, seconds: f64) -> Self {
        RunResult {
            id: spec.id.clone(),
            model: label.to_string(),
            size: spec.size,
            replicate: spec.replicate,
            seed: spec.seed,
            epochs,
            status: RunStatus::Failed,
            error: Some(error),
            offline_mse: None,
            online_mse: None,
            offline_per_state: Vec::new(),
            online_per_state: Vec::new(),
            generalisation: Vec::new(),
            params: Vec::new(),
            final_loss: None,
            train_pairs: 0,
            validation_pairs: 0,
            wall_seconds: seconds,
            warnings: Vec::new(),
            left_range: None,
        }
    }

    /// Whether it trained.
    pub fn is_ok(&self) -> bool {
        self.status == RunStatus::Ok
    }

    /// The offline error of an ok run, infinite when it was not finite.
    pub fn offline(&self) -> Option<f64> {
        self.is_ok()
            .then(|| self.offline_mse.unwrap_or(f64::INFINITY))
    }

    /// The online error of an ok run, infinite when it diverged.
    pub fn online(&self) -> Option<f64> {
        self.is_ok()
            .then(|| self.online_mse.unwrap_or(f64::INFINITY))
    }

    /// The value of a named measure of an ok run, infinite when not finite.
    pub fn measure(list: &[Measure], name: &str) -> Option<f64> {
        (list.iter().find(|m| m.name == name)).map(|m| m.value.unwrap_or(f64::INFINITY))
    }
}

/// `DIR/runs/<id>.json`.
pub fn result_path(dir: &Path, id: &str) -> PathBuf {
    dir.join(RUNS_DIR).join(format!("{id}.json"))
}

/// `DIR/runs/<id>/`: the run's weights.
pub fn weights_dir(dir: &Path, id: &str) -> PathBuf {
    dir.join(RUNS_DIR).join(id)
}

/// Writes a run's result atomically.
pub fn write_result(dir: &Path, result: &RunResult) -> Result<(), IoError> {
    let json = serde_json::to_string_pretty(result).unwrap_or_default();
    crate::io::write_atomic(&result_path(dir, &result.id), json.as_bytes())
}

/// The finished result of run `id`, if its file reads back with that id.
pub fn read_result(dir: &Path, id: &str) -> Option<RunResult> {
    let text = std::fs::read_to_string(result_path(dir, id)).ok()?;
    let result: RunResult = serde_json::from_str(&text).ok()?;
    (result.id == id).then_some(result)
}

/// Every readable result under `DIR/runs/`, sorted by id, and the files that did not read.
pub fn read_all(dir: &Path) -> (Vec<RunResult>, Vec<PathBuf>) {
    let mut results = Vec::new();
    let mut unreadable = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir.join(RUNS_DIR)) else {
        return (results, unreadable);
    };
    for path in entries.flatten().map(|entry| entry.path()) {
        if path.extension().is_none_or(|e| e != "json") || !path.is_file() {
            continue;
        }
        let stem = (path.file_stem()).map_or(String::new(), |s| s.to_string_lossy().into());
        match read_result(dir, &stem) {
            Some(result) => results.push(result),
            None => unreadable.push(path),
        }
    }
    results.sort_by(|a, b| a.id.cmp(&b.id));
    (results, unreadable)
}

/// Reads `DIR/study.json`.
pub fn read_study_record(dir: &Path) -> Result<Option<StudyRecord>, ExperimentError> {
    let path = dir.join(STUDY_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(error) => return Err(ExperimentError::unreadable_study(&path, &error)),
    };
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|error| ExperimentError::BadStudy {
            path: path.display().to_string(),
            reason: error.to_string(),
            source_code: None,
            span: None,
        })
}

/// An online MSE above this (a free run ending a thousand standard deviations away, or not
/// finite) counts as a free run that blew up in the summaries.
pub const BLOWN_UP_MSE: f64 = 1e6;

/// Median, minimum and maximum of replicate values.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Spread {
    /// Median (the mean of the two middle values for an even count).
    #[serde(with = "crate::json")]
    pub median: f64,
    /// Smallest.
    #[serde(with = "crate::json")]
    pub min: f64,
    /// Largest.
    #[serde(with = "crate::json")]
    pub max: f64,
}

/// The spread of `values` (infinities included), `None` when empty.
pub fn spread(values: &[f64]) -> Option<Spread> {
    let median = crate::numeric::median(values)?;
    let numbers = || values.iter().copied().filter(|v| !v.is_nan());
    Some(Spread {
        median,
        min: numbers().fold(f64::INFINITY, f64::min),
        max: numbers().fold(f64::NEG_INFINITY, f64::max),
    })
}

/// One row of the summary: a model at a size over its replicates.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SummaryRow {
    /// Model label.
    pub model: String,
    /// Training size.
    pub size: usize,
    /// Runs that trained.
    pub ok: usize,
    /// Runs that failed.
    pub failed: usize,
    /// Runs whose free run over the validation window blew up (online MSE above
    /// [`BLOWN_UP_MSE`] or not finite).
    pub blown_up: usize,
    /// Offline MSE.
    pub offline: Option<Spread>,
    /// Online MSE.
    pub online: Option<Spread>,
    /// Online MSE per generalisation record: `(file, spread)`.
    pub generalisation: Vec<(String, Option<Spread>)>,
    /// Median wall time, seconds.
    #[serde(with = "crate::json")]
    pub wall_seconds: Option<f64>,
}

/// The runs of `results` for model `label` at `size`.
pub fn runs_of<'a>(results: &'a [RunResult], label: &str, size: usize) -> Vec<&'a RunResult> {
    (results.iter())
        .filter(|r| r.model == label && r.size == size)
        .collect()
}

/// Summary rows in study order (models) and increasing size; cells without runs are left out.
pub fn summarise(study: &Study, results: &[RunResult]) -> Vec<SummaryRow> {
    let mut rows = Vec::new();
    for model in &study.models {
        for size in study.sorted_sizes() {
            let runs = runs_of(results, &model.label, size);
            if runs.is_empty() {
                continue;
            }
            let ok: Vec<&&RunResult> = runs.iter().filter(|r| r.is_ok()).collect();
            let values = |pick: &dyn Fn(&RunResult) -> Option<f64>| {
                spread(&ok.iter().filter_map(|r| pick(r)).collect::<Vec<_>>())
            };
            let generalisation = (study.generalisation.iter())
                .map(|path| {
                    let name = path.display().to_string();
                    let spread = values(&|r| RunResult::measure(&r.generalisation, &name));
                    (name, spread)
                })
                .collect();
            rows.push(SummaryRow {
                model: model.label.clone(),
                size,
                ok: ok.len(),
                failed: runs.len() - ok.len(),
                blown_up: (ok.iter())
                    .filter(|r| r.online().is_some_and(|e| e > BLOWN_UP_MSE))
                    .count(),
                offline: values(&RunResult::offline),
                online: values(&RunResult::online),
                generalisation,
                wall_seconds: values(&|r| Some(r.wall_seconds)).map(|s| s.median),
            });
        }
    }
    rows
}
