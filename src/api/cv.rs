//! `gbc train --cv` as a library call: one run per training experiment (those not held
//! out), each trained on the others and scored on the one it leaves out, kept under the
//! run directory with its held-out free run ([`crate::trained::cv`]).

use std::path::Path;

use super::{hold_out, ApiError, Model, TrainSpec};
use crate::record::Record;
use crate::trained::cv::{self, CrossValidation, Keep};

/// Runs the leave-one-experiment-out folds of `spec` over the experiments of `records`
/// that `spec` does not hold out, keeping each fold under `directory`;
/// `on_fold(k, folds, name)` hears before fold `k` starts (holding out experiment `name`),
/// `on_event` every fold's training.
pub fn cross_validate(
    model: &Model,
    records: Vec<Record>,
    spec: &TrainSpec,
    directory: &Path,
    (on_fold, on_event): FoldListeners,
) -> Result<CrossValidation, ApiError> {
    let (train, _) = hold_out(records, &spec.validation.holdout)?;
    let names: Vec<String> = train.iter().map(|r| r.name.clone()).collect();
    let described = spec.data.clone().unwrap_or_else(|| names.join(" "));
    let keep = Keep {
        directory: directory.to_path_buf(),
        model: (&model.origin, &model.source),
        data: &described,
        recoveries: spec.recoveries,
    };
    let settings = (&spec.options, &spec.recipe);
    Ok(cv::cross_validate(
        model.ir(),
        &train,
        settings,
        Some(&keep),
        (
            &mut |fold, folds| on_fold(fold, folds, &names[fold]),
            on_event,
        ),
    )?)
}

/// Who hears of [`cross_validate`]'s folds: `(on_fold(k, folds, held-out name), on_event)`.
pub type FoldListeners<'l> = (
    &'l mut dyn FnMut(usize, usize, &str),
    &'l mut dyn for<'a> FnMut(crate::train::Event<'a>),
);
