//! Training runs and their predictions: [`train`] turns a [`TrainSpec`] into a [`Run`],
//! which writes itself (weights, `run.json`, report page) and predicts records.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use super::{split, ApiError, Model, Split, Validation};
use crate::record::Record;
use crate::train::{
    Checkpoint, Event, History, Recipe, RunControl, TrainOptions, Trained, TrainingData,
};
use crate::trained::artifacts::{self, RunInfo};
use crate::trained::predict::{self, Mode};

/// Everything a training run is asked for, with the defaults of `gbc train` (its flags'
/// names are the fields' names).
#[derive(Debug, Clone)]
pub struct TrainSpec {
    /// Epochs, batch, learning rates, precision, sub-steps, engine, seed, history, ...
    pub options: TrainOptions,
    /// The objective and its schedule, the params' source, polish, range factor.
    pub recipe: Recipe,
    /// What validates.
    pub validation: Validation,
    /// Stop when the validation loss has not improved for this many epochs (`--early-stop`).
    pub early_stop: Option<usize>,
    /// Recoveries from a non-finite epoch before the run ends (`--recoveries`).
    pub recoveries: usize,
    /// Write a checkpoint into the run directory after every N epochs.
    pub checkpoint_every: Option<usize>,
    /// What `run.json` names as the data (the CLI: its files); `None`: the experiments.
    pub data: Option<String>,
}

impl Default for TrainSpec {
    fn default() -> Self {
        TrainSpec {
            options: TrainOptions::with(&crate::train::Settings::default()),
            recipe: Recipe::default(),
            validation: Validation::default(),
            early_stop: None,
            recoveries: crate::train::recovery::DEFAULT_RECOVERIES,
            checkpoint_every: None,
            data: None,
        }
    }
}

/// A trained model with what it was trained on and how.
pub struct Run {
    /// The model trained.
    pub model: Model,
    /// The network, its setup and the training report.
    pub trained: Trained,
    /// The run's metadata (what `run.json` holds).
    pub info: RunInfo,
    /// The experiments that trained and validated.
    pub split: Split,
    /// The rollout length of each epoch (for the report's phases).
    pub horizons: Vec<usize>,
    /// Where free runs start.
    pub history: History,
}

/// A table of predictions of one record: the header (`t`, states, closure outputs, model
/// outputs) and one column per header name, cut before a divergence (said in
/// `divergence`).
#[derive(Debug, Clone)]
pub struct Prediction {
    /// The experiment predicted.
    pub experiment: String,
    /// Column names.
    pub header: Vec<String>,
    /// Columns, one value per predicted row.
    pub columns: Vec<Vec<f64>>,
    /// Where a free run left the physical range, if it did.
    pub divergence: Option<String>,
}

/// How a run is driven from outside: where its checkpoints go, how it is stopped, what it
/// continues.
#[derive(Debug, Clone, Default)]
pub struct Control {
    /// The run directory checkpoints go to (none: no checkpoint).
    pub directory: Option<PathBuf>,
    /// Set (by a signal handler, a notebook's interrupt) to stop after the current epoch
    /// with a checkpoint.
    pub stop: Option<Arc<AtomicBool>>,
    /// A checkpoint to continue from.
    pub resume: Option<Checkpoint>,
    /// What the caller keeps with each checkpoint (the CLI: its command line).
    pub command: serde_json::Value,
    /// Test hook: stop after this epoch as if interrupted.
    pub stop_after: Option<usize>,
    /// Test hook: the loss of epoch `.0` reads NaN on its first `.1` tries.
    pub poison: Option<(usize, usize)>,
}

