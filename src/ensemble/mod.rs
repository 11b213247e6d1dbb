//! Ensembles of trained grey boxes and their calibrated prediction bands
//! (`gbc train --ensemble N`, `docs/uncertainty.md`).
//!
//! [`train_ensemble`] trains `N` members on `--jobs` threads, each on a one-thread rayon
//! pool (the queue of `gbc experiment`): member `k` (from 0) with seed `seed + k` and, with
//! [`Resample::Experiments`] (the default), on a bootstrap of the whole training
//! experiments ([`resample`]). Each member's run is saved as any run is
//! (`members/member-KK/`: weights, `run.json`, `model.gbm`) and runs free along every
//! experiment.
//!
//! The band of a measured cell ([`band`]) mixes the members' free runs with the
//! measurement noise ([`noise`]: declared, or estimated from the members' residuals on
//! their training experiments) and is stretched by a factor calibrated on the training
//! experiments alone: each one is predicted by the members that did not train on it (out of
//! bag), and the factor is the split-conformal quantile of how far its cells lie outside
//! their base band ([`calibrate`]). The held-out experiments are then used once, to count
//! the share of their measured cells inside the band (the coverage), which `ensemble.json`
//! and the summary report. Without resampling no member is out of bag anywhere: the band
//! is not calibrated and not claimed (no lo/hi columns).

pub mod band;
pub mod calibrate;
mod error;
mod info;
mod members;
pub mod noise;
pub mod page;
pub mod predict;
pub mod resample;
mod run;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_floor;

pub use crate::trained::keep::Keep;
#[cfg(test)]
pub use calibrate::{Calibration, StateScores};
pub use calibrate::{CellCount, Coverage};
pub use error::{check_level, EnsembleError};
pub use info::EnsembleInfo;
#[cfg(test)]
pub use info::ENSEMBLE_FILE;
pub use members::{train_ensemble, MemberEvent, Plan, Trained};
pub use noise::StateNoise;
pub use predict::{is_ensemble, load, predict_table, Loaded};
pub use resample::Resample;
#[cfg(test)]
pub use run::Run;

/// The band level reported unless `--band` says otherwise.
pub const DEFAULT_LEVEL: f64 = 0.9;
