//! Adam (Kingma & Ba 2015) with per-group learning rates and global-norm gradient
//! clipping, on one flat vector of weights: the one optimiser of training. Both engines (the
//! dfdx graph in `crate::engine::graph`, the hand-fused step in `crate::engine::fused`) call it; neither
//! keeps constants, bias correction or clipping of its own.

use std::ops::Range;

use super::real::Real;

/// Decay of the first-moment estimate.
pub const BETA1: f64 = 0.9;
/// Decay of the second-moment estimate.
pub const BETA2: f64 = 0.999;
/// The denominator's offset (on the bias-corrected second moment).
pub const EPSILON: f64 = 1e-8;

/// Adam's state as plain `f64` data: the number of steps taken and the first- and
/// second-moment estimates cut into tensors (in the engine's weight order).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct AdamState {
    /// Adam steps taken so far.
    pub steps: u64,
    /// First-moment estimate of each tensor.
    pub first: Vec<Vec<f64>>,
    /// Second-moment estimate of each tensor.
    pub second: Vec<Vec<f64>>,
}

/// What one optimiser step does besides the gradient: the learning rate of each run of the
/// flat weight vector and the optional clipping norm.
#[derive(Debug, Clone, PartialEq)]
pub struct Update<'a> {
    /// `(range, learning rate)` of consecutive runs of weights; weights outside every range
    /// stay where they are.
    pub groups: &'a [(Range<usize>, f64)],
    /// Rescale the whole gradient to at most this Euclidean norm (none: no clipping).
    pub max_gradient_norm: Option<f64>,
}

/// First- and second-moment estimates of a flat weight vector.
#[derive(Debug, Clone)]
pub struct Adam<E> {
    first: Vec<E>,
    second: Vec<E>,
    steps: i32,
}

impl<E: Real> Adam<E> {
    /// Zero moments for `size` weights.
    pub fn new(size: usize) -> Self {
        Adam {
            first: vec![E::ZERO; size],
            second: vec![E::ZERO; size],
            steps: 0,
        }
    }

    /// The step count and moments as plain `f64` data, cut into tensors of `lengths`.
    pub fn state(&self, lengths: &[usize]) -> AdamState {
        AdamState {
            steps: u64::try_from(self.steps).unwrap_or(0),
            first: cut(&self.first, lengths),
            second: cut(&self.second, lengths),
        }
    }

    /// Replaces the step count and moments; the state must hold tensors of `lengths`
    /// adding up to this optimiser's size. The error says what does not fit.
    pub fn set_state(&mut self, state: &AdamState, lengths: &[usize]) -> Result<(), String> {
        let fits = |moments: &[Vec<f64>]| {
            moments.len() == lengths.len()
                && moments.iter().zip(lengths).all(|(m, &n)| m.len() == n)
        };
        if !fits(&state.first)
            || !fits(&state.second)
            || lengths.iter().sum::<usize>() != self.first.len()
        {
            return Err(format!(
                "adam moments of sizes {:?} where the model's tensors have {lengths:?}",
                state.first.iter().map(Vec::len).collect::<Vec<_>>()
            ));
        }
        self.steps = i32::try_from(state.steps)
            .map_err(|_| format!("adam state after {} steps", state.steps))?;
        let flatten = |moments: &[Vec<f64>]| -> Vec<E> {
            (moments.iter().flatten())
                .map(|&v| E::from_double(v))
                .collect()
        };
        self.first = flatten(&state.first);
        self.second = flatten(&state.second);
        Ok(())
    }

    /// Clips `gradient` as `update` asks ([`clip`]) and takes one bias-corrected step of
    /// `weights` along it, each group at its own learning rate.
    pub fn step(&mut self, weights: &mut [E], gradient: &mut [E], update: &Update) {
        if let Some(limit) = update.max_gradient_norm {
            clip(gradient, limit);
        }
        self.steps += 1;
        let correction1 = 1.0 - BETA1.powi(self.steps);
        let correction2 = 1.0 - BETA2.powi(self.steps);
        let epsilon = E::from_double(EPSILON * correction2.sqrt());
        let (beta1, beta2) = (E::from_double(BETA1), E::from_double(BETA2));
        let (keep1, keep2) = (E::from_double(1.0 - BETA1), E::from_double(1.0 - BETA2));
        for (range, rate) in update.groups {
            // A group at rate 0 is held: it never moves, not even by a non-finite gradient.
            if *rate == 0.0 {
                continue;
            }
            let step = E::from_double(rate * correction2.sqrt() / correction1);
            let (Some(weights), Some(gradient), Some(first), Some(second)) = (
                weights.get_mut(range.clone()),
                gradient.get(range.clone()),
                self.first.get_mut(range.clone()),
                self.second.get_mut(range.clone()),
            ) else {
                continue;
            };
            for (((weight, &g), first), second) in
                (weights.iter_mut()).zip(gradient).zip(first).zip(second)
            {
                *first = beta1 * *first + keep1 * g;
                *second = beta2 * *second + keep2 * g * g;
                *weight = *weight - step * *first / (second.sqrt() + epsilon);
            }
        }
    }
}

