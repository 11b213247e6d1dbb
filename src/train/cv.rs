//! Leave-one-experiment-out cross-validation (`gbc train --cv`, records spec section 3):
//! each experiment in turn is held out, a model is trained on the others and scored on it;
//! the report gives each fold and the median over folds.

use std::time::Instant;

use crate::ir;
use crate::record::Record;

use super::{train_with, ErrorSet, Event, Part, Recipe, TrainError, TrainOptions, TrainingData};

/// One fold: the experiment held out and its errors.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fold {
    /// The held-out experiment.
    pub held_out: String,
    /// Its offline error (absent without a pair of measured history).
    pub offline: Option<ErrorSet>,
    /// Its online error.
    pub online: Option<ErrorSet>,
    /// Wall-clock seconds of the fold.
    #[serde(with = "crate::json")]
    pub seconds: f64,
}

/// Every fold and the medians over them.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CrossValidation {
    /// The folds, in data-set order.
    pub folds: Vec<Fold>,
    /// Median over folds of the overall offline error.
    #[serde(with = "crate::json")]
    pub median_offline: Option<f64>,
    /// Median over folds of the overall online error (infinite where a fold diverged).
    #[serde(with = "crate::json")]
    pub median_online: Option<f64>,
}

/// Trains one model per experiment of `records`, on all the others, and scores it on the
/// one held out; `on_fold(k, folds)` hears before fold `k` (0-based) starts, and
/// `on_event` of every fold's training.
pub fn cross_validate(
    model: &ir::Model,
    records: &[Record],
    (options, recipe): (&TrainOptions, &Recipe),
    on_fold: &mut dyn FnMut(usize, usize),
    on_event: &mut dyn FnMut(Event),
) -> Result<CrossValidation, TrainError> {
    if records.len() < 2 {
        return Err(TrainError::BadOption {
            option: "cv".into(),
            expected: "at least two experiments (each fold trains on the others)".into(),
            found: format!("{} experiment", records.len()),
        });
    }
    let mut folds = Vec::with_capacity(records.len());
    for (index, held) in records.iter().enumerate() {
        on_fold(index, records.len());
        let started = Instant::now();
        let train: Vec<Record> = (records.iter().enumerate())
            .filter(|(other, _)| *other != index)
            .map(|(_, r)| r.clone())
            .collect();
        let data = TrainingData {
            train: &train,
            validation: std::slice::from_ref(held),
            part: Part::All,
        };
        let options = TrainOptions {
            train_points: None,
            ..options.clone()
        };
        let trained = train_with(model, &data, &options, recipe, on_event)?;
        let metrics = trained.report.metrics;
        folds.push(Fold {
            held_out: held.name.clone(),
            offline: metrics.offline,
            online: metrics.online,
            seconds: started.elapsed().as_secs_f64(),
        });
    }
    let overall = |pick: &dyn Fn(&Fold) -> Option<&ErrorSet>| {
        let values: Vec<f64> = (folds.iter())
            .filter_map(|f| pick(f).map(|set| set.overall))
            .collect();
        crate::numeric::median(&values)
    };
    Ok(CrossValidation {
        median_offline: overall(&|f: &Fold| f.offline.as_ref()),
        median_online: overall(&|f: &Fold| f.online.as_ref()),
        folds,
    })
}
