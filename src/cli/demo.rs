//! `gbc demo`: the paper's two studies (chemostat, bioreactor), scaled down to finish in a
//! couple of minutes, with the shipped models and data; writes `demo/report.html` (every
//! figure inline and the tables) and each study's CSV/JSON under `demo/<study>/`.
//!
//! Runs from the repository root (the shipped `models/` are read relative to the current
//! directory). A re-run reuses finished runs. The full-scale commands are in
//! docs/reproduction.md.

use std::path::PathBuf;
use std::time::Instant;

use crate::cli::experiment::{default_jobs, failure, print_summary, ProgressBar};
use crate::cli::{CommandError, CommandResult};
use crate::experiment::merge::{publish, weights_in, Published, REPORT_FILE};
use crate::experiment::{execute, grid, prepare, report, ExperimentError, RunSpec, Study};

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
    let studies = Study::demo_studies();
    for path in studies.iter().flat_map(Study::files) {
        if !path.is_file() {
            return Err(CommandError::user(ExperimentError::MissingShippedFile {
                path: path.display().to_string(),
            }));
        }
    }
    let jobs = args.jobs.unwrap_or_else(default_jobs).max(1);
    let started = Instant::now();
    let prepared = (studies.iter())
        .map(prepare)
        .collect::<Result<Vec<_>, _>>()
        .map_err(failure)?;
    let grids: Vec<Vec<RunSpec>> = studies.iter().map(grid).collect();
    let selected: Vec<Vec<&RunSpec>> = grids.iter().map(|g| g.iter().collect()).collect();
    let dirs: Vec<PathBuf> = studies.iter().map(|s| args.out.join(&s.name)).collect();
    let plan: Vec<_> = (prepared.iter().zip(&selected).zip(&dirs))
        .map(|((p, s), d)| (p, s.as_slice(), d))
        .collect();
    let bar = ProgressBar::new(&plan);
    let mut all_results = Vec::new();
    for (prepared, runs, dir) in &plan {
        let outcome = execute(prepared, runs, dir, jobs, &|p| bar.observe(prepared, p));
        match outcome {
            Ok(results) => all_results.push(results),
            Err(error) => {
                bar.finish();
                return Err(failure(error));
            }
        }
    }
    bar.finish();
    let seconds = started.elapsed().as_secs_f64();
    let mut sections = Vec::new();
    let mut published: Vec<Published> = Vec::new();
    for ((prepared, _, dir), results) in plan.iter().zip(&all_results) {
        let outcome = publish(prepared, results, dir, &weights_in(dir)).map_err(failure)?;
        sections.push(outcome.section.clone());
        published.push(outcome);
    }
    let intro = format!(
        "<p>Both studies of Lovelett, Avalos &amp; Kevrekidis (2020), scaled down (3 \
         replicates instead of 20 and 10, and 300 instead of 1000 epochs for the bioreactor), \
         trained with {jobs} parallel {} in {seconds:.0} s. The first half trains with \
         gbc's default recipe (one-step epochs, then free-run rollouts of growing length, \
         the params polished); the second half, labelled <i>paper's recipe</i>, with the \
         paper's (the one-step loss every epoch). Each study's runs, tables \
         (<code>results.csv</code>, <code>results.json</code>, <code>summary.csv</code>) and \
         SVG figures are in <code>{}/&lt;study&gt;/</code>. Errors are MSEs of states z-scored \
         with the validation window's statistics. The full-scale studies and their results \
         are in <code>docs/reproduction.md</code>.</p>",
        if jobs == 1 { "job" } else { "jobs" },
        crate::plot::escape(&args.out.display().to_string())
    );
    let page = report::page(
        "gbc demo: the paper's two studies, scaled down",
        &intro,
        &sections,
    );
    let path = args.out.join(REPORT_FILE);
    crate::io::write_atomic(&path, page.as_bytes()).map_err(CommandError::user)?;
    for ((prepared, results), outcome) in prepared.iter().zip(&all_results).zip(&published) {
        print_summary(prepared, results, outcome, (0.0, 0));
    }
    println!(
        "demo finished in {seconds:.1} s; report: {}",
        path.display()
    );
    Ok(())
}
