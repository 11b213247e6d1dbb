//! How batches become network inputs: each closure's column layout and normalisation, and
//! the conversion of one-step [`Batch`]es and multi-step [`RolloutBatch`]es into graph
//! constants plus the state-fed embedding entries of every step and stage.

use std::ops::DerefMut;
use std::sync::Arc;

use dfdx::tensor::Cpu;
use dfdx::tensor_ops::Device;

use super::tape::{Element, EmbedColumns, EmbedEntry, GradientBuffer, Graph, Matrix};
use crate::engine::batch::{Batch, Feedback, RolloutBatch};
use crate::engine::error::BackendError;
use crate::engine::program::state_index;
use crate::engine::setup::Setup;
use crate::ir::{self, Activation, Constraint, Var};
use crate::numeric::real::{inverse_softplus, logit, Real};

/// The network-side description of one closure.
#[derive(Debug, Clone)]
pub struct ClosureLayout {
    /// Network input width.
    pub width: usize,
    /// Where the stage estimate enters the input (source 0 of every entry).
    pub state_columns: Arc<EmbedColumns>,
    /// Per input column: mean and std used for normalisation.
    column_mean: Vec<f64>,
    column_std: Vec<f64>,
    /// The lag-0 state columns and their constant part, `(0 - mean) / std`.
    stage_columns: Vec<(usize, f64)>,
    /// Hidden-layer activation.
    pub activation: Activation,
    /// Index of its first tensor in the weight list.
    pub first_tensor: usize,
    /// Number of affine layers.
    pub layers: usize,
}

/// A batch converted to the element type: the start states and one block per step.
pub struct Prepared<E: Element> {
    /// Batch rows.
    pub rows: usize,
    /// `rows x states` at the start.
    pub states: Matrix<E>,
    /// The steps, in order.
    pub steps: Vec<PreparedStep<E>>,
}

/// One step of a prepared batch.
pub struct PreparedStep<E: Element> {
    /// `rows x inputs`, held over the step.
    pub inputs: Arc<Vec<E>>,
    /// `constants[closure][offset]`: the normalised constant part of the network input.
    pub constants: Vec<Vec<Matrix<E>>>,
    /// `columns[closure][offset]`: the state-fed entries.
    pub columns: Vec<Vec<Arc<EmbedColumns>>>,
    /// `rows x measured` targets (empty when predicting).
    pub targets: Vec<E>,
    /// The step `h` of each row (kept in `f64`: the RK4 multiples are formed there).
    pub step_sizes: Vec<f64>,
    /// `rows x measured` loss weights (`None`: every cell weighs 1).
    pub weights: Option<Vec<E>>,
    /// `rows x observables` measured outputs at the step's end.
    pub observed: Vec<E>,
    /// Their loss weights (0: not measured).
    pub observed_weights: Vec<E>,
}

impl ClosureLayout {
    /// Normalises raw embedding rows; lag-0 state columns get `-mean/std` so that adding
    /// `state / std` in [`Graph::embed`] completes the z-score.
    pub fn normalise<E: Element>(&self, raw: &[f64]) -> Vec<E> {
        let mut values = Vec::with_capacity(raw.len());
        self.normalise_into(raw, &mut values);
        values
    }

    /// [`ClosureLayout::normalise`] into a buffer kept by the caller (cleared first): the
    /// one embedding normalisation of training, which the fused step calls too.
    pub fn normalise_into<E: Real>(&self, raw: &[f64], values: &mut Vec<E>) {
        values.clear();
        values.resize(raw.len(), E::ZERO);
        let width = self.width.min(self.column_mean.len());
        let (mean, std) = (&self.column_mean[..width], &self.column_std[..width]);
        for (row, out) in raw.chunks(self.width).zip(values.chunks_mut(self.width)) {
            let columns = row.len().min(width);
            // Every column first, over equal-length slices so that the division is
            // vectorised (exactly rounded: the same bits as one at a time) ...
            let (row, out) = (&row[..columns], &mut out[..columns]);
            for column in 0..columns {
                out[column] = E::from_double((row[column] - mean[column]) / std[column]);
            }
            // ... then the lag-0 state columns, whose source is 0.
            for &(column, constant) in &self.stage_columns {
                if let Some(out) = out.get_mut(column) {
                    *out = E::from_double(constant);
                }
            }
        }
    }

    /// The factor of a prediction fed back into network input `column` with interpolation
    /// weight `weight`: `weight / std` of the column (none outside the layout); the graph
    /// and the fused step both scale feedback by it.
    pub fn feedback_factor(&self, column: usize, weight: f64) -> Option<f64> {
        self.column_std.get(column).map(|std| weight / std)
    }

