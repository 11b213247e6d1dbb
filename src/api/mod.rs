//! The library API: what the commands do, as functions over typed values, for the CLI and
//! the Python package (`python/`) alike.
//!
//! - [`Model`]: a model compiled from a file or from text, with the source kept (a run
//!   records its hash).
//! - [`Table`] and [`Model::records`]: a data set read from files or from in-memory
//!   columns (a DataFrame), through the one data reader, so that both give the same
//!   records.
//! - [`TrainSpec`] and [`train`]: a training run (split, recipe, settings) with progress
//!   through a callback and cancellation through a flag; it returns a [`Run`] that writes
//!   itself (weights, `run.json`, report) and predicts.
//! - [`Run::predict`]: offline or online predictions of a record, as a [`Prediction`].
//! - [`DiagnoseSpec`] and [`diagnose`]: the sim-to-real gap of a mechanistic model, as a
//!   [`Diagnosis`] that renders itself as text, JSON and HTML.
//!
//! Every failure is an [`ApiError`]: the diagnostics of the input at fault (code, message,
//! location, help) or an internal error. Nothing here prints.

mod data;
mod diagnose;
mod error;
mod model;
mod run;
mod split;

pub use data::{Column, Table};
pub use diagnose::{diagnose, DiagnoseSpec, Diagnosis};
pub use error::ApiError;
pub use model::{read_records, Model};
pub use run::{train, Control, Prediction, Run, TrainSpec, REPORT_FILE};
pub use split::{hold_out, split, Split, Validation};
