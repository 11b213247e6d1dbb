//! `gbc.experiment`: a study of `gbc experiment` run from Python, its keywords parsed by the
//! command line's own flags (`gbc::api::flags`), stopped cleanly by a keyboard interrupt.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use gbc::api::experiment::Progress;
use gbc::api::experiment::StudyOutcome;
use gbc::api::flags as binding;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::{note, raise};

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
/// A `KeyboardInterrupt` the callback raises is returned (the study stops as at Ctrl-C);
/// any other error of the callback is ignored, as a progress display's is.
fn tell(
    callback: &Option<PyObject>,
    kind: &str,
    fill: impl FnOnce(&Bound<'_, PyDict>),
) -> Option<PyErr> {
    let callback = callback.as_ref()?;
    Python::with_gil(|py| {
        let dict = PyDict::new(py);
        let _ = dict.set_item("kind", kind);
        fill(&dict);
        let error = callback.call1(py, (dict,)).err()?;
        let interrupted = error.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py);
        interrupted.then_some(error)
    })
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
    let plan = binding::experiment_plan(&flags, &mut note).map_err(|e| raise(py, e))?;
    let run = plan.prepare().map_err(|e| raise(py, e))?;
    let total = run.selected().len();
    let name = format!("running {total} trainings");
    if let Some(interrupt) = tell(&callback, "stage", |d| {
        let _ = d.set_item("name", &name);
        let _ = d.set_item("total", total);
    }) {
        return Err(interrupt);
    }
    let stop = AtomicBool::new(false);
    let raised: Mutex<Option<PyErr>> = Mutex::new(None);
    let on_progress = |progress: Progress| match progress {
        Progress::Finished(spec, _) | Progress::Skipped(spec) => {
            let error = tell(&callback, "done", |d| {
                let _ = d.set_item("item", &spec.id);
            });
            if let Some(error) = error {
                stop.store(true, Ordering::SeqCst);
                let mut slot = raised.lock().unwrap_or_else(|e| e.into_inner());
                slot.get_or_insert(error);
            }
        }
        Progress::Started(_) | Progress::Epoch(..) => {}
    };
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
    let raised = raised.into_inner().unwrap_or_else(|e| e.into_inner());
    if let Some(interrupt) = interrupt.or(raised) {
        return Err(interrupt);
    }
    Ok(Study {
        outcome,
        directory: plan.out,
    })
}
