//! Studies (`gbc experiment`): several models trained over a grid of training sizes and
//! replicate seeds in parallel, their results (CSV, JSON), the paper's figures and a
//! report ([`crate::experiment`], docs/reproduction.md).
//!
//! [`StudyRun::prepare`] loads and checks a [`Study`] and picks its shard of the grid;
//! [`StudyRun::execute`] trains the pending runs into a directory (finished runs found
//! there are reused); [`StudyResults::publish`] writes tables, figures and the report, and
//! [`summary_text`] says what came out. [`merge`] joins the directories of several shards.
//! [`StudyPlan`] is a study with how to run it (shard, directory, threads);
//! [`StudyRun::complete`] executes and publishes it in one call (what `gbc experiment` and
//! the Python package's `gbc.experiment` do).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use super::ApiError;
use crate::experiment::merge::{publish, weights_in};
use crate::experiment::report::{compare, number};
use crate::experiment::results::summarise;
use crate::experiment::{execute_until, grid, prepare, ExperimentFailure};

pub use crate::experiment::merge::{Merged, Published};
pub use crate::experiment::results::read_result;
pub use crate::experiment::{
    default_jobs, Prepared, Progress, RunResult, RunSpec, RunStatus, Shard, Study, StudyRecord,
};

/// The files of an experiment directory as typed values: each run's result (under
/// [`results::RUNS_DIR`]) and the study record ([`results::STUDY_FILE`]), written and read
/// back with non-finite numbers by name.
pub mod results {
    pub use crate::experiment::results::{
        read_result, read_study_record, write_result, Measure, RUNS_DIR, STUDY_FILE,
    };
}

impl From<ExperimentFailure> for ApiError {
    fn from(failure: ExperimentFailure) -> Self {
        match failure {
            ExperimentFailure::User(reports) => ApiError::from(reports),
            ExperimentFailure::Internal(message) => ApiError::Internal(message),
        }
    }
}

/// A study with how to run it: which shard of its grid, into which directory, on how many
/// threads (the flags of `gbc experiment` besides the study's own).
#[derive(Debug, Clone)]
pub struct StudyPlan {
    /// The study.
    pub study: Study,
    /// The slice of the grid to train.
    pub shard: Shard,
    /// The experiment directory.
    pub out: PathBuf,
    /// Trainings at a time.
    pub jobs: usize,
}

impl StudyPlan {
    /// Loads and checks the study and selects the runs of its shard ([`StudyRun::prepare`]).
    pub fn prepare(&self) -> Result<StudyRun, ApiError> {
        StudyRun::prepare(&self.study, self.shard)
    }
}

/// What a study's run gave: its results and, for a whole study, what was published and
/// the summary `gbc experiment` prints.
pub struct StudyOutcome {
    /// The results of the runs of the shard.
    pub results: StudyResults,
    /// The tables, figures and report written (a whole study only: a shard's are written
    /// by `gbc experiment merge`).
    pub published: Option<Published>,
    /// What `gbc experiment` prints at the end.
    pub summary: String,
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
        self.execute_until(out, (jobs, &AtomicBool::new(false)), on_progress)
    }

    /// [`StudyRun::execute`] that starts no further run once `stop` is set (the runs under
    /// way finish and are kept; a later call reuses every finished run).
    pub fn execute_until(
        &self,
        out: &Path,
        (jobs, stop): (usize, &AtomicBool),
        on_progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<StudyResults, ApiError> {
        let selected = self.selected();
        let started = Instant::now();
        let reused = AtomicUsize::new(0);
        let how = (jobs.max(1), stop);
        let results = execute_until(&self.prepared, &selected, out, how, &|progress| {
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

impl StudyRun {
    /// Trains the selected runs into `plan.out` on `plan.jobs` threads, then publishes a
    /// whole study (tables, figures, report) and says what came out; a shard only trains
    /// and says how to merge. Once `stop` is set no further run starts: the outcome then
    /// publishes nothing and says how many runs finished (a later call reuses them).
    pub fn complete(
        &self,
        plan: &StudyPlan,
        stop: &AtomicBool,
        on_progress: &(dyn Fn(Progress) + Sync),
    ) -> Result<StudyOutcome, ApiError> {
        let results = self.execute_until(&plan.out, (plan.jobs, stop), on_progress)?;
        let selected = self.selected().len();
        if results.results.len() < selected {
            let summary = format!(
                "stopped: {} of {selected} runs finished in {} ({} reused); \
                 the same study into the same directory reuses them\n",
                results.results.len(),
                plan.out.display(),
                results.reused,
            );
            return Ok(StudyOutcome {
                results,
                published: None,
                summary,
            });
        }
        if !self.shard.is_all() {
            let summary = format!(
                "shard {}: {} runs finished in {:.1} s ({} reused, {} failed) in {}\n\
                 when every shard is done: gbc experiment merge {}\n",
                self.shard,
                results.results.len(),
                results.seconds,
                results.reused,
                results.failed(),
                plan.out.display(),
                plan.out.display()
            );
            return Ok(StudyOutcome {
                results,
                published: None,
                summary,
            });
        }
        let published = results.publish(self)?;
        let timing = (results.seconds, results.reused);
        let summary = summary_text(&self.prepared, &results.results, &published, timing);
        Ok(StudyOutcome {
            results,
            published: Some(published),
            summary,
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
