//! A recording session over dfdx 0.13: every intermediate is kept as a tape-free tensor and
//! every backward operation goes onto one shared tape.
//!
//! dfdx moves a tape through the tensors of a computation, so a tensor used twice needs its
//! tape split off first. Here each operation takes its operands as `retaped` copies (same
//! id, empty tape), runs, and the resulting tape is merged into the session's tape; the
//! value is returned without a tape. Since dfdx sorts backward operations by creation
//! order when it executes a merged tape, this is the same computation as threading one tape
//! by hand. Operations dfdx lacks (softplus, the fused physics, the embedding assembly and
//! the normalised loss) are added through the tape API: the forward runs on the raw data and
//! a backward closure accumulates into the operands' gradients.

use std::ops::DerefMut;
use std::sync::Arc;

use dfdx::shapes::{Axis, HasShape, Shape};
use dfdx::tensor::{
    Cpu, CpuError, Gradients, Merge, OwnedTape, PutTape, SplitTape, Storage, Tape, Tensor,
    TensorFromVec,
};
use dfdx::tensor_ops::{Backward, BroadcastTo, Device, TryAdd, TryMatMul, TryMul};

use crate::engine::error::BackendError;
use crate::engine::program::{Program, ProgramInputs};
use crate::ir::Activation;
use crate::numeric::Real;

/// An element type the graph can run in: the backend's [`Real`] and dfdx's `Dtype`.
pub trait Element: Real + dfdx::shapes::Dtype {}
impl Element for f32 {}
impl Element for f64 {}

/// A batch-major matrix `(rows, columns)`.
pub type Matrix<E> = Tensor<(usize, usize), E, Cpu>;
/// A vector.
pub type Vector<E> = Tensor<(usize,), E, Cpu>;
/// A scalar (the loss).
pub type Scalar<E> = Tensor<(), E, Cpu>;

/// The buffer dfdx keeps a gradient in.
pub type GradientBuffer<E> = <Cpu as Storage<E>>::Vec;

type Taped<S, E> = Tensor<S, E, Cpu, OwnedTape<E, Cpu>>;

/// One forward pass being recorded.
pub struct Graph<E: Element> {
    device: Cpu,
    tape: OwnedTape<E, Cpu>,
}

/// One state-fed entry of a closure's network input: column `column` gains
/// `factor * sources[source][state]` (the factor folds in `1 / std` and an interpolation
/// weight).
#[derive(Debug, Clone, PartialEq)]
pub struct EmbedEntry {
    /// Network input column.
    pub column: usize,
    /// Which source matrix: 0 the stage estimate, `j >= 1` the state predicted `j` steps
    /// into a rollout.
    pub source: usize,
    /// Entry of the source's state vector.
    pub state: usize,
    /// Multiplier.
    pub factor: f64,
    /// The batch rows it applies to (`None`: every row).
    pub rows: Option<std::ops::Range<usize>>,
}

/// One block of the loss: a prediction compared with its targets.
pub struct LossBlock<'a, E: Element> {
    /// `rows x width`; its first `inverse_std.len()` columns are compared.
    pub prediction: &'a Matrix<E>,
    /// `rows x inverse_std.len()` targets.
    pub targets: &'a [E],
    /// Their weights (`None`: every cell weighs 1).
    pub weights: Option<&'a [E]>,
    /// `1 / std` of each compared column.
    pub inverse_std: &'a [E],
}

/// The state-fed entries of a closure's network input.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct EmbedColumns {
    /// Entries, in any order.
    pub entries: Vec<EmbedEntry>,
}

