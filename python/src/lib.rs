//! `gbc._gbc`: the native half of the `gbc` Python package. It only converts: Python
//! values in, calls into the library API (`gbc::api`), Python values out. The pure-Python
//! half (`gbc/__init__.py`) turns DataFrames into tables and results into DataFrames.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use gbc::api::flags as binding;
use gbc::api::{self, ApiError, Column, History, PredictMode as Mode, Table, TrainEvent as Event};
use pyo3::create_exception;

mod ensemble;
mod saved;
mod study;

use ensemble::{train_ensemble, Ensemble};
use pyo3::exceptions::{PyException, PyKeyboardInterrupt, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use saved::{load_run, Saved};
use study::{experiment, Study};

create_exception!(_gbc, GbcError, PyException, "An error of gbc: its `code`, `message`, `file`, `line`, `column` and `help` are attributes; `diagnostics` lists every one.");

/// The Python exception of an API error: the first diagnostic's facts as attributes, all
/// of them in `diagnostics`, the rendered text as the message.
pub(crate) fn raise(py: Python<'_>, error: ApiError) -> PyErr {
    let records = error.records();
    let err = GbcError::new_err(error.rendered());
    let value = err.value(py);
    let first = records.first();
    let _ = value.setattr("code", first.and_then(|r| r.code.clone()));
    let _ = value.setattr("message", first.map(|r| r.message.clone()));
    let _ = value.setattr("file", first.and_then(|r| r.file.clone()));
    let _ = value.setattr("line", first.and_then(|r| r.line));
    let _ = value.setattr("column", first.and_then(|r| r.column));
    let _ = value.setattr("help", first.and_then(|r| r.help.clone()));
    let all = (records.iter())
        .map(|r| serde_json::to_string(r).unwrap_or_default())
        .collect::<Vec<_>>();
    let _ = value.setattr("diagnostics", all);
    err
}

/// A compiled `.gbm` model.
#[pyclass(module = "gbc._gbc", frozen)]
struct Model {
    inner: api::Model,
}

#[pymethods]
impl Model {
    /// Reads and compiles a model file.
    #[staticmethod]
    fn from_file(py: Python<'_>, path: PathBuf) -> PyResult<Model> {
        let inner = api::Model::from_file(&path).map_err(|e| raise(py, e))?;
        Ok(Model { inner })
    }

    /// Compiles model text; `name` names it in diagnostics.
    #[staticmethod]
    #[pyo3(signature = (text, name = "<text>"))]
    fn from_text(py: Python<'_>, text: &str, name: &str) -> PyResult<Model> {
        let inner = api::Model::from_text(text, name).map_err(|e| raise(py, e))?;
        Ok(Model { inner })
    }

    /// The model's name.
    #[getter]
    fn name(&self) -> String {
        self.inner.name().to_string()
    }

    /// The model's text.
    #[getter]
    fn source(&self) -> String {
        self.inner.source.clone()
    }

    /// The measured states, in declaration order.
    #[getter]
    fn states(&self) -> Vec<String> {
        self.inner
            .ir()
            .states
            .iter()
            .map(|s| s.name.clone())
            .collect()
    }

    /// The inputs, in declaration order.
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.inner
            .ir()
            .inputs
            .iter()
            .map(|s| s.name.clone())
            .collect()
    }

    /// The params with their declared values.
    #[getter]
    fn params(&self) -> Vec<(String, f64)> {
        (self.inner.ir().params.iter())
            .map(|p| (p.name.clone(), p.init))
            .collect()
    }

    fn __repr__(&self) -> String {
        format!("Model({:?})", self.inner.name())
    }
}

