//! Which experiments train and which validate, and how much of each training experiment
//! trains: the one rule of `gbc train`, its `--holdout`, `--val`, `--val-fraction`,
//! `--train-points` and `--cv`.

use super::ApiError;
use crate::record::Record;
use crate::train::{Part, TrainError};

/// How validation is asked for (the CLI's flags).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Validation {
    /// Experiments of the data set that validate instead of training (`--holdout`).
    pub holdout: Vec<String>,
    /// Hold out the last share of each experiment's rows (`--val-fraction`).
    pub val_fraction: Option<f64>,
    /// Train on the first N one-step pairs (the paper's protocol, `--train-points`).
    pub train_points: Option<usize>,
    /// Leave-one-experiment-out cross-validation (`--cv`): with nothing else validating,
    /// the final model trains on every experiment.
    pub cv: bool,
}

/// The experiments that train and validate, and the part of each training one that trains.
#[derive(Debug, Clone)]
pub struct Split {
    /// The training experiments.
    pub train: Vec<Record>,
    /// Whole experiments that validate.
    pub validation: Vec<Record>,
    /// How much of each training experiment trains.
    pub part: Part,
    /// What the split chose by itself, for the caller to say (e.g. the experiment that
    /// validates by default).
    pub note: Option<String>,
}

/// Splits `records` into the experiments that train and those named in `holdout`; an
/// unknown name is an error that lists the experiments, and holding out every experiment
/// leaves none to train.
pub fn hold_out(
    records: Vec<Record>,
    holdout: &[String],
) -> Result<(Vec<Record>, Vec<Record>), ApiError> {
    let names: Vec<&str> = records.iter().map(|r| r.name.as_str()).collect();
    for name in holdout {
        if !names.contains(&name.as_str()) {
            return Err(ApiError::from(TrainError::BadOption {
                option: "--holdout".into(),
                expected: format!(
                    "the name of an experiment ({})",
                    crate::suggest::did_you_mean(name, &names, "experiments")
                ),
                found: name.clone(),
            }));
        }
    }
    let (held, kept): (Vec<Record>, Vec<Record>) =
        records.into_iter().partition(|r| holdout.contains(&r.name));
    if kept.is_empty() {
        return Err(ApiError::from(TrainError::NoTrainingExperiment));
    }
    Ok((kept, held))
}

/// The split of `records` (plus the experiments of `val`, which validate) that `asked`
/// describes: `val_fraction` holds out each experiment's tail; `train_points`, or one
/// experiment with nothing validating, trains on the first pairs; otherwise whole
/// experiments, and with several and none held out the last one validates (said in
/// [`Split::note`]) unless `cv` asks to train the final model on all.
pub fn split(
    records: Vec<Record>,
    val: Vec<Record>,
    asked: &Validation,
) -> Result<Split, ApiError> {
    let (mut train, mut validation) = hold_out(records, &asked.holdout)?;
    validation.extend(val);
    let mut note = None;
    let part = if let Some(share) = asked.val_fraction {
        if !(share > 0.0 && share < 1.0) {
            return Err(ApiError::from(TrainError::BadOption {
                option: "--val-fraction".into(),
                expected: "a share strictly between 0 and 1".into(),
                found: share.to_string(),
            }));
        }
        Part::Tail(share)
    } else if asked.train_points.is_some() || (train.len() == 1 && validation.is_empty()) {
        Part::FirstPairs(asked.train_points)
    } else {
        if validation.is_empty() && !asked.cv {
            if let Some(last) = train.pop() {
                note = Some(format!(
                    "validating on experiment `{}` (the last one; choose with --holdout NAME, \
                     --val-fraction SHARE or --cv)",
                    last.name
                ));
                validation.push(last);
            }
        }
        Part::All
    };
    Ok(Split {
        train,
        validation,
        part,
        note,
    })
}