    /// The stage-estimate entries plus a rollout's feedback entries (each for its own
    /// rows), each scaled by its column's `1 / std`.
    fn with_feedback(
        &self,
        feedback: &[Feedback],
        rows: usize,
    ) -> Result<EmbedColumns, BackendError> {
        let mut columns = (*self.state_columns).clone();
        for entry in feedback {
            let factor = (self.feedback_factor(entry.column, entry.weight))
                .filter(|_| entry.sample >= 1 && entry.fits(rows))
                .ok_or_else(|| BackendError::internal("feedback outside the embedding"))?;
            columns.entries.push(EmbedEntry {
                column: entry.column,
                source: entry.sample,
                state: entry.state,
                factor,
                rows: Some(entry.rows.clone()),
            });
        }
        Ok(columns)
    }
}

fn expect(what: &str, actual: usize, expected: usize) -> Result<(), BackendError> {
    if actual == expected {
        Ok(())
    } else {
        Err(BackendError::internal(format!(
            "batch {what} has {actual} values, expected {expected}"
        )))
    }
}

fn convert<E: Element>(values: &[f64]) -> Vec<E> {
    values.iter().map(|&v| E::from_double(v)).collect()
}

/// Each row's step: `given` when it has one per row, else `nominal` for every row.
fn step_sizes(
    given: Option<&Vec<f64>>,
    rows: usize,
    nominal: f64,
) -> Result<Vec<f64>, BackendError> {
    match given.filter(|g| !g.is_empty()) {
        Some(sizes) => {
            expect("step sizes", sizes.len(), rows)?;
            if let Some(bad) = sizes.iter().find(|h| !(**h >= 0.0 && h.is_finite())) {
                return Err(BackendError::internal(format!("a step of size {bad}")));
            }
            Ok(sizes.clone())
        }
        None => Ok(vec![nominal; rows]),
    }
}

/// A step's observable block (targets or weights): `rows x observables`, zeros when the
/// batch gives none (every cell then weighs 0).
fn observed<E: Element>(
    given: Option<&Vec<f64>>,
    rows: usize,
    observables: usize,
) -> Result<Vec<E>, BackendError> {
    match given.filter(|g| !g.is_empty()) {
        Some(values) => {
            expect("observed outputs", values.len(), rows * observables)?;
            Ok(convert(values))
        }
        None => Ok(vec![E::ZERO; rows * observables]),
    }
}

/// The loss weights of a step (`None` when the batch gives none).
fn loss_weights<E: Element>(
    given: Option<&Vec<f64>>,
    rows: usize,
    measured: usize,
) -> Result<Option<Vec<E>>, BackendError> {
    match given.filter(|g| !g.is_empty()) {
        Some(weights) => {
            expect("loss weights", weights.len(), rows * measured)?;
            if weights.iter().any(|w| !(*w >= 0.0 && w.is_finite())) {
                return Err(BackendError::internal(
                    "a negative or non-finite loss weight",
                ));
            }
            Ok(Some(convert(weights)))
        }
        None => Ok(None),
    }
}

/// Normalised constant matrices of one step, `[closure][offset]`.
fn constants<E: Element>(
    graph: &Graph<E>,
    closures: &[ClosureLayout],
    rows: usize,
    embeddings: &[Vec<Vec<f64>>],
) -> Result<Vec<Vec<Matrix<E>>>, BackendError>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    expect("closures", embeddings.len(), closures.len())?;
    let mut constants = Vec::with_capacity(closures.len());
    for (closure, offsets) in closures.iter().zip(embeddings) {
        let mut per_offset = Vec::with_capacity(offsets.len());
        for raw in offsets {
            expect("embedding", raw.len(), rows * closure.width)?;
            per_offset.push(graph.matrix(rows, closure.width, closure.normalise(raw)));
        }
        constants.push(per_offset);
    }
    Ok(constants)
}

/// What a batch is prepared against: the closures' layouts, the program's shape, the
/// number of measured states and the nominal step.
pub struct Frame<'a> {
    /// Every closure's layout.
    pub closures: &'a [ClosureLayout],
    /// The physics program's shape.
    pub shape: &'a crate::engine::program::ProgramShape,
    /// Measured states (target columns).
    pub measured: usize,
    /// Measured outputs (observable columns).
    pub observables: usize,
    /// The step of rows that give none.
    pub nominal_step: f64,
}

