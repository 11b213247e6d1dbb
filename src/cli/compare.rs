//! `gbc compare MODEL DATA... --holdout NAME[,NAME] | --cv`: the grey box MODEL against
//! its fitted mechanism and the naive forecast on the same held-out experiments, scored by
//! the one error measure ([`crate::compare`], `docs/compare.md`). The table and the verdict
//! go to stdout, progress to stderr; `--json FILE` and `--html FILE` write the comparison
//! and its report.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};

use super::data::{load_records, ColumnArgs, HistoryArg};
use super::options::TrainingFlags;
use super::progress::{Announce, Count, Reporter};
use super::train::DEFAULT_RECOVERIES;
use super::{CommandError, CommandResult};
use crate::api::{self, CompareSpec, Model};
use crate::compare::{self, Event};
use crate::train::TrainOptions;

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
    let grey_box = Model::from_file(&args.model)?;
    let given = args.mechanism.as_ref().map(Model::from_file).transpose()?;
    let mechanism = api::mechanism_of(&grey_box, given.as_ref())?;
    let records = load_records(grey_box.ir(), &args.data, &args.columns)?;
    let mechanism_records = match &args.mechanism {
        Some(_) => load_records(&mechanism, &args.data, &args.columns)?,
        None => records.clone(),
    };
    let spec = spec_of(args)?;
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
    let to_stdout = (args.json.as_ref()).is_some_and(|p| p.as_os_str() == crate::io::STDOUT);
    if to_stdout {
        eprint!("{text}");
    } else {
        print!("{text}");
    }
    if let Some(path) = &args.json {
        crate::io::write_atomic(path, result.json()?.as_bytes()).map_err(CommandError::user)?;
    }
    if let Some(path) = &args.html {
        crate::io::write_atomic(path, result.html().as_bytes()).map_err(CommandError::user)?;
    }
    Ok(())
}

/// The API's spec of the flags: the split, the seeds, `gbc train`'s settings.
pub(crate) fn spec_of(args: &CompareArgs) -> Result<CompareSpec, CommandError> {
    let training = TrainOptions {
        dt: args.dt,
        history: args.history.into(),
        ..TrainOptions::with(&args.settings.settings()?)
    };
    Ok(CompareSpec {
        holdout: args.holdout.clone(),
        cv: args.cv,
        seeds: args.seeds,
        seed: args.seed,
        jobs: args.jobs,
        training,
        recoveries: args.recoveries,
        sparse_budget: (!args.settings.gives_budget())
            .then_some(crate::train::recipe::SPARSE_BUDGET),
    })
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
