//! What a fit by free runs reports: every unknown with its standard error, the direction
//! the data leave free, the training gap and the information criteria.

use serde::{Deserialize, Serialize};

use super::uncertainty::ParamEstimate;

/// How a fit went: params with uncertainty, the direction the data leave free, criteria.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct FitSummary {
    /// Every fitted unknown with its standard error.
    pub estimates: Vec<ParamEstimate>,
    /// When some param is not identified: the direction in which the fit is (nearly) free,
    /// as unit-normalised components in transformed coordinates (logarithms of `positive`
    /// params), largest first.
    #[serde(with = "crate::json")]
    pub free_direction: Vec<(String, f64)>,
    /// Training gap.
    #[serde(with = "crate::json")]
    pub gap_train: f64,
    /// Akaike's criterion on the training cells: `n ln(RSS / n) + 2 k`.
    #[serde(with = "crate::json")]
    pub aic: f64,
    /// Schwarz's (Bayesian) criterion: `n ln(RSS / n) + k ln n`.
    #[serde(with = "crate::json")]
    pub bic: f64,
    /// Fitted unknowns `k`.
    pub unknowns: usize,
    /// Starts run (the first and the random restarts spent).
    pub starts: usize,
    /// Seconds the fit took.
    #[serde(with = "crate::json")]
    pub seconds: f64,
    /// Unknowns held at their declared values because the fit left a direction free along
    /// them and holding them kept the gap (name, value); not counted in `unknowns`.
    #[serde(default, with = "crate::json")]
    pub pinned: Vec<(String, f64)>,
}
