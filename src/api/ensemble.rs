//! `gbc train --ensemble N` as a library call: the members trained on bootstraps of whole
//! training experiments (or on all of them), the prediction band calibrated on the
//! experiments each member did not draw, its coverage counted on the held-out ones, every
//! member and `ensemble.json` written under the run directory with the report page
//! (`docs/uncertainty.md`). The work is [`crate::ensemble`]; this gives it the split and
//! the files of [`super::train`] and a result that says what came out.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{split, ApiError, Model, TrainSpec, REPORT_FILE};
use crate::ensemble::{self, EnsembleInfo, MemberEvent, Plan, Trained};
use crate::record::Record;
use crate::train::TrainingData;

/// A trained ensemble: what `ensemble.json` holds, the report page, and the time it took.
pub struct EnsembleRun {
    /// The members' free runs and the ensemble's description.
    pub trained: Trained,
    /// The report page (`report.html`, written into the directory).
    pub page: String,
    /// What the split chose by itself (the experiment that validates by default).
    pub note: Option<String>,
    /// The run directory.
    pub directory: PathBuf,
    /// Wall-clock seconds of the training.
    pub seconds: f64,
}

impl EnsembleRun {
    /// What `ensemble.json` holds.
    pub fn info(&self) -> &EnsembleInfo {
        &self.trained.info
    }

    /// `ensemble.json`'s text (what `--json` writes).
    pub fn json(&self) -> Result<String, ApiError> {
        serde_json::to_string_pretty(&self.trained.info)
            .map_err(|error| ApiError::Internal(format!("cannot encode the ensemble: {error}")))
    }

    /// What `gbc train --ensemble` prints at the end: the band's noise and calibration, its
    /// coverage of the held-out experiments, the median's and the members' errors.
    pub fn summary_text(&self, model: &Model) -> String {
        super::summary::ensemble_summary(model.ir(), self.info(), self.seconds, &self.directory)
    }
}

/// Trains the ensemble of `plan` for `model` on `records` (validating on the held-out
/// experiments of `spec` and on `val`) into `directory`, and writes its report there;
/// `on_event` hears each member's start, epochs and end (from the member threads).
pub fn train_ensemble(
    model: &Model,
    (records, val): (Vec<Record>, Vec<Record>),
    (spec, plan): (&TrainSpec, &Plan),
    directory: &Path,
    on_event: &(dyn Fn(MemberEvent) + Sync),
) -> Result<EnsembleRun, ApiError> {
    let split = split(records, val, &spec.validation)?;
    let data = TrainingData {
        train: &split.train,
        validation: &split.validation,
        part: split.part,
    };
    let described = spec.data.clone().unwrap_or_else(|| experiments(&split));
    let keep = ensemble::Keep {
        directory: directory.to_path_buf(),
        model: (&model.origin, &model.source),
        data: &described,
        recoveries: spec.recoveries,
    };
    let started = Instant::now();
    let settings = (&spec.options, &spec.recipe);
    let trained = ensemble::train_ensemble(model.ir(), &data, settings, plan, &keep, on_event)
        .map_err(ApiError::user)?;
    let seconds = started.elapsed().as_secs_f64();
    let title = model.stem();
    let page = ensemble::page::ensemble_page(
        model.ir(),
        &trained,
        (data.train, data.validation),
        plan.level,
        &title,
    );
    crate::io::write_atomic(&directory.join(REPORT_FILE), page.as_bytes())
        .map_err(ApiError::user)?;
    Ok(EnsembleRun {
        trained,
        page,
        note: split.note,
        directory: directory.to_path_buf(),
        seconds,
    })
}

/// The experiments of a split, in words (what `ensemble.json` names as the data when no
/// files were given).
fn experiments(split: &super::Split) -> String {
    let names = (split.train.iter().chain(&split.validation)).map(|r| r.name.as_str());
    names.collect::<Vec<_>>().join(" ")
}
