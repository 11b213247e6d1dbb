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
mod members;
pub mod noise;
pub mod page;
pub mod predict;
pub mod resample;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_floor;

#[cfg(test)]
pub use calibrate::StateScores;
pub use calibrate::{Calibration, CellCount, Coverage, ErrorSummary};
pub use error::{check_level, EnsembleError};
pub use members::{train_ensemble, Keep, MemberEvent, Plan, Trained};
pub use noise::StateNoise;
pub use predict::{is_ensemble, load, predict_table, Loaded};

/// The file that describes an ensemble run, in its run directory.
pub const ENSEMBLE_FILE: &str = "ensemble.json";
/// The directory of the members' runs, under the run directory.
pub const MEMBERS_DIR: &str = "members";
/// The band level reported unless `--band` says otherwise.
pub const DEFAULT_LEVEL: f64 = 0.9;

/// What the members are trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Resample {
    /// A bootstrap of whole training experiments (as many draws as experiments, with
    /// replacement) per member: the experiments a member did not draw calibrate the band.
    Experiments,
    /// Every member on every training experiment, differing by seed alone (no member is
    /// out of bag: the band cannot be calibrated).
    None,
}

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
    pub status: String,
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

/// A member's free run along one experiment: per measured state, its value at each of the
/// experiment's rows (NaN where it did not run: before its start, after it stopped).
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// The row the free run starts at: its cells are the data's, never scored.
    pub start: usize,
    /// `states[i][row]`.
    pub states: Vec<Vec<f64>>,
}

impl Run {
    /// A run that reached no row (its prediction failed).
    pub fn none(record: &crate::record::Record, states: usize) -> Run {
        Run {
            start: record.len(),
            states: vec![vec![f64::NAN; record.len()]; states],
        }
    }

    /// The run of a prediction table along `record`: the first `states` columns after `t`,
    /// matched to the record's rows by time.
    pub fn of_table(
        table: &crate::trained::predict::PredictionTable,
        record: &crate::record::Record,
        states: usize,
    ) -> Run {
        let mut run = Run::none(record, states);
        let Some(times) = table.columns.first() else {
            return run;
        };
        let tolerance = record.time_tolerance();
        for (position, time) in times.iter().enumerate() {
            let Some(row) = row_at(record, *time, tolerance) else {
                continue;
            };
            run.start = run.start.min(row);
            for (state, values) in run.states.iter_mut().enumerate() {
                if let Some(value) = table.columns.get(state + 1).map(|c| c[position]) {
                    values[row] = value;
                }
            }
        }
        run
    }
}

/// The record row at `time`, within `tolerance` (the record's,
/// [`crate::record::Record::time_tolerance`]).
pub fn row_at(record: &crate::record::Record, time: f64, tolerance: f64) -> Option<usize> {
    let index = record.times.partition_point(|t| *t < time - tolerance);
    (record.times.get(index)).and_then(|t| ((t - time).abs() <= tolerance).then_some(index))
}
