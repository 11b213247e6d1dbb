//! The numeric helpers every stage shares: statistics ([`stats`]), dense linear algebra
//! ([`linalg`]: Cholesky, normal equations; [`eigen`]: symmetric eigen-decomposition) and one
//! Levenberg–Marquardt driver ([`lm`]).
//!
//! Training (`train::polish`, `train::balances`), the gap diagnosis (`diagnose::fit`,
//! `diagnose::correction`, `diagnose::symbolic`) and the experiments all call these; none
//! keeps a copy of its own. Everything here is plain `f64` on slices, row-major matrices,
//! and never prints.

pub mod eigen;
pub mod linalg;
pub mod lm;
pub mod stats;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_lm;

pub use eigen::symmetric_eigen;
pub use linalg::{dot, solve_spd, Cholesky, NormalEquations};
pub use lm::{minimise, Damping, GaussNewton, Linearisation, Outcome, Problem, Settings};
pub use stats::{mean_std, median, order_statistic, root_mean_square};
