//! The numeric helpers every stage shares: statistics ([`stats`]), dense linear algebra
//! ([`linalg`]: Cholesky, normal equations; [`lu`]: LU with pivoting, real or complex;
//! [`eigen`]: symmetric eigen-decomposition), one
//! Levenberg–Marquardt driver ([`lm`]), the training element types with the one safe
//! softplus ([`real`]), the one optimiser of training, Adam with clipping ([`adam`]),
//! library-call-free exact rounding ([`rounding`]), and the one tolerance times of a record
//! are compared with ([`times`]).
//!
//! Training (`train::polish`, `train::balances`), the gap diagnosis (`diagnose::fit`,
//! `diagnose::correction`, `diagnose::symbolic`) and the experiments all call these; none
//! keeps a copy of its own. Everything here works on slices (plain `f64`, or the training
//! element types of [`real`]), row-major matrices,
//! and never prints.

pub mod adam;
pub mod eigen;
pub mod linalg;
pub mod lm;
pub mod lu;
pub mod real;
pub mod rounding;
pub mod stats;
pub mod tensor;
pub mod text;
pub mod times;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_lm;
#[cfg(test)]
mod tests_times;

pub use adam::{Adam, AdamState, Update};
pub use eigen::symmetric_eigen;
pub use linalg::{dot, solve_spd, Cholesky, NormalEquations};
#[cfg(test)]
pub use lm::{minimise, Problem};
pub use lm::{Damping, GaussNewton, Settings};
pub use lu::{Complex, Lu};
pub use real::Real;
pub use stats::{mean_std, median, normal_cdf, order_statistic, root_mean_square};
pub use tensor::NamedTensor;
pub use times::{grid_step, time_tolerance, uniform_step, OffGrid};
