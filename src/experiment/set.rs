//! A study on a data set (records spec): every model reads the study's files with the one
//! reader ([`crate::data::read_set`]) and binds them to its own columns; the experiments
//! named in [`Validation::Holdout`] are held out and free-run whole, every other one
//! trains. A size is the first pairs over the training experiments in data-set order (as
//! `gbc train --train-points`), and every error is on the scale of the held-out
//! experiments' measured cells.

use super::{ExperimentError, ExperimentFailure, Study, Validation};
use crate::data::MinRows;
use crate::ir;
use crate::numeric::mean_std;
use crate::record::Record;
use crate::train::{Part, TrainingData};

/// The experiments of one model of a study on a data set.
#[derive(Debug, Clone)]
pub struct SetSplit {
    /// The experiments that train, in data-set order.
    pub train: Vec<Record>,
    /// The held-out experiments, in data-set order.
    pub held: Vec<Record>,
}

impl SetSplit {
    /// What a run trains on: the first pairs of the training experiments (the run's size is
    /// set through the options' `train_points`), validated on the held-out experiments.
    pub fn training_data(&self) -> TrainingData<'_> {
        TrainingData {
            train: &self.train,
            validation: &self.held,
            part: Part::All,
        }
    }
}

/// Reads the study's data set for `model` and splits it by the held-out names; an unknown
/// name lists the experiments there are, and holding out every experiment is refused.
pub fn load(study: &Study, model: &ir::Model) -> Result<SetSplit, ExperimentFailure> {
    let Validation::Holdout(names) = &study.validation else {
        return Err(ExperimentFailure::Internal(
            "a data-set split asked of a study without held-out experiments".into(),
        ));
    };
    let request = crate::record::request(model, &[], MinRows::new(2, "one step needs two rows"));
    let files: Vec<std::path::PathBuf> = (study.data.paths().into_iter())
        .map(std::path::Path::to_path_buf)
        .collect();
    let data = crate::data::read_set(&files, &request)?;
    let records = crate::record::bind(model, &data)
        .map_err(|error| ExperimentFailure::User(vec![miette::Report::new(error)]))?;
    let known: Vec<&str> = records.iter().map(|r| r.name.as_str()).collect();
    for name in names {
        if !known.contains(&name.as_str()) {
            return Err(ExperimentError::BadOption {
                option: "--holdout".into(),
                expected: format!(
                    "the name of an experiment ({})",
                    crate::suggest::did_you_mean(name, &known, "experiments")
                ),
                found: name.clone(),
            }
            .into());
        }
    }
    let (held, train): (Vec<Record>, Vec<Record>) =
        records.into_iter().partition(|r| names.contains(&r.name));
    if train.is_empty() {
        return Err(ExperimentError::BadOption {
            option: "--holdout".into(),
            expected: "at least one experiment left to train".into(),
            found: format!("all {} held out", held.len()),
        }
        .into());
    }
    Ok(SetSplit { train, held })
}

/// The standard deviation of each measured state over the held-out experiments' measured
/// cells, by name (the first model that has the state decides): the common scale of every
/// error of the study.
pub fn reference_scale<'a>(
    models: impl IntoIterator<Item = (&'a ir::Model, &'a SetSplit)>,
) -> Vec<(String, f64)> {
    let mut scale: Vec<(String, f64)> = Vec::new();
    for (model, set) in models {
        for (index, state) in model.states.iter().enumerate() {
            if scale.iter().any(|(name, _)| name == &state.name) {
                continue;
            }
            let cells: Vec<f64> = (set.held.iter())
                .flat_map(|record| record.states[index].iter().flatten().copied())
                .collect();
            if cells.len() >= 2 {
                scale.push((state.name.clone(), mean_std(&cells).1));
            }
        }
    }
    scale
}

/// The training pairs a model can take from the training experiments (the largest size)
/// under the study's settings.
pub fn available_pairs(
    model: &ir::Model,
    set: &SetSplit,
    options: &crate::train::TrainOptions,
) -> Result<usize, ExperimentFailure> {
    Ok(crate::train::available_pairs(
        model,
        &set.training_data(),
        options,
    )?)
}
