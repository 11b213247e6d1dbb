//! Leave-one-experiment-out cross-validation (`gbc train --cv`, records spec section 3):
//! each experiment in turn is held out, a model is trained on the others and scored on it;
//! the report gives each fold, the errors pooled over folds and the median over folds.
//!
//! Nothing is lost ([`Keep`]): each fold's run (weights, `run.json`, `model.gbm`) and its
//! held-out free run (`predictions.csv`, the columns `gbc predict --mode online` writes)
//! go to `cv/fold-K-NAME/` under the run directory, and the summary to `cv/summary.json`.
//! A fold that cannot train or validate is reported with why, and the others still are;
//! a fold whose training goes non-finite keeps its last finite weights, like any run.

use std::path::Path;
use std::time::Instant;

use crate::ir;
use crate::record::Record;

use super::artifacts;
pub use super::keep::Keep;
use super::predict::{predict_in_range, Mode};
use crate::train::{
    train_run, EpochDivergence, ErrorSet, Event, Part, PhysicalRange, Recipe, RunControl,
    TrainError, TrainOptions, Trained, TrainingData,
};

/// The directory of the folds under a run directory.
pub const CV_DIR: &str = "cv";
/// The summary of the folds, in [`CV_DIR`].
pub const SUMMARY_FILE: &str = "summary.json";
/// A fold's held-out free run, in its directory.
pub const PREDICTIONS_FILE: &str = "predictions.csv";

/// One fold: the experiment held out and its errors.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fold {
    /// The held-out experiment.
    pub held_out: String,
    /// Its offline error (absent without a pair of measured history).
    pub offline: Option<ErrorSet>,
    /// Its online error (with where the free run left the physical range, if it did).
    pub online: Option<ErrorSet>,
    /// Wall-clock seconds of the fold.
    #[serde(with = "crate::json")]
    pub seconds: f64,
    /// The fold's run directory, relative to the run directory (absent when not kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run: Option<String>,
    /// Where its training went non-finite, when it did (its run keeps the last finite
    /// epoch's weights).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diverged: Option<EpochDivergence>,
    /// Why nothing validates on this fold, when nothing does (its training failed, or the
    /// held-out experiment scores no cell).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nothing_validates: Option<String>,
}

/// Every fold, the errors pooled over them and the medians.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CrossValidation {
    /// The folds, in data-set order.
    pub folds: Vec<Fold>,
    /// Offline errors pooled over the folds that have one: per state and overall, each
    /// fold weighted by its scored cells.
    #[serde(default)]
    pub pooled_offline: Option<ErrorSet>,
    /// Online errors pooled likewise (infinite where a fold's free run diverged).
    #[serde(default)]
    pub pooled_online: Option<ErrorSet>,
    /// Median over folds of the overall offline error.
    #[serde(with = "crate::json")]
    pub median_offline: Option<f64>,
    /// Median over folds of the overall online error (infinite where a fold diverged).
    #[serde(with = "crate::json")]
    pub median_online: Option<f64>,
}

/// Who hears of the folds: `(on_fold, on_event)` of [`cross_validate`].
pub type Listeners<'l> = (
    &'l mut dyn FnMut(usize, usize),
    &'l mut dyn for<'a> FnMut(Event<'a>),
);

/// Trains one model per experiment of `records`, on all the others, and scores it on the
/// one held out; with `keep`, saves each fold ([`Keep`]). `on_fold(k, folds)` hears before
/// fold `k` (0-based) starts, `on_event` of every fold's training.
pub fn cross_validate(
    model: &ir::Model,
    records: &[Record],
    (options, recipe): (&TrainOptions, &Recipe),
    keep: Option<&Keep>,
    (on_fold, on_event): Listeners,
) -> Result<CrossValidation, TrainError> {
    if records.len() < 2 {
        return Err(TrainError::BadOption {
            option: "cv".into(),
            expected: "at least two experiments (each fold trains on the others)".into(),
            found: format!("{} experiment", records.len()),
        });
    }
    let options = TrainOptions {
        train_points: None,
        ..options.clone()
    };
    let mut folds = Vec::with_capacity(records.len());
    for index in 0..records.len() {
        on_fold(index, records.len());
        let fold = one_fold(model, (records, index), (&options, recipe), keep, on_event)?;
        folds.push(fold);
    }
    let overall = |pick: &dyn Fn(&Fold) -> Option<&ErrorSet>| {
        let values: Vec<f64> = (folds.iter())
            .filter_map(|f| pick(f).map(|set| set.overall))
            .collect();
        crate::numeric::median(&values)
    };
    let result = CrossValidation {
        pooled_offline: pooled(folds.iter().filter_map(|f| f.offline.as_ref())),
        pooled_online: pooled(folds.iter().filter_map(|f| f.online.as_ref())),
        median_offline: overall(&|f: &Fold| f.offline.as_ref()),
        median_online: overall(&|f: &Fold| f.online.as_ref()),
        folds,
    };
    if let Some(keep) = keep {
        let path = keep.directory.join(CV_DIR).join(SUMMARY_FILE);
        let json = serde_json::to_string_pretty(&result)
            .map_err(|error| crate::train::tensors::bad_run(&path, error))?;
        crate::io::write_atomic(&path, json.as_bytes())?;
    }
    Ok(result)
}

