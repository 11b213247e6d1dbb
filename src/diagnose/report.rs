//! The result of a diagnosis: plain data, serialised as the JSON of spec section 5 (with
//! extra fields), rendered as text by [`super::render`] and as HTML by [`super::html`].
//! Gaps of free runs that diverged are infinite, written by name in JSON (`"inf"`, see
//! [`crate::json`]: every number field goes through it, so the file reads back) and
//! "diverged" in text.

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
    /// What a correct model's held-out runs add to the noise floor (mean squared
    /// normalised deviation): the fitted params' uncertainty and the noise of the measured
    /// first rows they start from, carried by the runs' sensitivities
    /// ([`crate::solve::fit::predictive`]). `None`: it could not be computed.
    #[serde(default, with = "crate::json")]
    pub held_out_spread: Option<f64>,
    /// Whether the gap clearly exceeds what a correct model would show: the noise floor
    /// plus the held-out spread (see [`super::SIGNIFICANCE`]).
    pub significant: bool,
    /// The same held-out errors as `gbc train` and `gbc predict` pool them: the mean over
    /// measured states of each state's normalised MSE (`StateGap::online`), where the gap
    /// pools the cells.
    #[serde(default, with = "crate::json")]
    pub gap_before_per_state: f64,
    /// Per measured state, largest share first.
    pub states: Vec<StateGap>,
    /// Rates, groups of rates and balances where a free correction closes the gap, best
    /// first (near-ties: the most upstream, most specific first).
    pub locus: Vec<Locus>,
    /// Whether closing the gap needs history (see [`Memory`]).
    pub history_dependent: bool,
    /// The memory verdict with its reasons.
    pub memory: Memory,
    /// Time windows of the held-out part holding most of the error, largest share first.
    pub windows: Vec<Window>,
    /// Where in the operating range the error concentrates, strongest first.
    pub regime: Vec<Regime>,
    /// Candidate effects, each applied alone, best (smallest held-out gap) first.
    pub effects: Vec<EffectScore>,
    /// The first effect credited with the gap, if any (spec section 5).
    pub credited: Option<String>,
    /// Forward selection: the effects credited together, in order, and every step tried.
    pub selection: Selection,
    /// How sure the ranking of the single effects is.
    pub confidence: Confidence,
    /// Formulas for the correction at the best locus (sparse regression).
    pub hints: Vec<Formula>,
    /// The model's own params after fitting.
    #[serde(with = "crate::json")]
    pub fitted_params: BTreeMap<String, f64>,
    /// The fit of the model without effects: uncertainty, criteria, cost.
    pub base_fit: FitSummary,
    /// Initial values of measured states not measured at an experiment's first row.
    pub initial_states: Vec<InitialState>,
    /// What was fitted and what was scored.
    pub split: SplitSummary,
    /// Where the time went.
    pub timing: Timing,
    /// Set when the diagnosis was stopped (Ctrl-C, SIGTERM) before its end: the phase it
    /// stopped in and what was not run. What it holds is the fits so far, not a verdict.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub partial: Option<String>,
    /// Data and runs of the scored experiments, for plots (not serialised).
    #[serde(skip)]
    pub series: Vec<ExperimentSeries>,
}

/// The error of one measured state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StateGap {
    /// State name.
    pub name: String,
    /// Its share of the held-out free-run error.
    #[serde(with = "crate::json")]
    pub share: f64,
    /// Free-run (online) mean squared z-scored error at its held-out cells (`None`: none).
    #[serde(with = "crate::json")]
    pub online: Option<f64>,
    /// One-step (offline) error at its held-out cells whose previous row is measured
    /// (`None`: no such cell).
    #[serde(with = "crate::json")]
    pub offline: Option<f64>,
    /// Its measurement noise variance, normalised.
    #[serde(with = "crate::json")]
    pub noise: f64,
    /// Where that noise comes from (declared, or how it was estimated and how uncertain).
    #[serde(default)]
    pub noise_estimate: String,
    /// Held-out cells of this state.
    pub cells: usize,
}

