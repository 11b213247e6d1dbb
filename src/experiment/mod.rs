//! Experiments: grids of training runs over training sizes and replicate seeds, their
//! results, and the paper's figures (`gbc experiment`, `gbc demo`).
//!
//! A [`Study`] names models, a training record, a validation split, sizes, replicates and
//! training settings. [`prepare`] loads and checks everything once; [`grid`] lists the runs
//! and [`Shard`] slices them; [`execute`] trains runs in parallel, each writing its
//! [`RunResult`] atomically under `DIR/runs/` so a re-run skips finished runs; [`merge`] joins
//! the results of several directories (the slices of a job array); [`tables`] writes CSV and
//! JSON; [`figures`] draws the paper's figures as SVG and [`report`] puts them into HTML.
//!
//! Decisions:
//! - **Errors on one scale.** Validation errors are MSEs of states z-scored with the
//!   validation window's statistics, so models and sizes compare on the same scale (see
//!   [`results`]).
//! - **Grey box or black box** is read from the model: continuous balances (`der`) are grey
//!   boxes, discrete maps (`next`) black boxes ([`is_black_box`]).
//! - **Representative runs** for the trajectory figures: at the study's representative size,
//!   the replicate with the median online error (the lower middle one for an even count).

mod black_box;
pub mod data_figure;
mod error;
pub mod execute;
pub mod figure;
pub mod figures;
pub mod grid;
pub mod held_out;
pub mod merge;
pub mod prepare;
pub mod reference;
pub mod report;
pub mod results;
pub mod set;
pub mod study;
pub mod tables;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_run;

pub use error::{ExperimentError, ExperimentFailure};
#[cfg(test)]
pub use execute::execute;
pub use execute::{execute_until, Progress};
pub use grid::{grid, RunSpec, Shard};
pub use merge::merge;
pub use prepare::{prepare, Prepared};
pub use results::{RunResult, RunStatus, StudyRecord};
#[cfg(test)]
pub use study::StudyModel;
pub use study::{DataFiles, Study, Validation};

/// The default number of runs at once (trainings, ensemble members): the number of cores.
pub fn default_jobs() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from)
}