/// Fold `index`: trains on the other records, scores and (with `keep`) saves. A fold that
/// cannot train (its held-out experiment too short, say) is reported, not an error; an
/// I/O or internal failure is.
fn one_fold(
    model: &ir::Model,
    (records, index): (&[Record], usize),
    (options, recipe): (&TrainOptions, &Recipe),
    keep: Option<&Keep>,
    on_event: &mut dyn FnMut(Event),
) -> Result<Fold, TrainError> {
    let started = Instant::now();
    let held = &records[index];
    let train: Vec<Record> = (records.iter().enumerate())
        .filter(|(other, _)| *other != index)
        .map(|(_, r)| r.clone())
        .collect();
    let data = TrainingData {
        train: &train,
        validation: std::slice::from_ref(held),
        part: Part::All,
    };
    let control = RunControl {
        keep_last_finite: keep.is_some(),
        recoveries: keep.map_or(0, |k| k.recoveries),
        ..RunControl::default()
    };
    let mut fold = Fold {
        held_out: held.name.clone(),
        offline: None,
        online: None,
        seconds: 0.0,
        run: None,
        diverged: None,
        nothing_validates: None,
    };
    let trained = match train_run(model, &data, (options, recipe), &control, on_event) {
        Ok(trained) => trained,
        Err(error @ (TrainError::Io(_) | TrainError::Backend(_))) => return Err(error),
        Err(error) => {
            fold.nothing_validates = Some(format!("its training failed: {error}"));
            fold.seconds = started.elapsed().as_secs_f64();
            return Ok(fold);
        }
    };
    let metrics = &trained.report.metrics;
    (fold.offline, fold.online) = (metrics.offline.clone(), metrics.online.clone());
    fold.diverged = trained.report.diverged.clone();
    if fold.offline.is_none() && fold.online.is_none() {
        fold.nothing_validates = Some(format!(
            "`{}` scores no measured cell (no pair with a measured history, no free-run \
             row after its start)",
            held.name
        ));
    }
    if let Some(keep) = keep {
        fold.run = Some(save_fold(model, (index, held), options, keep, &trained)?);
    }
    fold.seconds = started.elapsed().as_secs_f64();
    Ok(fold)
}

/// Writes fold `index`'s run and its held-out free run; returns its directory relative to
/// the run directory.
fn save_fold(
    model: &ir::Model,
    (index, held): (usize, &Record),
    options: &TrainOptions,
    keep: &Keep,
    trained: &Trained,
) -> Result<String, TrainError> {
    let relative = Path::new(CV_DIR).join(fold_name(index, &held.name));
    let directory = keep.directory.join(&relative);
    let info = artifacts::run_info(model, keep.model, keep.data, options, trained);
    artifacts::save(&directory, &info, &trained.network)?;
    let range = PhysicalRange::new(
        &trained.setup.normalisation,
        trained.report.recipe.range_factor,
    );
    let how = (Mode::Online, options.history, range.as_ref());
    let mut table = predict_in_range(model, &trained.network, &trained.setup, held, how)?;
    table.cut_at_divergence();
    let path = directory.join(PREDICTIONS_FILE);
    crate::data::write_table(&path, None, &table.header, &table.columns)?;
    Ok(relative.display().to_string())
}

/// `fold-K-NAME`, K from 1 with two digits, NAME with anything but letters, digits, `-`,
/// `_` and `.` replaced by `_`.
pub fn fold_name(index: usize, name: &str) -> String {
    let clean: String = (name.chars())
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("fold-{:02}-{clean}", index + 1)
}

/// Error sets pooled: per state and overall, each set weighted by its scored cells (an
/// infinite error stays infinite). `None` for no set.
fn pooled<'e>(sets: impl Iterator<Item = &'e ErrorSet>) -> Option<ErrorSet> {
    let sets: Vec<&ErrorSet> = sets.collect();
    let first = sets.first()?;
    let weight = |set: &ErrorSet| set.cells.max(1) as f64;
    let mean = |value: &dyn Fn(&ErrorSet) -> Option<f64>| {
        let (sum, weights) =
            (sets.iter()).fold((0.0, 0.0), |(sum, weights), set| match value(set) {
                Some(v) => (sum + v * weight(set), weights + weight(set)),
                None => (sum, weights),
            });
        sum / weights
    };
    let states: Vec<String> = (first.per_state.iter()).map(|(n, _)| n.clone()).collect();
    let per_state = (states.iter())
        .map(|name| {
            let of = |set: &ErrorSet| {
                (set.per_state.iter())
                    .find(|(n, _)| n == name)
                    .map(|(_, v)| *v)
            };
            (name.clone(), mean(&of))
        })
        .collect();
    Some(ErrorSet {
        per_state,
        overall: mean(&|set| Some(set.overall)),
        rows: sets.iter().map(|s| s.rows).sum(),
        cells: sets.iter().map(|s| s.cells).sum(),
        divergence: None,
    })
}
