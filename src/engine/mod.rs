//! The engines wing: the two engines that compute training's gradients and what they
//! share, behind one interface.
//!
//! - [`batch`], [`setup`], [`settings`] and [`error`]: what both engines take, are built
//!   from and fail with (batches, the setup and element type, Adam's settings, the one
//!   error type), below everything else here;
//! - [`graph`]: the graph engine, the only module that names `dfdx` (the trainable network
//!   of the paper, its predictions, the ONNX-exportable weights);
//! - [`fused`]: the hand-fused engine (forward and reverse by hand, same results up to
//!   rounding, several times faster);
//! - [`program`] and [`elementwise`]: the physics program both engines run (the balances
//!   with their priors, consts, params and closure outputs) and its element-wise kernels;
//! - [`pairs`] and [`windows`]: the batches both take (one-step pairs, rollout windows);
//! - [`step`]: the [`step::Step`] interface of both engines and the one [`step::Optimiser`]
//!   that owns the weights and Adam's state, with the [`penalty::Penalty`] toward the
//!   mechanism.
//!
//! Training (`crate::train`) stands on this wing; nothing here imports it.

pub mod batch;
pub mod elementwise;
pub mod error;
pub mod fused;
pub mod graph;
pub mod pairs;
pub mod penalty;
pub mod program;
pub mod settings;
pub mod setup;
pub mod step;
pub mod windows;

#[cfg(test)]
pub(crate) mod fixtures;
