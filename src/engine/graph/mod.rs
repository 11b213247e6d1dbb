//! The trainable grey-box network (the only module that names `dfdx`).
//!
//! [`Network::build`] lowers a compiled [`ir::Model`] and a [`Setup`] (step
//! size, normalisation, closure scales, seed) into the recurrent network of the paper
//! (Lovelett et al. 2020, eq. 4-7): for each batch row the closure networks are evaluated on
//! the delay embedding at the RK4 stage times `t`, `t + h/2`, `t + h` with the stage state
//! estimate as the current state, the physics layer ([`program`]) combines them with priors,
//! consts and params into the balances, and the four stages are combined into `x(t + h)`
//! (optionally in `K` sub-steps of `h / K`). A `next` model is the discrete map
//! `x(t + h) = f(x(t), ...)`. The loss is the mean squared error of the next measured states
//! z-scored with the training split's mean and std; [`Network::train_step`] takes one Adam
//! step on it.
//!
//! Everything public here is plain data: batches, predictions and weights cross this
//! boundary as `f64` vectors, so the graph backend could change without touching callers.
//!
//! Meaning of closure outputs (spec section 3), with network output `n` and magnitude `s`:
//! no prior `o = s n`; `prior o *= p`: `o = p (1 + n)`; `prior o += p`: `o = p + s n`. A
//! `positive` output without a prior is then mapped through `s softplus(o / s)` and an
//! `in [lo, hi]` output through `lo + (hi - lo) sigmoid(4 (o - mid) / (hi - lo))` (unit
//! slope at the middle). A `positive` output with a prior keeps it exactly at `n = 0` and
//! vanishes with it: `max(p, 0) g(n)` with `g(n) = max(n + 7/8, 0) + exp(8 min(0, n + 7/8)) / 8` under `*=`,
//! `max(p + s n, 0)` under `+=` (`program::outputs`).
//! Params are trained unconstrained: `positive` through softplus (initialised at the
//! inverse softplus of the guess), `in [lo, hi]` through `lo + (hi - lo) sigmoid`.

pub mod layout;
mod net;
mod tape;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_irregular;
#[cfg(test)]
pub(crate) mod tests_positive;
#[cfg(test)]
mod tests_rollout;

use std::ops::Range;

use crate::ir;

pub use crate::numeric::AdamState;

/// The unconstrained starting values of the model's params (their transforms give the
/// declared initial guesses), as [`program::Program`] reads them.
pub fn initial_raw_params(model: &ir::Model) -> Vec<f64> {
    model
        .params
        .iter()
        .map(layout::raw_initial_value::<f64>)
        .collect()
}

/// The element type the network trains in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// 32-bit floats (faster).
    #[default]
    F32,
    /// 64-bit floats.
    F64,
}

impl Precision {
    /// The name in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

pub use crate::record::Normalisation;

/// Everything besides the model that fixes the network.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    /// The nominal step `h`: the integration grid's longest step (`--dt`; the sampling step
    /// of a uniform record), taken by batch rows that give no step of their own.
    pub step: f64,
    /// RK4 sub-steps per sample (1 = the paper's single step).
    pub substeps: usize,
    /// Element type.
    pub precision: Precision,
    /// Seed of the weight initialisation.
    pub seed: u64,
    /// Normalisation of embeddings and loss.
    pub normalisation: Normalisation,
    /// Magnitude `s_o` of every closure output, `scales[closure][output]`.
    pub scales: Vec<Vec<f64>>,
}

impl Setup {
    /// Number of distinct stage times per step at which embeddings are needed: `2K + 1`
    /// (offsets `m h / 2K`, `m = 0..=2K`) for `der` models, 1 for `next` models.
    pub fn stage_offsets(&self, dynamics: ir::Dynamics) -> usize {
        match dynamics {
            ir::Dynamics::Continuous => 2 * self.substeps.max(1) + 1,
            ir::Dynamics::Discrete => 1,
        }
    }
}

