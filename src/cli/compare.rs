//! `gbc compare MODEL DATA... --holdout NAME[,NAME] | --cv`: the grey box MODEL against
//! its fitted mechanism and the naive forecast on the same held-out experiments, scored by
//! the one error measure (`docs/compare.md`). The table and the verdict
//! go to stdout, progress to stderr; `--json FILE` and `--html FILE` write the comparison
//! and its report.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use super::progress::{Announce, Count, Reporter};
use super::{CommandError, CommandResult};
use gbc::api::flags::CompareArgs;
use gbc::api::{self, CompareEvent as Event, Model};

/// Runs the comparison and prints (and writes) it.
pub fn run(args: &CompareArgs) -> CommandResult {
    let mut inputs = vec![args.model.as_path()];
    inputs.extend(args.data.iter().map(PathBuf::as_path));
    inputs.extend(args.mechanism.iter().map(PathBuf::as_path));
    for output in [&args.json, &args.html].into_iter().flatten() {
        api::ensure_not_input(output, &inputs).map_err(CommandError::user)?;
    }
    let grey_box = Model::from_file(&args.model)?;
    let given = args.mechanism.as_ref().map(Model::from_file).transpose()?;
    let mechanism = api::mechanism_of(&grey_box, given.as_ref())?;
    let records = api::read_records(grey_box.ir(), &args.data, &args.columns.columns)?;
    let mechanism_records = match &args.mechanism {
        Some(_) => api::read_records(&mechanism, &args.data, &args.columns.columns)?,
        None => records.clone(),
    };
    let spec = args.spec()?;
    let reporter = Reporter::new();
    let finished = AtomicU64::new(0);
    let outcome = api::compare(
        (&grey_box, &mechanism),
        (records, mechanism_records),
        &spec,
        &mut |note| eprintln!("{note}"),
        &|event| report(&reporter, &finished, event),
    );
    reporter.finish();
    let result = outcome?;
    let text = result.text();
    let to_stdout = (args.json.as_ref()).is_some_and(|p| p.as_os_str() == api::STDOUT);
    if to_stdout {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
    if let Some(path) = &args.json {
        api::write_atomic(path, result.json()?.as_bytes()).map_err(CommandError::user)?;
    }
    if let Some(path) = &args.html {
        api::write_atomic(path, result.html().as_bytes()).map_err(CommandError::user)?;
    }
    Ok(())
}

/// Shows the runs on stderr: one stage counting the finished runs, the latest epoch or
/// result as its message.
fn report(reporter: &Reporter, finished: &AtomicU64, event: Event) {
    match event {
        Event::Started { runs, .. } => reporter.stage(
            &format!("comparing: {runs} fits and trainings (epochs as gbc train takes them)"),
            runs as u64,
            Count::Items("runs"),
            Announce::Now,
        ),
        Event::Epoch {
            member,
            held_out,
            epoch,
        } => reporter.update(
            finished.load(Ordering::Relaxed),
            format!(
                "{member} (holding out {}): epoch {epoch}",
                held_out.join(", ")
            ),
        ),
        Event::Finished {
            member,
            held_out,
            seconds,
            error,
        } => {
            finished.fetch_add(1, Ordering::Relaxed);
            let error = error.map_or("no score".into(), api::score_text);
            reporter.advance(
                1,
                format!(
                    "{member} (holding out {}) done in {seconds:.1} s, held-out error {error}",
                    held_out.join(", ")
                ),
            );
        }
    }
}
