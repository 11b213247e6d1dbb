//! The one interface between training and its engines, and the optimiser written once on
//! top of it.
//!
//! A [`Step`] is what an engine offers: given the weights (one flat vector, tensors back to
//! back in [`Network::weights`] order) and a batch (one-step pairs or rollout windows), the
//! loss and its flat gradient. Both engines run both kinds of batch: the graph backend
//! ([`Network`]) every model, the fused step ([`FusedNetwork`]) every model without measured
//! outputs, so a run stays on one engine from its first epoch to its last. The
//! [`Optimiser`] holds the weights and Adam's state in the run's precision and takes every
//! step ([`crate::numeric::Adam`]: bias correction, per-group learning rates, clipping),
//! whichever engine computed the gradient.

use std::ops::Range;

pub use crate::engine::batch::StepBatch;
use crate::engine::error::BackendError;
use crate::engine::fused::FusedNetwork;
use crate::engine::graph::Network;
use crate::engine::settings::StepSettings;
use crate::engine::setup::Precision;
use crate::numeric::{Adam, Real};

use super::penalty::Penalty;

/// An engine: the loss of a batch and its gradient at given weights.
pub trait Step {
    /// The loss of `batch` at the flat `weights`, its flat gradient written into
    /// `gradient` (kept by the caller from step to step).
    fn loss_and_gradient(
        &mut self,
        weights: &[f64],
        batch: StepBatch,
        gradient: &mut Vec<f64>,
    ) -> Result<f64, BackendError>;
}

impl Step for Network {
    fn loss_and_gradient(
        &mut self,
        weights: &[f64],
        batch: StepBatch,
        gradient: &mut Vec<f64>,
    ) -> Result<f64, BackendError> {
        self.set_flat_weights(weights)?;
        let (loss, tensors) = match batch {
            StepBatch::Pairs(batch) => self.gradient(batch)?,
            StepBatch::Windows(batch) => self.rollout_gradient(batch)?,
        };
        gradient.clear();
        gradient.extend(tensors.into_iter().flatten());
        Ok(loss)
    }
}

impl Step for FusedNetwork {
    fn loss_and_gradient(
        &mut self,
        weights: &[f64],
        batch: StepBatch,
        gradient: &mut Vec<f64>,
    ) -> Result<f64, BackendError> {
        self.set_flat_weights(weights)?;
        self.flat_gradient(batch, gradient)
    }
}

/// The weights and Adam's state of a run, in its precision; the one optimiser loop of
/// training.
#[derive(Clone)]
pub struct Optimiser {
    state: State,
    /// The weights as `f64` and the gradient, kept from step to step.
    buffers: (Vec<f64>, Vec<f64>),
    /// Where the params sit in the flat vector (none: the model has none).
    params: Option<Range<usize>>,
    /// The length of each of the network's tensors, in order (for Adam's state per tensor).
    lengths: Vec<usize>,
    /// The pull toward the mechanism, added to every step's loss and gradient (none: no
    /// pull).
    penalty: Option<Penalty>,
}

#[derive(Clone)]
enum State {
    Single(Vec<f32>, Adam<f32>),
    Double(Vec<f64>, Adam<f64>),
}

impl Optimiser {
    /// Starts from `network`'s weights with zero moments.
    pub fn new(network: &Network, precision: Precision) -> Self {
        let tensors = network.weights();
        let size: usize = tensors.iter().map(|t| t.values.len()).sum();
        let params = (tensors.last())
            .filter(|t| t.name == crate::vocabulary::PARAMS_TENSOR)
            .map(|t| size - t.values.len()..size);
        let flat = tensors.iter().flat_map(|t| t.values.iter().copied());
        let state = match precision {
            Precision::F32 => State::Single(flat.map(|v| v as f32).collect(), Adam::new(size)),
            Precision::F64 => State::Double(flat.collect(), Adam::new(size)),
        };
        let lengths = tensors.iter().map(|t| t.values.len()).collect();
        Optimiser {
            state,
            buffers: (Vec::new(), Vec::new()),
            params,
            lengths,
            penalty: None,
        }
    }

    /// Adds `penalty` to the loss and gradient of every step from now on
    /// (`crate::train::toward`); an inactive one is dropped.
    pub fn with_penalty(mut self, penalty: Penalty) -> Self {
        self.penalty = penalty.is_active().then_some(penalty);
        self
    }

    /// Continues from a resumed run's Adam step count and moments (none: a fresh start);
    /// their sizes must match the network's tensors.
    pub fn resumed(
        mut self,
        state: Option<&crate::numeric::AdamState>,
    ) -> Result<Self, BackendError> {
        let Some(state) = state else {
            return Ok(self);
        };
        let set = match &mut self.state {
            State::Single(_, adam) => adam.set_state(state, &self.lengths),
            State::Double(_, adam) => adam.set_state(state, &self.lengths),
        };
        set.map_err(BackendError::WeightsMismatch)?;
        Ok(self)
    }