/// A batch of one-step pairs, row-major.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Batch {
    /// Number of pairs.
    pub rows: usize,
    /// `rows x (measured + hidden)` states at `t`.
    pub states: Vec<f64>,
    /// `rows x inputs`: the inputs held over the step.
    pub inputs: Vec<f64>,
    /// `embeddings[closure][offset]`: `rows x width` raw (physical-unit) values of the
    /// embedding layout at stage time `t + offset * h / 2K`; lag-0 state entries are
    /// ignored (the stage estimate replaces them).
    pub embeddings: Vec<Vec<Vec<f64>>>,
    /// `rows x measured` states at `t + h` (may be empty when only predicting).
    pub targets: Vec<f64>,
    /// The step `h` of each row (irregular grids); empty: every row steps
    /// [`Setup::step`].
    pub step_sizes: Vec<f64>,
    /// `rows x measured` loss weight of each target cell: 0 where the cell was not
    /// measured, else the column's weight; empty: every cell weighs 1. The loss is
    /// `sum(w r^2) / #(w > 0)` over the z-scored residuals `r` of every weighted cell,
    /// states and observables together.
    pub weights: Vec<f64>,
    /// `rows x observables` measured values at `t + h` of the model outputs the
    /// normalisation lists as observables (empty for a model without any).
    pub observed: Vec<f64>,
    /// `rows x observables` loss weights of `observed` (0: not measured).
    pub observed_weights: Vec<f64>,
}

/// A predicted state fed back into a later step's embedding: at a rollout step, network
/// input `column` of a closure in each batch row of `rows` gains `weight` times state
/// `state` as predicted `sample` steps into that row's window (linear interpolation between
/// predicted samples; `sample >= 1`, sample 0 being the data the window starts from).
/// Windows that read their predictions alike (on a uniform track, every window of the same
/// length) share one entry over their rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Feedback {
    /// Batch rows (windows) it applies to.
    pub rows: std::ops::Range<usize>,
    /// Network input column of the closure.
    pub column: usize,
    /// Steps into the window of the predicted state (at least 1).
    pub sample: usize,
    /// Index of the measured state.
    pub state: usize,
    /// Interpolation weight (physical units; the backend normalises).
    pub weight: f64,
}

impl Feedback {
    /// Whether the entry names at least one row and no row outside a batch of `rows`.
    pub fn fits(&self, rows: usize) -> bool {
        self.rows.start < self.rows.end && self.rows.end <= rows
    }
}

/// A batch of free-run windows of `steps` steps, row-major per step: each window starts
/// at measured (and hidden-state) values and is stepped `steps` times, the network fed its
/// own predictions through the state and, by [`Feedback`], through the delay embedding.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RolloutBatch {
    /// Number of windows.
    pub rows: usize,
    /// Steps per window.
    pub steps: usize,
    /// `rows x (measured + hidden)` states at the window start.
    pub states: Vec<f64>,
    /// `inputs[step]`: `rows x inputs` held over that step.
    pub inputs: Vec<Vec<f64>>,
    /// `embeddings[step][closure][offset]`: `rows x width` raw embedding values from the
    /// data, with every share that a [`Feedback`] supplies left at zero (lag-0 state
    /// entries are ignored, as in [`Batch`]).
    pub embeddings: Vec<Vec<Vec<Vec<f64>>>>,
    /// `feedback[step][closure][offset]`: the predicted shares of every row.
    pub feedback: Vec<Vec<Vec<Vec<Feedback>>>>,
    /// `targets[step]`: `rows x measured` states after that step (empty when predicting).
    pub targets: Vec<Vec<f64>>,
    /// `step_sizes[step]`: the step `h` of each row (empty: [`Setup::step`] everywhere).
    pub step_sizes: Vec<Vec<f64>>,
    /// `weights[step]`: `rows x measured` loss weights as in [`Batch::weights`] (empty:
    /// every cell weighs 1).
    pub weights: Vec<Vec<f64>>,
    /// `observed[step]`: `rows x observables` as in [`Batch::observed`].
    pub observed: Vec<Vec<f64>>,
    /// `observed_weights[step]`: their loss weights.
    pub observed_weights: Vec<Vec<f64>>,
}

