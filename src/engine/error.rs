//! Why an engine could not be built or run: the one error type of the engines wing,
//! below everything else in it.

/// Why the network could not be built or run.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum BackendError {
    /// A bug: inconsistent model or batch.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Internal(#[from] crate::error::Bug),
    /// A model the chosen engine cannot run.
    #[error("expected a model the {engine} engine runs, found {what}")]
    #[diagnostic(
        code(gbm::E0402),
        help("train with `--engine graph`, which runs every model")
    )]
    Unsupported {
        /// The engine.
        engine: String,
        /// What it lacks.
        what: String,
    },
    /// Saved weights do not fit the model.
    #[error("expected weights for this model, found {0}")]
    #[diagnostic(
        code(gbm::E0401),
        help("use the weights trained with this model, or train it again")
    )]
    WeightsMismatch(String),
    /// A free run asked to stop (Ctrl-C, SIGTERM; [`crate::stop`]) before its end.
    #[error("the free run was stopped (Ctrl-C or SIGTERM) before its end")]
    #[diagnostic(
        code(gbm::E0719),
        help("the run was asked to stop before its end; run it again to the end")
    )]
    Stopped,
}

impl BackendError {
    /// An internal error with a message.
    pub fn internal(message: impl Into<String>) -> Self {
        BackendError::Internal(crate::error::Bug::new("the trainable network", message))
    }
}
