//! A data set from several files: the `--column` mapping checked, each file read, and each
//! experiment checked (time order, distinct names, inputs, states, length).

use super::error::DataError;
use super::experiment::{DataSet, Experiment};
use super::file::{open, read_rows, Opened};
use super::header::{EXPERIMENT, TIME};
use super::request::{MinRows, Request, Role};
use super::source::Source;
use crate::suggest::did_you_mean;
use std::path::PathBuf;

/// Reads the data set made of `files`, keeping the columns `request` asks for, and checks
/// every rule of the [module documentation](super).
pub fn read_set(files: &[PathBuf], request: &Request) -> Result<DataSet, DataError> {
    check_mapping(request)?;
    let sources = files
        .iter()
        .map(|path| load(path))
        .collect::<Result<Vec<_>, _>>()?;
    read_sources(sources, request)
}

/// Reads a data set from `(name, text)` pairs, each as if read from a file `name`;
/// otherwise as [`read_set`].
pub fn read_set_str(
    named_texts: &[(String, String)],
    request: &Request,
) -> Result<DataSet, DataError> {
    let sources = named_texts
        .iter()
        .map(|(name, text)| Source::new(name, PathBuf::from(name), text.clone()))
        .collect();
    read_sources(sources, request)
}

/// Reads the file at `path` into a source.
pub(super) fn load(path: &std::path::Path) -> Result<Source, DataError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| DataError::Unreadable {
        file: file.clone(),
        reason: crate::io::describe(&error),
    })?;
    Source::from_bytes(&file, path.to_path_buf(), bytes)
}

/// Reads and checks the experiments of `sources`.
fn read_sources(sources: Vec<Source>, request: &Request) -> Result<DataSet, DataError> {
    let experiments = experiments(sources, request)?;
    for experiment in &experiments {
        check_times(experiment)?;
        check_roles(experiment, request)?;
        check_length(experiment, &request.min_rows)?;
    }
    Ok(DataSet { experiments })
}

/// The experiments of `sources`, their names checked for being distinct, before the checks
/// of time order, roles and length.
pub(super) fn experiments(
    sources: Vec<Source>,
    request: &Request,
) -> Result<Vec<Experiment>, DataError> {
    check_mapping(request)?;
    let opened: Vec<Opened> = sources.into_iter().map(open).collect::<Result<_, _>>()?;
    let elsewhere = |header: &str| {
        opened
            .iter()
            .any(|file| file.header.matching(header).is_some())
    };
    let mut experiments: Vec<Experiment> = Vec::new();
    for file in &opened {
        let layout = file.header.layout(&file.source, request, &elsewhere)?;
        for experiment in read_rows(file, &layout, request)? {
            if let Some(first) = experiments.iter().find(|e| e.name == experiment.name) {
                return Err(duplicate(first, &experiment));
            }
            experiments.push(experiment);
        }
    }
    Ok(experiments)
}

/// Checks the `--column` mappings: each names a requested column, `t` or `experiment`,
/// once.
fn check_mapping(request: &Request) -> Result<(), DataError> {
    let mut names: Vec<&str> = vec![TIME, EXPERIMENT];
    names.extend(request.columns.iter().map(|wanted| wanted.name.as_str()));
    for (index, (name, header)) in request.mapping.iter().enumerate() {
        if !names.contains(&name.as_str()) {
            return Err(DataError::UnknownMapping {
                name: name.clone(),
                help: did_you_mean(name, &names, "names that can be mapped"),
            });
        }
        if let Some((_, first)) = request.mapping[..index].iter().find(|(n, _)| n == name) {
            return Err(DataError::RepeatedMapping {
                name: name.clone(),
                first: first.clone(),
                second: header.clone(),
            });
        }
    }
    Ok(())
}

/// Checks that time strictly increases within `experiment`.
pub(super) fn check_times(experiment: &Experiment) -> Result<(), DataError> {
    let origin = &experiment.origin;
    let time = origin.time.index;
    for sample in 1..experiment.len() {
        let (previous, found) = (experiment.times[sample - 1], experiment.times[sample]);
        if found > previous {
            continue;
        }
        let src = origin.source.clone();
        let span = origin.span(sample, Some(time));
        let at = origin.at(experiment.rows[sample], Some(origin.time.clone()));
        let experiment_name = experiment.name.clone();
        return Err(if found == previous {
            DataError::RepeatedTime {
                src,
                span,
                first_span: origin.span(sample - 1, Some(time)),
                time: found,
                experiment: experiment_name,
                first_row: experiment.rows[sample - 1],
                at,
            }
        } else {
            DataError::UnsortedTime {
                src,
                span,
                previous,
                found,
                experiment: experiment_name,
                previous_row: experiment.rows[sample - 1],
                at,
            }
        });
    }
    Ok(())
}

/// The error for a second experiment named like an earlier one.
fn duplicate(first: &Experiment, second: &Experiment) -> DataError {
    let place = |experiment: &Experiment| match &experiment.origin.experiment {
        Some(column) => (
            format!("`{}` row {}", experiment.origin.file, experiment.rows[0]),
            Some(column.clone()),
        ),
        None => (format!("`{}`", experiment.origin.file), None),
    };
    let (first_place, _) = place(first);
    let (_, column) = place(second);
    let origin = &second.origin;
    DataError::DuplicateExperiment {
        src: origin.source.clone(),
        span: origin.span(0, column.as_ref().map(|c| c.index)),
        name: second.name.clone(),
        first: first_place,
        at: origin.at(second.rows[0], column),
    }
}

/// Checks what the roles ask: an input has a value at the first row, a measured state has
/// at least one value.
fn check_roles(experiment: &Experiment, request: &Request) -> Result<(), DataError> {
    let origin = &experiment.origin;
    for wanted in &request.columns {
        let Some(series) = experiment.series(&wanted.name) else {
            continue;
        };
        let span = || origin.span(0, Some(series.index));
        let at = || origin.at(experiment.rows[0], Some(series.column()));
        match wanted.role {
            Role::Input if series.values[0].is_none() => {
                return Err(DataError::InputMissingAtStart {
                    src: origin.source.clone(),
                    span: span(),
                    input: wanted.name.clone(),
                    experiment: experiment.name.clone(),
                    at: at(),
                })
            }
            Role::State if series.values.iter().all(Option::is_none) => {
                return Err(DataError::StateNeverMeasured {
                    src: origin.source.clone(),
                    span: span(),
                    state: wanted.name.clone(),
                    experiment: experiment.name.clone(),
                    rows: experiment.len(),
                    at: at(),
                    help: format!(
                        "measure it, drop the experiment, or map another column with \
                         `--column {}=HEADER`",
                        wanted.name
                    ),
                })
            }
            _ => {}
        }
    }
    Ok(())
}

/// Checks that `experiment` has as many rows as the model needs.
pub(super) fn check_length(experiment: &Experiment, min_rows: &MinRows) -> Result<(), DataError> {
    if experiment.len() >= min_rows.rows {
        return Ok(());
    }
    let last = experiment.len().saturating_sub(1);
    let origin = &experiment.origin;
    Err(DataError::TooFewRows {
        src: origin.source.clone(),
        span: origin.span(last, None),
        needed: min_rows.rows,
        found: experiment.len(),
        reason: min_rows.reason.clone(),
        experiment: experiment.name.clone(),
        at: origin.at(experiment.rows.get(last).copied().unwrap_or(1), None),
    })
}
