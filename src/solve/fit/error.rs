//! Why a fit by free runs could not be made: the model, the records or the options.

use miette::Diagnostic;
use thiserror::Error;

/// A problem with the model, the records or the options of a fit by free runs (the
/// mechanism fit of `gbc train` and every fit of `gbc diagnose`).
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum FitError {
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
    /// Too few measured rows to fit on one part, or none to score on the other.
    #[error(
        "expected at least {needed} measured rows in the training part and one in the \
         held-out part, found {train} and {test} ({how})"
    )]
    #[diagnostic(
        code(gbm::E0803),
        help(
            "the diagnosis fits on the training part and scores on the held-out part: hold out \
             other experiments (--holdout NAME, --val FILE) or another share of each \
             (--val-fraction SHARE), or accept fewer rows with --min-rows N (the score of a \
             few rows is noisy)"
        )
    )]
    TooFewRows {
        /// Measured rows the training part needs.
        needed: usize,
        /// Measured rows in the training part.
        train: usize,
        /// Measured rows in the held-out part.
        test: usize,
        /// What was held out, in words.
        how: String,
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
    #[diagnostic(code(gbm::E0805))]
    BadOption {
        /// The option.
        option: String,
        /// What is accepted.
        expected: String,
        /// What was given.
        found: String,
        /// What to do instead.
        #[help]
        help: String,
    },
    /// A tail split that leaves one part of an experiment without a measured row.
    #[error(
        "expected at least one measured row in each part of experiment `{experiment}` split \
         by --val-fraction {share}, found {train} training and {test} held-out rows"
    )]
    #[diagnostic(
        code(gbm::E0806),
        help("choose a --val-fraction that leaves both parts a measured row, or hold out whole experiments (--holdout NAME)")
    )]
    TailTooSmall {
        /// The experiment.
        experiment: String,
        /// The share held out.
        share: f64,
        /// Measured rows that would train.
        train: usize,
        /// Measured rows that would be held out.
        test: usize,
    },
    /// A discrete map on rows that are not uniformly spaced.
    #[error("expected uniformly spaced rows for a `next` model, found irregular times in experiment `{experiment}`")]
    #[diagnostic(
        code(gbm::E0808),
        help("a discrete map steps from row to row; write the model with `der` balances to diagnose it on irregular data")
    )]
    IrregularMap {
        /// The experiment.
        experiment: String,
    },
    /// A bug: a synthesised model did not compile, or expressions do not fit their layout.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Internal(#[from] crate::error::Bug),
}

impl FitError {
    /// An internal error of a fit.
    pub fn internal(message: impl Into<String>) -> Self {
        FitError::Internal(crate::error::Bug::new("the diagnosis", message))
    }
}
