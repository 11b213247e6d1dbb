//! Preparing a study: [`prepare`] loads and checks every model and record once (models
//! compiled, records read with the columns the models need, the validation window cut,
//! every training size checked against the data, the files hashed for the study record),
//! so that [`super::execute`] only trains.

use std::ops::Range;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::results::{Fingerprint, StudyRecord};
use super::set::{self, SetSplit};
use super::{ExperimentError, ExperimentFailure, Study, Validation};
use crate::data::{Column, Dataset, MinRows};
use crate::engine::pairs::first_pair_row;
use crate::ir;
use crate::numeric::mean_std;
use crate::train::{self, TrainOptions};

/// A model of a study, compiled, with its validation record.
#[derive(Debug, Clone)]
pub struct LoadedModel {
    /// Its label.
    pub label: String,
    /// The model file.
    pub path: PathBuf,
    /// The compiled model.
    pub model: ir::Model,
    /// The file's text (for the weights' hash).
    pub source: String,
    /// Its validation record: the embedding history, then the validation window.
    pub validation: Dataset,
    /// Training pairs available before the validation window.
    pub available: usize,
    /// The row of [`Prepared::validation_source`] its validation record starts at.
    pub offset: usize,
    /// On a data set: its training and held-out experiments (then `validation` is empty).
    pub set: Option<SetSplit>,
}

/// A study with everything loaded and checked.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The study.
    pub study: Study,
    /// Its record (with the files' hashes).
    pub record: StudyRecord,
    /// The models, in study order.
    pub models: Vec<LoadedModel>,
    /// The rows that may train.
    pub training: Dataset,
    /// The whole record validation rows come from (the training file, or `--val FILE`).
    pub validation_source: Dataset,
    /// Standard deviation of each measured state over the validation window, by name: the
    /// common scale of every error.
    pub reference_scale: Vec<(String, f64)>,
    /// The generalisation records.
    pub generalisation: Vec<Dataset>,
    /// The truth model, if the study names one.
    pub truth: Option<ir::Model>,
}

/// Loads the study's models and records and checks that every size fits the data.
pub fn prepare(study: &Study) -> Result<Prepared, ExperimentFailure> {
    study.check()?;
    let mut reports = Vec::new();
    let mut compiled = Vec::new();
    for spec in &study.models {
        match crate::driver::compile_file(&spec.path, &[]) {
            Ok(result) => compiled.push(result.model),
            Err(errors) => reports.extend(errors),
        }
    }
    let truth = match &study.truth {
        Some(path) => match crate::driver::compile_file(path, &[]) {
            Ok(result) => Some(result.model),
            Err(errors) => {
                reports.extend(errors);
                None
            }
        },
        None => None,
    };
    if !reports.is_empty() {
        return Err(ExperimentFailure::User(reports));
    }
    if study.on_data_set() {
        return prepare_set(study, compiled, truth);
    }
    let required = required_columns(&compiled, truth.as_ref());
    let data = read_record(study.data.paths()[0], &required)?;
    let split = Split::new(study, &data, &required)?;
    let mut models = Vec::new();
    for (spec, model) in study.models.iter().zip(compiled) {
        let history = first_pair_row(&model, data.step);
        let (validation, available, offset) = split.for_model(&spec.label, history)?;
        check_sizes(
            study,
            &spec.label,
            available,
            "before the validation window",
        )?;
        models.push(LoadedModel {
            label: spec.label.clone(),
            path: spec.path.clone(),
            source: std::fs::read_to_string(&spec.path).unwrap_or_default(),
            model,
            validation,
            available,
            offset,
            set: None,
        });
    }
    let generalisation = (study.generalisation.iter())
        .map(|path| read_record(path, &required))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Prepared {
        record: study_record(study)?,
        study: study.clone(),
        reference_scale: split.reference_scale(&models),
        training: split.training,
        validation_source: split.source,
        models,
        generalisation,
        truth,
    })
}

