//! `gbc train --cv`: runs the leave-one-experiment-out folds ([`api::cross_validate`]), each
//! kept under the run directory, and prints per fold and pooled the error per state and
//! overall, which folds' free runs diverged and where, and why a fold validates nothing.

use std::cell::RefCell;
use std::path::Path;

use super::progress::Progress;
use super::CommandResult;
use gbc::api::summary::cv_table;
use gbc::api::{self, Model, Record, TrainEvent as Event, TrainSpec};

/// Runs the folds, keeping each under `directory`, and prints the table.
pub(super) fn cross_validate(
    model: &Model,
    records: Vec<Record>,
    spec: &TrainSpec,
    directory: &Path,
) -> CommandResult {
    let progress = RefCell::new(Progress::default());
    let epochs = spec.options.epochs;
    let mut on_fold = |fold: usize, folds: usize, name: &str| {
        progress.borrow_mut().finish();
        eprintln!(
            "cross-validation fold {}/{folds}: holding out `{name}`",
            fold + 1
        );
    };
    let mut on_event = |event: Event| progress.borrow_mut().observe(event, epochs);
    let listeners = (&mut on_fold as _, &mut on_event as _);
    let result = api::cross_validate(model, records, spec, directory, listeners);
    progress.borrow_mut().finish();
    let result = result?;
    print!("{}", cv_table(model.ir(), &result, directory));
    Ok(())
}
