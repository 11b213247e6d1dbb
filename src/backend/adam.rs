//! Adam (Kingma & Ba 2015) on host-side weight vectors, as in the paper's training.

use super::real::Real;
use super::BackendError;

/// Adam's state (Kingma & Ba 2015) as plain `f64` data: the number of steps taken and the
/// first- and second-moment estimates of every tensor, in [`super::Network::weights`] order. What
/// one training engine hands to the other so that training goes on where it was, bias
/// correction included; [`super::Network::adam_state`] and `FusedNetwork::adam_state` give it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AdamState {
    /// Adam steps taken so far.
    pub steps: u64,
    /// First-moment estimate of each tensor.
    pub first: Vec<Vec<f64>>,
    /// Second-moment estimate of each tensor.
    pub second: Vec<Vec<f64>>,
}

impl AdamState {
    /// Checks that the state fits tensors of `lengths` and returns its step count as the
    /// exponent of the bias correction.
    pub fn check(&self, lengths: &[usize]) -> Result<i32, BackendError> {
        let fits = |moments: &[Vec<f64>]| {
            moments.len() == lengths.len()
                && moments.iter().zip(lengths).all(|(m, &n)| m.len() == n)
        };
        if !fits(&self.first) || !fits(&self.second) {
            return Err(BackendError::WeightsMismatch(format!(
                "adam moments of sizes {:?} where the model's tensors have {lengths:?}",
                self.first.iter().map(Vec::len).collect::<Vec<_>>()
            )));
        }
        i32::try_from(self.steps).map_err(|_| {
            BackendError::WeightsMismatch(format!("adam state after {} steps", self.steps))
        })
    }
}

/// First- and second-moment estimates of every weight tensor.
#[derive(Debug, Clone)]
pub struct Adam<E> {
    first: Vec<Vec<E>>,
    second: Vec<Vec<E>>,
    steps: i32,
}

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPSILON: f64 = 1e-8;

impl<E: Real> Adam<E> {
    /// Zero moments for tensors of the given lengths.
    pub fn new(lengths: impl Iterator<Item = usize>) -> Self {
        let first: Vec<Vec<E>> = lengths.map(|n| vec![E::ZERO; n]).collect();
        let second = first.clone();
        Adam {
            first,
            second,
            steps: 0,
        }
    }

    /// The step count and moments as plain `f64` data.
    pub fn state(&self) -> AdamState {
        let to_double = |moments: &[Vec<E>]| -> Vec<Vec<f64>> {
            (moments.iter())
                .map(|m| m.iter().map(|v| v.to_double()).collect())
                .collect()
        };
        AdamState {
            steps: u64::try_from(self.steps).unwrap_or(0),
            first: to_double(&self.first),
            second: to_double(&self.second),
        }
    }

    /// Replaces the step count and moments (sizes must match the tensors').
    pub fn set_state(&mut self, state: &AdamState) -> Result<(), BackendError> {
        let lengths: Vec<usize> = self.first.iter().map(Vec::len).collect();
        self.steps = state.check(&lengths)?;
        let from_double = |moments: &[Vec<f64>]| -> Vec<Vec<E>> {
            (moments.iter())
                .map(|m| m.iter().map(|&v| E::from_double(v)).collect())
                .collect()
        };
        self.first = from_double(&state.first);
        self.second = from_double(&state.second);
        Ok(())
    }

    /// One bias-corrected update of `weights` along `gradients`, tensor `i` at learning
    /// rate `learning_rates[i]`.
    pub fn update(&mut self, weights: &mut [Vec<E>], gradients: &[Vec<E>], learning_rates: &[f64]) {
        self.steps += 1;
        let correction1 = 1.0 - BETA1.powi(self.steps);
        let correction2 = 1.0 - BETA2.powi(self.steps);
        let epsilon = E::from_double(EPSILON * correction2.sqrt());
        let (beta1, beta2) = (E::from_double(BETA1), E::from_double(BETA2));
        let (keep1, keep2) = (E::from_double(1.0 - BETA1), E::from_double(1.0 - BETA2));
        for (tensor, gradient) in gradients.iter().enumerate() {
            let rate = learning_rates.get(tensor).copied().unwrap_or(0.0);
            let step = E::from_double(rate * correction2.sqrt() / correction1);
            let first = &mut self.first[tensor];
            let second = &mut self.second[tensor];
            for (index, &g) in gradient.iter().enumerate() {
                first[index] = beta1 * first[index] + keep1 * g;
                second[index] = beta2 * second[index] + keep2 * g * g;
                weights[tensor][index] =
                    weights[tensor][index] - step * first[index] / (second[index].sqrt() + epsilon);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook form: m_hat / (sqrt(v_hat) + eps) with explicit bias correction.
    fn reference_steps(gradients: &[f64], learning_rate: f64) -> f64 {
        let (mut weight, mut m, mut v) = (1.0, 0.0, 0.0);
        for (t, &g) in gradients.iter().enumerate() {
            m = BETA1 * m + (1.0 - BETA1) * g;
            v = BETA2 * v + (1.0 - BETA2) * g * g;
            let m_hat = m / (1.0 - BETA1.powi(t as i32 + 1));
            let v_hat = v / (1.0 - BETA2.powi(t as i32 + 1));
            weight -= learning_rate * m_hat / (v_hat.sqrt() + EPSILON);
        }
        weight
    }

    #[test]
    fn matches_the_textbook_update() {
        let gradients = [0.3, -1.2, 0.05, 2.0, 0.0];
        let mut adam = Adam::<f64>::new([1].into_iter());
        let mut weights = vec![vec![1.0]];
        for &g in &gradients {
            adam.update(&mut weights, &[vec![g]], &[0.01]);
        }
        let expected = reference_steps(&gradients, 0.01);
        assert!((weights[0][0] - expected).abs() < 1e-12);
        // The first step moves by about the learning rate whatever the gradient's size.
        let mut fresh = Adam::<f64>::new([1].into_iter());
        let mut weight = vec![vec![0.0]];
        fresh.update(&mut weight, &[vec![1e-4]], &[0.01]);
        assert!((weight[0][0] + 0.01).abs() < 1e-6);
    }

    #[test]
    fn a_restored_state_goes_on_where_the_saved_one_was() {
        let gradients = [0.3, -1.2, 0.05, 2.0, 0.0];
        let mut saved = Adam::<f64>::new([1].into_iter());
        let mut weights = vec![vec![1.0]];
        for &g in &gradients[..2] {
            saved.update(&mut weights, &[vec![g]], &[0.01]);
        }
        let state = saved.state();
        assert_eq!(state.steps, 2);
        let mut restored = Adam::<f64>::new([1].into_iter());
        restored.set_state(&state).unwrap();
        for &g in &gradients[2..] {
            restored.update(&mut weights, &[vec![g]], &[0.01]);
        }
        let expected = reference_steps(&gradients, 0.01);
        assert!((weights[0][0] - expected).abs() < 1e-12);
        let wrong = AdamState {
            first: vec![vec![0.0; 2]],
            ..state
        };
        assert!(restored.set_state(&wrong).is_err());
    }
}
