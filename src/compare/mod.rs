//! `gbc compare`: one comparison a user can trust (issue 25). On the same held-out
//! experiments (`--holdout`) or leave-one-experiment-out folds (`--cv`), scored by the one
//! error measure (`docs/error-measure.md`):
//!
//! - the **mechanism**: the grey box with every closure output at its prior, or zero
//!   ([`ir::Model::mechanism`]), or a closure-free model given, fitted by the one fitter of
//!   mechanistic params ([`crate::diagnose::mechanism`], through [`train::train_run`], so
//!   that its error is the one `gbc train` reports for it) and run free on each held-out
//!   experiment from its first row;
//! - the **grey box**, trained with `gbc train`'s defaults once per seed, run free the same
//!   way: the median over seeds, the min–max range, and how many free runs diverged;
//! - the **naive forecast** ([`naive`]): the training experiments' mean at the same time
//!   since the start.
//!
//! [`run`] trains everything on `jobs` threads, [`score`] reduces the runs to scores and a
//! verdict, [`render`] writes the text table and [`html`] the report with the free runs
//! drawn side by side. The method is in `docs/compare.md`.

mod error;
pub mod html;
pub mod naive;
pub mod render;
mod run;
pub mod score;
#[cfg(test)]
mod tests;

pub use error::CompareError;
pub use run::compare;
#[cfg(test)]
pub use score::Standing;
pub use score::{Score, Verdict};

use crate::train::{ErrorSet, Recipe, TrainOptions};

/// Which experiments are held out.
#[derive(Debug, Clone, PartialEq)]
pub enum Splits {
    /// One split: these experiments held out, the others train.
    Holdout(Vec<String>),
    /// Leave-one-experiment-out: each experiment held out in turn.
    LeaveOneOut,
}

/// How a comparison runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// The held-out experiments.
    pub splits: Splits,
    /// The grey box's seeds, one training per seed and split (the mechanism's fit takes the
    /// first).
    pub seeds: Vec<u64>,
    /// The training options of every run (their seed is replaced by each run's).
    pub training: TrainOptions,
    /// The training recipe (`gbc train`'s default).
    pub recipe: Recipe,
    /// Trainings run at a time.
    pub jobs: usize,
    /// Recoveries from a non-finite epoch per training (`gbc train --recoveries`).
    pub recoveries: usize,
}

/// One thing a comparison trains: the mechanism, or the grey box with one seed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Member {
    /// The fitted mechanism.
    Mechanism,
    /// The grey box before training (its network at zero, its params from the mechanism
    /// fit): the mechanism run through the grey box's own free run, which measures the
    /// numerical resolution of the comparison.
    Untrained,
    /// The grey box trained with this seed.
    GreyBox(u64),
}

impl std::fmt::Display for Member {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Member::Mechanism => write!(formatter, "the mechanism"),
            Member::Untrained => write!(formatter, "the grey box untrained"),
            Member::GreyBox(seed) => write!(formatter, "the grey box, seed {seed}"),
        }
    }
}

/// Something worth showing while a comparison runs.
#[derive(Debug, Clone, Copy)]
pub enum Event<'a> {
    /// Before the first run: how many trainings and fits there are.
    Started {
        /// Runs in all (per split: the mechanism and one per seed).
        runs: usize,
        /// Epochs of each grey-box training.
        epochs: usize,
    },
    /// A run finished an epoch (1-based).
    Epoch {
        /// What trains.
        member: Member,
        /// The experiments held out.
        held_out: &'a [String],
        /// The epoch.
        epoch: usize,
    },
    /// A run finished.
    Finished {
        /// What trained.
        member: Member,
        /// The experiments held out.
        held_out: &'a [String],
        /// Its wall-clock seconds.
        seconds: f64,
        /// Its mean held-out error (`None`: it failed or scored no cell).
        error: Option<f64>,
    },
}

/// A comparison: every split with its runs and scores, and the summary over all held-out
/// experiments.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Comparison {
    /// The grey box's name.
    pub grey_box: String,
    /// The mechanism's name (the grey box's own, with `(mechanism)`, or the file given).
    pub mechanism: String,
    /// The grey box's seeds.
    pub seeds: Vec<u64>,
    /// Epochs of each grey-box training.
    pub epochs: usize,
    /// The measured states, in model order.
    pub states: Vec<String>,
    /// The axis titles of the report: time, then each state with its unit.
    pub labels: Vec<String>,
    /// Each split.
    pub splits: Vec<SplitResult>,
    /// Over every held-out experiment of every split: per run the mean of its errors over
    /// the experiments, then the same reduction as per experiment.
    pub overall: ExperimentScore,
}

/// One split: what trained, how each run did on each held-out experiment, and the scores.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SplitResult {
    /// The held-out experiments.
    pub held_out: Vec<String>,
    /// The training experiments.
    pub training: Vec<String>,
    /// The fitted mechanism's run.
    pub mechanism: MemberRun,
    /// The grey box before training, run as the trained ones are (`Member::Untrained`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub untrained: Option<MemberRun>,
    /// The grey box's runs, one per seed.
    pub grey_box: Vec<MemberRun>,
    /// The naive forecast of each held-out experiment.
    pub naive: Vec<HeldOutRun>,
    /// The scores on each held-out experiment.
    pub scores: Vec<ExperimentScore>,
}

/// One training (or fit) and its free runs on the held-out experiments.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MemberRun {
    /// Its seed.
    pub seed: u64,
    /// Wall-clock seconds.
    #[serde(with = "crate::json")]
    pub seconds: f64,
    /// Why it failed to train, when it did (it is then left out of the scores).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
    /// Where its training went non-finite, when it did (the last finite epoch's weights
    /// are scored).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training_diverged: Option<String>,
    /// Its params after training (fitted, for the mechanism).
    #[serde(with = "crate::json")]
    pub params: Vec<(String, f64)>,
    /// The epochs it trained (a sparse record's budget and `--toward-mechanism auto`'s
    /// stop decide them; 0: the mechanism itself).
    #[serde(default)]
    pub epochs: usize,
    /// Its free run on each held-out experiment.
    pub held_out: Vec<HeldOutRun>,
}

/// A free run (or the naive forecast) on one held-out experiment, with its error.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeldOutRun {
    /// The experiment.
    pub experiment: String,
    /// Its error (`None`: no measured cell after the first row); infinite where the free
    /// run diverged, with where and why.
    pub error: Option<ErrorSet>,
    /// The run at the experiment's rows, up to where it stopped.
    pub curve: Option<Curve>,
}

/// States over time.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Curve {
    /// Times.
    #[serde(with = "crate::json")]
    pub times: Vec<f64>,
    /// `states[i][k]`: measured state `i` at `times[k]` (NaN where there is no value).
    #[serde(with = "crate::json")]
    pub states: Vec<Vec<f64>>,
}

/// The three scores on one held-out experiment (or over all of them) and the verdict.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExperimentScore {
    /// The experiment (`overall` for the summary).
    pub experiment: String,
    /// The fitted mechanism's.
    pub mechanism: Score,
    /// The untrained grey box's (the mechanism through the grey box's free run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub untrained: Option<Score>,
    /// The grey box's: median over seeds, with the range.
    pub grey_box: Score,
    /// The naive forecast's.
    pub naive: Score,
    /// The grey box against the other two.
    pub verdict: Verdict,
}
