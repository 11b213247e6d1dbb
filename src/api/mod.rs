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
//! - [`flags`]: the flags of the commands as clap structs and the specs they ask for, the
//!   one definition the command line and a binding's keywords share.
//! - Model files as text ([`check_file`], [`syntax_tree_text`], [`format_source`],
//!   [`explain`], [`render_diagnostic`], [`ide`], [`new_project`]); the files a run writes
//!   ([`artifacts`]); writing files ([`write_atomic`]) and the stop request ([`stop`]).
//!
//! The events, options and errors these take and give are re-exported here under names
//! that say whose they are ([`TrainEvent`], [`MemberEvent`], [`CompareEvent`],
//! [`DiagnoseProgress`], [`TrainError`], ...): `gbc::api` is the library's whole public
//! face, what the CLI (`src/cli/`, in the binary), the Python package and the integration
//! tests use.
//!
//! Every failure is an [`ApiError`]: the diagnostics of the input at fault (code, message,
//! location, help) or an internal error. Nothing here prints.

pub mod artifacts;
pub mod bench;
mod compare;
mod cv;
mod data;
pub mod demo;
mod diagnose;
mod ensemble;
mod error;
pub mod experiment;
pub mod flags;
mod model;
mod run;
mod saved;
mod simulate;
mod source;
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
pub use saved::{
    export_ensemble, Export, ExportFormat, PredictEvent, PredictSpec, Predictions, SavedRun,
};
pub use simulate::{simulate, SimulateError, SimulateEvent, SimulateSpec, Simulation};
pub use source::{
    check_file, explain, format_source, ide, new_project, read_source, render_diagnostic,
    syntax_tree_text, FormatError, InitError, MessageFormat, Span, Template,
};
pub use split::{hold_out, split, Split, Validation};

pub use crate::compare::score::number as score_text;
pub use crate::compare::Event as CompareEvent;
pub use crate::data::format_number;
pub use crate::diagnose::{DiagnoseError, Progress as DiagnoseProgress, Report as DiagnosisReport};
pub use crate::engine::graph::Precision;
pub use crate::ensemble::{
    is_ensemble, MemberEvent, Plan as EnsemblePlan, Resample, DEFAULT_LEVEL as DEFAULT_BAND_LEVEL,
};
pub use crate::export::ensemble::EnsembleExport;
pub use crate::io::{ensure_not_input, write_atomic, STDOUT};
pub use crate::record::Record;
pub use crate::solve::ode::Tolerances;
pub use crate::train::checkpoint::EpochRow;
pub use crate::train::coverage::{
    Coverage as TrainingCoverage, DENSE_SHARE as DENSE_ONE_STEP_SHARE,
};
pub use crate::train::recovery::EpochPhase;
pub use crate::train::toward::ChoiceEvent;
pub use crate::train::{
    Checkpoint, Engine, EpochDivergence, ErrorSet, Event as TrainEvent, History, SparseBudget,
    TrainError, TrainReport, TRAINING as TRAINING_PHASE,
};
pub use crate::trained::cv::{CrossValidation, Fold as CvFold};
pub use crate::trained::predict::Mode as PredictMode;
pub use crate::trained::status::TrainingStatus;

/// The process's request to stop the running job (Ctrl-C, SIGTERM, or a caller), which every
/// long phase polls: a training between its batches, a fit between its trials.
pub mod stop {
    pub use crate::stop::{clear, flag, on_signal, request};
}