/// Trains `model` on `records` (and the experiments of `val`, which validate) as `spec`
/// asks. `on_event` hears of every warning, phase and epoch; setting `control.stop` ends
/// training after the current epoch (with a checkpoint in `control.directory`). A run that
/// went non-finite is returned with its last finite weights and `trained.report.diverged`
/// set; an interrupted one fails with [`crate::train::TrainError::Interrupted`].
pub fn train(
    model: &Model,
    (records, val): (Vec<Record>, Vec<Record>),
    spec: &TrainSpec,
    control: Control,
    on_event: &mut dyn FnMut(Event),
) -> Result<Run, ApiError> {
    let split = split(records, val, &spec.validation)?;
    let options = TrainOptions {
        train_points: spec.validation.train_points,
        ..spec.options.clone()
    };
    let mut horizons: Vec<usize> = (control.resume.iter())
        .flat_map(|checkpoint| checkpoint.log.iter().map(|row| row.horizon))
        .collect();
    let run_control = RunControl {
        directory: control.directory,
        every: spec.checkpoint_every,
        stop: control.stop,
        stop_after: control.stop_after,
        early_stop: spec.early_stop,
        resume: control.resume,
        command: control.command,
        keep_last_finite: true,
        recoveries: spec.recoveries,
        poison: control.poison,
        ..RunControl::default()
    };
    let data = TrainingData {
        train: &split.train,
        validation: &split.validation,
        part: split.part,
    };
    let trained = crate::train::train_run(
        model.ir(),
        &data,
        (&options, &spec.recipe),
        &run_control,
        &mut |event| {
            if let Event::Epoch { horizon, .. } = &event {
                horizons.push(*horizon);
            }
            on_event(event)
        },
    )?;
    let data_path = spec.data.clone().unwrap_or_else(|| data_names(&split));
    let info = artifacts::run_info(
        model.ir(),
        (&model.origin, &model.source),
        &data_path,
        &options,
        &trained,
    );
    Ok(Run {
        model: model.clone(),
        trained,
        info,
        split,
        horizons,
        history: options.history,
    })
}

/// The data a run names in its metadata: its experiments.
fn data_names(split: &Split) -> String {
    (split.train.iter().chain(&split.validation))
        .map(|r| r.name.clone())
        .collect::<Vec<_>>()
        .join(" ")
}

impl Run {
    /// Writes the run into `directory`: `weights.safetensors`, `run.json` and the report
    /// page `report.html` (each atomically; a non-finite weight is refused).
    pub fn save(&self, directory: &Path) -> Result<(), ApiError> {
        artifacts::save(directory, &self.info, &self.trained.network)?;
        crate::train::Checkpoint::remove(directory);
        crate::io::write_atomic(&directory.join(REPORT_FILE), self.report_html().as_bytes())
            .map_err(ApiError::user)
    }

    /// The run's metadata as the JSON of `run.json`.
    pub fn json(&self) -> Result<String, ApiError> {
        serde_json::to_string_pretty(&self.info)
            .map_err(|error| ApiError::Internal(format!("cannot encode metrics: {error}")))
    }

    /// The report page (HTML): losses, the free runs against the data, params.
    pub fn report_html(&self) -> String {
        crate::trained::page::run_page(
            self.model.ir(),
            &self.trained,
            (&self.split.train, &self.split.validation),
            (self.history, &self.horizons),
            &self.model.stem(),
        )
    }

    /// The trained params, in declaration order.
    pub fn params(&self) -> &[(String, f64)] {
        &self.trained.report.params
    }

    /// Predictions of each of `records`: offline (one step from the measured history) or
    /// online (free runs), from each record's first row (`history`).
    pub fn predict(
        &self,
        records: &[Record],
        mode: Mode,
        history: History,
    ) -> Result<Vec<Prediction>, ApiError> {
        let range = self.info.physical_range();
        let (network, setup) = (&self.trained.network, &self.trained.setup);
        (records.iter())
            .map(|record| {
                let how = (mode, history, range.as_ref());
                let mut table =
                    predict::predict_in_range(self.model.ir(), network, setup, record, how)?;
                let divergence = table.divergence.as_ref().map(|d| d.to_string());
                table.cut_at_divergence();
                Ok(Prediction {
                    experiment: record.name.clone(),
                    header: table.header,
                    columns: table.columns,
                    divergence,
                })
            })
            .collect()
    }

    /// The one-step map as an ONNX file's bytes (`gbc export`).
    pub fn export_onnx(
        &self,
        precision: crate::engine::graph::Precision,
    ) -> Result<Vec<u8>, ApiError> {
        let (network, setup) = (&self.trained.network, &self.trained.setup);
        crate::export::onnx(self.model.ir(), network, setup, precision)
            .map(|exported| exported.bytes)
            .map_err(|error| match error {
                crate::export::ExportError::Internal(message) => ApiError::Internal(message),
                not_finite => ApiError::user(not_finite),
            })
    }
}

/// The report page of a run directory.
pub const REPORT_FILE: &str = "report.html";
