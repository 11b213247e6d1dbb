//! The plain data both engines take and give: batches of one-step pairs and of rollout
//! windows, the predicted states fed back into a window's embeddings, and one-step
//! predictions. Everything crosses this boundary as `f64` vectors.

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
    /// [`Setup::step`](crate::engine::setup::Setup::step).
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
    /// `step_sizes[step]`: the step `h` of each row (empty:
    /// [`Setup::step`](crate::engine::setup::Setup::step) everywhere).
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
