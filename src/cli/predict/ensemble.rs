//! `gbc predict` on an ensemble run: the members' median of every column and, for free runs,
//! the calibrated band of each measured state (`X_lo`, `X_hi`), with its coverage of the
//! data's measured cells on stdout. The work is `gbc::ensemble::predict`.

use std::sync::atomic::{AtomicUsize, Ordering};

use super::{mode_of, PredictArgs};
use crate::cli::data::load_records;
use crate::cli::{CommandError, CommandResult};
use crate::ensemble::{self, CellCount};
use crate::ir::Model;
use crate::plot::tick_label;
use crate::train::predict::Mode;

/// Predicts with every member and writes the combined table.
pub(super) fn run(args: &PredictArgs, model: &Model, source: &str) -> CommandResult {
    let level = ensemble::check_level(args.band).map_err(CommandError::user)?;
    let loaded = ensemble::load(model, source, &args.weights).map_err(CommandError::user)?;
    for note in &loaded.notes {
        eprintln!("note: {note}");
    }
    let records = load_records(model, &args.data, &args.columns)?;
    let mode = mode_of(args.mode);
    let calibration = &loaded.info.calibration;
    let banded = mode == Mode::Online && calibration.calibrated;
    if mode != Mode::Online {
        eprintln!(
            "note: the band is calibrated for free runs (--mode online): these are the \
             members' median predictions alone"
        );
    } else if let Some(reason) = &calibration.reason {
        eprintln!(
            "note: the ensemble's band is not calibrated ({reason}): the members' median alone"
        );
    }
    let members = loaded.members.len();
    let jobs = args
        .jobs
        .unwrap_or_else(crate::cli::experiment::default_jobs)
        .max(1);
    eprintln!("predicting with {members} members ({jobs} at once)");
    let done = AtomicUsize::new(0);
    let on_member = |_member: usize| {
        let finished = done.fetch_add(1, Ordering::Relaxed) + 1;
        eprintln!("predicting: {finished}/{members} members");
    };
    let how = (mode, args.history.into(), jobs);
    let tables =
        ensemble::predict::member_tables(model, (source, &loaded), &records, how, &on_member)
            .map_err(CommandError::user)?;
    let (mut header, mut columns, mut labels) = (Vec::new(), Vec::<Vec<f64>>::new(), Vec::new());
    let mut coverage: Vec<CellCount> = Vec::new();
    for (index, record) in records.iter().enumerate() {
        let mine: Vec<_> = tables.iter().map(|m| m[index].clone()).collect();
        let combined = ensemble::predict_table(
            model,
            &loaded.info,
            (record, &mine),
            banded.then_some(level),
        )
        .map_err(CommandError::user)?;
        for stopped in &combined.stopped {
            eprintln!("warning: {stopped}; its free run stops there");
        }
        if let Some(time) = combined.ended {
            eprintln!(
                "warning: {}: fewer than half the members run from t = {time}: the predictions stop before it",
                record.name
            );
        }
        add_counts(&mut coverage, &combined.coverage);
        let table = combined.table;
        let rows = table.columns.first().map_or(0, Vec::len);
        labels.extend(std::iter::repeat_n(record.name.clone(), rows));
        if columns.is_empty() {
            (header, columns) = (table.header, table.columns);
        } else {
            for (all, part) in columns.iter_mut().zip(table.columns) {
                all.extend(part);
            }
        }
    }
    let labels = (records.len() > 1).then_some(("experiment", labels.as_slice()));
    crate::data::write_table(&args.output, labels, &header, &columns)
        .map_err(CommandError::user)?;
    print!("{}", coverage_text(&coverage, level));
    Ok(())
}

/// Adds one experiment's counts to the totals, state by state.
fn add_counts(totals: &mut Vec<CellCount>, counts: &[CellCount]) {
    for count in counts {
        match totals.iter_mut().find(|t| t.state == count.state) {
            Some(total) => total.add(count),
            None => totals.push(count.clone()),
        }
    }
}

/// The coverage on stdout: overall, then per state.
fn coverage_text(coverage: &[CellCount], level: f64) -> String {
    let mut overall = CellCount::new("all");
    coverage.iter().for_each(|c| overall.add(c));
    if overall.cells == 0 {
        return String::new();
    }
    let share = |c: &CellCount| format!("{} of {} ({:.1} %)", c.inside, c.cells, 100.0 * c.share());
    let mut text = format!(
        "the {} % band holds {} measured cells after each free run's start\n",
        tick_label(100.0 * level),
        share(&overall)
    );
    for count in coverage {
        text.push_str(&format!("  {:<12} {}\n", count.state, share(count)));
    }
    text
}
