//! A comparison's result: every split with its runs and scores, and the summary over all
//! held-out experiments (what `gbc compare --json` writes and its report draws).

use super::score::{Score, Verdict};
use crate::train::ErrorSet;

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

/// How close (relative) the untrained grey box's params must be to the mechanism's for it
/// to be the mechanism: the training precision's rounding (`f32` by default).
const SAME_PARAMS: f64 = 1e-5;

impl SplitResult {
    /// The epochs each grey-box run that trained took: "seed 1 280, seed 2 300".
    pub fn epochs_trained(&self) -> String {
        let runs: Vec<String> = (self.grey_box.iter())
            .filter(|r| r.failed.is_none())
            .map(|r| format!("seed {} {}", r.seed, r.epochs))
            .collect();
        runs.join(", ")
    }

    /// Whether the untrained grey box is the fitted mechanism (the same params, within the
    /// training precision), so that its distance from the mechanism's error is numerical.
    /// On a dense record the grey box's params come from the balances or Adam instead.
    pub fn untrained_is_mechanism(&self) -> bool {
        let Some(untrained) = &self.untrained else {
            return false;
        };
        let fitted = &self.mechanism.params;
        untrained.params.len() == fitted.len()
            && (untrained.params.iter().zip(fitted)).all(|((a, x), (b, y))| {
                a == b && (x - y).abs() <= SAME_PARAMS * x.abs().max(y.abs())
            })
    }
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
