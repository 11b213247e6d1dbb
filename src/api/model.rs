//! A model compiled from a file or from text, with its source kept.

use std::path::{Path, PathBuf};

use super::data::{table_text, Table};
use super::ApiError;
use crate::data::{MinRows, Request};
use crate::driver::{self, Compiled};
use crate::ir;
use crate::record::Record;

/// A compiled model and the text it was compiled from.
#[derive(Debug, Clone)]
pub struct Model {
    /// Where the text came from: the file's path as given, or the name given with the
    /// text (diagnostics and run files name it).
    pub origin: String,
    /// The file, when the model was read from one.
    pub path: Option<PathBuf>,
    /// The text.
    pub source: String,
    /// The checked and lowered model.
    pub compiled: Compiled,
    /// The candidate effects applied before lowering (none: the model as written).
    pub effects: Vec<String>,
}

impl Model {
    /// Reads and compiles the model file at `path` (every error of the file at once).
    pub fn from_file(path: impl AsRef<Path>) -> Result<Model, ApiError> {
        Model::from_file_with_effects(path, &[])
    }

    /// Reads and compiles the model file at `path` with the candidate `effects` applied
    /// before lowering (`--effect NAME`).
    pub fn from_file_with_effects(
        path: impl AsRef<Path>,
        effects: &[String],
    ) -> Result<Model, ApiError> {
        let path = path.as_ref();
        let source = driver::read_source(path).map_err(|report| vec![report])?;
        let origin = path.display().to_string();
        let names: Vec<&str> = effects.iter().map(String::as_str).collect();
        let compiled = driver::compile(&origin, &source, &names)?;
        Ok(Model {
            origin,
            path: Some(path.to_path_buf()),
            source,
            compiled,
            effects: effects.to_vec(),
        })
    }

    /// Compiles `text`, named `origin` in diagnostics (e.g. `"<notebook>"`).
    pub fn from_text(text: &str, origin: &str) -> Result<Model, ApiError> {
        let compiled = driver::compile(origin, text, &[])?;
        Ok(Model {
            origin: origin.to_string(),
            path: None,
            source: text.to_string(),
            compiled,
            effects: Vec::new(),
        })
    }

    /// The same model with the candidate `effects` applied before lowering, compiled again
    /// from its text.
    pub fn with_effects(&self, effects: &[String]) -> Result<Model, ApiError> {
        let names: Vec<&str> = effects.iter().map(String::as_str).collect();
        let compiled = driver::compile(&self.origin, &self.source, &names)?;
        Ok(Model {
            compiled,
            effects: effects.to_vec(),
            ..self.clone()
        })
    }

    /// The compiled model.
    pub fn ir(&self) -> &ir::Model {
        &self.compiled.model
    }

    /// The canonical text of the compiled model (what `gbc compile --emit ir` prints).
    pub fn ir_text(&self) -> String {
        ir::print(self.ir())
    }

    /// The model's name (its `model` line).
    pub fn name(&self) -> &str {
        &self.compiled.model.name
    }

    /// A short name for runs and report titles: the file's stem, else the model's name.
    pub fn stem(&self) -> String {
        (self.path.as_ref().and_then(|p| p.file_stem()))
            .map_or(self.name().to_string(), |s| s.to_string_lossy().into())
    }

    /// Reads `files` as one data set bound to this model ([`read_records`]).
    pub fn records_from_files(
        &self,
        files: &[PathBuf],
        columns: &[(String, String)],
    ) -> Result<Vec<Record>, ApiError> {
        read_records(self.ir(), files, columns)
    }

    /// Reads in-memory tables (one per source, each of one or more experiments) as one data
    /// set bound to this model, by the same reader and rules as files: each table is
    /// written as CSV text (a missing cell empty) and read as the file `table.name`.
    pub fn records(
        &self,
        tables: &[Table],
        columns: &[(String, String)],
    ) -> Result<Vec<Record>, ApiError> {
        if tables.is_empty() {
            return Ok(Vec::new());
        }
        let texts = (tables.iter())
            .map(|table| Ok((table.name.clone(), table_text(table)?)))
            .collect::<Result<Vec<_>, ApiError>>()?;
        let request = request(self.ir(), columns);
        let data = crate::data::read_set_str(&texts, &request).map_err(ApiError::user)?;
        crate::record::bind(self.ir(), &data).map_err(ApiError::user)
    }
}

/// The columns `model` reads, with `columns` mappings (`NAME=HEADER`), at least two rows
/// per experiment.
fn request(model: &ir::Model, columns: &[(String, String)]) -> Request {
    let rows = MinRows::new(2, "one step needs two rows");
    crate::record::request(model, columns, rows)
}

/// Reads `files` as one data set bound to `model`: every experiment of every file, in
/// order (`columns`: `--column NAME=HEADER` mappings). No file, no record.
pub fn read_records(
    model: &ir::Model,
    files: &[PathBuf],
    columns: &[(String, String)],
) -> Result<Vec<Record>, ApiError> {
    if files.is_empty() {
        return Ok(Vec::new());
    }
    let data = crate::data::read_set(files, &request(model, columns)).map_err(ApiError::user)?;
    crate::record::bind(model, &data).map_err(ApiError::user)
}
