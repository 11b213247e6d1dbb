//! The grey-box network in one element type: closure MLPs with runtime sizes, the physics
//! program, and the RK4 (or discrete) step of the paper, recorded on a [`Graph`].

use std::ops::DerefMut;
use std::sync::Arc;

use dfdx::tensor::Cpu;
use dfdx::tensor_ops::Device;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::adam::Adam;
use super::graph::{
    gradient_of, Element, GradientBuffer, Graph, Matrix, Scalar, StateColumns, Vector,
};
use super::program::{state_index, Program};
use super::real::{inverse_softplus, logit};
use super::{BackendError, Batch, NamedTensor, Prediction, Setup};
use crate::ir::{self, Activation, Constraint, Dynamics, Var};

/// Scale of the last layer's initial weights relative to Glorot's: small, so that a model
/// starts as its priors (spec section 3).
pub const INIT_LAST_LAYER: f64 = 1e-2;

/// The network-side description of one closure.
struct ClosureLayout {
    /// Network input width.
    width: usize,
    /// Where the stage estimate enters the input.
    state_columns: Arc<StateColumns>,
    /// Per input column: mean and std used for normalisation.
    column_mean: Vec<f64>,
    column_std: Vec<f64>,
    /// Which columns are lag-0 states (their constant part is `-mean/std`).
    is_stage_state: Vec<bool>,
    activation: Activation,
    /// Index of its first tensor in the weight list, and its number of affine layers.
    first_tensor: usize,
    layers: usize,
}

/// The trainable grey-box network in element type `E`.
pub struct GreyBox<E: Element> {
    device: Cpu,
    program: Arc<Program>,
    balances: Arc<Vec<usize>>,
    closures: Vec<ClosureLayout>,
    dynamics: Dynamics,
    step: f64,
    substeps: usize,
    inverse_std: Vec<E>,
    names: Vec<String>,
    shapes: Vec<Vec<usize>>,
    weights: Vec<Vec<E>>,
    adam: Adam<E>,
}

/// The weights of one pass as graph tensors.
struct Tensors<E: Element> {
    layers: Vec<Vec<(Matrix<E>, Vector<E>)>>,
    params: Option<Vector<E>>,
}

