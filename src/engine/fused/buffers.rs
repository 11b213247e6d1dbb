//! The buffers the fused kernel keeps from batch to batch: what each stage evaluation
//! keeps for the reverse pass ([`Stage`]), the reverse pass's own ([`Scratch`]), and what
//! each step of a loaded window reads ([`StepData`], with its checked feedback).

use crate::engine::program::ReverseScratch;

/// What one stage evaluation keeps for the reverse pass.
#[derive(Debug, Default)]
pub(super) struct Stage<E> {
    /// The step of the window the stage belongs to.
    pub step: usize,
    /// Index of the stage time (into each closure's embeddings).
    pub offset: usize,
    /// `rows x states`: the state estimate the stage is evaluated at.
    pub state: Vec<E>,
    /// `layers[closure][l]`: the activations leaving layer `l` (`l >= 1`; entry 0 unused);
    /// the last entry is the network output.
    pub layers: Vec<Vec<Vec<E>>>,
    /// `slopes[closure][l]`: the activation's slope at hidden layer `l + 1`.
    pub slopes: Vec<Vec<Vec<E>>>,
    /// Register values of the physics program.
    pub values: Vec<E>,
    /// `rows x states`: the balances (or next values of a `next` model).
    pub balances: Vec<E>,
}

/// Buffers of the reverse pass, kept from step to step.
#[derive(Debug, Default)]
pub(super) struct Scratch<E> {
    /// `offset_deltas[closure][stage time]`: first-layer deltas summed over the stages at
    /// that time (`rows x widths[1]`).
    pub offset_deltas: Vec<Vec<Vec<E>>>,
    /// The adjoints of the stages' balances of the sub-step being reversed.
    pub stage_seeds: Vec<Vec<E>>,
    /// `rows x widths[0]`: the gradient of one closure's network input at one stage time
    /// (for the predictions a rollout feeds back).
    pub input_gradient: Vec<E>,
    /// The gradient being passed down a network.
    pub delta: Vec<E>,
    /// The gradient of the layer below it.
    pub below: Vec<E>,
    /// The stage estimate in the lag-0 state columns (`rows x columns`).
    pub estimate: Vec<E>,
    /// The first-layer weights of those columns (`columns x widths[1]`).
    pub estimate_weights: Vec<E>,
    /// The gradient of the estimate.
    pub estimate_gradient: Vec<E>,
    /// The gradient of those weights.
    pub estimate_weight_gradient: Vec<E>,
    /// The physics program's reverse sweep.
    pub physics: ReverseScratch<E>,
}

/// What one step of a loaded window reads.
#[derive(Debug, Default)]
pub(super) struct StepData<E> {
    /// `rows x inputs` held over the step.
    pub inputs: Vec<E>,
    /// `constants[closure][offset]`: the normalised embedding (lag-0 state entries
    /// `-mean/std`), plus the fed-back predictions once the step has run.
    pub constants: Vec<Vec<Vec<E>>>,
    /// The sub-step `h / K` of each row.
    pub substep_sizes: Vec<f64>,
    /// `rows x measured` targets.
    pub targets: Vec<E>,
    /// `rows x measured` loss weights (empty: every cell weighs 1).
    pub loss_weights: Vec<E>,
    /// The predicted states fed into the step's embeddings.
    pub feedback: Vec<FedBack<E>>,
}

/// A checked [`Feedback`](crate::engine::batch::Feedback) entry of one step.
#[derive(Debug, Clone, Copy)]
pub(super) struct FedBack<E> {
    /// The closure whose network input it enters.
    pub closure: usize,
    /// The stage time it enters at.
    pub offset: usize,
    /// The first of its batch rows, `first..end`.
    pub first: usize,
    /// The end of its batch rows.
    pub end: usize,
    /// The network input column.
    pub column: usize,
    /// Index into the trajectory (`1..=step`).
    pub sample: usize,
    /// The predicted state it reads.
    pub state: usize,
    /// `weight / std` of the column.
    pub factor: E,
}
