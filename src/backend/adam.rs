//! Adam (Kingma & Ba 2015) on host-side weight vectors, as in the paper's training.

use super::real::Real;

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
}