    /// Adam's step count and moments, per tensor.
    pub fn adam_state(&self) -> crate::numeric::AdamState {
        match &self.state {
            State::Single(_, adam) => adam.state(&self.lengths),
            State::Double(_, adam) => adam.state(&self.lengths),
        }
    }

    /// The current weights, flat, as `f64` (exact in either precision).
    pub fn weights(&self) -> Vec<f64> {
        let mut flat = Vec::new();
        self.weights_into(&mut flat);
        flat
    }

    fn weights_into(&self, flat: &mut Vec<f64>) {
        flat.clear();
        match &self.state {
            State::Single(weights, _) => flat.extend(weights.iter().map(|&v| f64::from(v))),
            State::Double(weights, _) => flat.extend_from_slice(weights),
        }
    }

    /// One step on `batch`: the engine's gradient at the current weights, with the pull
    /// toward the mechanism's where there is one, clipped, then Adam with the params at
    /// their own learning rate; the loss (with the pull's penalty) before it.
    pub fn step(
        &mut self,
        engine: &mut dyn Step,
        batch: StepBatch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        let (mut flat, mut gradient) = std::mem::take(&mut self.buffers);
        self.weights_into(&mut flat);
        let mut loss = engine.loss_and_gradient(&flat, batch, &mut gradient);
        if let (Ok(value), Some(penalty)) = (loss.as_mut(), &self.penalty) {
            *value += penalty.add(&flat, &mut gradient);
        }
        if loss.is_ok() {
            match &mut self.state {
                State::Single(weights, adam) => {
                    update(weights, adam, &gradient, settings, &self.params)
                }
                State::Double(weights, adam) => {
                    update(weights, adam, &gradient, settings, &self.params)
                }
            }
        }
        self.buffers = (flat, gradient);
        loss
    }
}

fn update<E: Real>(
    weights: &mut [E],
    adam: &mut Adam<E>,
    gradient: &[f64],
    settings: &StepSettings,
    params: &Option<Range<usize>>,
) {
    let mut gradient: Vec<E> = gradient.iter().map(|&g| E::from_double(g)).collect();
    settings.adam_step(adam, weights, &mut gradient, params.clone());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fixtures::{kitchen_sink, random_batch, setup};
    use crate::engine::settings::TrainStep;
    use crate::ir::Activation;

    fn settings() -> StepSettings {
        StepSettings {
            learning_rate: 0.01,
            param_learning_rate: 0.003,
            max_gradient_norm: Some(0.5),
        }
    }

    /// The optimiser over the graph engine takes exactly the steps the graph network's own
    /// Adam takes (same arithmetic in the same precision), in both precisions.
    #[test]
    fn the_optimiser_steps_as_the_engines_own_adam() {
        let model = kitchen_sink(Activation::Softplus);
        for precision in [Precision::F32, Precision::F64] {
            let setup = setup(&model, precision, 1);
            let mut reference = Network::build(&model, &setup).unwrap();
            let mut engine = Network::build(&model, &setup).unwrap();
            let mut optimiser = Optimiser::new(&engine, precision);
            assert!(optimiser.params.is_some(), "the model has params");
            for seed in 0..4 {
                let batch = random_batch(&model, &setup, 6, seed);
                let expected = reference.train_step_with(&batch, &settings()).unwrap();
                let pairs = StepBatch::Pairs(&batch);
                let loss = optimiser.step(&mut engine, pairs, &settings()).unwrap();
                assert_eq!(loss, expected);
            }
            let flat: Vec<f64> = (reference.weights().iter())
                .flat_map(|t| t.values.clone())
                .collect();
            assert_eq!(optimiser.weights(), flat);
        }
    }

    /// The fused engine under the same optimiser follows the graph engine to rounding.
    #[test]
    fn the_fused_engine_follows_the_graph_engine_under_one_optimiser() {
        let model = kitchen_sink(Activation::Softplus);
        let setup = setup(&model, Precision::F64, 1);
        let mut graph = Network::build(&model, &setup).unwrap();
        let mut fused = FusedNetwork::build(&model, &setup).unwrap();
        let mut on_graph = Optimiser::new(&graph, Precision::F64);
        let mut on_fused = Optimiser::new(&graph, Precision::F64);
        for seed in 0..4 {
            let batch = random_batch(&model, &setup, 6, seed);
            let pairs = StepBatch::Pairs(&batch);
            let a = on_graph.step(&mut graph, pairs, &settings()).unwrap();
            let b = on_fused.step(&mut fused, pairs, &settings()).unwrap();
            assert!((a - b).abs() <= 1e-10 * a.abs(), "{a} vs {b}");
        }
        for (a, b) in on_graph.weights().iter().zip(on_fused.weights()) {
            assert!((a - b).abs() <= 1e-9 * (1.0 + a.abs()), "{a} vs {b}");
        }
    }
}
