//! `Model.train(..., ensemble=N)`: an ensemble of `gbc train --ensemble N` trained from
//! Python into its run directory, its members' progress through the callback.

use std::path::PathBuf;

use gbc::api::flags as binding;
use gbc::api::{self, MemberEvent};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::{note, raise, records, Model};

/// A trained ensemble: its directory, `ensemble.json`, the summary and the report.
#[pyclass(module = "gbc._gbc", frozen)]
pub struct Ensemble {
    inner: api::EnsembleRun,
    summary: String,
}

#[pymethods]
impl Ensemble {
    /// The run directory (`ensemble.json`, `members/`, `report.html`).
    fn directory(&self) -> PathBuf {
        self.inner.directory.clone()
    }

    /// `ensemble.json`'s text.
    fn json(&self, py: Python<'_>) -> PyResult<String> {
        self.inner.json().map_err(|e| raise(py, e))
    }

    /// What `gbc train --ensemble` prints at the end.
    fn summary(&self) -> String {
        self.summary.clone()
    }

    /// The report page.
    fn html(&self) -> String {
        self.inner.page.clone()
    }
}

/// A member's event as the callback's dict: `done` when a member finishes (`item`: the
/// member, `status`), a `warning` with the stop every member ends at.
fn tell(callback: &Option<PyObject>, event: MemberEvent) {
    let Some(callback) = callback else { return };
    Python::with_gil(|py| {
        let dict = PyDict::new(py);
        match event {
            MemberEvent::Finished { member, status, .. } => {
                let _ = dict.set_item("kind", "done");
                let _ = dict.set_item("item", member);
                let _ = dict.set_item("status", status);
            }
            MemberEvent::Chosen { stop, epochs } => {
                let message = format!(
                    "toward the mechanism: every member stops after epoch {stop} of {epochs}"
                );
                let _ = dict.set_item("kind", "warning");
                let _ = dict.set_item("message", message);
            }
            _ => return,
        }
        let _ = callback.call1(py, (dict,));
    });
}

/// Trains the ensemble `gbc train`'s `flags` ask for (`--ensemble N`) of `model` on `data`,
/// validating on `val`; `callback(event: dict)` hears each member start and finish.
#[pyfunction]
#[pyo3(signature = (model, data, val, flags, callback = None))]
pub fn train_ensemble(
    py: Python<'_>,
    model: &Model,
    data: &Bound<'_, PyList>,
    val: &Bound<'_, PyList>,
    flags: Vec<String>,
    callback: Option<PyObject>,
) -> PyResult<Ensemble> {
    let model = &model.inner;
    let (spec, directory) =
        binding::train_spec(&flags, model, None, &mut note).map_err(|e| raise(py, e))?;
    let plan = binding::ensemble_plan(&flags)
        .map_err(|e| raise(py, e))?
        .ok_or_else(|| pyo3::exceptions::PyValueError::new_err("expected `ensemble=N`"))?;
    let (records, val) = (records(py, model, data)?, records(py, model, val)?);
    let on_event = |event: MemberEvent| tell(&callback, event);
    let outcome = py.allow_threads(|| {
        api::train_ensemble(model, (records, val), (&spec, &plan), &directory, &on_event)
    });
    let inner = outcome.map_err(|e| raise(py, e))?;
    let summary = inner.summary_text(model);
    Ok(Ensemble { inner, summary })
}