/// A one-step batch as a prepared batch of one step.
pub fn prepare<E: Element>(
    graph: &Graph<E>,
    frame: &Frame,
    batch: &Batch,
) -> Result<Prepared<E>, BackendError>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    let (closures, shape) = (frame.closures, frame.shape);
    let rows = batch.rows;
    expect("states", batch.states.len(), rows * shape.states)?;
    expect("inputs", batch.inputs.len(), rows * shape.inputs)?;
    let constants = constants(graph, closures, rows, &batch.embeddings)?;
    let columns = (closures.iter().zip(&constants))
        .map(|(closure, offsets)| vec![Arc::clone(&closure.state_columns); offsets.len()])
        .collect();
    Ok(Prepared {
        rows,
        states: graph.matrix(rows, shape.states, convert(&batch.states)),
        steps: vec![PreparedStep {
            inputs: Arc::new(convert(&batch.inputs)),
            constants,
            columns,
            targets: convert(&batch.targets),
            step_sizes: step_sizes(Some(&batch.step_sizes), rows, frame.nominal_step)?,
            weights: loss_weights(Some(&batch.weights), rows, frame.measured)?,
            observed: observed(Some(&batch.observed), rows, frame.observables)?,
            observed_weights: observed(Some(&batch.observed_weights), rows, frame.observables)?,
        }],
    })
}

/// A rollout batch as a prepared batch of `batch.steps` steps.
pub fn prepare_rollout<E: Element>(
    graph: &Graph<E>,
    frame: &Frame,
    batch: &RolloutBatch,
) -> Result<Prepared<E>, BackendError>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    let (closures, shape) = (frame.closures, frame.shape);
    let rows = batch.rows;
    for (what, count) in [
        ("step-size steps", batch.step_sizes.len()),
        ("weight steps", batch.weights.len()),
    ] {
        if count != 0 {
            expect(what, count, batch.steps)?;
        }
    }
    expect("states", batch.states.len(), rows * shape.states)?;
    expect("input steps", batch.inputs.len(), batch.steps)?;
    expect("embedding steps", batch.embeddings.len(), batch.steps)?;
    expect("feedback steps", batch.feedback.len(), batch.steps)?;
    if !batch.targets.is_empty() {
        expect("target steps", batch.targets.len(), batch.steps)?;
    }
    let mut steps = Vec::with_capacity(batch.steps);
    for step in 0..batch.steps {
        expect("inputs", batch.inputs[step].len(), rows * shape.inputs)?;
        let constants = constants(graph, closures, rows, &batch.embeddings[step])?;
        let feedback = &batch.feedback[step];
        expect("feedback closures", feedback.len(), closures.len())?;
        let mut columns = Vec::with_capacity(closures.len());
        for ((closure, offsets), per_offset) in closures.iter().zip(feedback).zip(&constants) {
            expect("feedback offsets", offsets.len(), per_offset.len())?;
            let built = (offsets.iter())
                .map(|entries| closure.with_feedback(entries, rows).map(Arc::new))
                .collect::<Result<Vec<_>, _>>()?;
            columns.push(built);
        }
        let targets = batch.targets.get(step).map_or(Vec::new(), |t| convert(t));
        steps.push(PreparedStep {
            inputs: Arc::new(convert(&batch.inputs[step])),
            constants,
            columns,
            targets,
            step_sizes: step_sizes(batch.step_sizes.get(step), rows, frame.nominal_step)?,
            weights: loss_weights(batch.weights.get(step), rows, frame.measured)?,
            observed: observed(batch.observed.get(step), rows, frame.observables)?,
            observed_weights: observed(batch.observed_weights.get(step), rows, frame.observables)?,
        });
    }
    Ok(Prepared {
        rows,
        states: graph.matrix(rows, shape.states, convert(&batch.states)),
        steps,
    })
}

/// The layout of `closure`, whose tensors start at `first_tensor`.
pub fn closure_layout(
    model: &ir::Model,
    closure: &ir::Closure,
    setup: &Setup,
    first_tensor: usize,
) -> Result<ClosureLayout, BackendError> {
    let norm = &setup.normalisation;
    let layout = closure.embedding.layout();
    let (mut column_mean, mut column_std) = (Vec::new(), Vec::new());
    let (mut entries, mut stage_columns) = (Vec::new(), Vec::new());
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
            entries.push(EmbedEntry {
                column,
                source: 0,
                state: state_index(model, var)?,
                factor: 1.0 / std,
                rows: None,
            });
            stage_columns.push((column, (0.0 - mean) / std));
        }
    }
    Ok(ClosureLayout {
        width: layout.len(),
        state_columns: Arc::new(EmbedColumns { entries }),
        column_mean,
        column_std,
        stage_columns,
        activation: closure.network.activation,
        first_tensor,
        layers: closure.network.hidden.len() + 1,
    })
}

/// Checks that the setup's vectors fit the model.
pub fn check_setup(model: &ir::Model, setup: &Setup) -> Result<(), BackendError> {
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

/// The unconstrained starting values of the model's params (their transforms give the
/// declared initial guesses), as [`crate::engine::program::Program`] reads them.
pub fn initial_raw_params(model: &ir::Model) -> Vec<f64> {
    model.params.iter().map(raw_initial_value::<f64>).collect()
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