/// A batch converted to the element type.
struct Prepared<E: Element> {
    rows: usize,
    states: Matrix<E>,
    inputs: Arc<Vec<E>>,
    constants: Vec<Vec<Matrix<E>>>,
    targets: Vec<E>,
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
                weights.push(
                    (0..fan_in * fan_out)
                        .map(|_| E::from_double(rng.gen_range(-limit..=limit)))
                        .collect(),
                );
                names.push(format!("{prefix}.bias"));
                shapes.push(vec![fan_out]);
                weights.push(vec![E::ZERO; fan_out]);
                fan_in = fan_out;
            }
            closures.push(layout);
        }
        if !model.params.is_empty() {
            names.push("params".to_string());
            shapes.push(vec![model.params.len()]);
            weights.push(model.params.iter().map(raw_initial_value::<E>).collect());
        }
        let adam = Adam::new(weights.iter().map(Vec::len));
        let inverse_std = (setup.normalisation.state_std.iter())
            .map(|&s| E::from_double(1.0 / s))
            .collect();
        Ok(GreyBox {
            device: Cpu::default(),
            program: Arc::new(program),
            balances,
            closures,
            dynamics: model.dynamics,
            step: setup.step,
            substeps: setup.substeps.max(1),
            inverse_std,
            names,
            shapes,
            weights,
            adam,
        })
    }

    /// One Adam step; returns the loss before it.
    pub fn train_step(&mut self, batch: &Batch, learning_rate: f64) -> Result<f64, BackendError> {
        let (loss, gradients) = self.loss_and_gradient(batch)?;
        self.adam
            .update(&mut self.weights, &gradients, learning_rate);
        Ok(loss)
    }

    /// The loss of a batch.
    pub fn loss(&self, batch: &Batch) -> Result<f64, BackendError> {
        let mut graph = Graph::new(&self.device);
        let (_, loss) = self.record_loss(&mut graph, batch)?;
        Ok(loss.as_vec()[0].to_double())
    }

    /// Records the forward pass and the loss of a batch on `graph`.
    fn record_loss(
        &self,
        graph: &mut Graph<E>,
        batch: &Batch,
    ) -> Result<(Tensors<E>, Scalar<E>), BackendError> {
        let measured = self.inverse_std.len();
        if batch.targets.len() != batch.rows * measured {
            return Err(BackendError::internal(format!(
                "batch targets have {} values, expected {}",
                batch.targets.len(),
                batch.rows * measured
            )));
        }
        let tensors = self.tensors(graph);
        let prepared = self.prepare(graph, batch)?;
        let (next, _) = self.step(graph, &tensors, &prepared)?;
        let loss = graph.normalised_mse(&next, &prepared.targets, &self.inverse_std)?;
        Ok((tensors, loss))
    }

    /// The loss and its gradient per weight tensor, as `f64`.
    pub fn gradient(&self, batch: &Batch) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        let (loss, gradients) = self.loss_and_gradient(batch)?;
        let gradients = (gradients.iter())
            .map(|g| g.iter().map(|v| v.to_double()).collect())
            .collect();
        Ok((loss, gradients))
    }

    fn loss_and_gradient(&self, batch: &Batch) -> Result<(f64, Vec<Vec<E>>), BackendError> {
        let mut graph = Graph::new(&self.device);
        let (tensors, loss) = self.record_loss(&mut graph, batch)?;
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
        let (next, values) = self.step(&mut graph, &tensors, &prepared)?;
        let to_double = |block: Vec<E>| block.into_iter().map(|v| v.to_double()).collect();
        let rows = prepared.rows;
        Ok(Prediction {
            next_states: to_double(next.as_vec()),
            closure_outputs: to_double(self.program.read(
                &values,
                rows,
                &self.program.closure_outputs,
            )),
            outputs: to_double(self.program.read(&values, rows, &self.program.outputs)),
        })
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
        let values = self.program.forward(&super::program::ProgramInputs {
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

    fn tensors(&self, graph: &Graph<E>) -> Tensors<E> {
        let mut layers = Vec::with_capacity(self.closures.len());
        for closure in &self.closures {
            let mut closure_layers = Vec::with_capacity(closure.layers);
            for layer in 0..closure.layers {
                let index = closure.first_tensor + 2 * layer;
                let (rows, columns) = (self.shapes[index][0], self.shapes[index][1]);
                let weight = graph.matrix(rows, columns, self.weights[index].clone());
                let bias = graph.vector(self.weights[index + 1].clone());
                closure_layers.push((weight, bias));
            }
            layers.push(closure_layers);
        }
        let params = (self.names.last())
            .filter(|name| name.as_str() == "params")
            .map(|_| graph.vector(self.weights[self.weights.len() - 1].clone()));
        Tensors { layers, params }
    }

    fn prepare(&self, graph: &Graph<E>, batch: &Batch) -> Result<Prepared<E>, BackendError> {
        let rows = batch.rows;
        let shape = self.program.shape();
        let expect = |what: &str, actual: usize, expected: usize| {
            if actual == expected {
                Ok(())
            } else {
                Err(BackendError::internal(format!(
                    "batch {what} has {actual} values, expected {expected}"
                )))
            }
        };
        expect("states", batch.states.len(), rows * shape.states)?;
        expect("inputs", batch.inputs.len(), rows * shape.inputs)?;
        expect("closures", batch.embeddings.len(), self.closures.len())?;
        let convert = |values: &[f64]| {
            values
                .iter()
                .map(|&v| E::from_double(v))
                .collect::<Vec<E>>()
        };
        let mut constants = Vec::with_capacity(self.closures.len());
        for (closure, offsets) in self.closures.iter().zip(&batch.embeddings) {
            let mut per_offset = Vec::with_capacity(offsets.len());
            for raw in offsets {
                expect("embedding", raw.len(), rows * closure.width)?;
                per_offset.push(graph.matrix(rows, closure.width, closure.normalise(raw)));
            }
            constants.push(per_offset);
        }
        Ok(Prepared {
            rows,
            states: graph.matrix(rows, shape.states, convert(&batch.states)),
            inputs: Arc::new(convert(&batch.inputs)),
            constants,
            targets: convert(&batch.targets),
        })
    }

    /// `x(t + h)` for every row, and the register values of the first stage (at `t`).
    fn step(
        &self,
        graph: &mut Graph<E>,
        tensors: &Tensors<E>,
        batch: &Prepared<E>,
    ) -> Result<(Matrix<E>, Arc<Vec<E>>), BackendError> {
        let (first, values) = self.stage(graph, tensors, batch, &batch.states, 0)?;
        if self.dynamics == Dynamics::Discrete {
            return Ok((first, values));
        }
        let dt = self.step / self.substeps as f64;
        let mut state = batch.states.clone();
        let mut k1 = first;
        for substep in 0..self.substeps {
            let start = 2 * substep;
            if substep > 0 {
                k1 = self.stage(graph, tensors, batch, &state, start)?.0;
            }
            let x2 = graph.axpy(&state, dt / 2.0, &k1)?;
            let k2 = self.stage(graph, tensors, batch, &x2, start + 1)?.0;
            let x3 = graph.axpy(&state, dt / 2.0, &k2)?;
            let k3 = self.stage(graph, tensors, batch, &x3, start + 1)?.0;
            let x4 = graph.axpy(&state, dt, &k3)?;
            let k4 = self.stage(graph, tensors, batch, &x4, start + 2)?.0;
            let sum = graph.axpy(&k1, 2.0, &k2)?;
            let sum = graph.axpy(&sum, 2.0, &k3)?;
            let sum = graph.axpy(&sum, 1.0, &k4)?;
            state = graph.axpy(&state, dt / 6.0, &sum)?;
        }
        Ok((state, values))
    }

    /// The balances at one stage: every closure's network on its embedding (with `state`
    /// as the lag-0 states), then the physics program.
    fn stage(
        &self,
        graph: &mut Graph<E>,
        tensors: &Tensors<E>,
        batch: &Prepared<E>,
        state: &Matrix<E>,
        offset: usize,
    ) -> Result<(Matrix<E>, Arc<Vec<E>>), BackendError> {
        let mut nets = Vec::with_capacity(self.closures.len());
        for (index, closure) in self.closures.iter().enumerate() {
            let constant = (batch.constants[index].get(offset)).ok_or_else(|| {
                BackendError::internal(format!("no embedding at offset {offset}"))
            })?;
            let mut hidden = graph.embed(constant, state, &closure.state_columns)?;
            let layers = &tensors.layers[index];
            for (layer, (weight, bias)) in layers.iter().enumerate() {
                hidden = graph.affine(&hidden, weight, bias)?;
                if layer + 1 < layers.len() {
                    hidden = graph.activation(&hidden, closure.activation)?;
                }
            }
            nets.push(hidden);
        }
        graph.physics(
            &self.program,
            &self.balances,
            state,
            &batch.inputs,
            tensors.params.as_ref(),
            &nets,
        )
    }
}

impl ClosureLayout {
    /// Normalises raw embedding rows; lag-0 state columns get `-mean/std` so that adding
    /// `state / std` in [`Graph::embed`] completes the z-score.
    fn normalise<E: Element>(&self, raw: &[f64]) -> Vec<E> {
        let mut values = Vec::with_capacity(raw.len());
        for (index, &value) in raw.iter().enumerate() {
            let column = index % self.width;
            let (mean, std) = (self.column_mean[column], self.column_std[column]);
            let source = if self.is_stage_state[column] {
                0.0
            } else {
                value
            };
            values.push(E::from_double((source - mean) / std));
        }
        values
    }
}

fn closure_layout(
    model: &ir::Model,
    closure: &ir::Closure,
    setup: &Setup,
    first_tensor: usize,
) -> Result<ClosureLayout, BackendError> {
    let norm = &setup.normalisation;
    let layout = closure.embedding.layout();
    let (mut column_mean, mut column_std) = (Vec::new(), Vec::new());
    let (mut entries, mut is_stage_state) = (Vec::new(), Vec::new());
    for (column, &(var, lag)) in layout.iter().enumerate() {
        let (mean, std) = match var {
            Var::Input(i) => (norm.input_mean.get(i), norm.input_std.get(i)),
            Var::State(i) => (norm.state_mean.get(i), norm.state_std.get(i)),
            other => {
                return Err(BackendError::internal(format!(
                    "closure `{}` observes {other:?}, which is not measured",
                    closure.name
                )))
            }
        };
        let (mean, std) = mean
            .zip(std)
            .map(|(m, s)| (*m, *s))
            .ok_or_else(|| BackendError::internal(format!("no normalisation for {var:?}")))?;
        column_mean.push(mean);
        column_std.push(std);
        let stage_state = matches!(var, Var::State(_)) && lag == 0;
        if stage_state {
            entries.push((column, state_index(model, var)?, 1.0 / std));
        }
        is_stage_state.push(stage_state);
    }
    Ok(ClosureLayout {
        width: layout.len(),
        state_columns: Arc::new(StateColumns { entries }),
        column_mean,
        column_std,
        is_stage_state,
        activation: closure.network.activation,
        first_tensor,
        layers: closure.network.hidden.len() + 1,
    })
}

/// Checks that the setup's vectors fit the model.
fn check_setup(model: &ir::Model, setup: &Setup) -> Result<(), BackendError> {
    let norm = &setup.normalisation;
    let fits = norm.state_mean.len() == model.states.len()
        && norm.state_std.len() == model.states.len()
        && norm.input_mean.len() == model.inputs.len()
        && norm.input_std.len() == model.inputs.len()
        && setup.scales.len() == model.closures.len()
        && (setup.scales.iter().zip(&model.closures)).all(|(s, c)| s.len() == c.outputs.len());
    if fits && setup.step > 0.0 && setup.step.is_finite() {
        Ok(())
    } else {
        Err(BackendError::internal(format!(
            "the setup does not fit model `{}` (normalisation, scales or step)",
            model.name
        )))
    }
}

/// The unconstrained starting value of a param, so that its transform gives the guess.
pub fn raw_initial_value<E: Element>(param: &ir::Param) -> E {
    let raw = match param.constraint {
        Constraint::Free => param.init,
        Constraint::Positive => inverse_softplus(param.init.max(1e-12)),
        Constraint::Bounds(lo, hi) => {
            let fraction = ((param.init - lo) / (hi - lo)).clamp(1e-6, 1.0 - 1e-6);
            logit(fraction)
        }
    };
    E::from_double(raw)
}
