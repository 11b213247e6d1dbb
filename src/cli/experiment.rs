//! `gbc experiment`: train several models over a grid of training sizes and replicate seeds
//! in parallel, and write the results (CSV, JSON), the paper's figures (SVG) and a report.
//!
//! The study comes from `--preset`, `--config FILE` or the flags (`--model`, `--data`, ...);
//! flags override a preset or config. `--shard K/N` runs one slice of the grid (a job array);
//! `gbc experiment merge DIR...` joins slices. Progress on stderr (a bar on a terminal,
//! else a line every few seconds, [`crate::cli::progress`]); the summary on stdout. See docs/reproduction.md.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use crate::cli::progress::{Announce, Count, Reporter};
use crate::cli::CommandResult;
use gbc::api::experiment::{
    read_result, summary_text, Prepared, Progress, Published, RunResult, RunSpec,
};
use gbc::api::flags::RunArgs;

/// Arguments of `gbc experiment`.
#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct ExperimentArgs {
    /// `merge`: join the results of several experiment directories.
    #[command(subcommand)]
    pub action: Option<ExperimentAction>,
    /// The study and how to run it (boxed: the flags are many).
    #[command(flatten)]
    pub run: Box<RunArgs>,
}

/// Subcommands of `gbc experiment`.
#[derive(Debug, clap::Subcommand)]
pub enum ExperimentAction {
    /// Join the runs of several directories of one study (e.g. the slices of --shard) and
    /// write the tables, figures and report.
    Merge(MergeArgs),
}

/// Arguments of `gbc experiment merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// Experiment directories (written by `gbc experiment -o DIR`).
    #[arg(required = true, value_name = "DIR")]
    pub dirs: Vec<PathBuf>,
    /// Where to write the joined tables, figures and report (default: the first DIR; also
    /// `--out`, deprecated).
    #[arg(short, long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// Runs `gbc experiment` or `gbc experiment merge`.
pub fn run(args: &ExperimentArgs) -> CommandResult {
    match &args.action {
        Some(ExperimentAction::Merge(merge)) => run_merge(merge),
        None => run_study(&args.run),
    }
}

/// The default number of trainings at once: the number of cores.
pub use gbc::api::experiment::default_jobs;

/// Prints a note the flags give (a deprecated flag) on stderr.
fn note(text: String) {
    eprintln!("{text}");
}

/// Runs the study the flags describe (or prints it, `--print-study`).
fn run_study(args: &RunArgs) -> CommandResult {
    if args.print_study {
        println!("{}", args.study(&mut note)?.to_json());
        return Ok(());
    }
    let plan = args.plan(&mut note)?;
    let run = plan.prepare()?;
    let bar = ProgressBar::new(&[(&run.prepared, &run.selected(), &plan.out)]);
    let never = std::sync::atomic::AtomicBool::new(false);
    let outcome = run.complete(&plan, &never, &|p| bar.observe(&run.prepared, p));
    bar.finish();
    let outcome = outcome?;
    print!("{}", outcome.summary);
    if outcome.published.is_some() {
        println!("report: {}", plan.out.join("report.html").display());
    }
    Ok(())
}

/// Joins the results of several experiment directories and prints the summary.
fn run_merge(args: &MergeArgs) -> CommandResult {
    let out = args.out.clone().unwrap_or_else(|| args.dirs[0].clone());
    let merged = gbc::api::experiment::merge(&args.dirs, &out)?;
    for path in &merged.unreadable {
        eprintln!(
            "warning: left out `{}`: it does not read as a run result",
            path.display()
        );
    }
    print_summary(
        &merged.prepared,
        &merged.results,
        &merged.published,
        (0.0, 0),
    );
    println!("report: {}", out.join("report.html").display());
    Ok(())
}

/// Prints the medians per model and size, the grey-box tally and the notes
/// ([`summary_text`]).
pub fn print_summary(
    prepared: &Prepared,
    results: &[RunResult],
    published: &Published,
    timing: (f64, usize),
) {
    print!("{}", summary_text(prepared, results, published, timing));
}

/// One progress report over every pending run of one or more studies, advanced per epoch
/// (the shared [`Reporter`]: a bar on a terminal, else a line every few seconds).
pub struct ProgressBar {
    reporter: Reporter,
    finished: AtomicUsize,
    total: usize,
    /// Pair-epochs counted so far, per run id.
    counted: Mutex<HashMap<String, u64>>,
}

impl ProgressBar {
    /// A report over the runs of `studies` not yet finished in their directories.
    pub fn new(studies: &[(&Prepared, &[&RunSpec], &PathBuf)]) -> Self {
        let mut work = 0;
        let mut total = 0;
        for (prepared, runs, dir) in studies {
            for spec in runs.iter() {
                if read_result(dir, &spec.id).is_none() {
                    work += spec.cost(prepared.study.settings.epochs);
                    total += 1;
                }
            }
        }
        let reporter = Reporter::new();
        if total > 0 {
            let name = format!("running {total} trainings");
            reporter.stage(&name, work, Count::Percent, Announce::Now);
            reporter.update(0, format!("0/{total} runs"));
        }
        ProgressBar {
            reporter,
            finished: AtomicUsize::new(0),
            total,
            counted: Mutex::new(HashMap::new()),
        }
    }

    /// Advances on an event of a study's execution.
    pub fn observe(&self, prepared: &Prepared, progress: Progress) {
        let mut counted = self.counted.lock().unwrap_or_else(|p| p.into_inner());
        match progress {
            Progress::Epoch(spec, _) => {
                *counted.entry(spec.id.clone()).or_insert(0) += spec.size as u64;
                let finished = self.finished.load(Ordering::Relaxed);
                let runs = format!("{finished}/{} runs", self.total);
                self.reporter.advance(spec.size as u64, runs);
            }
            Progress::Finished(spec, _) => {
                // A run that failed stopped early: count the epochs it did not train.
                let done = counted.remove(&spec.id).unwrap_or(0);
                let rest = (spec.cost(prepared.study.settings.epochs)).saturating_sub(done);
                let finished = self.finished.fetch_add(1, Ordering::Relaxed) + 1;
                let runs = format!("{finished}/{} runs", self.total);
                self.reporter.advance(rest, runs);
            }
            Progress::Skipped(_) | Progress::Started(_) => {}
        }
    }

    /// Clears the bar.
    pub fn finish(&self) {
        self.reporter.finish();
    }
}
