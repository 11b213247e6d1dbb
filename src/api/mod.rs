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
//! - [`train_ensemble`]: `--ensemble N`, members trained in parallel with their prediction
//!   band calibrated and its coverage counted, as an [`EnsembleRun`] (its directory
//!   written, JSON, summary).
//! - [`cross_validate`]: `--cv`, a run per experiment left out, each kept with its
//!   held-out free run, as a [`crate::trained::cv::CrossValidation`].
//! - [`Run::predict`]: offline or online predictions of a record, as a [`Prediction`].
//! - [`SimulateSpec`] and [`simulate`]: a model integrated under input programmes (noise,
//!   ranges, fitted params, initial values), or a what-if run of a trained run, as a
//!   [`Simulation`] that writes itself as CSV or JSON.
//! - [`SavedRun`]: a run (or ensemble) read back from its directory, which predicts
//!   records as [`Predictions`] (`gbc predict`) and exports its one-step map (`gbc export`).
//! - [`CompareSpec`] and [`compare`]: a grey box against its fitted mechanism and the
//!   naive forecast, as a [`CompareResult`] (text, JSON, HTML).
//! - [`bench`]: how fast the shipped models train and simulate, on this machine.
//! - [`experiment`]: studies over training sizes and seeds, run, published and summarised.
//! - [`DiagnoseSpec`] and [`diagnose`]: the sim-to-real gap of a mechanistic model, as a
//!   [`Diagnosis`] that renders itself as text, JSON and HTML.
//!
//! Every failure is an [`ApiError`]: the diagnostics of the input at fault (code, message,
//! location, help) or an internal error. Nothing here prints.

pub mod bench;
mod compare;
mod cv;
mod data;
pub mod demo;
mod diagnose;
mod ensemble;
mod error;
pub mod experiment;
mod model;
mod run;
mod saved;
mod simulate;
mod split;
pub mod summary;
#[cfg(test)]
mod tests_saved;

pub use compare::{compare, mechanism_of, CompareResult, CompareSpec};
pub use cv::cross_validate;
pub use data::{Column, Table};
pub use diagnose::{diagnose, DiagnoseSpec, Diagnosis};
pub use ensemble::{train_ensemble, EnsembleRun};
pub use error::ApiError;
pub use model::{read_records, Model};
pub use run::{train, Control, Prediction, Run, TrainSpec, REPORT_FILE};
pub use saved::{Export, ExportFormat, PredictEvent, PredictSpec, Predictions, SavedRun};
pub use simulate::{simulate, SimulateError, SimulateEvent, SimulateSpec, Simulation};
pub use split::{hold_out, split, Split, Validation};