/// Tables from Python: `(name, headers, columns)` each, every column a list of floats
/// (NaN missing) or of strings.
fn tables(given: &Bound<'_, PyList>) -> PyResult<Vec<Table>> {
    let mut out = Vec::new();
    for item in given.iter() {
        let (name, headers, columns): (String, Vec<String>, Vec<Bound<'_, PyAny>>) =
            item.extract()?;
        let columns = (columns.iter())
            .map(|column| match column.extract::<Vec<f64>>() {
                Ok(numbers) => Ok(Column::Numbers(numbers)),
                Err(_) => column.extract::<Vec<String>>().map(Column::Labels),
            })
            .collect::<PyResult<Vec<_>>>()
            .map_err(|_| PyValueError::new_err("a column must hold numbers or strings"))?;
        out.push(Table {
            name,
            headers,
            columns,
        });
    }
    Ok(out)
}

pub(crate) fn records(
    py: Python<'_>,
    model: &api::Model,
    given: &Bound<'_, PyList>,
) -> PyResult<Vec<api::Record>> {
    let tables = tables(given)?;
    model.records(&tables, &[]).map_err(|e| raise(py, e))
}

/// A training event as a dict for the Python callback.
fn event_dict<'py>(py: Python<'py>, event: &Event) -> PyResult<Option<Bound<'py, PyDict>>> {
    let dict = PyDict::new(py);
    match event {
        Event::Started {
            epochs,
            train_pairs,
            validation_pairs,
        } => {
            dict.set_item("kind", "started")?;
            dict.set_item("epochs", epochs)?;
            dict.set_item("train_pairs", train_pairs)?;
            dict.set_item("validation_pairs", validation_pairs)?;
        }
        Event::Epoch {
            epoch,
            loss,
            horizon,
        } => {
            dict.set_item("kind", "epoch")?;
            dict.set_item("epoch", epoch)?;
            dict.set_item("loss", loss)?;
            dict.set_item("horizon", horizon)?;
        }
        Event::Warning(warning) => {
            dict.set_item("kind", "warning")?;
            dict.set_item("message", warning.to_string())?;
        }
        Event::Recovered(recovery) => {
            dict.set_item("kind", "warning")?;
            dict.set_item("message", recovery.to_string())?;
        }
        Event::Phase(phase) => {
            dict.set_item("kind", "phase")?;
            dict.set_item("phase", *phase)?;
        }
        _ => return Ok(None),
    }
    Ok(Some(dict))
}

/// A trained run.
#[pyclass(module = "gbc._gbc", unsendable)]
struct Run {
    inner: api::Run,
    directory: PathBuf,
    /// `--cv`'s folds: `cv/summary.json`'s text and the table `gbc train --cv` prints.
    cv: Option<(String, String)>,
}

