//! The trainable grey-box network (the only module that names `dfdx`).
//!
//! [`Network::build`] lowers a compiled [`ir::Model`] and a [`Setup`] (step
//! size, normalisation, closure scales, seed) into the recurrent network of the paper
//! (Lovelett et al. 2020, eq. 4-7): for each batch row the closure networks are evaluated on
//! the delay embedding at the RK4 stage times `t`, `t + h/2`, `t + h` with the stage state
//! estimate as the current state, the physics layer ([`crate::engine::program`]) combines
//! them with priors, consts and params into the balances, and the four stages are combined
//! into `x(t + h)` as RK4's tableau says ([`crate::solve::ode::tableau::RK4`]; optionally in
//! `K` sub-steps of `h / K`). A `next` model is the discrete map `x(t + h) = f(x(t), ...)`.
//! The loss is the mean squared error of the next measured states z-scored with the
//! training split's mean and std; [`TrainStep::train_step`] takes one Adam step on it.
//!
//! Everything public here is plain data: batches, predictions and weights cross this
//! boundary as `f64` vectors, so the graph backend could change without touching callers.
//! The data both engines share ([`crate::engine::batch`], [`crate::engine::setup`],
//! [`crate::engine::settings`], [`crate::engine::error`]) is re-exported here.
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
mod network;
mod tape;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_irregular;
#[cfg(test)]
pub(crate) mod tests_positive;
#[cfg(test)]
mod tests_rollout;

#[cfg(test)]
pub use crate::engine::batch::Feedback;
pub use crate::engine::batch::{Batch, Prediction, RolloutBatch};
pub use crate::engine::error::BackendError;
pub use crate::engine::settings::StepSettings;
pub use crate::engine::setup::{Precision, Setup};
pub use crate::numeric::{AdamState, NamedTensor};
pub use crate::record::Normalisation;
pub use layout::initial_raw_params;
pub use network::Network;
