//! The flags of `gbc compare` ([`CompareArgs`]) and the comparison they ask for.

use std::path::PathBuf;

use super::data::{ColumnArgs, HistoryArg};
use super::training::TrainingFlags;
use crate::api::{ApiError, CompareSpec};
use crate::train::TrainOptions;

/// Arguments of `gbc compare`.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The grey-box model (with closures).
    pub model: PathBuf,
    /// The data set: one or more CSV files, each an experiment (or several, with an
    /// `experiment` column), as `gbc train` reads them.
    #[arg(required = true, num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// Experiments held out (comma-separated or repeated); default: the last one.
    #[arg(long, value_name = "NAME", num_args = 1.., value_delimiter = ',')]
    pub holdout: Vec<String>,
    /// Leave-one-experiment-out: each experiment held out in turn.
    #[arg(long, conflicts_with = "holdout")]
    pub cv: bool,
    /// The mechanistic model to compare with (no closures, the grey box's states); default:
    /// the grey box with every closure output at its prior, or zero.
    #[arg(long, value_name = "FILE")]
    pub mechanism: Option<PathBuf>,
    /// Grey-box trainings per split, seeds --seed, --seed + 1, ...
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub seeds: u64,
    /// The first seed (the mechanism's fit takes it too).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Trainings at a time (default: every core).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Longest integration step (default: as `gbc train`).
    #[arg(long, value_name = "H")]
    pub dt: Option<f64>,
    /// Where free runs of whole experiments and training windows start.
    #[arg(long, value_enum, default_value_t = HistoryArg::Held)]
    pub history: HistoryArg,
    /// How data columns are named.
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// Epochs, batch, learning rate, precision, sub-steps, engine (as `gbc train`).
    #[command(flatten)]
    pub settings: TrainingFlags,
    /// Recoveries from a non-finite epoch per training (as `gbc train --recoveries`).
    #[arg(long, value_name = "N", default_value_t = crate::train::recovery::DEFAULT_RECOVERIES)]
    pub recoveries: usize,
    /// Write the comparison as JSON to this file (`-`: standard output; the table then
    /// goes to standard error).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write the HTML report (the free runs drawn side by side) to this file.
    #[arg(long, value_name = "FILE")]
    pub html: Option<PathBuf>,
}

impl CompareArgs {
    /// The API's spec of the flags: the split, the seeds, `gbc train`'s settings.
    pub fn spec(&self) -> Result<CompareSpec, ApiError> {
        let training = TrainOptions {
            dt: self.dt,
            history: self.history.into(),
            ..TrainOptions::with(&self.settings.settings()?)
        };
        Ok(CompareSpec {
            holdout: self.holdout.clone(),
            cv: self.cv,
            seeds: self.seeds,
            seed: self.seed,
            jobs: self.jobs,
            training,
            recoveries: self.recoveries,
            sparse_budget: (!self.settings.gives_budget())
                .then_some(crate::train::recipe::SPARSE_BUDGET),
        })
    }
}
