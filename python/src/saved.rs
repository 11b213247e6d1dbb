//! `gbc.load_run`: a run or ensemble directory of `gbc train` read back, predicting as
//! `gbc predict --weights DIR` does.

use std::path::PathBuf;

use gbc::api;
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::{history_of, mode_of, precision_of, raise, records, Model};

/// A run or ensemble directory read back, as `gbc predict --weights DIR` reads it.
#[pyclass(module = "gbc._gbc", frozen)]
pub struct Saved {
    inner: api::SavedRun,
    directory: PathBuf,
}

#[pymethods]
impl Saved {
    /// Whether it is an ensemble (its predictions carry a band).
    fn is_ensemble(&self) -> bool {
        self.inner.is_ensemble()
    }

    /// How the model differs from the one trained, outside its structure.
    fn notes(&self) -> Vec<String> {
        self.inner.notes().to_vec()
    }

    /// Predictions along every experiment of `data` as `gbc predict` writes them:
    /// `(header, columns, experiment of each row, band coverage in words)`.
    #[pyo3(signature = (data, mode = "offline", history = "held", band = 0.9))]
    #[allow(clippy::type_complexity)]
    fn predict(
        &self,
        py: Python<'_>,
        data: &Bound<'_, PyList>,
        mode: &str,
        history: &str,
        band: f64,
    ) -> PyResult<(Vec<String>, Vec<Vec<f64>>, Vec<String>, String)> {
        let spec = api::PredictSpec {
            mode: mode_of(mode)?,
            history: history_of(history)?,
            band,
            ..api::PredictSpec::default()
        };
        let records = records(py, self.inner.model(), data)?;
        let predicted = (self.inner.predict(&records, &spec, &|_| {})).map_err(|e| raise(py, e))?;
        let coverage = predicted.coverage_text();
        Ok((
            predicted.header,
            predicted.columns,
            predicted.experiments,
            coverage,
        ))
    }

    /// Writes the one-step map as ONNX to `path` as `gbc export` does, and returns the
    /// files written: for an ensemble, every used member's map beside `path` and the
    /// band's facts (`NAME.band.json`, docs/export.md).
    #[pyo3(signature = (path, precision = "f32"))]
    fn export_onnx(
        &self,
        py: Python<'_>,
        path: PathBuf,
        precision: &str,
    ) -> PyResult<Vec<PathBuf>> {
        let precision = precision_of(precision)?;
        if self.inner.is_ensemble() {
            let model = self.inner.model();
            let exported = api::export_ensemble(model, &self.directory, precision, &path)
                .map_err(|e| raise(py, e))?;
            exported
                .write()
                .map_err(|e| raise(py, api::ApiError::user(e)))?;
            let members = exported.members.iter().map(|(path, _)| path.clone());
            return Ok(members.chain([exported.band_path.clone()]).collect());
        }
        let export =
            (self.inner.export(api::ExportFormat::Onnx, precision)).map_err(|e| raise(py, e))?;
        export.write(&path).map_err(|e| raise(py, e))?;
        Ok(vec![path])
    }
}

/// Reads the run or ensemble `gbc train` wrote into `directory`, for `model`.
#[pyfunction]
pub fn load_run(py: Python<'_>, model: &Model, directory: PathBuf) -> PyResult<Saved> {
    let inner = api::SavedRun::load(&model.inner, &directory).map_err(|e| raise(py, e))?;
    Ok(Saved { inner, directory })
}