/// Trains `model` on `data` (tables), validating on `val` (tables), with the CLI's
/// `flags`; `callback(event: dict)` hears of each phase, epoch and warning. A keyboard
/// interrupt stops training after the current epoch, keeps a checkpoint in the run
/// directory and raises `KeyboardInterrupt`; `resume=DIR` continues such a run (the same
/// data and flags), ending where an uninterrupted run ends.
#[pyfunction]
#[pyo3(signature = (model, data, val, flags, callback = None, resume = None))]
fn train(
    py: Python<'_>,
    model: &Model,
    data: &Bound<'_, PyList>,
    val: &Bound<'_, PyList>,
    flags: Vec<String>,
    callback: Option<PyObject>,
    resume: Option<PathBuf>,
) -> PyResult<Run> {
    let model = &model.inner;
    let (spec, directory) = binding::train_spec(&flags, model, resume.as_deref(), &mut note)
        .map_err(|e| raise(py, e))?;
    let (records, val) = (records(py, model, data)?, records(py, model, val)?);
    let command = serde_json::json!({ "python": flags });
    let checkpoint = match &resume {
        Some(resumed) => Some(checkpoint_of(py, resumed, &command)?),
        None => None,
    };
    let cv = match spec.validation.cv && resume.is_none() {
        true => Some(folds(
            py,
            model,
            records.clone(),
            (&spec, &directory),
            &callback,
        )?),
        false => None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let control = api::Control {
        directory: Some(directory.clone()),
        stop: Some(stop.clone()),
        resume: checkpoint,
        command,
        ..api::Control::default()
    };
    let mut failure: Option<PyErr> = None;
    let outcome = api::train(model, (records, val), &spec, control, &mut |event| {
        if let (Some(callback), Ok(Some(dict))) = (&callback, event_dict(py, &event)) {
            if let Err(error) = callback.call1(py, (dict,)) {
                failure.get_or_insert(error);
                stop.store(true, Ordering::SeqCst);
            }
        }
        if let Err(error) = py.check_signals() {
            failure.get_or_insert(error);
            stop.store(true, Ordering::SeqCst);
        }
    });
    match outcome {
        Ok(inner) => {
            inner.save(&directory).map_err(|e| raise(py, e))?;
            Ok(Run {
                inner,
                directory,
                cv,
            })
        }
        Err(error) if error.is_interrupted() => {
            Err(failure.unwrap_or_else(|| PyKeyboardInterrupt::new_err(error.to_string())))
        }
        Err(error) => Err(raise(py, error)),
    }
}

/// `--cv`'s folds, each kept under `directory`: `cv/summary.json`'s text and the table
/// `gbc train --cv` prints; `callback` hears a `stage` per fold and its epochs.
fn folds(
    py: Python<'_>,
    model: &api::Model,
    records: Vec<api::Record>,
    (spec, directory): (&api::TrainSpec, &std::path::Path),
    callback: &Option<PyObject>,
) -> PyResult<(String, String)> {
    let epochs = spec.options.epochs;
    let mut on_fold = |fold: usize, folds: usize, name: &str| {
        let Some(callback) = callback else { return };
        let dict = PyDict::new(py);
        let _ = dict.set_item("kind", "stage");
        let stage = format!("fold {}/{folds}: holding out {name}", fold + 1);
        let _ = dict.set_item("name", stage);
        let _ = dict.set_item("total", epochs);
        let _ = callback.call1(py, (dict,));
    };
    let mut on_event = |event: Event| {
        if let (Some(callback), Ok(Some(dict))) = (callback, event_dict(py, &event)) {
            let _ = callback.call1(py, (dict,));
        }
    };
    let listeners = (&mut on_fold as _, &mut on_event as _);
    let result = api::cross_validate(model, records, spec, directory, listeners)
        .map_err(|e| raise(py, e))?;
    let json = serde_json::to_string_pretty(&result)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
    let table = api::summary::cv_table(model.ir(), &result, directory);
    Ok((json, table))
}

/// The checkpoint of the stopped run in `directory`, which must have been trained with the
/// same keywords (`command`).
fn checkpoint_of(
    py: Python<'_>,
    directory: &std::path::Path,
    command: &serde_json::Value,
) -> PyResult<api::Checkpoint> {
    let checkpoint = api::Checkpoint::load(directory).map_err(|e| raise(py, ApiError::from(e)))?;
    if &checkpoint.command != command {
        return Err(PyValueError::new_err(format!(
            "the run in {} was trained with other keywords ({}): resume it with the same ones",
            directory.display(),
            checkpoint.command
        )));
    }
    Ok(checkpoint)
}

#[pymethods]
impl Run {
    /// The run directory (weights, run.json, report.html).
    #[getter]
    fn directory(&self) -> PathBuf {
        self.directory.clone()
    }

    /// The run's metadata, as `run.json` holds it (JSON text).
    fn json(&self, py: Python<'_>) -> PyResult<String> {
        self.inner.json().map_err(|e| raise(py, e))
    }

    /// `--cv`'s folds as `cv/summary.json` holds them (JSON text), if it ran them.
    fn cv_json(&self) -> Option<String> {
        self.cv.as_ref().map(|(json, _)| json.clone())
    }

    /// The table `gbc train --cv` prints, if it ran the folds.
    fn cv_table(&self) -> Option<String> {
        self.cv.as_ref().map(|(_, table)| table.clone())
    }

    /// The report page (HTML).
    fn report_html(&self) -> String {
        self.inner.report_html()
    }

    /// The trained params, in declaration order.
    #[getter]
    fn params(&self) -> Vec<(String, f64)> {
        self.inner.params().to_vec()
    }

    /// Predictions of each experiment of `data` (tables): `(experiment, header, columns,
    /// divergence)` per experiment; `mode` is `offline`, `online` or
    /// `online-trained-step`, `history` `held` or `measured`.
    #[pyo3(signature = (data, mode = "offline", history = "held"))]
    #[allow(clippy::type_complexity)]
    fn predict(
        &self,
        py: Python<'_>,
        data: &Bound<'_, PyList>,
        mode: &str,
        history: &str,
    ) -> PyResult<Vec<(String, Vec<String>, Vec<Vec<f64>>, Option<String>)>> {
        let (mode, history) = (mode_of(mode)?, history_of(history)?);
        let records = records(py, &self.inner.model, data)?;
        let predictions =
            (self.inner.predict(&records, mode, history)).map_err(|e| raise(py, e))?;
        Ok(predictions
            .into_iter()
            .map(|p| (p.experiment, p.header, p.columns, p.divergence))
            .collect())
    }

    /// Writes the one-step map as an ONNX file (`precision`: `f32` or `f64`).
    #[pyo3(signature = (path, precision = "f32"))]
    fn export_onnx(&self, py: Python<'_>, path: PathBuf, precision: &str) -> PyResult<()> {
        let precision = precision_of(precision)?;
        let bytes = self
            .inner
            .export_onnx(precision)
            .map_err(|e| raise(py, e))?;
        api::write_atomic(&path, &bytes).map_err(|e| raise(py, ApiError::user(e)))
    }
}

/// A finished diagnosis.
#[pyclass(module = "gbc._gbc", frozen)]
struct Diagnosis {
    inner: api::Diagnosis,
}

#[pymethods]
impl Diagnosis {
    /// The text report.
    fn text(&self) -> String {
        self.inner.text()
    }

    /// The report as JSON text (what `--json` writes).
    fn json(&self, py: Python<'_>) -> PyResult<String> {
        self.inner.json().map_err(|e| raise(py, e))
    }

    /// The HTML page (what `--html` writes).
    fn html(&self) -> String {
        self.inner.html()
    }
}

/// Diagnoses `model` against `data` (tables), scoring `val` (tables) too, with the CLI's
/// `flags`; `callback(event: dict)` hears of each stage and fit.
#[pyfunction]
#[pyo3(signature = (model, data, val, flags, callback = None))]
fn diagnose(
    py: Python<'_>,
    model: &Model,
    data: &Bound<'_, PyList>,
    val: &Bound<'_, PyList>,
    flags: Vec<String>,
    callback: Option<PyObject>,
) -> PyResult<Diagnosis> {
    let model = &model.inner;
    let spec = binding::diagnose_spec(&flags).map_err(|e| raise(py, e))?;
    let (records, val) = (records(py, model, data)?, records(py, model, val)?);
    let on_progress = |event: api::DiagnoseProgress| {
        let Some(callback) = &callback else { return };
        Python::with_gil(|py| {
            let dict = PyDict::new(py);
            let _ = match event {
                api::DiagnoseProgress::Stage { name, total } => dict
                    .set_item("kind", "stage")
                    .and(dict.set_item("name", name))
                    .and(dict.set_item("total", total)),
                api::DiagnoseProgress::Round {
                    fit,
                    done,
                    max,
                    best,
                    seconds,
                } => dict
                    .set_item("kind", "round")
                    .and(dict.set_item("fit", fit))
                    .and(dict.set_item("done", done))
                    .and(dict.set_item("max", max))
                    .and(dict.set_item("best", best))
                    .and(dict.set_item("seconds", seconds)),
                api::DiagnoseProgress::Done { item, seconds } => dict
                    .set_item("kind", "done")
                    .and(dict.set_item("item", item))
                    .and(dict.set_item("seconds", seconds)),
            };
            let _ = callback.call1(py, (dict,));
        });
    };
    let outcome = py.allow_threads(|| api::diagnose(model, (records, val), &spec, &on_progress));
    let inner = outcome.map_err(|e| raise(py, e))?;
    Ok(Diagnosis { inner })
}

/// Simulates `model` with `gbc simulate`'s `flags` (no `-o`): `(header, columns)` of the
/// record, and the notes and warnings the command prints.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn simulate(
    py: Python<'_>,
    model: &Model,
    flags: Vec<String>,
) -> PyResult<(Vec<String>, Vec<Vec<f64>>, Vec<String>)> {
    let (spec, effects) = binding::simulate_spec(&flags).map_err(|e| raise(py, e))?;
    let model = match effects.is_empty() {
        true => model.inner.clone(),
        false => model
            .inner
            .with_effects(&effects)
            .map_err(|e| raise(py, e))?,
    };
    let mut messages = Vec::new();
    let outcome = py.allow_threads(|| {
        api::simulate(&model, &spec, &mut |event| match event {
            api::SimulateEvent::Note(note) => messages.push(format!("note: {note}")),
            api::SimulateEvent::Warning(warning) => messages.push(format!("warning: {warning}")),
            _ => {}
        })
    });
    let simulation = outcome.map_err(|e| raise(py, e))?;
    Ok((simulation.header, simulation.columns, messages))
}

