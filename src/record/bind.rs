//! A data set bound to a model: which columns a model reads (the [`request`]) and the
//! experiments in model terms ([`bind`]).
//!
//! Inputs are required and held between their given values; measured states are required
//! unless the model has an `output` that the data measure (an observable), in which case a
//! state without a column is simply not measured; every model `output` is read where a
//! column (or a `--column` mapping) names it.

use super::experiment::{Observable, Record};
use crate::data::{DataSet, Experiment, MinRows, Request, Wanted};
use crate::ir;

/// The columns `model` reads, with `--column` mappings and the rows each experiment needs.
pub fn request(
    model: &ir::Model,
    mapping: &[(String, String)],
    min_rows: impl Into<MinRows>,
) -> Request {
    let observables_possible = !model.outputs.is_empty();
    let mut columns: Vec<Wanted> = model
        .inputs
        .iter()
        .map(|i| Wanted::input(&i.name))
        .collect();
    columns.extend(model.states.iter().map(|s| {
        if observables_possible {
            Wanted::optional(&s.name)
        } else {
            Wanted::state(&s.name)
        }
    }));
    columns.extend(model.outputs.iter().map(|o| Wanted::optional(&o.name)));
    Request::new(columns)
        .with_mapping(mapping.to_vec())
        .with_min_rows(min_rows)
}

/// Why a data set does not fit a model.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum BindError {
    /// A measured state without a column, in a model that measures no output either.
    #[error("expected a column `{state}` in experiment `{experiment}` (`{file}`), found none")]
    #[diagnostic(
        code(gbm::E0230),
        help(
            "every measured state needs a column (map another header with --column \
             {state}=HEADER), unless an `output` of the model is measured instead"
        )
    )]
    MissingState {
        /// The state.
        state: String,
        /// The experiment.
        experiment: String,
        /// Its file.
        file: String,
    },
    /// No state and no observable of an experiment is measured anywhere.
    #[error("expected a measured state or output in experiment `{experiment}`, found none")]
    #[diagnostic(
        code(gbm::E0231),
        help("the loss sits at measured cells: give at least one state or output column")
    )]
    NothingMeasured {
        /// The experiment.
        experiment: String,
    },
}

/// The experiments of `data` in `model` terms, in data-set order.
pub fn bind(model: &ir::Model, data: &DataSet) -> Result<Vec<Record>, BindError> {
    data.experiments
        .iter()
        .map(|experiment| bind_one(model, experiment))
        .collect()
}

fn bind_one(model: &ir::Model, experiment: &Experiment) -> Result<Record, BindError> {
    let rows = experiment.times.len();
    let series = |name: &str| experiment.columns.iter().find(|s| s.name == name);
    let inputs = (model.inputs.iter())
        .map(|input| {
            let mut held = 0.0;
            let cells = series(&input.name).map(|s| s.values.clone());
            (0..rows)
                .map(|row| {
                    if let Some(value) = cells.as_ref().and_then(|c| c[row]) {
                        held = value;
                    }
                    held
                })
                .collect()
        })
        .collect();
    let observables: Vec<Observable> = (model.outputs.iter().enumerate())
        .filter_map(|(index, output)| {
            let cells = series(&output.name)?;
            cells
                .values
                .iter()
                .any(Option::is_some)
                .then(|| Observable {
                    output: index,
                    name: output.name.clone(),
                    cells: cells.values.clone(),
                })
        })
        .collect();
    let mut states = Vec::with_capacity(model.states.len());
    for state in &model.states {
        match series(&state.name) {
            Some(cells) => states.push(cells.values.clone()),
            None if !observables.is_empty() => states.push(vec![None; rows]),
            None => {
                return Err(BindError::MissingState {
                    state: state.name.clone(),
                    experiment: experiment.name.clone(),
                    file: experiment.file.display().to_string(),
                })
            }
        }
    }
    let measured = states.iter().flatten().any(Option::is_some) || !observables.is_empty();
    if !measured {
        return Err(BindError::NothingMeasured {
            experiment: experiment.name.clone(),
        });
    }
    Ok(Record {
        name: experiment.name.clone(),
        source: experiment.file.display().to_string(),
        times: experiment.times.clone(),
        inputs,
        states,
        observables,
    })
}
