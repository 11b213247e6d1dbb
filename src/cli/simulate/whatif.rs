//! `gbc simulate MODEL --weights RUN_DIR --input u=... --t-end T`: a what-if run of a trained
//! model (see `gbc::train::predict::whatif`), written as CSV: `t`, the inputs, the states
//! (measured, then hidden), every closure output and every model output.
//!
//! The model is matched to the weights by its structure: a model whose comments, consts or
//! balances changed runs with notes on stderr saying what changed; one whose structure
//! changed is refused (E0416). A run that leaves the physical range of the training data
//! stops before it with a warning, as `gbc predict --mode online` does; a value that is not
//! finite is never written (E0253).

use std::path::Path;

use super::super::data::load_records;
use super::super::train::{read_source, train_error};
use super::{
    initial_values, input_signals, CommandError, CommandResult, SimulateArgs, SimulateError,
};
use crate::ir::Model;
use crate::train::predict::whatif::{what_if, WhatIf, WhatIfError};
use crate::train::{artifacts, PhysicalRange};

/// Runs the trained model of `weights` under the arguments' programmes and writes the table.
pub fn run(model: &Model, weights: &Path, args: &SimulateArgs) -> CommandResult {
    let source = read_source(&args.model)?;
    if crate::ensemble::is_ensemble(weights) {
        return run_ensemble(model, (weights, &source), args);
    }
    let restored = artifacts::restore_with_notes(model, &source, weights).map_err(train_error)?;
    for note in &restored.notes {
        eprintln!("note: {note}");
    }
    let history = match &args.history {
        Some(path) => Some(read_history(model, path, args)?),
        None => None,
    };
    let t_start = (args.t_start)
        .or_else(|| history.as_ref().and_then(|h| h.times.last().copied()))
        .unwrap_or(0.0);
    let dt = args.dt.unwrap_or(restored.setup.step);
    let signals = input_signals(model, args, (t_start, args.t_end, dt))?;
    let what = WhatIf {
        signals: &signals,
        t_start,
        t_end: args.t_end,
        dt,
        initial: initial_values(model, &args.init)?,
        history: history.as_ref(),
    };
    let range = PhysicalRange::of_run(&restored.info);
    let mut table = what_if(
        model,
        (&restored.network, &restored.setup),
        &what,
        range.as_ref(),
    )
    .map_err(|error| match error {
        WhatIfError::Train(error) => train_error(error),
        other => CommandError::user(other),
    })?;
    if let Some(divergence) = &table.divergence {
        eprintln!("warning: {divergence}; the run stops before it");
    }
    table.cut_at_divergence();
    crate::data::write_csv(&args.output, &table.header, &table.columns).map_err(CommandError::user)
}

/// The what-if run of every member of the ensemble in `weights`: the members' median and
/// the calibrated band of each measured state (`X_lo`, `X_hi`).
fn run_ensemble(
    model: &Model,
    (weights, source): (&Path, &str),
    args: &SimulateArgs,
) -> CommandResult {
    let level = crate::ensemble::check_level(args.band).map_err(CommandError::user)?;
    let loaded = crate::ensemble::load(model, source, weights).map_err(CommandError::user)?;
    for note in &loaded.notes {
        eprintln!("note: {note}");
    }
    if let Some(reason) = &loaded.info.calibration.reason {
        eprintln!(
            "note: the ensemble's band is not calibrated ({reason}): the members' median alone"
        );
    }
    let history = match &args.history {
        Some(path) => Some(read_history(model, path, args)?),
        None => None,
    };
    let t_start = (args.t_start)
        .or_else(|| history.as_ref().and_then(|h| h.times.last().copied()))
        .unwrap_or(0.0);
    let dt = args.dt.unwrap_or(loaded.step);
    let signals = input_signals(model, args, (t_start, args.t_end, dt))?;
    let what = WhatIf {
        signals: &signals,
        t_start,
        t_end: args.t_end,
        dt,
        initial: initial_values(model, &args.init)?,
        history: history.as_ref(),
    };
    let jobs = crate::cli::experiment::default_jobs();
    eprintln!("running {} members ({jobs} at once)", loaded.members.len());
    let band = crate::ensemble::predict::what_if_band(
        model,
        (source, &loaded),
        &what,
        (Some(level), jobs),
    )
    .map_err(CommandError::user)?;
    for stopped in &band.stopped {
        eprintln!("warning: {stopped}; its run stops there");
    }
    if let Some(time) = band.ended {
        eprintln!(
            "warning: fewer than half the members run from t = {time}: the run stops before it"
        );
    }
    let table = band.table;
    crate::data::write_csv(&args.output, &table.header, &table.columns).map_err(CommandError::user)
}

/// The one experiment of the history file.
fn read_history(
    model: &Model,
    path: &Path,
    args: &SimulateArgs,
) -> Result<crate::record::Record, CommandError> {
    let mut records = load_records(model, &[path.to_path_buf()], &args.columns)?;
    if records.len() != 1 {
        return Err(CommandError::user(SimulateError::SeveralHistories {
            path: path.display().to_string(),
            found: records.len(),
        }));
    }
    Ok(records.remove(0))
}
