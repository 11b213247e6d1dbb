//! The result of a diagnosis: plain data, serialised as the JSON of spec section 5 (with a
//! few extra fields), rendered as text by [`super::render`] and as HTML by [`super::html`].

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A complete diagnosis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// Model name.
    pub model: String,
    /// Held-out gap of the model with its own params fitted.
    #[serde(with = "crate::json")]
    pub gap_before: f64,
    /// Gap a perfect model would show: the measurement noise in normalised units.
    #[serde(with = "crate::json")]
    pub noise_floor: f64,
    /// Whether the gap clearly exceeds the noise (see [`super::SIGNIFICANCE`]).
    pub significant: bool,
    /// Per measured state, largest share first.
    pub states: Vec<StateGap>,
    /// Rates and balances where a free correction closes the gap, best first.
    pub locus: Vec<Locus>,
    /// Whether closing the gap at the best locus needs history (dim > 1 beats dim 1).
    pub history_dependent: bool,
    /// Time windows of the held-out part holding most of the error, largest share first.
    pub windows: Vec<Window>,
    /// Where in the operating range the error concentrates, strongest first.
    pub regime: Vec<Regime>,
    /// Candidate effects, best (smallest held-out gap) first.
    pub effects: Vec<EffectScore>,
    /// The effect credited with the gap, if any.
    pub credited: Option<String>,
    /// The two best effects applied together.
    pub combined: Option<Combined>,
    /// How stable the effect ranking is over the halves of the training part.
    pub confidence: Confidence,
    /// Formulas for the correction at the best locus (sparse regression).
    pub hints: Vec<Formula>,
    /// The model's own params after fitting.
    #[serde(with = "crate::json")]
    pub fitted_params: BTreeMap<String, f64>,
    /// What was fitted and what was scored.
    pub split: SplitSummary,
    /// Data and runs on the held-out record, for plots (not serialised).
    #[serde(skip)]
    pub series: Series,
}

/// The error of one measured state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateGap {
    /// State name.
    pub name: String,
    /// Its share of the held-out free-run error.
    #[serde(with = "crate::json")]
    pub share: f64,
    /// Free-run (online) mean squared z-scored error on the held-out rows.
    #[serde(with = "crate::json")]
    pub online: f64,
    /// One-step (offline) mean squared z-scored error on the held-out rows.
    #[serde(with = "crate::json")]
    pub offline: f64,
    /// Its measurement noise variance, normalised.
    #[serde(with = "crate::json")]
    pub noise: f64,
}

/// What kind of quantity a locus is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LocusKind {
    /// A `let` (rate law).
    Let,
    /// An `output`.
    Output,
    /// A closure output.
    Closure,
    /// A state's balance (`der X += c`).
    Balance,
}

/// A place where a free correction was tried.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Locus {
    /// The let's name, or the state's for a balance.
    pub name: String,
    /// Its kind.
    pub kind: LocusKind,
    /// Held-out gap with the best correction there.
    #[serde(with = "crate::json")]
    pub bound_after: f64,
    /// Held-out gap with a correction that sees the present only (dim 1).
    #[serde(with = "crate::json")]
    pub bound_present: f64,
    /// Held-out gap with a correction that also sees the measured history (dim > 1).
    #[serde(with = "crate::json")]
    pub bound_history: f64,
    /// Whether the held-out data cannot tell this locus from the best one (paired test
    /// over time blocks; always true for the best).
    pub tied: bool,
}

/// A time window of the held-out part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Window {
    /// First time.
    #[serde(with = "crate::json")]
    pub t_start: f64,
    /// Last time.
    #[serde(with = "crate::json")]
    pub t_end: f64,
    /// Share of the held-out error.
    #[serde(with = "crate::json")]
    pub share: f64,
}

/// A range of one variable where the error concentrates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Regime {
    /// Input or measured state.
    pub variable: String,
    /// `[lo, hi]` of the range.
    #[serde(with = "crate::json")]
    pub range: [f64; 2],
    /// Share of the held-out error in that range.
    #[serde(with = "crate::json")]
    pub share: f64,
    /// Share of the held-out rows in that range.
    #[serde(with = "crate::json")]
    pub row_share: f64,
    /// Whether the range is the variable's lowest bin ("below hi").
    pub lowest: bool,
    /// Whether the range is the variable's highest bin ("above lo").
    pub highest: bool,
}

/// A candidate effect after fitting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EffectScore {
    /// Effect name.
    pub name: String,
    /// Description.
    pub description: Option<String>,
    /// Held-out gap with the effect applied and all params fitted.
    #[serde(with = "crate::json")]
    pub gap_after: f64,
    /// `1 - gap_after / gap_before`.
    #[serde(with = "crate::json")]
    pub shrink: f64,
    /// Fitted params: the effect's own, then the model's.
    #[serde(with = "crate::json")]
    pub params: BTreeMap<String, f64>,
    /// Held-out gaps after fitting on the first and on the second half of the training part.
    #[serde(with = "crate::json")]
    pub gap_after_halves: [f64; 2],
}

/// Two effects applied together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Combined {
    /// The effects.
    pub names: Vec<String>,
    /// Held-out gap.
    #[serde(with = "crate::json")]
    pub gap_after: f64,
    /// `1 - gap_after / gap_before`.
    #[serde(with = "crate::json")]
    pub shrink: f64,
}

/// Stability of the effect ranking.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Confidence {
    /// Whether the best effect is the same when fitting on either half of the training part.
    pub stable: bool,
    /// `(gap_after of the second - gap_after of the first) / gap_before`.
    #[serde(with = "crate::json")]
    pub margin: f64,
    /// The best effect when fitting on each half.
    pub best_by_half: [Option<String>; 2],
}

/// A formula found by sparse regression.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Formula {
    /// What it approximates (e.g. "correction of mu").
    pub target: String,
    /// The formula, e.g. `-0.31 * mu * E_B`.
    pub text: String,
    /// Coefficient of determination on the training rows.
    #[serde(with = "crate::json")]
    pub r2: f64,
    /// Number of terms.
    pub terms: usize,
}

/// Sizes and times of the split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplitSummary {
    /// Training rows.
    pub train_rows: usize,
    /// Held-out rows.
    pub test_rows: usize,
    /// First held-out time.
    #[serde(with = "crate::json")]
    pub t_test_start: f64,
    /// Last held-out time.
    #[serde(with = "crate::json")]
    pub t_test_end: f64,
    /// Whether the held-out rows come from a separate file.
    pub separate_test: bool,
}

/// Time series on the held-out record for plots.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Times of the whole held-out record (from its row 0).
    pub times: Vec<f64>,
    /// First scored row.
    pub first_scored: usize,
    /// Measured-state names.
    pub names: Vec<String>,
    /// Data, one column per measured state.
    pub data: Vec<Vec<f64>>,
    /// Free run of the fitted model, one column per measured state.
    pub before: Vec<Vec<f64>>,
    /// Free run with the best effect, if any was fitted.
    pub after: Option<Vec<Vec<f64>>>,
    /// Squared z-scored error summed over states, per scored row (before).
    pub errors: Vec<f64>,
}
