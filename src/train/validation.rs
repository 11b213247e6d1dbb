//! Training and validation splits: a record turned into pairs with hidden-state
//! estimates, and the paper's two validation errors on each validation set.

use crate::backend::{Network, Setup};
use crate::data::Dataset;
use crate::ir;

use super::evaluate::{offline_error, online_error, run_in_hidden, simulate, Feed, PhysicalRange};
use super::pairs::{stage_fractions, PairTable, Record};
use super::{pair_count, record_of, ErrorSet, TrainError, TrainOptions};

/// A set of pairs to validate on.
#[derive(Debug, Clone, Copy)]
pub enum Validation<'a> {
    /// The pairs of the training record after the training pairs (none when every pair
    /// trains).
    Rest,
    /// Every pair of another record.
    File(&'a Dataset),
}

/// A record turned into pairs, with hidden-state estimates.
pub(super) struct Split {
    /// What it is called in reports.
    pub name: String,
    pub record: Record,
    pub table: PairTable,
    pub hidden: Vec<Vec<f64>>,
}

/// Re-runs the hidden states along a split's record with the current network.
pub(super) fn refresh_hidden(
    network: &Network,
    model: &ir::Model,
    split: &mut Split,
    fractions: &[f64],
    hidden_init: &[f64],
) -> Result<(), TrainError> {
    if model.hidden.is_empty() {
        return Ok(());
    }
    split.hidden = run_in_hidden(network, model, &split.record, fractions, hidden_init)?;
    split.table.set_hidden(&split.hidden);
    Ok(())
}

/// The validation splits that have pairs, in the order asked for.
pub(super) fn validation_splits(
    model: &ir::Model,
    training: &Split,
    validations: &[Validation],
    (first, fractions): (usize, &[f64]),
    hidden_init: &[f64],
) -> Result<Vec<Split>, TrainError> {
    let mut splits = Vec::new();
    for validation in validations {
        let (name, record, rows) = match validation {
            Validation::File(data) => {
                let record = record_of(model, data)?;
                let step = training.record.step;
                if (record.step - step).abs() > 1e-9 * step {
                    return Err(TrainError::StepMismatch {
                        file: data.path.display().to_string(),
                        expected: step,
                        found: record.step,
                    });
                }
                let count = pair_count(data, &record, first)?;
                let name = data.path.display().to_string();
                (name, record, (first..first + count).collect::<Vec<_>>())
            }
            Validation::Rest => {
                let start = first + training.table.len();
                let end = training.record.len().saturating_sub(1);
                let name = format!("{} (rest)", training.name);
                (name, training.record.clone(), (start..end).collect())
            }
        };
        if rows.is_empty() {
            continue;
        }
        let hidden = vec![hidden_init.to_vec(); record.len()];
        let table = PairTable::build(model, &record, &rows, &hidden, fractions);
        splits.push(Split {
            name,
            record,
            table,
            hidden,
        });
    }
    Ok(splits)
}

/// Offline and online errors of a split with the current network (hidden states run in
/// first).
pub(super) fn validate(
    network: &Network,
    model: &ir::Model,
    split: &mut Split,
    (setup, options, range): (&Setup, &TrainOptions, Option<&PhysicalRange>),
    hidden_init: &[f64],
) -> Result<(ErrorSet, ErrorSet), TrainError> {
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    refresh_hidden(network, model, split, &fractions, hidden_init)?;
    let offline = offline_error(network, model, &split.table, &setup.normalisation)?;
    let start = split.table.rows[0];
    let last = split.record.len() - 1;
    let end = match options.online_horizon {
        Some(horizon) => (start + (horizon / setup.step).round() as usize).min(last),
        None => last,
    };
    let hidden = split.hidden.get(start).cloned().unwrap_or_default();
    let run = simulate(
        network,
        model,
        &split.record,
        &fractions,
        (start, end.saturating_sub(1).max(start)),
        &hidden,
        (Feed::Own, range),
    )?;
    let online = online_error(model, &split.record, &run, &setup.normalisation);
    Ok((offline, online))
}
