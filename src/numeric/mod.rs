//! The numeric helpers every stage shares (statistics; the rest arrives with the numeric
//! branch).

pub mod stats;

pub use stats::{mean_std, median};
