//! `gbc demo`: the paper's two studies scaled down ([`gbc::api::demo`]): parses, calls,
//! shows progress and prints each study's summary.

use std::path::PathBuf;

use crate::cli::experiment::{default_jobs, print_summary, ProgressBar};
use crate::cli::{CommandError, CommandResult};
use gbc::api::demo::Demo;

/// Arguments of `gbc demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Output directory.
    #[arg(
        short,
        long = "output",
        alias = "out",
        value_name = "DIR",
        default_value = "demo"
    )]
    pub out: PathBuf,
    /// Trainings run at once (default: the number of cores).
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
}

/// Runs both scaled-down studies and writes the report.
pub fn run(args: &DemoArgs) -> CommandResult {
    let demo = Demo::prepare(&args.out).map_err(CommandError::from)?;
    let jobs = args.jobs.unwrap_or_else(default_jobs).max(1);
    let selected: Vec<Vec<_>> = demo.studies.iter().map(|s| s.selected()).collect();
    let dirs: Vec<PathBuf> = demo.studies.iter().map(|s| demo.directory(s)).collect();
    let plan: Vec<_> = (demo.studies.iter().zip(&selected).zip(&dirs))
        .map(|((study, runs), dir)| (&study.prepared, runs.as_slice(), dir))
        .collect();
    let bar = ProgressBar::new(&plan);
    let outcome = demo.execute(jobs, &|prepared, progress| bar.observe(prepared, progress));
    bar.finish();
    let done = outcome.map_err(CommandError::from)?;
    for (study, (results, published)) in demo.studies.iter().zip(&done.studies) {
        print_summary(&study.prepared, &results.results, published, (0.0, 0));
    }
    println!(
        "demo finished in {:.1} s; report: {}",
        done.seconds,
        done.report.display()
    );
    Ok(())
}