/// What kind of place a locus is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, PartialOrd, Ord)]
#[serde(rename_all = "lowercase")]
pub enum LocusKind {
    /// A `let` (rate law).
    Let,
    /// Lets that share an input and a form, each corrected, fitted jointly.
    Group,
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
    /// The let's name, the group's members joined by `+`, or the state's for a balance.
    pub name: String,
    /// Its kind.
    pub kind: LocusKind,
    /// The corrected lets (or the balance's state).
    pub members: Vec<String>,
    /// Held-out gap with the best correction there.
    #[serde(with = "crate::json")]
    pub bound_after: f64,
    /// Held-out gap with a correction that sees the present only.
    #[serde(with = "crate::json")]
    pub bound_present: f64,
    /// Held-out gap with a correction that also sees the history.
    #[serde(with = "crate::json")]
    pub bound_history: f64,
    /// Whether the held-out data cannot tell this locus from the best one (block
    /// bootstrap; always true for the first).
    pub tied: bool,
    /// Lets between it and the balances it reaches (0 for a balance): larger is upstream.
    pub depth: usize,
    /// Seconds spent fitting and scoring its corrections.
    #[serde(with = "crate::json")]
    pub seconds: f64,
}

/// Whether closing the gap needs memory, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Memory {
    /// The verdict.
    pub history_needed: bool,
    /// Whether the free corrections alone decided it (at the best locus, history beats the
    /// present by the margin, see [`super::locus::HISTORY_MARGIN`]).
    pub probe: bool,
    /// The longest time constant of the history features, chosen from the data.
    #[serde(with = "crate::json")]
    pub span: f64,
    /// The time constants of the history features.
    #[serde(with = "crate::json")]
    pub time_constants: Vec<f64>,
    /// Why, in words.
    pub reason: String,
}

/// A time window of the held-out part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Window {
    /// The experiment.
    pub experiment: String,
    /// First measured time.
    #[serde(with = "crate::json")]
    pub t_start: f64,
    /// Last measured time.
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

pub use crate::solve::fit::FitSummary;
#[cfg(test)]
pub use crate::solve::fit::ParamEstimate;

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
    /// Fitted params: the effect's own and the model's.
    #[serde(with = "crate::json")]
    pub params: BTreeMap<String, f64>,
    /// The fit: uncertainty, criteria and cost.
    pub fit: FitSummary,
    /// Hidden states the effect adds.
    pub adds_hidden: Vec<String>,
    /// Share of bootstrap draws in which it is best.
    #[serde(with = "crate::json")]
    pub probability_best: f64,
    /// Standard error of its gap minus the best's (0 for the best).
    #[serde(with = "crate::json")]
    pub spread: f64,
    /// Whether the held-out data cannot tell it from the best.
    pub tied: bool,
}

/// One step of forward selection.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelectionStep {
    /// The effect this step adds.
    pub added: String,
    /// The effects applied together after it.
    pub effects: Vec<String>,
    /// Training gap of the set's fit.
    #[serde(with = "crate::json", default)]
    pub gap_train: f64,
    /// Held-out gap of the set.
    #[serde(with = "crate::json")]
    pub gap_after: f64,
    /// `1 - gap_after / gap_before`.
    #[serde(with = "crate::json")]
    pub shrink: f64,
    /// BIC of the set's fit minus the model's (negative: better).
    #[serde(with = "crate::json", default)]
    pub delta_bic: f64,
    /// Akaike's criterion of the set's fit.
    #[serde(with = "crate::json")]
    pub aic: f64,
    /// Schwarz's criterion of the set's fit.
    #[serde(with = "crate::json")]
    pub bic: f64,
    /// Fitted unknowns.
    pub unknowns: usize,
    /// Standard error of the held-out gap's decrease from the previous set.
    #[serde(with = "crate::json")]
    pub spread: f64,
    /// The other additions tried at this step, with their held-out gaps.
    #[serde(with = "crate::json")]
    pub alternatives: Vec<(String, f64)>,
    /// Whether the addition is credited.
    pub accepted: bool,
    /// Why it is credited or not, in words.
    pub reason: String,
    /// The set's fit (its params with their uncertainty): what a verdict that credits the
    /// set rests on, pairs included. Absent in reports written before it was kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitSummary>,
}

/// Forward selection over the effects.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Selection {
    /// Every set of effects fitted (alone, pairs, triples), best criterion first.
    pub steps: Vec<SelectionStep>,
    /// The candidates credited together: effects, and constants refitted (`refit NAME`).
    pub credited: Vec<String>,
    /// The constants among [`Selection::credited`] the data contradict (refitted), by name.
    #[serde(default)]
    pub refitted: Vec<String>,
    /// Held-out gap of the credited set (the gap before when none).
    #[serde(with = "crate::json")]
    pub gap_after: f64,
    /// The verdict and its reason, in words.
    pub stop: String,
    /// The criterion the choice was made by (computed without the held-out data).
    #[serde(default)]
    pub criterion: String,
    /// The combinations of effects tried (pairs, triples), `a + b`.
    #[serde(default)]
    pub combinations: Vec<String>,
    /// When the training data cannot decide: the sets between which (the best first).
    #[serde(default)]
    pub undecided: Vec<String>,
}

