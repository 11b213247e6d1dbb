//! `gbc.experiment`: a study of `gbc experiment` run from Python, its keywords parsed by the
//! CLI's own flags, stopped cleanly by a keyboard interrupt.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use gbc::api::experiment::StudyOutcome;
use gbc::cli::binding;
use gbc::experiment::Progress;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{command_error, raise};

/// What a study gave: its directory, the summary `gbc experiment` prints, and whether its
/// tables, figures and report were written.
#[pyclass(module = "gbc._gbc", frozen)]
pub struct Study {
    outcome: StudyOutcome,
    directory: PathBuf,
}

#[pymethods]
impl Study {
    /// The experiment directory (`results.csv`, `results.json`, `report.html`, the runs).
    fn directory(&self) -> PathBuf {
        self.directory.clone()
    }

    /// What `gbc experiment` prints at the end.
    fn summary(&self) -> String {
        self.outcome.summary.clone()
    }

    /// Whether the tables, figures and report were written (a whole study that finished;
    /// not a shard, not a stopped study).
    fn published(&self) -> bool {
        self.outcome.published.is_some()
    }

    /// Runs finished (trained now or reused from the directory).
    fn finished(&self) -> usize {
        self.outcome.results.results.len()
    }
}

/// Tells `callback` how far the study is: a `stage` event with the runs in all, then a
/// `done` event per run finished or reused.
fn tell(callback: &Option<PyObject>, kind: &str, fill: impl FnOnce(&Bound<'_, PyDict>)) {
    let Some(callback) = callback else { return };
    Python::with_gil(|py| {
        let dict = PyDict::new(py);
        let _ = dict.set_item("kind", kind);
        fill(&dict);
        let _ = callback.call1(py, (dict,));
    });
}

/// Runs the study `gbc experiment`'s `flags` describe (`--preset`, `--config`, or
/// `--model`, `--data`, `--sizes`, ...). A keyboard interrupt starts no further run: the
/// runs under way finish and are kept in the directory, and `KeyboardInterrupt` is raised;
/// the same call again reuses every finished run.
#[pyfunction]
#[pyo3(signature = (flags, callback = None))]
pub fn experiment(
    py: Python<'_>,
    flags: Vec<String>,
    callback: Option<PyObject>,
) -> PyResult<Study> {
    let plan = binding::experiment_plan(&flags).map_err(|e| command_error(py, e))?;
    let run = plan.prepare().map_err(|e| raise(py, e))?;
    let total = run.selected().len();
    let name = format!("running {total} trainings");
    tell(&callback, "stage", |d| {
        let _ = d.set_item("name", &name);
        let _ = d.set_item("total", total);
    });
    let on_progress = |progress: Progress| match progress {
        Progress::Finished(spec, _) | Progress::Skipped(spec) => {
            tell(&callback, "done", |d| {
                let _ = d.set_item("item", &spec.id);
            });
        }
        Progress::Started(_) | Progress::Epoch(..) => {}
    };
    let stop = AtomicBool::new(false);
    let mut interrupt: Option<PyErr> = None;
    let outcome = std::thread::scope(|scope| {
        let worker = scope.spawn(|| run.complete(&plan, &stop, &on_progress));
        // Signals reach Python on the main thread only: it waits here and checks them.
        while !worker.is_finished() {
            py.allow_threads(|| std::thread::sleep(Duration::from_millis(100)));
            if let Err(error) = py.check_signals() {
                interrupt.get_or_insert(error);
                stop.store(true, Ordering::SeqCst);
            }
        }
        // An interrupt that arrived after the last check (the study's last run ended within
        // the same 100 ms) is the caller's too: it is raised, not left pending.
        if let Err(error) = py.check_signals() {
            interrupt.get_or_insert(error);
        }
        worker.join()
    });
    let outcome = outcome
        .map_err(|_| pyo3::exceptions::PyRuntimeError::new_err("the study's thread panicked"))?
        .map_err(|e| raise(py, e))?;
    if let Some(interrupt) = interrupt {
        return Err(interrupt);
    }
    Ok(Study {
        outcome,
        directory: plan.out,
    })
}
