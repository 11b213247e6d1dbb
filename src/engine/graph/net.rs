//! The grey-box network in one element type: closure MLPs with runtime sizes, the physics
//! program, and the RK4 (or discrete) step of the paper, recorded on a [`Graph`] once per
//! step of a batch (one step for one-step pairs, `K` for a rollout window).

use std::ops::DerefMut;
use std::sync::Arc;

use dfdx::tensor::Cpu;
use dfdx::tensor_ops::Device;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::layout::{
    check_setup, closure_layout, prepare, prepare_rollout, raw_initial_value, ClosureLayout, Frame,
    Prepared, PreparedStep,
};
use super::tape::{gradient_of, Element, GradientBuffer, Graph, LossBlock, Matrix, Scalar, Vector};
use crate::engine::batch::{Batch, Prediction, RolloutBatch};
use crate::engine::error::BackendError;
use crate::engine::program::Program;
#[cfg(test)]
use crate::engine::settings::StepSettings;
use crate::engine::setup::Setup;
use crate::ir::{self, Dynamics};
use crate::numeric::NamedTensor;
#[cfg(test)]
use crate::numeric::{Adam, AdamState};

mod forward;

/// Scale of the last layer's initial weights relative to Glorot's: zero, so that every
/// closure output starts at exactly its value at network output 0 (its prior, or 0 without
/// one; `docs/training.md`, "Starting from the mechanism"). The hidden layers start at
/// Glorot's scale; the first step's gradient reaches the last layer through their
/// activations and the rest through it.
pub const INIT_LAST_LAYER: f64 = 0.0;

/// The trainable grey-box network in element type `E`.
pub struct GreyBox<E: Element> {
    device: Cpu,
    program: Arc<Program>,
    balances: Arc<Vec<usize>>,
    /// Registers of the measured outputs (observables), in the normalisation's order.
    observables: Arc<Vec<usize>>,
    observable_inverse_std: Vec<E>,
    closures: Vec<ClosureLayout>,
    dynamics: Dynamics,
    step: f64,
    substeps: usize,
    inverse_std: Vec<E>,
    names: Vec<String>,
    shapes: Vec<Vec<usize>>,
    weights: Vec<Vec<E>>,
    /// The engine's own optimiser, for its tests (training steps through
    /// [`crate::engine::step::Optimiser`]).
    #[cfg(test)]
    adam: Adam<E>,
}

/// The weights of one pass as graph tensors.
struct Tensors<E: Element> {
    layers: Vec<Vec<(Matrix<E>, Vector<E>)>>,
    params: Option<Vector<E>>,
}

/// What a batch's forward pass yields: the predicted states after each step and the
/// register values of the first stage of the first step.
struct Forward<E: Element> {
    predictions: Vec<Matrix<E>>,
    /// Per step, the observables at the predicted state (none without observables).
    observations: Vec<Matrix<E>>,
    first_values: Arc<Vec<E>>,
}