/// A finished comparison.
#[pyclass(module = "gbc._gbc", frozen)]
struct Comparison {
    inner: api::CompareResult,
}

#[pymethods]
impl Comparison {
    /// The table and the verdict (what `gbc compare` prints).
    fn text(&self) -> String {
        self.inner.text()
    }

    /// The comparison as JSON text (what `--json` writes).
    fn json(&self, py: Python<'_>) -> PyResult<String> {
        self.inner.json().map_err(|e| raise(py, e))
    }

    /// The HTML page (what `--html` writes).
    fn html(&self) -> String {
        self.inner.html()
    }
}

/// Compares the grey box `model` with its mechanism (`mechanism`, or the grey box with its
/// closures at their priors) and the naive forecast on `data` (tables), with
/// `gbc compare`'s `flags`; `callback(event: dict)` hears when each run finishes.
#[pyfunction]
#[pyo3(signature = (model, data, flags, mechanism = None, callback = None))]
fn compare(
    py: Python<'_>,
    model: &Model,
    data: &Bound<'_, PyList>,
    flags: Vec<String>,
    mechanism: Option<&Model>,
    callback: Option<PyObject>,
) -> PyResult<Comparison> {
    let grey_box = &model.inner;
    let spec = binding::compare_spec(&flags).map_err(|e| raise(py, e))?;
    let given = mechanism.map(|m| &m.inner);
    let mechanism_ir = api::mechanism_of(grey_box, given).map_err(|e| raise(py, e))?;
    let records = records(py, grey_box, data)?;
    let mechanism_records = match given {
        Some(model) => self::records(py, model, data)?,
        None => records.clone(),
    };
    let on_event = |event: api::CompareEvent| {
        let Some(callback) = &callback else { return };
        if let api::CompareEvent::Finished {
            member, seconds, ..
        } = event
        {
            Python::with_gil(|py| {
                let dict = PyDict::new(py);
                let _ = dict.set_item("kind", "done");
                let _ = dict.set_item("item", member.to_string());
                let _ = dict.set_item("seconds", seconds);
                let _ = callback.call1(py, (dict,));
            });
        }
    };
    let outcome = py.allow_threads(|| {
        api::compare(
            (grey_box, &mechanism_ir),
            (records, mechanism_records),
            &spec,
            &mut |_note| {},
            &on_event,
        )
    });
    let inner = outcome.map_err(|e| raise(py, e))?;
    Ok(Comparison { inner })
}

