//! The recorded forward pass of [`GreyBox`]: a batch's tensors on the graph, each step's
//! RK4 stages (or discrete update) through the closure networks and the physics program,
//! in the order of its tableau ([`crate::solve::ode::tableau`]), and the observables at
//! each predicted state.

use std::ops::DerefMut;

use dfdx::shapes::HasShape;
use dfdx::tensor::Cpu;
use dfdx::tensor_ops::Device;

use super::*;
use crate::solve::ode::tableau::{Combination, RK4};

impl<E: Element> GreyBox<E>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    pub(super) fn tensors(&self, graph: &Graph<E>) -> Tensors<E> {
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
            .filter(|name| name.as_str() == crate::vocabulary::PARAMS_TENSOR)
            .map(|_| graph.vector(self.weights[self.weights.len() - 1].clone()));
        Tensors { layers, params }
    }

    pub(super) fn frame(&self) -> Frame<'_> {
        Frame {
            closures: &self.closures,
            shape: self.program.shape(),
            measured: self.inverse_std.len(),
            observables: self.observables.len(),
            nominal_step: self.step,
        }
    }

    pub(super) fn prepare(
        &self,
        graph: &Graph<E>,
        batch: &Batch,
    ) -> Result<Prepared<E>, BackendError> {
        prepare(graph, &self.frame(), batch)
    }

    pub(super) fn prepare_rollout(
        &self,
        graph: &Graph<E>,
        batch: &RolloutBatch,
    ) -> Result<Prepared<E>, BackendError> {
        prepare_rollout(graph, &self.frame(), batch)
    }

    /// Runs every step of a prepared batch, each from the previous step's prediction.
    pub(super) fn forward(
        &self,
        graph: &mut Graph<E>,
        tensors: &Tensors<E>,
        prepared: &Prepared<E>,
    ) -> Result<Forward<E>, BackendError> {
        let mut history = vec![prepared.states.clone()];
        let mut first_values = None;
        let mut observations = Vec::new();
        for step in &prepared.steps {
            let (next, values) = self.step(graph, tensors, step, &history)?;
            first_values.get_or_insert(values);
            if !self.observables.is_empty() {
                observations.push(self.observe(graph, tensors, step, (&next, &history))?);
            }
            history.push(next);
        }
        let first_values = first_values.unwrap_or_else(|| Arc::new(Vec::new()));
        history.remove(0);
        Ok(Forward {
            predictions: history,
            observations,
            first_values,
        })
    }

    /// `x(t + h)` for every row from the last state of `history`, and the register values
    /// of the first stage (at `t`).
    pub(super) fn step(
        &self,
        graph: &mut Graph<E>,
        tensors: &Tensors<E>,
        batch: &PreparedStep<E>,
        history: &[Matrix<E>],
    ) -> Result<(Matrix<E>, Arc<Vec<E>>), BackendError> {
        let start = (history.last())
            .ok_or_else(|| BackendError::internal("a step without a start state"))?;
        let (first, values) =
            self.stage(graph, tensors, batch, (start, history), (0, &self.balances))?;
        if self.dynamics == Dynamics::Discrete {
            return Ok((first, values));
        }
        let mut state = start.clone();
        let mut first = Some(first);
        for substep in 0..self.substeps {
            state = self.substep(
                graph,
                tensors,
                batch,
                (&state, history),
                (substep, &mut first),
            )?;
        }
        Ok((state, values))
    }

    /// Each row's sub-step `dt = h / K` divided by `divisor` (a denominator of the tableau).
    fn substep_factors(&self, batch: &PreparedStep<E>, divisor: f64) -> Vec<E> {
        let substeps = self.substeps as f64;
        (batch.step_sizes.iter())
            .map(|&h| E::from_double(h / substeps / divisor))
            .collect()
    }

    /// Sub-step `substep` from `state`: RK4's stages at their estimates, then the step along
    /// its weights. The first stage of the first sub-step is `first`, already evaluated.
    fn substep(
        &self,
        graph: &mut Graph<E>,
        tensors: &Tensors<E>,
        batch: &PreparedStep<E>,
        (state, history): (&Matrix<E>, &[Matrix<E>]),
        (substep, first): (usize, &mut Option<Matrix<E>>),
    ) -> Result<Matrix<E>, BackendError> {
        let mut slopes = Vec::with_capacity(RK4.stages.len());
        for (index, coupling) in RK4.stages.iter().enumerate() {
            let offset = (RK4.stage_offset(substep, index), &self.balances);
            let slope = match first.take() {
                Some(slope) => slope,
                None if coupling.is_empty() => {
                    self.stage(graph, tensors, batch, (state, history), offset)?
                        .0
                }
                None => {
                    let factors = self.substep_factors(batch, coupling.divisor());
                    let slope = combine(graph, coupling, &slopes)?;
                    let estimate = graph.axpy_rows(state, &factors, &slope)?;
                    self.stage(graph, tensors, batch, (&estimate, history), offset)?
                        .0
                }
            };
            slopes.push(slope);
        }
        let factors = self.substep_factors(batch, RK4.weights.divisor());
        let sum = combine(graph, &RK4.weights, &slopes)?;
        graph.axpy_rows(state, &factors, &sum)
    }

    /// The observables at the end of a step: the model's measured outputs at the predicted
    /// state, the networks evaluated on the embedding at the step's end.
    pub(super) fn observe(
        &self,
        graph: &mut Graph<E>,
        tensors: &Tensors<E>,
        batch: &PreparedStep<E>,
        (state, history): (&Matrix<E>, &[Matrix<E>]),
    ) -> Result<Matrix<E>, BackendError> {
        let last = batch
            .constants
            .first()
            .map_or(0, |c| c.len().saturating_sub(1));
        let targets = Arc::clone(&self.observables);
        Ok(self
            .stage(graph, tensors, batch, (state, history), (last, &targets))?
            .0)
    }

    /// The registers `targets` at one stage: every closure's network on its embedding (the stage
    /// estimate `state` in the lag-0 state columns, earlier predictions of `history` where
    /// the batch feeds them back), then the physics program.
    pub(super) fn stage(
        &self,
        graph: &mut Graph<E>,
        tensors: &Tensors<E>,
        batch: &PreparedStep<E>,
        (state, history): (&Matrix<E>, &[Matrix<E>]),
        (offset, targets): (usize, &Arc<Vec<usize>>),
    ) -> Result<(Matrix<E>, Arc<Vec<E>>), BackendError> {
        let sources: Vec<&Matrix<E>> = std::iter::once(state)
            .chain(history.iter().skip(1))
            .collect();
        let mut nets = Vec::with_capacity(self.closures.len());
        for (index, closure) in self.closures.iter().enumerate() {
            let missing = || BackendError::internal(format!("no embedding at offset {offset}"));
            let constant = (batch.constants[index].get(offset)).ok_or_else(missing)?;
            let columns = (batch.columns[index].get(offset)).ok_or_else(missing)?;
            let mut hidden = graph.embed(constant, &sources, columns)?;
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
            targets,
            state,
            &batch.inputs,
            tensors.params.as_ref(),
            &nets,
        )
    }
}

/// `n_0 k_0 + n_1 k_1 + ...` over the stages that enter `combination`, left to right (a
/// numerator of 1 on the first is that slope itself).
fn combine<E: Element, const S: usize>(
    graph: &mut Graph<E>,
    combination: &Combination<S>,
    slopes: &[Matrix<E>],
) -> Result<Matrix<E>, BackendError>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    let mut terms = combination.terms();
    let (first, numerator) = (terms.next())
        .ok_or_else(|| BackendError::internal("a stage combination without a slope"))?;
    let mut sum = if numerator == 1.0 {
        slopes[first].clone()
    } else {
        let (rows, columns) = *slopes[first].shape();
        let zero = graph.matrix(rows, columns, vec![E::ZERO; rows * columns]);
        graph.axpy(&zero, numerator, &slopes[first])?
    };
    for (stage, numerator) in terms {
        sum = graph.axpy(&sum, numerator, &slopes[stage])?;
    }
    Ok(sum)
}
