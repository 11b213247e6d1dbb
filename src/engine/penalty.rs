//! The penalty toward the mechanism (`--toward-mechanism STRENGTH`, `crate::train::toward`)
//! over a network's flat weight vector: what the one [`super::step::Optimiser`] adds to every
//! step of either engine.

use std::ops::Range;

use crate::ir;
use crate::numeric::NamedTensor;

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

    /// The penalty's gradient is the derivative of its value (central differences), it
    /// reaches the last layers and the params only, and vanishes at the start.
    #[test]
    fn the_penalty_pulls_the_last_layer_to_zero_and_the_params_to_their_start() {
        use crate::ir::Activation;
        let model = crate::engine::fixtures::kitchen_sink(Activation::Tanh);
        let setup = crate::engine::fixtures::setup(&model, crate::engine::graph::Precision::F64, 1);
        let network = crate::engine::graph::Network::build(&model, &setup).unwrap();
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