/// A study on a data set: each model binds the experiments to its own columns.
fn prepare_set(
    study: &Study,
    compiled: Vec<ir::Model>,
    truth: Option<ir::Model>,
) -> Result<Prepared, ExperimentFailure> {
    let first = study.data.paths()[0].to_path_buf();
    let empty = Dataset {
        path: first,
        times: Vec::new(),
        step: 0.0,
        columns: Vec::new(),
    };
    let mut models = Vec::new();
    for (spec, model) in study.models.iter().zip(compiled) {
        let split = set::load(study, &model)?;
        let available = set::available_pairs(&model, &split, &study_options(study))?;
        check_sizes(study, &spec.label, available, "in the training experiments")?;
        models.push(LoadedModel {
            label: spec.label.clone(),
            path: spec.path.clone(),
            source: std::fs::read_to_string(&spec.path).unwrap_or_default(),
            model,
            validation: empty.clone(),
            available,
            offset: 0,
            set: Some(split),
        });
    }
    Ok(Prepared {
        record: study_record(study)?,
        study: study.clone(),
        reference_scale: set::reference_scale(
            (models.iter()).filter_map(|m| m.set.as_ref().map(|set| (&m.model, set))),
        ),
        training: empty.clone(),
        validation_source: empty,
        models,
        generalisation: Vec::new(),
        truth,
    })
}

/// Refuses a size above the `available` training pairs of model `label` (`where_`: where
/// they come from).
fn check_sizes(
    study: &Study,
    label: &str,
    available: usize,
    where_: &str,
) -> Result<(), ExperimentFailure> {
    match study.sizes.iter().copied().find(|s| *s > available) {
        Some(size) => Err(ExperimentError::BadOption {
            option: "--sizes".into(),
            expected: format!(
                "sizes of at most {available} (the training pairs of `{label}` {where_})"
            ),
            found: size.to_string(),
        }
        .into()),
        None => Ok(()),
    }
}

/// Every column the models (and the truth's inputs) read.
fn required_columns(models: &[ir::Model], truth: Option<&ir::Model>) -> Vec<String> {
    let mut required: Vec<String> = Vec::new();
    let names = (models.iter())
        .flat_map(|m| {
            m.inputs
                .iter()
                .map(|i| &i.name)
                .chain(m.states.iter().map(|s| &s.name))
        })
        .chain(truth.into_iter().flat_map(|t| {
            (t.inputs.iter().map(|i| &i.name)).chain(t.states.iter().map(|s| &s.name))
        }));
    for name in names {
        if !required.contains(name) {
            required.push(name.clone());
        }
    }
    required
}

fn read_record(path: &Path, required: &[String]) -> Result<Dataset, ExperimentFailure> {
    let names: Vec<&str> = required.iter().map(String::as_str).collect();
    Ok(crate::data::read(
        path,
        &names,
        MinRows::new(2, "one step needs two rows"),
    )?)
}

/// The training rows and where validation comes from.
struct Split {
    training: Dataset,
    /// The record validation rows are taken from.
    source: Dataset,
    /// First validated row of `source` (a step starts there).
    start: usize,
    /// Whether `source` is a separate file (its own history) or the training record.
    separate: bool,
}

impl Split {
    fn new(study: &Study, data: &Dataset, required: &[String]) -> Result<Split, ExperimentFailure> {
        match &study.validation {
            Validation::FromRow(row) => {
                if *row + 2 > data.len() {
                    return Err(ExperimentError::BadOption {
                        option: "--val-from".into(),
                        expected: format!(
                            "a row below {} (the record's rows less one)",
                            data.len() - 1
                        ),
                        found: row.to_string(),
                    }
                    .into());
                }
                Ok(Split {
                    training: slice(data, 0..*row),
                    source: data.clone(),
                    start: *row,
                    separate: false,
                })
            }
            Validation::File(path) => Ok(Split {
                training: data.clone(),
                source: read_record(path, required)?,
                start: 0,
                separate: true,
            }),
            Validation::Holdout(_) => Err(ExperimentFailure::Internal(
                "a uniform split asked of a study on a data set".into(),
            )),
        }
    }