/// Rescales `gradient` to Euclidean norm `limit` when it is longer and finite (the norm
/// summed in `f64` in order); the one gradient clipping of training.
pub fn clip<E: Real>(gradient: &mut [E], limit: f64) {
    let norm = (gradient.iter())
        .map(|g| g.to_double().powi(2))
        .sum::<f64>()
        .sqrt();
    if norm > limit && norm.is_finite() {
        let factor = E::from_double(limit / norm);
        gradient.iter_mut().for_each(|g| *g = *g * factor);
    }
}

/// A flat vector cut into consecutive tensors of `lengths`, as `f64`.
fn cut<E: Real>(flat: &[E], lengths: &[usize]) -> Vec<Vec<f64>> {
    let mut start = 0;
    (lengths.iter())
        .map(|&n| {
            let end = (start + n).min(flat.len());
            let part = flat[start.min(end)..end].iter().map(|v| v.to_double());
            start += n;
            part.collect()
        })
        .collect()
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

    fn plain(rate: f64) -> [(Range<usize>, f64); 1] {
        [(0..1, rate)]
    }

    #[test]
    fn matches_the_textbook_update() {
        let gradients = [0.3, -1.2, 0.05, 2.0, 0.0];
        let mut adam = Adam::<f64>::new(1);
        let mut weights = vec![1.0];
        let groups = plain(0.01);
        let update = Update {
            groups: &groups,
            max_gradient_norm: None,
        };
        for &g in &gradients {
            adam.step(&mut weights, &mut [g], &update);
        }
        let expected = reference_steps(&gradients, 0.01);
        assert!((weights[0] - expected).abs() < 1e-12);
        // The first step moves by about the learning rate whatever the gradient's size.
        let mut fresh = Adam::<f64>::new(1);
        let mut weight = vec![0.0];
        fresh.step(&mut weight, &mut [1e-4], &update);
        assert!((weight[0] + 0.01).abs() < 1e-6);
    }

    #[test]
    fn groups_take_their_own_rates_and_weights_outside_stay() {
        let mut adam = Adam::<f64>::new(3);
        let mut weights = vec![0.0; 3];
        let groups = [(0..1, 0.01), (1..2, 0.1)];
        let update = Update {
            groups: &groups,
            max_gradient_norm: None,
        };
        adam.step(&mut weights, &mut [1.0, 1.0, 1.0], &update);
        assert!((weights[0] + 0.01).abs() < 1e-9);
        assert!((weights[1] + 0.1).abs() < 1e-8);
        assert_eq!(weights[2], 0.0);
    }

    #[test]
    fn clipping_rescales_long_gradients_only() {
        let mut long = [3.0_f64, 4.0];
        clip(&mut long, 1.0);
        assert!((long[0] - 0.6).abs() < 1e-15 && (long[1] - 0.8).abs() < 1e-15);
        let mut short = [0.3_f32, 0.4];
        clip(&mut short, 1.0);
        assert_eq!(short, [0.3, 0.4]);
        let mut infinite = [f64::INFINITY, 1.0];
        clip(&mut infinite, 1.0);
        assert_eq!(infinite[1], 1.0);
    }

    #[test]
    fn a_restored_state_goes_on_where_the_saved_one_was() {
        let gradients = [0.3, -1.2, 0.05, 2.0, 0.0];
        let groups = plain(0.01);
        let update = Update {
            groups: &groups,
            max_gradient_norm: None,
        };
        let mut saved = Adam::<f64>::new(1);
        let mut weights = vec![1.0];
        for &g in &gradients[..2] {
            saved.step(&mut weights, &mut [g], &update);
        }
        let state = saved.state(&[1]);
        assert_eq!(state.steps, 2);
        let mut restored = Adam::<f64>::new(1);
        restored.set_state(&state, &[1]).unwrap();
        for &g in &gradients[2..] {
            restored.step(&mut weights, &mut [g], &update);
        }
        let expected = reference_steps(&gradients, 0.01);
        assert!((weights[0] - expected).abs() < 1e-12);
        let wrong = AdamState {
            first: vec![vec![0.0; 2]],
            ..state
        };
        assert!(restored.set_state(&wrong, &[1]).is_err());
    }
}
