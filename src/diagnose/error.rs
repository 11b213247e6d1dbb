//! Why a diagnosis could not be made.

use miette::Diagnostic;
use thiserror::Error;

use crate::solve::fit::FitError;

/// A problem with the model, the data or the options of a diagnosis.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum DiagnoseError {
    /// The model, the records or the options cannot be fitted (codes E0801 to E0808).
    #[error(transparent)]
    #[diagnostic(transparent)]
    Fit(#[from] FitError),
    /// Stopped by Ctrl-C or SIGTERM before its end; the report written is partial.
    #[error("the diagnosis was stopped before its end: {note}")]
    #[diagnostic(
        code(gbm::E0810),
        help("the report printed and written (--json, --html) holds the fits so far and says it is partial; run the diagnosis again to the end for a verdict (--skip-loci, or fewer --restarts, make it shorter)")
    )]
    Stopped {
        /// Where it stopped.
        note: String,
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
