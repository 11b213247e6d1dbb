//! `gbc compare MODEL DATA... --holdout NAME[,NAME] | --cv`: the grey box MODEL against
//! its fitted mechanism and the naive forecast on the same held-out experiments, scored by
//! the one error measure ([`crate::compare`], `docs/compare.md`). The table and the verdict
//! go to stdout, progress to stderr; `--json FILE` and `--html FILE` write the comparison
//! and its report.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use super::data::{load_records, ColumnArgs, HistoryArg};
use super::experiment::default_jobs;
use super::options::TrainingFlags;
use super::progress::{Announce, Count, Reporter};
use super::train::DEFAULT_RECOVERIES;
use super::{CommandError, CommandResult};
use crate::compare::{self, CompareError, Event, Options, Splits};
use crate::train::{Recipe, TrainOptions};

/// Arguments of `gbc compare`.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The grey-box model (with closures).
    pub model: PathBuf,
    /// The data set: one or more CSV files, each an experiment (or several, with an
    /// `experiment` column), as `gbc train` reads them.
    #[arg(required = true, num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// Experiments held out (comma-separated or repeated); default: the last one.
    #[arg(long, value_name = "NAME", num_args = 1.., value_delimiter = ',')]
    pub holdout: Vec<String>,
    /// Leave-one-experiment-out: each experiment held out in turn.
    #[arg(long, conflicts_with = "holdout")]
    pub cv: bool,
    /// The mechanistic model to compare with (no closures, the grey box's states); default:
    /// the grey box with every closure output at its prior, or zero.
    #[arg(long, value_name = "FILE")]
    pub mechanism: Option<PathBuf>,
    /// Grey-box trainings per split, seeds --seed, --seed + 1, ...
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub seeds: u64,
    /// The first seed (the mechanism's fit takes it too).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Trainings at a time (default: every core).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Longest integration step (default: as `gbc train`).
    #[arg(long, value_name = "H")]
    pub dt: Option<f64>,
    /// Where free runs of whole experiments and training windows start.
    #[arg(long, value_enum, default_value_t = HistoryArg::Held)]
    pub history: HistoryArg,
    /// How data columns are named.
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// Epochs, batch, learning rate, precision, sub-steps, engine (as `gbc train`).
    #[command(flatten)]
    pub settings: TrainingFlags,
    /// Recoveries from a non-finite epoch per training (as `gbc train --recoveries`).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_RECOVERIES)]
    pub recoveries: usize,
    /// Write the comparison as JSON to this file (`-`: standard output; the table then
    /// goes to standard error).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write the HTML report (the free runs drawn side by side) to this file.
    #[arg(long, value_name = "FILE")]
    pub html: Option<PathBuf>,
}

/// Runs the comparison and prints (and writes) it.
pub fn run(args: &CompareArgs) -> CommandResult {
    let mut inputs = vec![args.model.as_path()];
    inputs.extend(args.data.iter().map(PathBuf::as_path));
    inputs.extend(args.mechanism.iter().map(PathBuf::as_path));
    for output in [&args.json, &args.html].into_iter().flatten() {
        crate::io::ensure_not_input(output, &inputs).map_err(CommandError::user)?;
    }
    let grey_box = super::load_model(&args.model)?;
    let mechanism = match &args.mechanism {
        Some(path) => super::load_model(path)?,
        None if grey_box.closures.is_empty() => {
            return Err(CommandError::user(CompareError::NoClosure {
                model: grey_box.name.clone(),
            }))
        }
        None => {
            let mut mechanism = grey_box.mechanism();
            mechanism.name = format!("{} (mechanism)", grey_box.name);
            mechanism
        }
    };
    let records = load_records(&grey_box, &args.data, &args.columns)?;
    let mechanism_records = match &args.mechanism {
        Some(_) => load_records(&mechanism, &args.data, &args.columns)?,
        None => records.clone(),
    };
    let options = options(args, &records)?;
    let reporter = Reporter::new();
    let finished = AtomicU64::new(0);
    let outcome = compare::compare(
        (&grey_box, &mechanism),
        (&records, &mechanism_records),
        &options,
        &|event| report(&reporter, &finished, event),
    );
    reporter.finish();
    let comparison = outcome.map_err(|e| CommandError::user(flagged(e)))?;
    let text = compare::render::text(&comparison);
    let to_stdout = (args.json.as_ref()).is_some_and(|p| p.as_os_str() == crate::io::STDOUT);
    if to_stdout {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&comparison)
            .map_err(|e| CommandError::Internal(format!("cannot encode the comparison: {e}")))?;
        crate::io::write_atomic(path, format!("{json}\n").as_bytes())
            .map_err(CommandError::user)?;
    }
    if let Some(path) = &args.html {
        let title = (args.model.file_stem())
            .map_or(grey_box.name.clone(), |s| s.to_string_lossy().to_string());
        let page = compare::html::page(&comparison, &records, &title);
        crate::io::write_atomic(path, page.as_bytes()).map_err(CommandError::user)?;
    }
    Ok(())
}

/// The comparison's options from the flags: the split (default: the last experiment,
/// announced), the seeds, `gbc train`'s settings and recipe.
fn options(args: &CompareArgs, records: &[crate::record::Record]) -> Result<Options, CommandError> {
    let splits = if args.cv {
        Splits::LeaveOneOut
    } else if args.holdout.is_empty() {
        let last = records.last().map(|r| r.name.clone()).unwrap_or_default();
        eprintln!(
            "holding out experiment `{last}` (the last one; choose with --holdout NAME or --cv)"
        );
        Splits::Holdout(vec![last])
    } else {
        Splits::Holdout(args.holdout.clone())
    };
    let training = TrainOptions {
        dt: args.dt,
        history: args.history.into(),
        ..TrainOptions::with(&args.settings.settings()?)
    };
    Ok(Options {
        splits,
        seeds: (0..args.seeds).map(|k| args.seed + k).collect(),
        training,
        recipe: Recipe::default(),
        jobs: args.jobs.unwrap_or_else(default_jobs),
        recoveries: args.recoveries,
    })
}

/// A training error whose option is a settings field, renamed to its flag.
fn flagged(error: CompareError) -> CompareError {
    match error {
        CompareError::Train(error) => CompareError::Train(super::options::with_flag(error)),
        other => other,
    }
}

/// Shows the runs on stderr: one stage counting the finished runs, the latest epoch or
/// result as its message.
fn report(reporter: &Reporter, finished: &AtomicU64, event: Event) {
    match event {
        Event::Started { runs, epochs } => reporter.stage(
            &format!("comparing: {runs} fits and trainings ({epochs} epochs each)"),
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
            let error = error.map_or("no score".into(), compare::score::number);
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
