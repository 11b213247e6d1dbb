//! Fitting a mechanistic model's params to measured experiments by free runs: the one
//! fitter below `gbc train` (its mechanism fit) and `gbc diagnose` (every fit it scores).
//!
//! - [`split`]: the records in model terms, the rows that fit and the rows that are
//!   scored, where each free run starts, the z-scoring statistics and declared noise.
//! - [`simulate`]: a model compiled for free runs from an experiment's first row, with its
//!   sensitivities ([`sensitivity`]).
//! - [`fitter`]: multi-start Levenberg–Marquardt on the z-scored free-run residuals in
//!   transformed coordinates; [`model`]: a model fitted on a split, held along a free
//!   direction; [`unknowns`]: what a fit solves for.
//! - [`uncertainty`]: standard errors, identifiability and the free direction, reported
//!   as a [`FitSummary`]; [`noise`]: the measurement noise from the data alone;
//!   [`predictive`]: the spread a correct model's held-out runs add to the noise.
//! - [`mechanism`]: a model without closures fitted to whole training experiments
//!   (`gbc train`'s mechanism fit).

mod error;
pub mod fitter;
pub mod mechanism;
pub mod model;
pub mod noise;
mod observed;
pub mod predictive;
pub mod sensitivity;
pub mod simulate;
pub mod split;
mod summary;
pub mod uncertainty;
pub mod unknowns;

pub use error::FitError;
pub use mechanism::{check_fittable, fit_mechanism, MechanismFit};
pub use summary::{FitSummary, ParamEstimate};

/// How to fit: the options a fit by free runs shares between `gbc train` and
/// `gbc diagnose` (the same flags).
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Most random restarts of each fit besides the declared or warm start (fits stop
    /// earlier once two starts agree).
    pub restarts: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// Whether hidden states start from values fitted per training experiment.
    pub fit_initial: bool,
    /// Whether the first row's measured cells of the training experiments are fitted as
    /// unknowns (`--fit-starts`; else the free runs start at them, as the records spec says).
    pub fit_starts: bool,
    /// The measurement noise (`ir::merge_noise` of the model's declarations and the
    /// command line's `--noise`); `None`: the model's declarations.
    pub noise: Option<Vec<crate::ir::Noise>>,
    /// Measured rows each part (training, held-out) needs; default [`split::MIN_ROWS`].
    pub min_rows: usize,
}

impl FitOptions {
    /// A bad option (`--min-rows` below 2), as the error that names it.
    pub fn check(&self) -> Result<(), FitError> {
        if self.min_rows < 2 {
            return Err(FitError::BadOption {
                option: "--min-rows".into(),
                expected: "at least 2 measured rows".into(),
                found: self.min_rows.to_string(),
                help: "a fit and a score each need a few measured rows; the default is 10".into(),
            });
        }
        Ok(())
    }

    /// A seed for task `index`, derived from the user's seed.
    pub fn task_seed(&self, index: u64) -> u64 {
        self.seed
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(index.wrapping_mul(0xD1B5_4A32_D192_ED03))
    }
}
