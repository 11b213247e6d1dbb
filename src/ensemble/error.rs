//! Why an ensemble cannot be trained, read or used.

use miette::Diagnostic;
use thiserror::Error;

use crate::error::Bug;
use crate::train::TrainError;

/// An ensemble failure: bad options, too few members, an unreadable ensemble run, or a
/// member's training or prediction failure.
#[derive(Debug, Error, Diagnostic)]
pub enum EnsembleError {
    /// Fewer than two members asked for.
    #[error("expected at least 2 members for --ensemble, found {found}")]
    #[diagnostic(
        code(gbm::E0450),
        help("a band needs several members: e.g. `--ensemble 5` (a single run: leave --ensemble out)")
    )]
    TooFewMembers {
        /// The number given.
        found: usize,
    },
    /// Whole experiments cannot be resampled.
    #[error("expected {expected} to resample whole experiments, found {found}")]
    #[diagnostic(
        code(gbm::E0451),
        help("hold out whole experiments (--holdout NAME, --val FILE) and train on at least two, or train the members on every experiment with `--resample none` (the band is then not calibrated and not written)")
    )]
    CannotResample {
        /// What resampling needs.
        expected: String,
        /// What the data and flags give.
        found: String,
    },
    /// Fewer than two members ended finite.
    #[error("expected at least 2 members to finish, found {finished} of {members}: {why}")]
    #[diagnostic(
        code(gbm::E0452),
        help("each member's run and status are in members/ and ensemble.json; lower the learning rate or add epochs, or train more members")
    )]
    MembersFailed {
        /// Members that finished.
        finished: usize,
        /// Members trained.
        members: usize,
        /// The first failure, in words.
        why: String,
    },
    /// `ensemble.json` cannot be read.
    #[error("cannot read the ensemble `{path}`: {reason}")]
    #[diagnostic(
        code(gbm::E0453),
        help("the directory must hold an ensemble written by `gbc train --ensemble N -o DIR`")
    )]
    BadEnsemble {
        /// The file.
        path: String,
        /// Why.
        reason: String,
    },
    /// A band level outside (0, 1).
    #[error("expected a band level strictly between 0 and 1 for --band, found {found}")]
    #[diagnostic(code(gbm::E0454), help("e.g. `--band 0.9` for the 90 % band"))]
    BadLevel {
        /// The level given.
        found: f64,
    },
    /// A member's training, saving or prediction failed.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Train(#[from] TrainError),
    /// A what-if run cannot start.
    #[error(transparent)]
    #[diagnostic(transparent)]
    WhatIf(#[from] crate::trained::predict::whatif::WhatIfError),
    /// An invariant broke.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Internal(#[from] Bug),
}

impl EnsembleError {
    /// A job thread that could not start.
    pub fn cannot_start(message: String) -> Self {
        EnsembleError::Internal(Bug::new("the ensemble's job queue", message))
    }
}

/// Checks a band level: strictly between 0 and 1.
pub fn check_level(level: f64) -> Result<f64, EnsembleError> {
    if level > 0.0 && level < 1.0 {
        Ok(level)
    } else {
        Err(EnsembleError::BadLevel { found: level })
    }
}
