//! Why a comparison could not run: bad input (codes E12xx), or a training failure that is
//! not one seed's own (I/O, internal).

use miette::Diagnostic;
use thiserror::Error;

use crate::train::TrainError;

/// A comparison failure.
#[derive(Debug, Error, Diagnostic)]
pub enum CompareError {
    /// The grey box has no closure, so there is no mechanism inside it to compare with.
    #[error(
        "expected a grey box (a model with a closure) to compare with its mechanism, found no \
         closure in `{model}`"
    )]
    #[diagnostic(
        code(gbm::E1201),
        help(
            "give the grey box as MODEL, or name the mechanistic model to compare with: \
             `--mechanism FILE`"
        )
    )]
    NoClosure {
        /// The model's name.
        model: String,
    },
    /// `--mechanism FILE` names a model with closures.
    #[error("expected a mechanistic model (no closures) in `{file}`, found closure `{closure}`")]
    #[diagnostic(
        code(gbm::E1202),
        help("the mechanism is fitted by free runs: give a model without closures")
    )]
    MechanismHasClosures {
        /// The file.
        file: String,
        /// Its first closure.
        closure: String,
    },
    /// The mechanism and the grey box measure different states.
    #[error(
        "expected the mechanism `{mechanism}` to have the grey box's states ({grey_box}), found \
         {found}"
    )]
    #[diagnostic(
        code(gbm::E1203),
        help(
            "both are scored on the same measured cells: declare the same states, in the same \
             order"
        )
    )]
    DifferentStates {
        /// The mechanism's name.
        mechanism: String,
        /// The grey box's states.
        grey_box: String,
        /// The mechanism's states.
        found: String,
    },
    /// A bad option value.
    #[error("expected {expected} for {option}, found {found}")]
    #[diagnostic(code(gbm::E1204), help("{help}"))]
    BadOption {
        /// The flag.
        option: String,
        /// What it takes.
        expected: String,
        /// What was given.
        found: String,
        /// What to do.
        help: String,
    },
    /// Training or fitting failed for a reason that is not one seed's own (I/O, a bug, bad
    /// input every run shares).
    #[error(transparent)]
    #[diagnostic(transparent)]
    Train(#[from] TrainError),
    /// A bug in gbc.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Internal(#[from] crate::error::Bug),
}
