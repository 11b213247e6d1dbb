//! `gbc train --cv`: runs the leave-one-experiment-out folds ([`crate::train::cv`]), each
//! kept under the run directory, and prints per fold and pooled the error per state and
//! overall, which folds' free runs diverged and where, and why a fold validates nothing.

use super::progress::Progress;
use super::{train_error, CommandResult};
use crate::api::summary::cv_table;
use crate::ir::Model;
use crate::record::Record;
use crate::train::cv::{self, Keep};
use crate::train::{Event, Recipe, TrainOptions};
use std::cell::RefCell;

/// Runs the folds, keeping each under `keep.directory`, and prints the table.
pub(super) fn cross_validate(
    model: &Model,
    records: &[Record],
    settings: (&TrainOptions, &Recipe),
    keep: &Keep,
) -> CommandResult {
    let progress = RefCell::new(Progress::default());
    let epochs = settings.0.epochs;
    let mut on_fold = |fold: usize, folds: usize| {
        progress.borrow_mut().finish();
        let name = &records[fold].name;
        eprintln!(
            "cross-validation fold {}/{folds}: holding out `{name}`",
            fold + 1
        );
    };
    let mut on_event = |event: Event| progress.borrow_mut().observe(event, epochs);
    let result = cv::cross_validate(
        model,
        records,
        settings,
        Some(keep),
        (&mut on_fold, &mut on_event),
    );
    progress.borrow_mut().finish();
    let result = result.map_err(train_error)?;
    print!("{}", cv_table(model, &result, &keep.directory));
    Ok(())
}
