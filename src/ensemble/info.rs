//! `ensemble.json`: what an ensemble run is made of (its members, how each trained, the
//! band rule, its calibration and coverage), and where it lies in the run directory.

use super::calibrate::{Calibration, Coverage, ErrorSummary};
use super::noise::StateNoise;
use super::resample::Resample;

/// The file that describes an ensemble run, in its run directory.
pub const ENSEMBLE_FILE: &str = "ensemble.json";
/// The directory of the members' runs, under the run directory.
pub const MEMBERS_DIR: &str = "members";

/// `ensemble.json`: the members, how each was trained, the band rule, its calibration and
/// its coverage of the held-out experiments.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EnsembleInfo {
    /// Version of gbc that trained it.
    pub gbc_version: String,
    /// The model file as given.
    pub model: String,
    /// The data files, in words.
    pub data: String,
    /// The seed of member 1 (member `k` has `seed + k - 1`).
    pub seed: u64,
    /// What the members trained on.
    pub resample: Resample,
    /// The training experiments, in data-set order (a member's draws index them).
    pub training_experiments: Vec<String>,
    /// The held-out experiments the coverage is counted on.
    pub validation_experiments: Vec<String>,
    /// Every member, in order.
    pub members: Vec<MemberInfo>,
    /// How a band is made from the members.
    pub band: BandRule,
    /// The factor that makes the band's level true on the training experiments.
    pub calibration: Calibration,
    /// The share of held-out measured cells inside the band (absent without held-out
    /// cells).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<Coverage>,
    /// The held-out errors of the members' median and of each member.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub errors: Option<ErrorSummary>,
}

impl EnsembleInfo {
    /// The members that make up the ensemble (trained to the end, finite).
    pub fn used(&self) -> impl Iterator<Item = &MemberInfo> {
        self.members.iter().filter(|m| m.used)
    }
}

/// One member of an ensemble.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MemberInfo {
    /// 1-based.
    pub index: usize,
    /// Its seed.
    pub seed: u64,
    /// Its run directory, relative to the ensemble's.
    pub run: String,
    /// The training experiments it drew, in draw order (a name may repeat).
    pub trained_on: Vec<String>,
    /// The training experiments it did not draw (out of bag).
    pub out_of_bag: Vec<String>,
    /// `finished`, `diverged: ...` or `failed: ...`.
    pub status: crate::trained::status::TrainingStatus,
    /// Whether it makes up the ensemble (a member that failed or diverged does not).
    pub used: bool,
    /// Its error on the held-out experiments (the members' common measure, see
    /// [`ErrorSummary`]).
    #[serde(with = "crate::json")]
    pub validation_error: Option<f64>,
    /// Wall-clock seconds of its training and free runs.
    #[serde(with = "crate::json")]
    pub seconds: f64,
}

/// How the band of a measured state is made (the rule in words, the base level, the noise
/// of each state).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BandRule {
    /// The rule in words.
    pub rule: String,
    /// The level of the base band the calibrated factor stretches.
    #[serde(with = "crate::json")]
    pub base_level: f64,
    /// The measurement noise of each measured state.
    pub noise: Vec<StateNoise>,
}

/// The rule of [`BandRule::rule`].
pub const RULE: &str = "the members' free runs, each with Gaussian measurement noise, mixed \
     with equal weights; the central base-level interval of the mixture around the members' \
     median, both half-widths stretched by the calibrated factor of the level";
