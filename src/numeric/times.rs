//! How closely the times of one record can be compared: a tolerance fitted to the record,
//! and the uniform grid it implies (issue 24: a plate reader's times jitter by about
//! `1e-7` h around a uniform grid, and must train as their rounded version does).
//!
//! The tolerance ([`time_tolerance`]) is the distance below which two times of the record
//! are the same time. It is the largest of
//!
//! - the printed precision of the times: one unit of the last decimal written (a time read
//!   as `0.166666736` is known to `1e-9`), taken from the shortest decimal that gives each
//!   time back, where that is finer than the cap below (whole numbers on a grid of step 1
//!   are not known to 1 only because they were written without decimals);
//! - [`SCATTER_FACTOR`] times the interquartile range of the steps (times that jitter
//!   uniformly by `a` around a grid give steps within `2a` of it and an interquartile range
//!   of about `1.2 a`; a Gaussian jitter of deviation `s`, steps rarely beyond `5 s` and a
//!   range of about `1.9 s`; a missing row or an irregular step now and then does not move
//!   a quartile; not counted below [`MIN_SCATTER_STEPS`] steps);
//! - [`FLOOR_SHARE`] of the median step (the relative tolerance used before);
//!
//! bounded by [`CAP_SHARE`] of the median step, plus a few ulps of the largest time. Every
//! comparison of times in a record (is it uniform, is an interval longer than the step, is
//! a gap within a state's limit, which knot does a time fall on, where does the embedding's
//! history end) uses this one tolerance.

use super::stats::{median, order_statistic};

/// The scatter term of the tolerance, in interquartile ranges of the steps.
pub const SCATTER_FACTOR: f64 = 4.0;

/// The fewest steps whose scatter says something about a jitter (with fewer, one odd step
/// would be a quartile).
pub const MIN_SCATTER_STEPS: usize = 8;

/// The least tolerance, as a share of the median step.
pub const FLOOR_SHARE: f64 = 1e-6;

/// The largest tolerance, as a share of the median step: times that scatter more than this
/// are irregular, whatever their scatter.
pub const CAP_SHARE: f64 = 1e-2;

/// The most decimals a printed time is taken to carry (beyond, the time was computed).
const MAX_DECIMALS: i32 = 20;

/// The distance below which two times of `times` are the same time (see the module's
/// documentation); rounding noise alone (a few ulps) for fewer than two times.
pub fn time_tolerance(times: &[f64]) -> f64 {
    let magnitude = times.iter().fold(0.0_f64, |m, t| m.max(t.abs()));
    let ulps = 8.0 * f64::EPSILON * magnitude;
    let steps: Vec<f64> = times.windows(2).map(|pair| pair[1] - pair[0]).collect();
    let Some(typical) = median(&steps) else {
        return ulps;
    };
    let quartile = |fraction| order_statistic(&steps, fraction).unwrap_or(typical);
    let scatter = if steps.len() >= MIN_SCATTER_STEPS {
        quartile(0.75) - quartile(0.25)
    } else {
        0.0
    };
    let cap = CAP_SHARE * typical.abs();
    let quantum = decimal_quantum(times);
    let precision = if quantum <= cap { quantum } else { 0.0 };
    let fitted = (precision.max(SCATTER_FACTOR * scatter)).max(FLOOR_SHARE * typical.abs());
    fitted.min(cap) + ulps
}

/// One unit of the last decimal of the most finely printed time: `1e-9` for times written
/// with nine decimals, `1` for whole numbers (1 for no times).
pub fn decimal_quantum(times: &[f64]) -> f64 {
    let decimals = times.iter().map(|&t| decimals(t)).max();
    10f64.powi(-decimals.unwrap_or(0))
}

/// The decimals after the point of the shortest decimal that gives `t` back (0 for whole
/// numbers), at most [`MAX_DECIMALS`].
fn decimals(t: f64) -> i32 {
    if t == 0.0 || !t.is_finite() {
        return 0;
    }
    let text = format!("{t:e}");
    let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    let fraction = mantissa.split_once('.').map_or(0, |(_, f)| f.len()) as i32;
    (fraction - exponent).clamp(0, MAX_DECIMALS)
}

/// Where `times` leave their uniform grid: into `sample`, a step of `expected` was typical.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffGrid {
    /// The sample that is off the grid (its step from the one before is not typical, or it
    /// lies off the line through the first and last times).
    pub sample: usize,
    /// The typical (median) step.
    pub expected: f64,
}

/// The mean step of `times` when they lie on a uniform grid within `tolerance`: every step
/// within `tolerance` of the median step, and every time within `tolerance` of the line
/// through the first and last times (no drift). `Ok(None)` for fewer than two times; the
/// first sample off the grid otherwise.
pub fn grid_step(times: &[f64], tolerance: f64) -> Result<Option<f64>, OffGrid> {
    let steps: Vec<f64> = times.windows(2).map(|pair| pair[1] - pair[0]).collect();
    let Some(typical) = median(&steps) else {
        return Ok(None);
    };
    let off = |sample: usize| OffGrid {
        sample,
        expected: typical,
    };
    if let Some(index) = steps.iter().position(|s| (s - typical).abs() > tolerance) {
        return Err(off(index + 1));
    }
    let (first, last) = (times[0], times[times.len() - 1]);
    let mean = (last - first) / steps.len() as f64;
    let drift = (times.iter().enumerate())
        .position(|(i, &t)| (t - (first + i as f64 * mean)).abs() > tolerance);
    match drift {
        Some(sample) => Err(off(sample)),
        None => Ok(Some(mean)),
    }
}

/// The mean step of `times` when they lie on a uniform grid within their own fitted
/// tolerance ([`time_tolerance`], [`grid_step`]); `None` for irregular times or fewer than
/// two.
pub fn uniform_step(times: &[f64]) -> Option<f64> {
    grid_step(times, time_tolerance(times)).ok().flatten()
}
