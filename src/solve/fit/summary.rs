//! What a fit by free runs reports: every unknown with its standard error, the direction
//! the data leave free, the training gap and the information criteria; what counts as
//! identified.

use serde::{Deserialize, Serialize};

/// Relative standard error above which a param counts as poorly identified (in `gbc
/// diagnose` and in training's polish and balance fit).
pub const IDENTIFIABILITY_LIMIT: f64 = 0.05;

/// Relative standard error at or below which an error is round-off, not a statistical one
/// (see [`ParamEstimate::statistical_error`]). The fits' free runs are solved to a relative
/// tolerance of 1e-8 (`diagnose::simulate::tolerances`) and their residuals summed in `f64`:
/// a fit whose error is below a billionth of its value reproduces its data to the solver's
/// and the arithmetic's precision (noise-free data, a rate fixed by an exact balance), so the
/// number measures the arithmetic, and a move divided by it (issue 43: `Y_X` moved 1e-9,
/// "+96721.50 standard errors" of 1e-14) says nothing about the data.
pub const ROUNDING_LEVEL: f64 = 1e-9;

/// A fitted param with its uncertainty: what training's polish and balance fit report,
/// and what `diagnose` reports of its fits.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParamEstimate {
    /// Param name (in `diagnose`, `X@experiment` for a fitted initial value).
    pub name: String,
    /// Fitted value (the declared one when `held`).
    #[serde(with = "crate::json")]
    pub value: f64,
    /// Linearised standard error (infinite when the data do not determine it); `None`
    /// (`null`) when the param is `held`: it was not fitted, so it has none.
    #[serde(with = "crate::json")]
    pub std_error: Option<f64>,
    /// `std_error / |value|` (`None` with it).
    #[serde(with = "crate::json")]
    pub relative_error: Option<f64>,
    /// Whether `relative_error` is below [`IDENTIFIABILITY_LIMIT`]; never for a `held`
    /// param (runs written before the name was shared with `diagnose` call it
    /// `well_identified`).
    #[serde(alias = "well_identified")]
    pub identified: bool,
    /// Whether the param was held at its declared value (pinned along a free direction)
    /// instead of fitted (files written before the field read as `false`).
    #[serde(default)]
    pub held: bool,
}

impl ParamEstimate {
    /// A fitted param with standard error `std_error` (a non-finite one is infinite).
    pub fn fitted(name: String, value: f64, std_error: f64) -> ParamEstimate {
        let std_error = if std_error.is_finite() {
            std_error
        } else {
            f64::INFINITY
        };
        let relative_error = std_error / value.abs().max(1e-300);
        ParamEstimate {
            name,
            value,
            std_error: Some(std_error),
            relative_error: Some(relative_error),
            identified: relative_error < IDENTIFIABILITY_LIMIT,
            held: false,
        }
    }

    /// A param held at `value` instead of fitted: no standard error, not identified.
    pub fn held_at(name: String, value: f64) -> ParamEstimate {
        ParamEstimate {
            name,
            value,
            std_error: None,
            relative_error: None,
            identified: false,
            held: true,
        }
    }

    /// The standard error when it is a statistical one: not held, finite, and above
    /// [`ROUNDING_LEVEL`] of the value (below it, round-off).
    pub fn statistical_error(&self) -> Option<f64> {
        let floor = ROUNDING_LEVEL * self.value.abs();
        (self.std_error).filter(|s| !self.held && s.is_finite() && *s > 0.0 && *s > floor)
    }
}

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
