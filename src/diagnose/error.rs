//! Why a diagnosis could not be made.

use miette::Diagnostic;
use thiserror::Error;

/// A problem with the model, the data or the options of a diagnosis.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum DiagnoseError {
    /// The model has closures: it is not a mechanistic simulator.
    #[error("cannot diagnose model `{model}`: it has closures ({closures})")]
    #[diagnostic(
        code(gbm::E0801),
        help("diagnose the mechanistic model: replace every closure by a rate law, and list candidate mechanisms as `effect`s")
    )]
    HasClosures {
        /// Model name.
        model: String,
        /// Closure names, comma separated.
        closures: String,
    },
    /// A hidden state has no declared initial value, so a free run cannot start.
    #[error("hidden state `{state}` has no initial value")]
    #[diagnostic(
        code(gbm::E0802),
        help("a free run starts hidden states at their declared values: write `hidden {state} = ...`")
    )]
    MissingInitial {
        /// The hidden state.
        state: String,
    },
    /// Too few rows to fit on one part and score on the other.
    #[error("expected at least {needed} data rows, found {rows}")]
    #[diagnostic(
        code(gbm::E0803),
        help("the diagnosis fits on the training part and scores on the held-out part; each needs at least 10 rows")
    )]
    TooFewRows {
        /// Rows found.
        rows: usize,
        /// Rows needed.
        needed: usize,
    },
    /// The model cannot be run on the data with its initial params.
    #[error("the model cannot be run on the data: {reason}")]
    #[diagnostic(
        code(gbm::E0804),
        help("check the initial values of the params and that the first data row is a valid state of the model")
    )]
    Unsimulable {
        /// What went wrong.
        reason: String,
    },
    /// A bad option value.
    #[error("invalid option `{option}`: expected {expected}, found {found}")]
    #[diagnostic(
        code(gbm::E0805),
        help("see `gbc diagnose --help` for the accepted values")
    )]
    BadOption {
        /// The option.
        option: String,
        /// What is accepted.
        expected: String,
        /// What was given.
        found: String,
    },
    /// The test record's step differs from the training record's.
    #[error("the test data are sampled every {test}, the training data every {train}")]
    #[diagnostic(code(gbm::E0806), help("sample both records on the same step"))]
    StepMismatch {
        /// Training step.
        train: f64,
        /// Test step.
        test: f64,
    },
    /// A column the model needs is not in the data (normally caught when reading).
    #[error("data file `{file}` has no column `{column}`")]
    #[diagnostic(
        code(gbm::E0807),
        help("the data need a column for every input and measured state of the model")
    )]
    MissingColumn {
        /// The file.
        file: String,
        /// The column.
        column: String,
    },
    /// A bug: a synthesised model did not compile, or expressions do not fit their layout.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Internal(#[from] crate::error::Bug),
}

impl DiagnoseError {
    /// An internal error of the diagnosis.
    pub fn internal(message: impl Into<String>) -> Self {
        DiagnoseError::Internal(crate::error::Bug::new("the diagnosis", message))
    }
}
