//! Why an experiment could not run.

use std::sync::Arc;

use miette::{Diagnostic, NamedSource, SourceSpan};
use thiserror::Error;

use crate::data::DataError;
use crate::io::IoError;
use crate::solve::ode::SimError;
use crate::train::TrainError;

/// A problem with an experiment's description or directory.
#[derive(Debug, Error, Diagnostic)]
pub enum ExperimentError {
    /// A study file that cannot be read or parsed.
    #[error("cannot read study `{path}`: {reason}")]
    #[diagnostic(
        code(gbm::E0901),
        help(
            "a study is a JSON object like the files in `experiments/`; see docs/reproduction.md"
        )
    )]
    BadStudy {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
        /// The file's text, where it was read.
        #[source_code]
        source_code: Option<Arc<NamedSource<String>>>,
        /// Where in the file.
        #[label("here")]
        span: Option<SourceSpan>,
    },
    /// A bad setting.
    #[error("expected {expected} for {option}, found {found}")]
    #[diagnostic(code(gbm::E0902), help("see `gbc experiment --help`"))]
    BadOption {
        /// The option (or study field).
        option: String,
        /// What is allowed.
        expected: String,
        /// What was given.
        found: String,
    },
    /// The output directory holds runs of another study.
    #[error(
        "expected the study recorded in `{dir}` (or an empty directory), found a different {what}"
    )]
    #[diagnostic(
        code(gbm::E0903),
        help(
            "finished runs are reused only by the same study (models, data, split, training \
             settings and file contents); choose a new --out directory or restore the settings"
        )
    )]
    StudyChanged {
        /// The experiment directory.
        dir: String,
        /// What differs.
        what: String,
    },
    /// Directories to merge that hold different studies.
    #[error("expected results of one study, found different studies in `{first}` and `{other}`")]
    #[diagnostic(
        code(gbm::E0904),
        help("merge only the slices (`--shard K/N`) of one `gbc experiment` command")
    )]
    MergeMismatch {
        /// The first directory.
        first: String,
        /// The directory that differs.
        other: String,
    },
    /// A directory without a study record.
    #[error("expected an experiment directory with `study.json`, found none in `{dir}`")]
    #[diagnostic(
        code(gbm::E0905),
        help("pass directories written by `gbc experiment --out DIR`")
    )]
    NotAnExperiment {
        /// The directory.
        dir: String,
    },
    /// A file shipped with gbc is missing: the command runs outside the repository.
    #[error("expected the shipped file `{path}`, found nothing there")]
    #[diagnostic(
        code(gbm::E0906),
        help(
            "run `gbc demo` from the root of the gbc repository (the directory with `models/`), \
             e.g. `cargo run --release -- demo`"
        )
    )]
    MissingShippedFile {
        /// The file, relative to the current directory.
        path: String,
    },
    /// A model, record or truth file that the study names cannot be read.
    #[error("cannot read `{path}`, named by the study: {reason}")]
    #[diagnostic(
        code(gbm::E0907),
        help("check that the file still exists and is readable; paths are relative to the current directory")
    )]
    UnreadableFile {
        /// The file.
        path: String,
        /// Why (the system's reason).
        reason: String,
    },
}

impl ExperimentError {
    /// A study file at `path` that the system cannot read.
    pub fn unreadable_study(path: &std::path::Path, error: &std::io::Error) -> ExperimentError {
        ExperimentError::BadStudy {
            path: path.display().to_string(),
            reason: crate::io::describe(error),
            source_code: None,
            span: None,
        }
    }
}

/// Why an experiment stopped: problems with the user's input (each a diagnostic, with its
/// source where it has one), or a bug in gbc.
#[derive(Debug)]
pub enum ExperimentFailure {
    /// Bad input: models, data, settings, directories.
    User(Vec<miette::Report>),
    /// A bug in gbc.
    Internal(String),
}

impl ExperimentFailure {
    /// A user failure from one diagnostic.
    pub fn user(diagnostic: impl Diagnostic + Send + Sync + 'static) -> Self {
        if crate::error::is_bug(&diagnostic) {
            return ExperimentFailure::Internal(diagnostic.to_string());
        }
        ExperimentFailure::User(vec![miette::Report::new(diagnostic)])
    }
}

impl From<ExperimentError> for ExperimentFailure {
    fn from(error: ExperimentError) -> Self {
        ExperimentFailure::user(error)
    }
}

impl From<IoError> for ExperimentFailure {
    fn from(error: IoError) -> Self {
        ExperimentFailure::user(error)
    }
}

impl From<DataError> for ExperimentFailure {
    fn from(error: DataError) -> Self {
        ExperimentFailure::user(error)
    }
}

impl From<TrainError> for ExperimentFailure {
    fn from(error: TrainError) -> Self {
        ExperimentFailure::user(error)
    }
}

impl From<SimError> for ExperimentFailure {
    fn from(error: SimError) -> Self {
        ExperimentFailure::user(error)
    }
}

impl From<Vec<miette::Report>> for ExperimentFailure {
    fn from(reports: Vec<miette::Report>) -> Self {
        ExperimentFailure::User(reports)
    }
}
