//! Studies (`gbc experiment`): several models trained over a grid of training sizes and
//! replicate seeds in parallel, their results (CSV, JSON), the paper's figures and a
//! report ([`crate::experiment`], docs/reproduction.md).
//!
//! [`StudyRun::prepare`] loads and checks a [`Study`] and picks its shard of the grid;
//! [`StudyRun::execute`] trains the pending runs into a directory (finished runs found
//! there are reused); [`StudyResults::publish`] writes tables, figures and the report, and
//! [`summary_text`] says what came out. [`merge`] joins the directories of several shards.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use super::ApiError;
use crate::experiment::merge::{publish, weights_in, Merged, Published};
use crate::experiment::report::{compare, number};
use crate::experiment::results::summarise;
use crate::experiment::{
    execute, grid, prepare, ExperimentFailure, Prepared, Progress, RunResult, RunSpec, Shard, Study,
};

impl From<ExperimentFailure> for ApiError {
    fn from(failure: ExperimentFailure) -> Self {
        match failure {
            ExperimentFailure::User(reports) => ApiError::from(reports),
            ExperimentFailure::Internal(message) => ApiError::Internal(message),
        }
    }
}

/// A study loaded and checked (models compiled, records read), with the runs of its shard.
pub struct StudyRun {
    /// The study with its models and records.
    pub prepared: Prepared,
    /// Every run of the grid.
    pub runs: Vec<RunSpec>,
    /// The slice of the grid this run trains.
    pub shard: Shard,
}

/// What a study's execution gave.
pub struct StudyResults {
    /// One result per selected run (finished, reused or failed).
    pub results: Vec<RunResult>,
    /// Wall time of the execution, seconds.
    pub seconds: f64,
    /// Runs found finished in the directory and reused.
    pub reused: usize,
    /// The directory written.
    pub out: PathBuf,
}

impl StudyRun {
    /// Loads and checks `study` and selects the runs of `shard`.
    pub fn prepare(study: &Study, shard: Shard) -> Result<StudyRun, ApiError> {
        let prepared = prepare(study)?;
        Ok(StudyRun {
            prepared,
            runs: grid(study),
            shard,
        })
    }

    /// The runs this shard trains.
    pub fn selected(&self) -> Vec<&RunSpec> {
        self.shard.select(&self.runs)
    }

    /// Trains the selected runs into `out` on `jobs` threads; `on_progress` hears every
    /// run's start, epochs and end (from the worker threads).
    pub fn execute(
        &self,
        out: &Path,
        jobs: usize,
        on_progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<StudyResults, ApiError> {
        let selected = self.selected();
        let started = Instant::now();
        let reused = AtomicUsize::new(0);
        let results = execute(&self.prepared, &selected, out, jobs.max(1), &|progress| {
            if let Progress::Skipped(_) = &progress {
                reused.fetch_add(1, Ordering::Relaxed);
            }
            on_progress(progress)
        })?;
        Ok(StudyResults {
            results,
            seconds: started.elapsed().as_secs_f64(),
            reused: reused.into_inner(),
            out: out.to_path_buf(),
        })
    }
}

impl StudyResults {
    /// Runs that failed.
    pub fn failed(&self) -> usize {
        self.results.iter().filter(|r| !r.is_ok()).count()
    }

    /// Writes the tables, figures and report of a whole study into its directory (the
    /// weights of its runs found there).
    pub fn publish(&self, study: &StudyRun) -> Result<Published, ApiError> {
        let weights = weights_in(&self.out);
        Ok(publish(
            &study.prepared,
            &self.results,
            &self.out,
            &weights,
        )?)
    }
}

/// Joins the results of several experiment directories (shards of one study) into `out`
/// and publishes them.
pub fn merge(dirs: &[PathBuf], out: &Path) -> Result<Merged, ApiError> {
    Ok(crate::experiment::merge(dirs, out)?)
}

/// The medians per model and size, the grey-box tally, failures and notes, as
/// `gbc experiment` prints them; `timing` is the wall time and the number of runs reused
/// (zeros leave them out).
pub fn summary_text(
    prepared: &Prepared,
    results: &[RunResult],
    published: &Published,
    (seconds, reused): (f64, usize),
) -> String {
    let failed = results.iter().filter(|r| !r.is_ok()).count();
    let timing = match (seconds > 0.0, reused > 0) {
        (true, true) => format!(" in {seconds:.1} s, {reused} reused from earlier runs"),
        (true, false) => format!(" in {seconds:.1} s"),
        _ => String::new(),
    };
    let mut lines = vec![
        format!(
            "{}: {} runs{timing} ({failed} failed); validation MSE, median over replicates:",
            prepared.study.name,
            results.len()
        ),
        format!(
            "  {:<20} {:>7} {:>12} {:>12} {:>10}",
            "model", "points", "offline", "online", "blown up"
        ),
    ];
    for row in summarise(&prepared.study, results) {
        let median = |s: Option<crate::experiment::results::Spread>| {
            s.map_or("-".into(), |s| number(s.median))
        };
        lines.push(format!(
            "  {:<20} {:>7} {:>12} {:>12} {:>10}",
            row.model,
            row.size,
            median(row.offline),
            median(row.online),
            format!("{}/{}", row.blown_up, row.ok)
        ));
    }
    for c in compare(prepared, results) {
        lines.push(format!(
            "  {} below {}: online at {}/{} sizes, offline at {}/{}",
            c.grey, c.black, c.online.0, c.online.1, c.offline.0, c.offline.1
        ));
    }
    for result in results.iter().filter(|r| !r.is_ok()) {
        let message = result.error.as_deref().unwrap_or("unknown");
        lines.push(format!("  failed {}: {message}", result.id));
    }
    for note in &published.notes {
        lines.push(format!("  note: {note}"));
    }
    lines.iter().map(|line| format!("{line}\n")).collect()
}