impl<E: Element> Graph<E>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    /// Starts recording on `device`.
    pub fn new(device: &Cpu) -> Self {
        Graph {
            device: device.clone(),
            tape: OwnedTape::default(),
        }
    }

    /// A constant matrix from row-major values.
    pub fn matrix(&self, rows: usize, columns: usize, values: Vec<E>) -> Matrix<E> {
        self.device.tensor_from_vec(values, (rows, columns))
    }

    /// A constant vector.
    pub fn vector(&self, values: Vec<E>) -> Vector<E> {
        let length = values.len();
        self.device.tensor_from_vec(values, (length,))
    }

    /// Merges an operation's tape into the session's and returns the bare value.
    fn keep<S: Shape>(&mut self, taped: Taped<S, E>) -> Tensor<S, E, Cpu> {
        let (value, tape) = taped.split_tape();
        let main = std::mem::take(&mut self.tape);
        self.tape = main.merge(tape);
        value
    }

    fn traced<S: Shape>(tensor: &Tensor<S, E, Cpu>) -> Taped<S, E> {
        tensor.retaped::<OwnedTape<E, Cpu>>()
    }

    /// `input @ weight + bias`, the bias broadcast over rows.
    pub fn affine(
        &mut self,
        input: &Matrix<E>,
        weight: &Matrix<E>,
        bias: &Vector<E>,
    ) -> Result<Matrix<E>, BackendError> {
        let rows = input.shape().0;
        let columns = weight.shape().1;
        let product = Self::traced(input).try_matmul(Self::traced(weight))?;
        let spread = Self::traced(bias).try_broadcast_like::<_, Axis<0>>(&(rows, columns))?;
        let sum = product.try_add(spread)?;
        Ok(self.keep(sum))
    }

    /// `a + factor * b`.
    pub fn axpy(
        &mut self,
        a: &Matrix<E>,
        factor: f64,
        b: &Matrix<E>,
    ) -> Result<Matrix<E>, BackendError> {
        let scaled = Self::traced(b).try_mul(E::from_double(factor))?;
        let sum = Self::traced(a).try_add(scaled)?;
        Ok(self.keep(sum))
    }

    /// `a + diag(factors) b`: row `i` of `b` scaled by `factors[i]` (a step of its own
    /// size per row).
    pub fn axpy_rows(
        &mut self,
        a: &Matrix<E>,
        factors: &[E],
        b: &Matrix<E>,
    ) -> Result<Matrix<E>, BackendError> {
        let (rows, columns) = *a.shape();
        if *b.shape() != (rows, columns) || factors.len() != rows {
            return Err(BackendError::internal("axpy_rows operands differ in shape"));
        }
        let mut values = a.as_vec();
        let b_values = b.as_vec();
        for (row, &factor) in factors.iter().enumerate() {
            let span = row * columns..(row + 1) * columns;
            for (slot, &value) in values[span.clone()].iter_mut().zip(&b_values[span]) {
                *slot += value * factor;
            }
        }
        let result = self.device.try_tensor_from_vec(values, (rows, columns))?;
        let (a_ghost, b_ghost, result_ghost) = (a.ghost(), b.ghost(), result.ghost());
        let factors = factors.to_vec();
        self.tape.add_backward_op(move |grads| {
            let upstream = grads.get_or_alloc_mut(&result_ghost)?.to_vec();
            accumulate(grads.get_or_alloc_mut(&a_ghost)?, &upstream);
            let target = grads.get_or_alloc_mut(&b_ghost)?;
            for (row, &factor) in factors.iter().enumerate() {
                let span = row * columns..(row + 1) * columns;
                for (slot, &g) in target[span.clone()].iter_mut().zip(&upstream[span]) {
                    *slot += g * factor;
                }
            }
            Ok(())
        });
        Ok(result)
    }

    /// A hidden-layer activation.
    pub fn activation(
        &mut self,
        input: &Matrix<E>,
        activation: Activation,
    ) -> Result<Matrix<E>, BackendError> {
        let taped = Self::traced(input);
        let output = match activation {
            Activation::Softplus => return self.softplus(input),
            Activation::Linear => return Ok(input.clone()),
            Activation::Tanh => taped.try_tanh()?,
            Activation::Relu => taped.try_relu()?,
            Activation::Sigmoid => taped.try_sigmoid()?,
            Activation::Gelu => taped.try_fast_gelu()?,
        };
        Ok(self.keep(output))
    }

    /// Elementwise softplus, safe for large |x| in value and gradient (dfdx has none).
    pub fn softplus(&mut self, input: &Matrix<E>) -> Result<Matrix<E>, BackendError> {
        // One exponential per element serves both passes (`Real::softplus_and_slope`).
        let mut slopes = input.as_vec();
        let mut output = Vec::with_capacity(slopes.len());
        for x in slopes.iter_mut() {
            let (value, slope) = x.softplus_and_slope();
            output.push(value);
            *x = slope;
        }
        let result = self.device.try_tensor_from_vec(output, *input.shape())?;
        let (input_ghost, result_ghost) = (input.ghost(), result.ghost());
        self.tape.add_backward_op(move |grads| {
            let upstream = grads.get_or_alloc_mut(&result_ghost)?.to_vec();
            let target = grads.get_or_alloc_mut(&input_ghost)?;
            for ((slot, g), slope) in target.iter_mut().zip(upstream).zip(slopes) {
                *slot += g * slope;
            }
            Ok(())
        });
        Ok(result)
    }

    /// A closure's network input: the constant embedding part (inputs and data-valued
    /// lags, already normalised; entries fed by a state holding `-mean/std` or the
    /// normalised data share of an interpolation) plus `factor * sources[source][state]`
    /// for each entry of `columns`. Source 0 is the stage estimate of the current state;
    /// sources 1.. are states predicted earlier in a rollout.
    pub fn embed(
        &mut self,
        constant: &Matrix<E>,
        sources: &[&Matrix<E>],
        columns: &Arc<EmbedColumns>,
    ) -> Result<Matrix<E>, BackendError> {
        let (rows, width) = *constant.shape();
        let mut values = constant.as_vec();
        let mut source_values = Vec::with_capacity(sources.len());
        for source in sources {
            if source.shape().0 != rows {
                return Err(BackendError::internal("embedding sources differ in rows"));
            }
            source_values.push((source.shape().1, source.as_vec()));
        }
        for entry in &columns.entries {
            let (state_width, state_values) = (source_values.get(entry.source))
                .filter(|(width, _)| entry.state < *width)
                .filter(|_| (entry.rows.as_ref()).is_none_or(|r| r.start < r.end && r.end <= rows))
                .ok_or_else(|| BackendError::internal("embedding entry without a source"))?;
            let factor = E::from_double(entry.factor);
            for row in entry_rows(entry, rows) {
                values[row * width + entry.column] +=
                    state_values[row * state_width + entry.state] * factor;
            }
        }
        let result = self.device.try_tensor_from_vec(values, (rows, width))?;
        let result_ghost = result.ghost();
        let ghosts: Vec<_> = sources.iter().map(|s| (s.ghost(), s.shape().1)).collect();
        let columns = Arc::clone(columns);
        self.tape.add_backward_op(move |grads| {
            let upstream = grads.get_or_alloc_mut(&result_ghost)?.to_vec();
            for (source, (ghost, state_width)) in ghosts.iter().enumerate() {
                let entries = columns.entries.iter().filter(|e| e.source == source);
                let mut entries = entries.peekable();
                if entries.peek().is_none() {
                    continue;
                }
                let target = grads.get_or_alloc_mut(ghost)?;
                for entry in entries {
                    let factor = E::from_double(entry.factor);
                    for row in entry_rows(entry, rows) {
                        target[row * state_width + entry.state] +=
                            upstream[row * width + entry.column] * factor;
                    }
                }
            }
            Ok(())
        });
        Ok(result)
    }

    /// The physics layer: the program's `targets` registers (balances, or next values for
    /// discrete models) for each row, from the state estimate, the held inputs, the raw
    /// params and every closure's network output. Also returns all register values.
    pub fn physics(
        &mut self,
        program: &Arc<Program>,
        targets: &Arc<Vec<usize>>,
        states: &Matrix<E>,
        inputs: &Arc<Vec<E>>,
        params: Option<&Vector<E>>,
        nets: &[Matrix<E>],
    ) -> Result<(Matrix<E>, Arc<Vec<E>>), BackendError> {
        let rows = states.shape().0;
        let state_values = states.as_vec();
        let param_values = params.map(|p| p.as_vec()).unwrap_or_default();
        let net_values: Vec<Vec<E>> = nets.iter().map(|n| n.as_vec()).collect();
        let values = {
            let net_slices: Vec<&[E]> = net_values.iter().map(Vec::as_slice).collect();
            let program_inputs = ProgramInputs {
                rows,
                states: &state_values,
                inputs,
                params: &param_values,
                nets: &net_slices,
            };
            Arc::new(program.forward(&program_inputs))
        };
        let output = program.read(&values, rows, targets);
        let result = self
            .device
            .try_tensor_from_vec(output, (rows, targets.len()))?;
        let result_ghost = result.ghost();
        let states_ghost = states.ghost();
        let params_ghost = params.map(|p| p.ghost());
        let nets_ghost: Vec<_> = nets.iter().map(|n| n.ghost()).collect();
        let (program, targets, inputs) = (program.clone(), targets.clone(), inputs.clone());
        let kept_values = Arc::clone(&values);
        self.tape.add_backward_op(move |grads| {
            let seed = grads.get_or_alloc_mut(&result_ghost)?.to_vec();
            let net_slices: Vec<&[E]> = net_values.iter().map(Vec::as_slice).collect();
            let program_inputs = ProgramInputs {
                rows,
                states: &state_values,
                inputs: &inputs,
                params: &param_values,
                nets: &net_slices,
            };
            let gradients = program.backward(&program_inputs, &kept_values, &targets, &seed);
            accumulate(grads.get_or_alloc_mut(&states_ghost)?, &gradients.states);
            if let Some(ghost) = &params_ghost {
                accumulate(grads.get_or_alloc_mut(ghost)?, &gradients.params);
            }
            for (ghost, gradient) in nets_ghost.iter().zip(&gradients.nets) {
                accumulate(grads.get_or_alloc_mut(ghost)?, gradient);
            }
            Ok(())
        });
        Ok((result, values))
    }

    /// The weighted mean of `((prediction - target) * inverse_std)^2` over the cells of
    /// every block: each block compares the first `inverse_std.len()` columns of its
    /// prediction with its `rows x inverse_std.len()` targets, each cell weighted by its
    /// weight where given (0: not measured); the sum is divided by the number of cells of
    /// positive weight over all blocks (every cell of a block without weights counts).
    pub fn normalised_mse(&mut self, blocks: &[LossBlock<E>]) -> Result<Scalar<E>, BackendError> {
        if blocks.is_empty() {
            return Err(BackendError::internal("loss needs a target block"));
        }
        let mut cells = 0usize;
        let mut residuals = Vec::with_capacity(blocks.len());
        let mut shapes = Vec::with_capacity(blocks.len());
        let mut total = E::ZERO;
        for block in blocks {
            let (rows, width) = *block.prediction.shape();
            let measured = block.inverse_std.len();
            let values = block.prediction.as_vec();
            let weight_fits = block.weights.is_none_or(|w| w.len() == rows * measured);
            if values.len() != rows * width
                || block.targets.len() != rows * measured
                || measured > width
                || !weight_fits
            {
                return Err(BackendError::internal("loss blocks differ in size"));
            }
            // Scaled residual times its weight: the gradient's factor per cell.
            let mut weighted = vec![E::ZERO; rows * measured];
            for row in 0..rows {
                for state in 0..measured {
                    let cell = row * measured + state;
                    let w = block.weights.map_or(<E as Real>::ONE, |w| w[cell]);
                    if w <= E::ZERO {
                        continue;
                    }
                    cells += 1;
                    let scaled = (values[row * width + state] - block.targets[cell])
                        * block.inverse_std[state];
                    weighted[cell] = w * scaled;
                    total += w * scaled * scaled;
                }
            }
            residuals.push(weighted);
            shapes.push((rows, width, block.inverse_std.to_vec()));
        }
        let count = E::from_double(cells.max(1) as f64);
        let loss = self.device.try_tensor_from_vec(vec![total / count], ())?;
        let loss_ghost = loss.ghost();
        let ghosts: Vec<_> = blocks.iter().map(|b| b.prediction.ghost()).collect();
        self.tape.add_backward_op(move |grads| {
            let upstream = grads.get_or_alloc_mut(&loss_ghost)?[0];
            let factor = upstream * E::from_double(2.0) / count;
            for ((ghost, block_residuals), (rows, width, inverse_std)) in
                ghosts.iter().zip(&residuals).zip(&shapes)
            {
                let measured = inverse_std.len();
                let target = grads.get_or_alloc_mut(ghost)?;
                for row in 0..*rows {
                    for state in 0..measured {
                        target[row * width + state] +=
                            factor * block_residuals[row * measured + state] * inverse_std[state];
                    }
                }
            }
            Ok(())
        });
        Ok(loss)
    }

    /// Runs the reverse pass from `loss` through everything recorded.
    pub fn backward(self, loss: Scalar<E>) -> Result<Gradients<E, Cpu>, BackendError> {
        Ok(loss.put_tape(self.tape).try_backward()?)
    }
}

/// The gradient accumulated for `tensor` (zeros if it took no part in the loss).
pub fn gradient_of<S: Shape, E: Element>(
    grads: &mut Gradients<E, Cpu>,
    tensor: &Tensor<S, E, Cpu>,
) -> Result<Vec<E>, BackendError>
where
    Cpu: Device<E>,
    GradientBuffer<E>: DerefMut<Target = Vec<E>>,
{
    Ok(grads.get_or_alloc_mut(tensor)?.to_vec())
}

/// The batch rows an embedding entry adds to.
fn entry_rows(entry: &EmbedEntry, rows: usize) -> std::ops::Range<usize> {
    match &entry.rows {
        Some(range) => range.clone(),
        None => 0..rows,
    }
}

fn accumulate<E: Real>(target: &mut [E], source: &[E]) {
    for (slot, &value) in target.iter_mut().zip(source) {
        *slot += value;
    }
}

impl From<CpuError> for BackendError {
    fn from(error: CpuError) -> Self {
        BackendError::internal(format!("tensor operation failed: {error:?}"))
    }
}