/// A batch of the training loss: one-step pairs or rollout windows.
#[derive(Debug, Clone, Copy)]
pub enum StepBatch<'a> {
    /// One-step pairs.
    Pairs(&'a Batch),
    /// Rollout windows.
    Windows(&'a RolloutBatch),
}

/// How one optimiser step is taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSettings {
    /// Adam learning rate of the network weights.
    pub learning_rate: f64,
    /// Adam learning rate of the raw params.
    pub param_learning_rate: f64,
    /// Rescale the whole gradient to at most this Euclidean norm (none: no clipping).
    pub max_gradient_norm: Option<f64>,
}

impl StepSettings {
    /// One learning rate for everything, no clipping.
    pub fn plain(learning_rate: f64) -> Self {
        StepSettings {
            learning_rate,
            param_learning_rate: learning_rate,
            max_gradient_norm: None,
        }
    }

    /// The optimiser's groups over `size` weights back to back: the params (at `params`,
    /// when the model has any) at their own rate, everything else at the network's.
    pub fn groups(&self, size: usize, params: Option<Range<usize>>) -> Vec<(Range<usize>, f64)> {
        match params {
            Some(params) => vec![
                (0..params.start, self.learning_rate),
                (params.start..params.end, self.param_learning_rate),
                (params.end..size, self.learning_rate),
            ],
            None => vec![(0..size, self.learning_rate)],
        }
    }
}

/// One-step predictions for a batch.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// `rows x (measured + hidden)` predicted states at `t + h`.
    pub next_states: Vec<f64>,
    /// `rows x (all closure outputs)` at `t`, from the states at `t`.
    pub closure_outputs: Vec<f64>,
    /// `rows x (model outputs)` at `t`.
    pub outputs: Vec<f64>,
    /// `rows x observables` measured outputs at `t + h`, at the predicted state (empty for
    /// a model without observables).
    pub observed: Vec<f64>,
}

pub use crate::numeric::NamedTensor;

/// Why the network could not be built or run.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum BackendError {
    /// A bug: inconsistent model or batch.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Internal(#[from] crate::error::Bug),
    /// A model the chosen engine cannot run.
    #[error("expected a model the {engine} engine runs, found {what}")]
    #[diagnostic(
        code(gbm::E0402),
        help("train with `--engine graph`, which runs every model")
    )]
    Unsupported {
        /// The engine.
        engine: String,
        /// What it lacks.
        what: String,
    },
    /// Saved weights do not fit the model.
    #[error("expected weights for this model, found {0}")]
    #[diagnostic(
        code(gbm::E0401),
        help("use the weights trained with this model, or train it again")
    )]
    WeightsMismatch(String),
    /// A free run asked to stop (Ctrl-C, SIGTERM; [`crate::stop`]) before its end.
    #[error("the free run was stopped (Ctrl-C or SIGTERM) before its end")]
    #[diagnostic(
        code(gbm::E0719),
        help("the run was asked to stop before its end; run it again to the end")
    )]
    Stopped,
}

impl BackendError {
    /// An internal error with a message.
    pub fn internal(message: impl Into<String>) -> Self {
        BackendError::Internal(crate::error::Bug::new("the trainable network", message))
    }
}

/// The trainable network in the chosen precision, with its Adam state.
pub struct Network {
    inner: Inner,
}

enum Inner {
    Single(net::GreyBox<f32>),
    Double(net::GreyBox<f64>),
}

/// Runs `$body` with `$net` bound to whichever precision the caller's `Inner::Single` /
/// `Inner::Double` value holds (the network here and the fused step share that shape).
macro_rules! dispatch {
    ($self:expr, $net:ident => $body:expr) => {
        match &$self.inner {
            Inner::Single($net) => $body,
            Inner::Double($net) => $body,
        }
    };
    (mut $self:expr, $net:ident => $body:expr) => {
        match &mut $self.inner {
            Inner::Single($net) => $body,
            Inner::Double($net) => $body,
        }
    };
}
pub(crate) use dispatch;

