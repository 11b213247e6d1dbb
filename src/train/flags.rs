//! The one mapping from a training setting's field to the flag (and keyword) that sets it,
//! so that a bad value is reported as the user typed it, on the command line or in Python.

use super::TrainError;

/// The flag that sets a training field (`batch_size` -> `--batch`); the one mapping.
pub fn flag_of(field: &str) -> Option<&'static str> {
    Some(match field {
        "epochs" => "--epochs",
        "batch_size" => "--batch",
        "learning_rate" => "--lr",
        "precision" => "--precision",
        "substeps" => "--substeps",
        "engine" => "--engine",
        "train_points" => "--train-points",
        "online_horizon" => "--online-horizon",
        "dt" => "--dt",
        "column_weights" => "--weight",
        "param_learning_rate" => "--param-lr",
        "horizon" => "--horizon",
        "range_factor" => "--range-factor",
        "max_gradient_norm" => "--clip",
        "warmup_share" => "--warmup",
        "ramp_share" => "--ramp",
        "windows_per_batch" => "--windows",
        "cv" => "--cv",
        "toward_mechanism" => "--toward-mechanism",
        _ => return None,
    })
}

/// A training error whose option is a field set by a flag, renamed to the flag.
pub fn with_flag(error: TrainError) -> TrainError {
    match error {
        TrainError::BadOption {
            option,
            expected,
            found,
        } => TrainError::BadOption {
            option: flag_of(&option).map_or(option, str::to_string),
            expected,
            found,
        },
        other => other,
    }
}
