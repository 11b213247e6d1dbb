//! A what-if run of a trained model (see [`crate::trained::predict::whatif`]): the trained
//! model free-run under the spec's input programmes from the declared, given or measured
//! initial state.
//!
//! The model is matched to the weights by its structure: a model whose comments, consts or
//! balances changed runs with notes saying what changed; one whose structure changed is
//! refused (E0416). A run that leaves the physical range of the training data stops before
//! it with a warning, as an online prediction does; a value that is not finite is never
//! written (E0253). An ensemble run gives the members' median and the calibrated band of
//! each measured state (`X_lo`, `X_hi`).

use std::path::Path;

use super::{
    initial_values, input_signals, ApiError, Model, SimulateError, SimulateEvent, SimulateSpec,
    Simulation,
};
use crate::record::Record;
use crate::trained::artifacts;
use crate::trained::predict::whatif::{what_if, WhatIf, WhatIfError};

/// Runs the trained model of `weights` as `spec` asks.
pub(super) fn run(
    model: &Model,
    weights: &Path,
    spec: &SimulateSpec,
    on_event: &mut dyn FnMut(SimulateEvent),
) -> Result<Simulation, ApiError> {
    if crate::ensemble::is_ensemble(weights) {
        return run_ensemble(model, weights, spec, on_event);
    }
    let ir = model.ir();
    let restored = artifacts::restore_with_notes(ir, &model.source, weights)?;
    for note in &restored.notes {
        on_event(SimulateEvent::Note(note.clone()));
    }
    let history = read_history(model, spec)?;
    let (signals, what) = start(model, spec, history.as_ref(), restored.setup.step)?;
    let what = WhatIf {
        signals: &signals,
        ..what
    };
    let range = restored.info.physical_range();
    let network = (&restored.network, &restored.setup);
    let mut table = what_if(ir, network, &what, range.as_ref()).map_err(|error| match error {
        WhatIfError::Train(error) => ApiError::from(error),
        other => ApiError::user(other),
    })?;
    if let Some(divergence) = &table.divergence {
        on_event(SimulateEvent::Warning(format!(
            "{divergence}; the run stops before it"
        )));
    }
    table.cut_at_divergence();
    Ok(Simulation::of_table(table.header, table.columns))
}

/// The input signals and the start of a what-if run (its signals left empty, for the
/// caller to fill in: they borrow from the first).
fn start<'a>(
    model: &Model,
    spec: &SimulateSpec,
    history: Option<&'a Record>,
    step: f64,
) -> Result<(Vec<crate::signal::Signal>, WhatIf<'a>), ApiError> {
    let t_start = (spec.t_start)
        .or_else(|| history.and_then(|h| h.times.last().copied()))
        .unwrap_or(0.0);
    let dt = spec.dt.unwrap_or(step);
    let signals = input_signals(model.ir(), &spec.inputs, (t_start, spec.t_end, dt))?;
    let what = WhatIf {
        signals: &[],
        t_start,
        t_end: spec.t_end,
        dt,
        initial: initial_values(model.ir(), &spec.init)?,
        history,
    };
    Ok((signals, what))
}

/// The what-if run of every member of the ensemble in `weights`: the members' median and
/// the calibrated band of each measured state (`X_lo`, `X_hi`).
fn run_ensemble(
    model: &Model,
    weights: &Path,
    spec: &SimulateSpec,
    on_event: &mut dyn FnMut(SimulateEvent),
) -> Result<Simulation, ApiError> {
    let (ir, source) = (model.ir(), model.source.as_str());
    let level = crate::ensemble::check_level(spec.band).map_err(ApiError::user)?;
    let loaded = crate::ensemble::load(ir, source, weights).map_err(ApiError::user)?;
    for note in &loaded.notes {
        on_event(SimulateEvent::Note(note.clone()));
    }
    if let Some(reason) = &loaded.info.calibration.reason {
        on_event(SimulateEvent::Note(format!(
            "the ensemble's band is not calibrated ({reason}): the members' median alone"
        )));
    }
    let history = read_history(model, spec)?;
    let (signals, what) = start(model, spec, history.as_ref(), loaded.step)?;
    let what = WhatIf {
        signals: &signals,
        ..what
    };
    let jobs = spec
        .jobs
        .unwrap_or_else(crate::experiment::default_jobs)
        .max(1);
    let members = loaded.members.len();
    on_event(SimulateEvent::Members { members, jobs });
    let how = (Some(level), jobs);
    let band = crate::ensemble::predict::what_if_band(ir, (source, &loaded), &what, how)
        .map_err(ApiError::user)?;
    for stopped in &band.stopped {
        on_event(SimulateEvent::Warning(format!(
            "{stopped}; its run stops there"
        )));
    }
    if let Some(time) = band.ended {
        on_event(SimulateEvent::Warning(format!(
            "fewer than half the members run from t = {time}: the run stops before it"
        )));
    }
    Ok(Simulation::of_table(band.table.header, band.table.columns))
}

/// The one experiment of the spec's history file, if it names one.
fn read_history(model: &Model, spec: &SimulateSpec) -> Result<Option<Record>, ApiError> {
    let Some(path) = &spec.history else {
        return Ok(None);
    };
    let mut records = model.records_from_files(std::slice::from_ref(path), &spec.columns)?;
    if records.len() != 1 {
        return Err(ApiError::user(SimulateError::SeveralHistories {
            path: path.display().to_string(),
            found: records.len(),
        }));
    }
    Ok(Some(records.remove(0)))
}