/// `f32` or `f64`, as `--precision` spells them.
pub(crate) fn precision_of(precision: &str) -> PyResult<api::Precision> {
    match precision {
        "f32" => Ok(api::Precision::F32),
        "f64" => Ok(api::Precision::F64),
        other => Err(PyValueError::new_err(format!(
            "expected precision `f32` or `f64`, found `{other}`"
        ))),
    }
}

/// `offline`, `online` or `online-trained-step`, as `gbc predict --mode` spells them.
pub(crate) fn mode_of(mode: &str) -> PyResult<Mode> {
    match mode {
        "offline" => Ok(Mode::Offline),
        "online" => Ok(Mode::Online),
        "online-trained-step" | "online_trained_step" => Ok(Mode::OnlineTrainedStep),
        other => Err(PyValueError::new_err(format!(
            "expected mode `offline`, `online` or `online-trained-step`, found `{other}`"
        ))),
    }
}

/// `held` or `measured`, as `--history` spells them.
pub(crate) fn history_of(history: &str) -> PyResult<History> {
    match history {
        "held" => Ok(History::Held),
        "measured" => Ok(History::Measured),
        other => Err(PyValueError::new_err(format!(
            "expected history `held` or `measured`, found `{other}`"
        ))),
    }
}

/// Prints a note of the flags (the run directory chosen, a deprecated keyword) on stderr,
/// as the command line does.
pub(crate) fn note(text: String) {
    eprintln!("{text}");
}

/// The native module.
#[pymodule]
fn _gbc(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Model>()?;
    m.add_class::<Run>()?;
    m.add_class::<Diagnosis>()?;
    m.add_class::<Comparison>()?;
    m.add_class::<Saved>()?;
    m.add_class::<Study>()?;
    m.add_class::<Ensemble>()?;
    m.add_function(wrap_pyfunction!(train, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(load_run, m)?)?;
    m.add_function(wrap_pyfunction!(experiment, m)?)?;
    m.add_function(wrap_pyfunction!(train_ensemble, m)?)?;
    m.add("GbcError", m.py().get_type::<GbcError>())?;
    Ok(())
}