impl Network {
    /// Lowers `model` into a trainable network with freshly initialised weights.
    pub fn build(model: &ir::Model, setup: &Setup) -> Result<Network, BackendError> {
        let inner = match setup.precision {
            Precision::F32 => Inner::Single(net::GreyBox::build(model, setup)?),
            Precision::F64 => Inner::Double(net::GreyBox::build(model, setup)?),
        };
        Ok(Network { inner })
    }

    /// One Adam step on the batch's loss; returns the loss before the step.
    pub fn train_step(&mut self, batch: &Batch, learning_rate: f64) -> Result<f64, BackendError> {
        self.train_step_with(batch, &StepSettings::plain(learning_rate))
    }

    /// One Adam step on the batch's loss with separate param learning rate and optional
    /// gradient clipping; returns the loss before the step.
    pub fn train_step_with(
        &mut self,
        batch: &Batch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        dispatch!(mut self, net => net.train_step(batch, settings))
    }

    /// One Adam step on the mean normalised squared error over every step of every
    /// window of a rollout batch (gradients through the whole rollout); returns the loss
    /// before the step.
    pub fn rollout_step(
        &mut self,
        batch: &RolloutBatch,
        settings: &StepSettings,
    ) -> Result<f64, BackendError> {
        dispatch!(mut self, net => net.rollout_step(batch, settings))
    }

    /// The rollout loss of a batch (see [`Network::rollout_step`]).
    pub fn rollout_loss(&self, batch: &RolloutBatch) -> Result<f64, BackendError> {
        dispatch!(self, net => net.rollout_loss(batch))
    }

    /// The rollout loss and its gradient with respect to every tensor of
    /// [`Network::weights`].
    pub fn rollout_gradient(
        &self,
        batch: &RolloutBatch,
    ) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        dispatch!(self, net => net.rollout_gradient(batch))
    }

    /// The states after each step of each window: `[step]` of `rows x (measured + hidden)`.
    pub fn rollout_predict(&self, batch: &RolloutBatch) -> Result<Vec<Vec<f64>>, BackendError> {
        dispatch!(self, net => net.rollout_predict(batch))
    }

    /// The normalised one-step loss of a batch.
    pub fn loss(&self, batch: &Batch) -> Result<f64, BackendError> {
        dispatch!(self, net => net.loss(batch))
    }

    /// The loss and its gradient with respect to every tensor of [`Network::weights`].
    pub fn gradient(&self, batch: &Batch) -> Result<(f64, Vec<Vec<f64>>), BackendError> {
        dispatch!(self, net => net.gradient(batch))
    }

    /// One-step predictions (no targets needed).
    pub fn predict(&self, batch: &Batch) -> Result<Prediction, BackendError> {
        dispatch!(self, net => net.predict(batch))
    }

    /// The trainable tensors: each closure's layers, then the raw params (if any).
    pub fn weights(&self) -> Vec<NamedTensor> {
        dispatch!(self, net => net.weights())
    }

    /// Replaces the trainable tensors (names and shapes must match [`Network::weights`]).
    pub fn set_weights(&mut self, weights: &[NamedTensor]) -> Result<(), BackendError> {
        dispatch!(mut self, net => net.set_weights(weights))
    }

    /// Replaces the trainable values from one flat vector (the tensors of
    /// [`Network::weights`] back to back).
    pub fn set_flat_weights(&mut self, flat: &[f64]) -> Result<(), BackendError> {
        dispatch!(mut self, net => net.set_flat_weights(flat))
    }

    /// The constrained values of the model's params, in declaration order.
    pub fn param_values(&self) -> Vec<f64> {
        dispatch!(self, net => net.param_values())
    }

    /// RK4 sub-steps per call (1 for `next` models).
    pub fn substeps(&self) -> usize {
        dispatch!(self, net => net.substeps())
    }

    /// The same network taking `substeps` RK4 sub-steps per call (weights copied, a fresh
    /// optimiser).
    pub fn with_substeps(&self, substeps: usize) -> Network {
        let inner = match &self.inner {
            Inner::Single(net) => Inner::Single(net.with_substeps(substeps)),
            Inner::Double(net) => Inner::Double(net.with_substeps(substeps)),
        };
        Network { inner }
    }
}