    /// A model's validation record, its available training pairs, and the row of the
    /// source its record starts at.
    fn for_model(
        &self,
        label: &str,
        history: usize,
    ) -> Result<(Dataset, usize, usize), ExperimentFailure> {
        let too_short = |what: &str| ExperimentError::BadOption {
            option: "--val-from".into(),
            expected: format!(
                "room for the {history} rows of embedding history of `{label}` {what}"
            ),
            found: format!("{} rows", self.training.len()),
        };
        let available = (self.training.len())
            .checked_sub(history + 1)
            .filter(|a| *a > 0)
            .ok_or_else(|| too_short("and one training pair"))?;
        if self.separate {
            if self.source.len() < history + 2 {
                return Err(too_short("and one step in the validation file").into());
            }
            return Ok((self.source.clone(), available, 0));
        }
        let first = self
            .start
            .checked_sub(history)
            .ok_or_else(|| too_short("before it"))?;
        Ok((
            slice(&self.source, first..self.source.len()),
            available,
            first,
        ))
    }

    /// Std of each measured state over the validation window.
    fn reference_scale(&self, models: &[LoadedModel]) -> Vec<(String, f64)> {
        let history = (models.iter())
            .map(|m| first_pair_row(&m.model, self.source.step))
            .max()
            .unwrap_or(0);
        let start = if self.separate { history } else { self.start };
        let mut scale: Vec<(String, f64)> = Vec::new();
        for state in models.iter().flat_map(|m| &m.model.states) {
            if scale.iter().any(|(name, _)| name == &state.name) {
                continue;
            }
            if let Some(values) = self.source.column(&state.name) {
                let window = &values[start.min(values.len())..];
                scale.push((state.name.clone(), mean_std(window).1));
            }
        }
        scale
    }
}

/// Rows `rows` of a record.
pub fn slice(data: &Dataset, rows: Range<usize>) -> Dataset {
    Dataset {
        path: data.path.clone(),
        times: data.times[rows.clone()].to_vec(),
        step: data.step,
        columns: (data.columns.iter())
            .map(|c| Column {
                name: c.name.clone(),
                values: c.values[rows.clone()].to_vec(),
            })
            .collect(),
    }
}

/// The study with the hashes of its files.
fn study_record(study: &Study) -> Result<StudyRecord, ExperimentFailure> {
    let paths = study.files();
    let files = (paths.into_iter())
        .map(|path| {
            let bytes = std::fs::read(path).map_err(|error| ExperimentError::UnreadableFile {
                path: path.display().to_string(),
                reason: crate::io::describe(&error),
            })?;
            let sha256 = Sha256::digest(&bytes)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            Ok(Fingerprint {
                path: path.display().to_string(),
                sha256,
            })
        })
        .collect::<Result<Vec<_>, ExperimentError>>()?;
    Ok(StudyRecord {
        gbc_version: env!("CARGO_PKG_VERSION").to_string(),
        study: study.clone(),
        files,
    })
}

/// The training options every run of `study` shares.
pub(super) fn study_options(study: &Study) -> TrainOptions {
    TrainOptions {
        // The paper's protocol: validation runs start from measured history. On a data
        // set, each experiment starts at its first row (as `gbc train` does).
        history: if study.on_data_set() {
            train::History::Held
        } else {
            train::History::Measured
        },
        // The free run covers the whole validation window (the default).
        ..TrainOptions::with(&study.settings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file the study names that cannot be read when the study is hashed is reported by
    /// its path, as a file of the study (not as an unreadable study file).
    #[test]
    fn an_unreadable_file_of_the_study_is_named() {
        let study = Study {
            truth: Some("models/nowhere/truth.gbm".into()),
            ..Study::chemostat()
        };
        match study_record(&study) {
            Err(ExperimentFailure::User(reports)) => {
                let text = reports[0].to_string();
                assert!(
                    text.contains("`models/nowhere/truth.gbm`, named by the study"),
                    "{text}"
                );
            }
            other => panic!("expected a user error, found {other:?}"),
        }
    }
}
