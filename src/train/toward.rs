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
//! [`super::step::Optimiser`], so that both engines train under it. The loss is a mean
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

use std::ops::Range;

use crate::backend::NamedTensor;
use crate::ir;

mod choice;
mod distance;
pub use choice::{choose, Candidate, ChoiceEvent, StopChoice};
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

/// The penalty of a strength over a network's flat weight vector.
#[derive(Debug, Clone, PartialEq)]
pub struct Penalty {
    strength: f64,
    /// Where each closure's last layer (weights, then biases) sits.
    last: Vec<Range<usize>>,
    /// Where the params sit, and their raw values at the start.
    params: Option<(Range<usize>, Vec<f64>)>,
}

impl Penalty {
    /// The penalty of `strength` on the network of `model` whose tensors are `tensors`
    /// (in flat order), the params pulled toward `start` (their raw values).
    pub fn new(model: &ir::Model, tensors: &[NamedTensor], strength: f64, start: &[f64]) -> Self {
        let last_names: Vec<String> = (model.closures.iter())
            .flat_map(|c| {
                let prefix = format!("closure.{}.layer{}", c.name, c.network.hidden.len());
                [format!("{prefix}.weight"), format!("{prefix}.bias")]
            })
            .collect();
        let (mut last, mut params, mut at) = (Vec::new(), None, 0);
        for tensor in tensors {
            let range = at..at + tensor.values.len();
            if last_names.contains(&tensor.name) {
                last.push(range.clone());
            } else if tensor.name == crate::vocabulary::PARAMS_TENSOR && start.len() == range.len()
            {
                params = Some((range.clone(), start.to_vec()));
            }
            at = range.end;
        }
        Penalty {
            strength,
            last,
            params,
        }
    }

    /// Whether it pulls at all.
    pub fn is_active(&self) -> bool {
        self.strength > 0.0
    }

    /// Adds the penalty's gradient at `weights` to `gradient`; returns the penalty.
    pub fn add(&self, weights: &[f64], gradient: &mut [f64]) -> f64 {
        if !self.is_active() {
            return 0.0;
        }
        let count: usize = self.last.iter().map(|r| r.len()).sum();
        let mut penalty = 0.0;
        if count > 0 {
            let factor = self.strength / count as f64;
            for range in &self.last {
                for i in range.clone() {
                    penalty += 0.5 * factor * weights[i] * weights[i];
                    gradient[i] += factor * weights[i];
                }
            }
        }
        if let Some((range, start)) = self.params.as_ref().filter(|(r, _)| !r.is_empty()) {
            let factor = self.strength / range.len() as f64;
            for (i, theta0) in range.clone().zip(start) {
                let moved = weights[i] - theta0;
                penalty += 0.5 * factor * moved * moved;
                gradient[i] += factor * moved;
            }
        }
        penalty
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

    /// The penalty's gradient is the derivative of its value (central differences), it
    /// reaches the last layers and the params only, and vanishes at the start.
    #[test]
    fn the_penalty_pulls_the_last_layer_to_zero_and_the_params_to_their_start() {
        use crate::ir::Activation;
        let model = crate::train::fixtures::kitchen_sink(Activation::Tanh);
        let setup = crate::train::fixtures::setup(&model, crate::backend::Precision::F64, 1);
        let network = crate::backend::Network::build(&model, &setup).unwrap();
        let tensors = network.weights();
        let start = network.weights().last().unwrap().values.clone();
        let penalty = Penalty::new(&model, &tensors, 0.3, &start);
        let flat: Vec<f64> = tensors.iter().flat_map(|t| t.values.clone()).collect();
        let mut gradient = vec![0.0; flat.len()];
        // A fresh network is the mechanism: nothing to pay.
        assert_eq!(penalty.add(&flat, &mut gradient), 0.0);
        assert!(gradient.iter().all(|&g| g == 0.0));
        let moved: Vec<f64> = (0..flat.len())
            .map(|i| flat[i] + 0.1 + 0.01 * i as f64)
            .collect();
        let value = penalty.add(&moved, &mut gradient);
        assert!(value > 0.0);
        let (mut at, mut touched) = (0, 0);
        for tensor in &tensors {
            let last = tensor.name.ends_with(".layer2.weight")
                || tensor.name.ends_with(".layer2.bias")
                || tensor.name == crate::vocabulary::PARAMS_TENSOR;
            for i in at..at + tensor.values.len() {
                let h = 1e-6;
                let (mut up, mut down) = (moved.clone(), moved.clone());
                up[i] += h;
                down[i] -= h;
                let mut scratch = vec![0.0; flat.len()];
                let numeric =
                    (penalty.add(&up, &mut scratch) - penalty.add(&down, &mut scratch)) / (2.0 * h);
                assert!(
                    (numeric - gradient[i]).abs() < 1e-8,
                    "{}: {numeric} vs {}",
                    tensor.name,
                    gradient[i]
                );
                assert_eq!(gradient[i] != 0.0, last, "{}", tensor.name);
                touched += usize::from(last);
            }
            at += tensor.values.len();
        }
        assert!(touched > 0);
    }
}
