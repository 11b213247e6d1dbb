//! Named arrays of `f64`: what network weights and raw params are as plain data, between
//! the engines, the run files, the finite checks and the export.

/// A named array of trainable values (network weights, raw params).
#[derive(Debug, Clone, PartialEq)]
pub struct NamedTensor {
    /// Name, e.g. `closure.r.layer0.weight` or `params`.
    pub name: String,
    /// Dimensions.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub values: Vec<f64>,
}
