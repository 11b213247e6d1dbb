//! Regularisation toward the mechanism (`--toward-mechanism`, `docs/training.md`,
//! "Starting from the mechanism").
//!
//! Every closure network's last layer starts at zero, where each closure output is its
//! prior (or 0 without one): a zero last layer *is* the mechanism, and the params start at
//! their fitted values. The penalty of strength `λ`,
//!
//! `λ/2 · mean over last-layer weights and biases of w²  +  λ/2 · mean over params of
//! (θ - θ₀)²`
//!
//! (`θ` the raw, unconstrained param values, `θ₀` their values at the start of training),
//! is added to the loss of every step and its gradient to the engine's, in the one
//! [`crate::engine::step::Optimiser`], so that both engines train under it. The loss is a mean
//! squared error of z-scored states (about 1 for a model that knows nothing, 1e-4 to 1e-2
//! for a good one), so `λ = 1e-2` charges a last layer whose weights have an RMS of 0.3 as
//! much as a mean squared error of `4.5e-4`.
//!
//! `auto` (the default) pulls by early stopping instead: training starts at the mechanism
//! and ends after the number of epochs that leave-one-experiment-out cross-validation over
//! the training experiments chose, 0 (the mechanism itself) when no training beats it on
//! the experiments it did not see ([`choice`], `docs/training.md`, "Starting from the
//! mechanism"). Early stopping from a start is the classic implicit form of the pull toward
//! it (Bishop 1995); it costs one training per fold, where a grid of strengths costs one
//! per fold and strength.

pub use crate::engine::penalty::Penalty;

mod choice;
mod distance;
pub use choice::{choose, ChoiceEvent, StopChoice};
pub use distance::{output_distances, param_distances, OutputDistance, ParamDistance};

/// What a run reports of its distance from the mechanism (`run.json` under
/// `toward_mechanism`, and the end-of-run summary).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MechanismDistance {
    /// The strength trained with.
    #[serde(with = "crate::json")]
    pub strength: f64,
    /// How `auto` chose where training stops (absent for a fixed strength).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub choice: Option<StopChoice>,
    /// Why `auto` chose nothing and trained without a pull (one training experiment, say).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unchosen: Option<String>,
    /// Each closure output's distance from its value at network output 0, over the
    /// training points.
    pub outputs: Vec<OutputDistance>,
    /// Each param's distance from its start.
    pub params: Vec<ParamDistance>,
}

/// The strength of the pull toward the mechanism.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TowardMechanism {
    /// A fixed strength `λ >= 0` (0: no pull).
    Strength(f64),
    /// Early stopping from the mechanism, the stop chosen by cross-validation over the
    /// training experiments ([`choose`]); no pull where it cannot be chosen.
    Auto,
}

impl TowardMechanism {
    /// The fixed strength (`None` for `auto`).
    pub fn strength(self) -> Option<f64> {
        match self {
            TowardMechanism::Strength(s) => Some(s),
            TowardMechanism::Auto => None,
        }
    }

    /// Whether the value is allowed: a finite strength `>= 0`, or `auto`.
    pub fn is_valid(self) -> bool {
        self.strength().is_none_or(|s| s.is_finite() && s >= 0.0)
    }
}

impl std::fmt::Display for TowardMechanism {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TowardMechanism::Strength(s) => write!(f, "{s}"),
            TowardMechanism::Auto => write!(f, "auto"),
        }
    }
}

impl std::str::FromStr for TowardMechanism {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        if text.trim() == "auto" {
            return Ok(TowardMechanism::Auto);
        }
        let value = TowardMechanism::Strength(text.trim().parse::<f64>().map_err(|_| {
            format!("`{text}` is neither `auto` nor a number (a strength such as 0.01)")
        })?);
        if value.is_valid() {
            Ok(value)
        } else {
            Err(format!("`{text}` is not a finite strength >= 0"))
        }
    }
}

impl serde::Serialize for TowardMechanism {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self {
            TowardMechanism::Strength(s) => serializer.serialize_f64(*s),
            TowardMechanism::Auto => serializer.serialize_str("auto"),
        }
    }
}

impl<'de> serde::Deserialize<'de> for TowardMechanism {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        #[derive(serde::Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(f64),
            Word(String),
        }
        match Raw::deserialize(deserializer)? {
            Raw::Number(s) => Ok(TowardMechanism::Strength(s)),
            Raw::Word(word) => word.parse().map_err(serde::de::Error::custom),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_strength_reads_and_writes_as_a_number_or_auto() {
        assert_eq!("auto".parse(), Ok(TowardMechanism::Auto));
        assert_eq!("0.01".parse(), Ok(TowardMechanism::Strength(0.01)));
        assert!("-1".parse::<TowardMechanism>().is_err());
        assert!("inf".parse::<TowardMechanism>().is_err());
        assert!("strong".parse::<TowardMechanism>().is_err());
        for value in [TowardMechanism::Auto, TowardMechanism::Strength(0.1)] {
            let text = serde_json::to_string(&value).unwrap();
            assert_eq!(
                serde_json::from_str::<TowardMechanism>(&text).unwrap(),
                value
            );
        }
        assert!(serde_json::from_str::<TowardMechanism>("\"strong\"").is_err());
    }
}
