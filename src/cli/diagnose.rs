//! `gbc diagnose MODEL DATA... [--val FILE...] [--holdout NAME...] [--val-fraction SHARE]`:
//! where a mechanistic model misses a data set of experiments, which of its candidate
//! effects cause it, and how far it shrinks (spec section 5; method in `docs/diagnose.md`).
//! Data are read as `gbc train` reads them (records spec). Text on stdout, optionally
//! `--json` and `--html` reports and `--figures` SVG files.

use super::progress::{Announce, Count, Reporter};
use super::{CommandError, CommandResult};
use gbc::api::flags::DiagnoseArgs;
use gbc::api::{self, DiagnoseError, DiagnoseProgress as Progress};
use std::path::PathBuf;

/// Runs the diagnosis and prints (and writes) its report.
pub fn run(args: &DiagnoseArgs) -> CommandResult {
    let mut inputs = vec![args.model.as_path()];
    inputs.extend(args.data.iter().map(PathBuf::as_path));
    inputs.extend(args.val.iter().map(PathBuf::as_path));
    for output in [&args.json, &args.html].into_iter().flatten() {
        api::ensure_not_input(output, &inputs).map_err(CommandError::user)?;
    }
    let spec = args.spec()?;
    let model = api::Model::from_file(&args.model)?;
    spec.noise_of(&model)?;
    let records = model.records_from_files(&args.data, &args.columns.columns)?;
    let val = model.records_from_files(&args.val, &args.columns.columns)?;
    let reporter = Reporter::new();
    let outcome = api::diagnose(&model, (records, val), &spec, &|event| {
        report(&reporter, event)
    });
    reporter.finish();
    let diagnosis = outcome?;
    print!("{}", diagnosis.text());
    write_outputs(args, &diagnosis)?;
    match &diagnosis.report.partial {
        Some(note) => Err(CommandError::user(DiagnoseError::Stopped {
            note: note.clone(),
        })),
        None => Ok(()),
    }
}

/// Writes the reports `--json`, `--html` and `--figures` ask for.
fn write_outputs(args: &DiagnoseArgs, diagnosis: &api::Diagnosis) -> CommandResult {
    if let Some(path) = &args.json {
        let json = diagnosis.json()?;
        api::write_atomic(path, format!("{json}\n").as_bytes()).map_err(CommandError::user)?;
    }
    if let Some(path) = &args.html {
        api::write_atomic(path, diagnosis.html().as_bytes()).map_err(CommandError::user)?;
    }
    if let Some(directory) = &args.figures {
        for (file, svg) in diagnosis.figures() {
            api::write_atomic(&directory.join(file), svg.as_bytes()).map_err(CommandError::user)?;
        }
    }
    Ok(())
}

/// Reports the stages of a diagnosis ([`Reporter`]: a bar on a terminal, else a line per
/// stage and one every few seconds).
fn report(reporter: &Reporter, event: Progress) {
    match event {
        Progress::Stage { name, total } => {
            reporter.stage(name, total as u64, Count::Items("fits"), Announce::Now)
        }
        Progress::Round {
            fit,
            done,
            max,
            best,
            seconds,
        } => reporter.message(round_message(&fit, (done, max), best, seconds)),
        Progress::Done { item, seconds } => {
            reporter.advance(1, format!("`{item}` done in {seconds:.1} s"))
        }
    }
}

/// "`overflow`: start 6 of at most 13, best training gap 0.0123, at most 40 s more": a fit
/// under way (its search may stop sooner than its budget; the bound is its pace so far).
fn round_message(fit: &str, (done, max): (usize, usize), best: f64, seconds: f64) -> String {
    let best = match best.is_finite() {
        true => format!("best training gap {best:.4}"),
        false => "no start has run through yet".to_string(),
    };
    let left = match done {
        0 => String::new(),
        _ if done >= max => String::new(),
        _ => {
            let rest = seconds / done as f64 * (max - done) as f64;
            format!(", at most {} more", super::progress::duration(rest))
        }
    };
    format!("`{fit}`: start {done} of at most {max}, {best}{left}")
}
