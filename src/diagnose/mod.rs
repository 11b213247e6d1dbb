//! Sim-to-real gap diagnosis (`gbc diagnose`, spec section 5): a mechanistic model against
//! a data set of experiments (irregular times, missing cells). Method and worked examples:
//! `docs/diagnose.md`.
//!
//! 1. **Gap.** The model's `param`s (and starts no cell or declaration gives) are fitted on
//!    the training parts ([`fit`]: Levenberg–Marquardt on the z-scored free-run residuals
//!    at measured cells, restarts spent where the starts disagree, standard errors and the
//!    direction the data leave free from [`uncertainty`]); the held-out free runs give the
//!    gap, per measured state its share, free-run (online) and one-step (offline) errors.
//!    The noise floor ([`noise`]) says what a perfect model would score.
//! 2. **Where.** A free correction is added at each `let`, each group of lets sharing an
//!    input and a form ([`graph`]) and each balance ([`locus`]), once seeing the present
//!    only and once a fading memory whose span is chosen from the data ([`memory`]); the
//!    held-out gap it leaves bounds what any mechanism there can achieve. Windows and
//!    regime ([`evaluate`]) say when and where the error lies; a sparse regression
//!    ([`symbolic`]) proposes formulas for the correction.
//! 3. **Which and how far.** Every `effect` is applied alone, all params fitted, and ranked
//!    by held-out gap with a block-bootstrap uncertainty ([`effects`], [`ranking`]); forward
//!    selection ([`selection`]) credits several effects in order while each pays for its
//!    params on held-out data.

mod assemble;
mod candidates;
mod context;
mod correction;
mod effects;
mod error;
mod evaluate;
mod features;
mod graph;
pub mod html;
mod locus;
pub mod memory;
mod ranking;
mod refine;
pub mod render;
mod report;
mod selection;
mod steps;
mod symbolic;

pub use crate::solve::fit::split::MIN_ROWS;
pub use context::{Options, Problem, Progress};
#[cfg(test)]
pub use context::{DEFAULT_TAIL, SIGNIFICANCE};
pub use error::DiagnoseError;
pub use report::*;
pub use steps::diagnose;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_held;
#[cfg(test)]
mod tests_jacobian;
#[cfg(test)]
mod tests_json;
#[cfg(test)]
mod tests_lab;
#[cfg(test)]
mod tests_refit;
#[cfg(test)]
mod tests_sets;