impl<E: Element> GreyBox<E>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    /// Builds the network and initialises its weights from `setup.seed`.
    pub fn build(model: &ir::Model, setup: &Setup) -> Result<Self, BackendError> {
        check_setup(model, setup)?;
        let program = Program::compile(model, &setup.scales)?;
        let balances = Arc::new(program.balances.clone());
        let norm = &setup.normalisation;
        let observables = (norm.observables.iter())
            .map(|&output| {
                (program.outputs.get(output).copied())
                    .ok_or_else(|| BackendError::internal(format!("no output {output}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        if norm.observable_std.len() != observables.len() {
            return Err(BackendError::internal(
                "observables without their statistics",
            ));
        }
        let observable_inverse_std = (norm.observable_std.iter())
            .map(|&s| E::from_double(1.0 / s))
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(setup.seed);
        let (mut names, mut shapes, mut weights) = (Vec::new(), Vec::new(), Vec::new());
        let mut closures = Vec::new();
        for closure in &model.closures {
            let layout = closure_layout(model, closure, setup, names.len())?;
            let mut fan_in = layout.width;
            let widths = closure.network.hidden.iter().copied();
            let outputs = closure.outputs.len();
            for (layer, fan_out) in widths.chain([outputs]).enumerate() {
                let last = layer == layout.layers - 1;
                let limit = (6.0 / (fan_in + fan_out) as f64).sqrt()
                    * if last { INIT_LAST_LAYER } else { 1.0 };
                let prefix = format!("closure.{}.layer{layer}", closure.name);
                names.push(format!("{prefix}.weight"));
                shapes.push(vec![fan_in, fan_out]);
                weights.push(if limit == 0.0 {
                    vec![E::ZERO; fan_in * fan_out]
                } else {
                    (0..fan_in * fan_out)
                        .map(|_| E::from_double(rng.gen_range(-limit..=limit)))
                        .collect()
                });
                names.push(format!("{prefix}.bias"));
                shapes.push(vec![fan_out]);
                weights.push(vec![E::ZERO; fan_out]);
                fan_in = fan_out;
            }
            closures.push(layout);
        }
        if !model.params.is_empty() {
            names.push(crate::vocabulary::PARAMS_TENSOR.to_string());
            shapes.push(vec![model.params.len()]);
            weights.push(model.params.iter().map(raw_initial_value::<E>).collect());
        }
        let inverse_std = (setup.normalisation.state_std.iter())
            .map(|&s| E::from_double(1.0 / s))
            .collect();
        Ok(GreyBox {
            device: Cpu::default(),
            program: Arc::new(program),
            balances,
            observables: Arc::new(observables),
            observable_inverse_std,
            closures,
            dynamics: model.dynamics,
            step: setup.step,
            substeps: setup.substeps.max(1),
            inverse_std,
            names,
            shapes,
            #[cfg(test)]
            adam: Adam::new(weights.iter().map(Vec::len).sum()),
            weights,
        })
    }

    /// RK4 sub-steps per call.
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// The same network (program, weights, normalisation) taking `substeps` RK4 sub-steps
    /// per call, with a fresh optimiser: what a free run's step control calls once per
    /// sub-step of its own.
    pub fn with_substeps(&self, substeps: usize) -> Self {
        GreyBox {
            device: Cpu::default(),
            program: Arc::clone(&self.program),
            balances: Arc::clone(&self.balances),
            observables: Arc::clone(&self.observables),
            observable_inverse_std: self.observable_inverse_std.clone(),
            closures: self.closures.clone(),
            dynamics: self.dynamics,
            step: self.step,
            substeps: substeps.max(1),
            inverse_std: self.inverse_std.clone(),
            names: self.names.clone(),
            shapes: self.shapes.clone(),
            #[cfg(test)]
            adam: Adam::new(self.weights.iter().map(Vec::len).sum()),
            weights: self.weights.clone(),
        }
    }

    /// One Adam step on a one-step batch; returns the loss before it.
    #[cfg(test)]
    pub fn train_step(
        &mut self,
        batch: &Batch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        let (loss, gradients) = self.loss_and_gradient(|graph, this| this.prepare(graph, batch))?;
        self.update(gradients, settings);
        Ok(loss)
    }

    /// One Adam step on a rollout batch; returns the loss before it.
    #[cfg(test)]
    pub fn rollout_step(
        &mut self,
        batch: &RolloutBatch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        let (loss, gradients) =
            self.loss_and_gradient(|graph, this| this.prepare_rollout(graph, batch))?;
        self.update(gradients, settings);
        Ok(loss)
    }

    /// Clips the gradient's global norm (when asked) and takes the Adam step, params at
    /// their own learning rate ([`crate::numeric::Adam`], on the tensors back to back).
    #[cfg(test)]
    fn update(&mut self, gradients: Vec<Vec<E>>, settings: &StepSettings) {
        let size: usize = self.weights.iter().map(Vec::len).sum();
        let params = (self.names.last())
            .filter(|n| *n == crate::vocabulary::PARAMS_TENSOR)
            .and_then(|_| self.weights.last())
            .map(|p| size - p.len()..size);
        let mut flat = self.weights.concat();
        let mut gradient = gradients.concat();
        settings.adam_step(&mut self.adam, &mut flat, &mut gradient, params);
        let mut values = flat.into_iter();
        for tensor in &mut self.weights {
            tensor.iter_mut().zip(&mut values).for_each(|(w, v)| *w = v);
        }
    }

    /// The loss of a one-step batch.
    pub fn loss(&self, batch: &Batch) -> Result<f64, BackendError> {
        self.value_of(|graph, this| this.prepare(graph, batch))
    }

    /// The loss of a rollout batch.
    pub fn rollout_loss(&self, batch: &RolloutBatch) -> Result<f64, BackendError> {
        self.value_of(|graph, this| this.prepare_rollout(graph, batch))
    }

    fn value_of(
        &self,
        prepare: impl FnOnce(&Graph<E>, &Self) -> Result<Prepared<E>, BackendError>,
    ) -> Result<f64, BackendError> {
        let mut graph = Graph::new(&self.device);
        let prepared = prepare(&graph, self)?;
        let (_, loss) = self.record_loss(&mut graph, &prepared)?;
        Ok(loss.as_vec()[0].to_double())
    }

    /// Records the forward pass and the loss of a prepared batch on `graph`.
    fn record_loss(
        &self,
        graph: &mut Graph<E>,
        prepared: &Prepared<E>,
    ) -> Result<(Tensors<E>, Scalar<E>), BackendError> {
        let measured = self.inverse_std.len();
        for step in &prepared.steps {
            if step.targets.len() != prepared.rows * measured {
                return Err(BackendError::internal(format!(
                    "batch targets have {} values, expected {}",
                    step.targets.len(),
                    prepared.rows * measured
                )));
            }
        }
        let tensors = self.tensors(graph);
        let forward = self.forward(graph, &tensors, prepared)?;
        let mut blocks: Vec<LossBlock<E>> = (forward.predictions.iter())
            .zip(&prepared.steps)
            .map(|(prediction, step)| LossBlock {
                prediction,
                targets: &step.targets,
                weights: step.weights.as_deref(),
                inverse_std: &self.inverse_std,
            })
            .collect();
        for (observation, step) in forward.observations.iter().zip(&prepared.steps) {
            blocks.push(LossBlock {
                prediction: observation,
                targets: &step.observed,
                weights: Some(&step.observed_weights),
                inverse_std: &self.observable_inverse_std,
            });
        }
        let loss = graph.normalised_mse(&blocks)?;
        Ok((tensors, loss))
    }

    /// The loss of a one-step batch and its gradient per weight tensor, as `f64`.
    pub fn gradient(&self, batch: &Batch) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        let (loss, gradients) = self.loss_and_gradient(|graph, this| this.prepare(graph, batch))?;
        Ok((loss, to_double(gradients)))
    }

    /// The loss of a rollout batch and its gradient per weight tensor, as `f64`.
    pub fn rollout_gradient(
        &self,
        batch: &RolloutBatch,
    ) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        let (loss, gradients) =
            self.loss_and_gradient(|graph, this| this.prepare_rollout(graph, batch))?;
        Ok((loss, to_double(gradients)))
    }

    fn loss_and_gradient(
        &self,
        prepare: impl FnOnce(&Graph<E>, &Self) -> Result<Prepared<E>, BackendError>,
    ) -> Result<(f64, Vec<Vec<E>>), BackendError> {
        let mut graph = Graph::new(&self.device);
        let prepared = prepare(&graph, self)?;
        let (tensors, loss) = self.record_loss(&mut graph, &prepared)?;
        let value = loss.as_vec()[0].to_double();
        let mut grads = graph.backward(loss)?;
        let mut gradients = Vec::with_capacity(self.weights.len());
        for layers in &tensors.layers {
            for (weight, bias) in layers {
                gradients.push(gradient_of(&mut grads, weight)?);
                gradients.push(gradient_of(&mut grads, bias)?);
            }
        }
        if let Some(params) = &tensors.params {
            gradients.push(gradient_of(&mut grads, params)?);
        }
        Ok((value, gradients))
    }

    /// One-step predictions with the closure and model outputs at `t`.
    pub fn predict(&self, batch: &Batch) -> Result<Prediction, BackendError> {
        let mut graph = Graph::new(&self.device);
        let tensors = self.tensors(&graph);
        let prepared = self.prepare(&graph, batch)?;
        let forward = self.forward(&mut graph, &tensors, &prepared)?;
        let rows = prepared.rows;
        let values = &forward.first_values;
        let next = (forward.predictions.first())
            .ok_or_else(|| BackendError::internal("a one-step batch without a step"))?;
        Ok(Prediction {
            next_states: block_to_double(next.as_vec()),
            closure_outputs: block_to_double(self.program.read(
                values,
                rows,
                &self.program.closure_outputs,
            )),
            outputs: block_to_double(self.program.read(values, rows, &self.program.outputs)),
            observed: (forward.observations.first())
                .map_or(Vec::new(), |o| block_to_double(o.as_vec())),
        })
    }

    /// The states predicted after each step of a rollout batch, `[step]` of
    /// `rows x (measured + hidden)`.
    pub fn rollout_predict(&self, batch: &RolloutBatch) -> Result<Vec<Vec<f64>>, BackendError> {
        let mut graph = Graph::new(&self.device);
        let tensors = self.tensors(&graph);
        let prepared = self.prepare_rollout(&graph, batch)?;
        let forward = self.forward(&mut graph, &tensors, &prepared)?;
        Ok((forward.predictions.into_iter())
            .map(|p| block_to_double(p.as_vec()))
            .collect())
    }

    /// The trainable tensors as named `f64` arrays.
    pub fn weights(&self) -> Vec<NamedTensor> {
        (self.names.iter().zip(&self.shapes).zip(&self.weights))
            .map(|((name, shape), values)| NamedTensor {
                name: name.clone(),
                shape: shape.clone(),
                values: values.iter().map(|v| v.to_double()).collect(),
            })
            .collect()
    }

    /// Replaces the trainable tensors after checking names and shapes.
    pub fn set_weights(&mut self, weights: &[NamedTensor]) -> Result<(), BackendError> {
        if weights.len() != self.names.len() {
            return Err(BackendError::WeightsMismatch(format!(
                "{} tensors where the model has {}",
                weights.len(),
                self.names.len()
            )));
        }
        for ((tensor, name), shape) in weights.iter().zip(&self.names).zip(&self.shapes) {
            let length: usize = shape.iter().product();
            if &tensor.name != name || &tensor.shape != shape || tensor.values.len() != length {
                return Err(BackendError::WeightsMismatch(format!(
                    "`{}` {:?} where the model has `{name}` {shape:?}",
                    tensor.name, tensor.shape
                )));
            }
        }
        self.weights = (weights.iter())
            .map(|t| t.values.iter().map(|&v| E::from_double(v)).collect())
            .collect();
        Ok(())
    }

    /// Replaces the trainable values from one flat vector (tensors back to back, as
    /// [`GreyBox::weights`] lists them).
    pub fn set_flat_weights(&mut self, flat: &[f64]) -> Result<(), BackendError> {
        let size: usize = self.weights.iter().map(Vec::len).sum();
        if flat.len() != size {
            return Err(BackendError::WeightsMismatch(format!(
                "{} values where the model has {size}",
                flat.len()
            )));
        }
        let mut values = flat.iter();
        for tensor in &mut self.weights {
            for (slot, &value) in tensor.iter_mut().zip(&mut values) {
                *slot = E::from_double(value);
            }
        }
        Ok(())
    }

    /// Adam's step count and moments.
    #[cfg(test)]
    pub fn adam_state(&self) -> AdamState {
        self.adam.state(&self.lengths())
    }

    #[cfg(test)]
    fn lengths(&self) -> Vec<usize> {
        self.weights.iter().map(Vec::len).collect()
    }

    /// Replaces Adam's step count and moments.
    #[cfg(test)]
    pub fn set_adam_state(&mut self, state: &AdamState) -> Result<(), BackendError> {
        (self.adam.set_state(state, &self.lengths())).map_err(BackendError::WeightsMismatch)
    }

    /// Constrained param values.
    pub fn param_values(&self) -> Vec<f64> {
        if self.program.param_values.is_empty() {
            return Vec::new();
        }
        let raw: Vec<E> = self.weights[self.weights.len() - 1].clone();
        let nets: Vec<Vec<E>> = (self.program.shape().nets.iter())
            .map(|&n| vec![E::ZERO; n])
            .collect();
        let net_slices: Vec<&[E]> = nets.iter().map(Vec::as_slice).collect();
        let states = vec![E::ZERO; self.program.shape().states];
        let inputs = vec![E::ZERO; self.program.shape().inputs];
        let values = self
            .program
            .forward(&crate::engine::program::ProgramInputs {
                rows: 1,
                states: &states,
                inputs: &inputs,
                params: &raw,
                nets: &net_slices,
            });
        (self
            .program
            .read(&values, 1, &self.program.param_values)
            .into_iter())
        .map(|v| v.to_double())
        .collect()
    }
}

fn to_double<E: Element>(gradients: Vec<Vec<E>>) -> Vec<Vec<f64>> {
    gradients.into_iter().map(block_to_double).collect()
}

fn block_to_double<E: Element>(block: Vec<E>) -> Vec<f64> {
    block.into_iter().map(|v| v.to_double()).collect()
}