/// How sure the ranking of the single effects is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Confidence {
    /// Whether the best effect is told apart from every other one.
    pub separated: bool,
    /// `(gap after of the second - gap after of the first) / gap_before`.
    #[serde(with = "crate::json")]
    pub margin: f64,
    /// The margin's standard error (block bootstrap), in the same units.
    #[serde(with = "crate::json")]
    pub margin_error: f64,
    /// Share of bootstrap draws in which the best is best.
    #[serde(with = "crate::json")]
    pub probability_best: f64,
    /// The effects the held-out data cannot tell from the best (the best included).
    pub indistinguishable: Vec<String>,
    /// Blocks resampled.
    pub blocks: usize,
    /// Draws.
    pub resamples: usize,
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

/// A measured state's initial value that no cell gives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InitialState {
    /// The experiment.
    pub experiment: String,
    /// The state.
    pub state: String,
    /// Its value (under the model's fitted params).
    #[serde(with = "crate::json")]
    pub value: f64,
    /// `declared`, `fitted`, `first measured value` or `from the first row's observables`.
    pub origin: String,
}

/// One scored part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScoredPart {
    /// The experiment.
    pub experiment: String,
    /// First scored time.
    #[serde(with = "crate::json")]
    pub t_start: f64,
    /// Last scored time.
    #[serde(with = "crate::json")]
    pub t_end: f64,
    /// Scored rows with a measured cell.
    pub rows: usize,
}

/// Sizes of the split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplitSummary {
    /// Measured rows that train.
    pub train_rows: usize,
    /// Measured rows that are scored.
    pub test_rows: usize,
    /// Experiments with a training part.
    pub train_experiments: Vec<String>,
    /// The scored parts.
    pub scored: Vec<ScoredPart>,
    /// `tail` (the last share of each experiment) or `experiments` (whole ones).
    pub holdout: String,
    /// The share of a tail split.
    #[serde(with = "crate::json")]
    pub share: Option<f64>,
    /// The measured rows a part should have (`--min-rows`): a held-out part with fewer is
    /// scored, and its score said to rest on few rows.
    #[serde(default)]
    pub min_rows: usize,
}

impl SplitSummary {
    /// Whether the held-out score rests on fewer rows than [`SplitSummary::min_rows`].
    pub fn sparse(&self) -> bool {
        self.test_rows < self.min_rows
    }
}

/// Where the time went, in seconds of wall time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Timing {
    /// The whole diagnosis.
    #[serde(with = "crate::json")]
    pub total: f64,
    /// Fitting the model without effects.
    #[serde(with = "crate::json")]
    pub base_fit: f64,
    /// Fitting every effect alone.
    #[serde(with = "crate::json")]
    pub effects: f64,
    /// Forward selection beyond the first effect.
    #[serde(with = "crate::json")]
    pub selection: f64,
    /// The free corrections.
    #[serde(with = "crate::json")]
    pub loci: f64,
    /// Worker threads.
    pub jobs: usize,
}

/// One scored experiment's data and free runs, for plots.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ExperimentSeries {
    /// The experiment.
    pub name: String,
    /// Times of its rows (from its first row to its last scored one).
    pub times: Vec<f64>,
    /// First scored row.
    pub first_scored: usize,
    /// Measured-state names.
    pub names: Vec<String>,
    /// Units of the measured states and of time, where the model declares them.
    pub units: Vec<Option<String>>,
    /// The time unit.
    pub time_unit: Option<String>,
    /// Data cells, one column per measured state.
    pub data: Vec<Vec<Option<f64>>>,
    /// Free run of the fitted model, one column per measured state.
    pub before: Vec<Vec<f64>>,
    /// Free run with the credited effects (or the best one), if fitted.
    pub after: Option<Vec<Vec<f64>>>,
    /// What `after` applies.
    pub after_name: String,
    /// Per scored row: squared z-scored error summed over its cells (`None`: no cell).
    pub errors: Vec<Option<f64>>,
}
