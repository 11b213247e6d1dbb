//! `gbc train --cv`: runs the leave-one-experiment-out folds ([`crate::train::cv`]), each
//! kept under the run directory, and prints per fold and pooled the error per state and
//! overall, which folds' free runs diverged and where, and why a fold validates nothing.

use std::cell::RefCell;
use std::fmt::Write as _;
use std::path::Path;

use super::progress::Progress;
use super::summary::error;
use super::{train_error, CommandResult};
use crate::ir::Model;
use crate::record::Record;
use crate::train::cv::{self, CrossValidation, Keep};
use crate::train::{ErrorSet, Event, Recipe, TrainOptions};

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
    print!("{}", table(model, &result, &keep.directory));
    Ok(())
}

/// The folds as text: per fold and pooled, the online error of each state and overall and
/// the offline error overall; then the medians, the divergences and the empty folds.
pub(super) fn table(model: &Model, result: &CrossValidation, directory: &Path) -> String {
    let mut out = String::new();
    let states: Vec<&str> = model.states.iter().map(|s| s.name.as_str()).collect();
    let _ = writeln!(
        out,
        "leave-one-experiment-out cross-validation ({} folds; MSE of z-scored states, \
         online per state):",
        result.folds.len()
    );
    let mut header = format!("  {:<24}", "held out");
    for state in &states {
        let _ = write!(header, " {state:>12}");
    }
    let _ = writeln!(out, "{header} {:>12} {:>12}", "online", "offline");
    let row =
        |out: &mut String, name: &str, online: Option<&ErrorSet>, offline: Option<&ErrorSet>| {
            let mut line = format!("  {name:<24}");
            for state in &states {
                let value = online
                    .and_then(|s| s.per_state.iter().find(|(n, _)| n == state))
                    .map_or("-".into(), |(_, e)| error(*e));
                let _ = write!(line, " {value:>12}");
            }
            let overall = |set: Option<&ErrorSet>| set.map_or("-".into(), |s| error(s.overall));
            let _ = writeln!(
                out,
                "{line} {:>12} {:>12}",
                overall(online),
                overall(offline)
            );
        };
    for fold in &result.folds {
        row(
            &mut out,
            &fold.held_out,
            fold.online.as_ref(),
            fold.offline.as_ref(),
        );
    }
    row(
        &mut out,
        "pooled",
        result.pooled_online.as_ref(),
        result.pooled_offline.as_ref(),
    );
    let median = |value: Option<f64>| value.map_or("-".into(), error);
    let pad = " ".repeat(13 * states.len());
    let _ = writeln!(
        out,
        "  {:<24}{pad} {:>12} {:>12}",
        "median",
        median(result.median_online),
        median(result.median_offline)
    );
    for fold in &result.folds {
        notes(&mut out, fold);
    }
    let _ = writeln!(
        out,
        "each fold's run and held-out free run: {}",
        directory.join(cv::CV_DIR).display()
    );
    out
}

/// A fold's divergences and why it validates nothing, each on a line.
fn notes(out: &mut String, fold: &cv::Fold) {
    let name = &fold.held_out;
    if let Some(divergence) = fold.online.as_ref().and_then(|s| s.divergence.as_ref()) {
        let _ = writeln!(out, "  fold `{name}`: {divergence}");
    }
    if let Some(diverged) = &fold.diverged {
        let _ = writeln!(
            out,
            "  fold `{name}`: training went non-finite in epoch {} ({}): {}; its run keeps \
             epoch {}",
            diverged.epoch, diverged.phase, diverged.what, diverged.kept_epoch
        );
    }
    if let Some(why) = &fold.nothing_validates {
        let _ = writeln!(out, "  fold `{name}` validates nothing: {why}");
    }
}
