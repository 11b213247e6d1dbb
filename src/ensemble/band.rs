//! The prediction band of one cell (`docs/uncertainty.md`).
//!
//! The members' free runs give `N` predictions `p_k` of a measured state at a time; a
//! measurement there is modelled as one of them, chosen at random, plus Gaussian noise of
//! standard deviation `sigma(p_k)` (the state's noise, [`super::noise`]): the predictive
//! distribution is the mixture `F(y) = mean_k Phi((y - p_k) / sigma(p_k))`. Its *base* band
//! is the central [`BASE_LEVEL`] interval of `F` around the members' median `m`, as the two
//! half-widths `m - F^-1(0.05)` and `F^-1(0.95) - m`.
//!
//! The band at level `L` stretches both half-widths by one factor `c_L`, chosen so that `L`
//! of the calibration cells fall inside ([`calibrated_factor`], split-conformal): a cell's
//! *score* is how many base half-widths it lies from `m` on its side ([`BaseBand::score`]),
//! and `c_L` is the `ceil((n + 1) L)`-th smallest of the `n` calibration scores.
//!
//! A state declared `nonnegative` has a *floor* (0): its measurement is the Gaussian draw
//! censored there (a draw below reads as the floor, [`crate::ensemble::noise`]), so every
//! quantile of `F` is the uncensored one raised to the floor, a measured value is scored
//! and counted as the censored reading `max(y, floor)`, and the stretched band is cut at
//! the floor ([`BaseBand::stretched`]). Cutting changes no cell's inside or outside: the
//! censored reading is never below the floor. So the calibration is the same
//! split-conformal quantile, of the censored readings' scores.

use crate::numeric::{median, normal_cdf};

/// The level of the base band whose half-widths the calibrated factor multiplies.
pub const BASE_LEVEL: f64 = 0.9;

/// One member's prediction of a cell with its noise: `(prediction, sigma)`.
pub type Draw = (f64, f64);

/// The base band of one cell: the members' median and the base half-widths below and
/// above it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaseBand {
    /// The members' median prediction.
    pub median: f64,
    /// `median - F^-1((1 - BASE_LEVEL) / 2)`, never negative.
    pub below: f64,
    /// `F^-1((1 + BASE_LEVEL) / 2) - median`, never negative.
    pub above: f64,
    /// The floor of a state declared `nonnegative` (0), where the measurement is censored;
    /// `-inf` for none.
    pub floor: f64,
}

impl BaseBand {
    /// The base band of the mixture of `draws`; `None` without a finite draw.
    pub fn of(draws: &[Draw]) -> Option<BaseBand> {
        Self::floored(draws, None)
    }

    /// The base band of the mixture of `draws` with each measurement censored at `floor`
    /// (none: not censored): both quantiles raised to the floor; `None` without a finite
    /// draw.
    pub fn floored(draws: &[Draw], floor: Option<f64>) -> Option<BaseBand> {
        let floor = floor.unwrap_or(f64::NEG_INFINITY);
        let finite: Vec<Draw> = (draws.iter().copied())
            .filter(|(p, s)| p.is_finite() && s.is_finite() && *s >= 0.0)
            .collect();
        let predictions: Vec<f64> = finite.iter().map(|d| d.0).collect();
        let median = median(&predictions)?;
        let tail = (1.0 - BASE_LEVEL) / 2.0;
        let lower = mixture_quantile(&finite, tail)?.max(floor);
        let upper = mixture_quantile(&finite, 1.0 - tail)?.max(floor);
        Some(BaseBand {
            median,
            below: (median - lower).max(0.0),
            above: (upper - median).max(0.0),
            floor,
        })
    }

    /// How many base half-widths the reading of `measured` (censored at the floor) lies
    /// from the median, on its side (0 at the median; infinite off a side of zero width).
    pub fn score(&self, measured: f64) -> f64 {
        let measured = measured.max(self.floor);
        let (distance, width) = if measured >= self.median {
            (measured - self.median, self.above)
        } else {
            (self.median - measured, self.below)
        };
        if distance == 0.0 {
            0.0
        } else if width > 0.0 {
            distance / width
        } else {
            f64::INFINITY
        }
    }

    /// The band with both half-widths stretched by `factor`, cut at the floor: `(lo, hi)`.
    pub fn stretched(&self, factor: f64) -> (f64, f64) {
        (
            (self.median - factor * self.below).max(self.floor),
            (self.median + factor * self.above).max(self.floor),
        )
    }

    /// Whether the band stretched by `factor` holds the reading of `measured` (censored at
    /// the floor).
    pub fn covers(&self, factor: f64, measured: f64) -> bool {
        inside(self.stretched(factor), measured.max(self.floor))
    }
}

/// The mixture's distribution function at `y`: the mean over draws of
/// `Phi((y - p) / sigma)` (a step at `p` where `sigma` is 0).
pub fn mixture_cdf(draws: &[Draw], y: f64) -> f64 {
    let one = |&(p, sigma): &Draw| {
        if sigma > 0.0 {
            normal_cdf((y - p) / sigma)
        } else if y >= p {
            1.0
        } else {
            0.0
        }
    };
    draws.iter().map(one).sum::<f64>() / draws.len().max(1) as f64
}

/// The smallest `y` with `mixture_cdf(y) >= q` (to a relative `1e-12` of the draws' span),
/// by bisection between where every component is below and above; `None` without draws.
pub fn mixture_quantile(draws: &[Draw], q: f64) -> Option<f64> {
    if draws.is_empty() {
        return None;
    }
    let reach = |(p, sigma): &Draw, side: f64| p + side * 12.0 * sigma;
    let mut low = draws
        .iter()
        .map(|d| reach(d, -1.0))
        .fold(f64::MAX, f64::min);
    let mut high = draws.iter().map(|d| reach(d, 1.0)).fold(f64::MIN, f64::max);
    let tolerance = 1e-12
        * (high - low)
            .abs()
            .max(low.abs().max(high.abs()))
            .max(1e-300);
    if mixture_cdf(draws, low) >= q {
        return Some(low);
    }
    for _ in 0..200 {
        if high - low <= tolerance {
            break;
        }
        let middle = 0.5 * (low + high);
        if mixture_cdf(draws, middle) >= q {
            high = middle;
        } else {
            low = middle;
        }
    }
    Some(high)
}

/// The split-conformal factor at `level` from calibration `scores`: the
/// `ceil((n + 1) level)`-th smallest of the `n` scores; `None` where that exceeds `n` (too
/// few cells to calibrate the level: fewer than `level / (1 - level)`) or the factor is not
/// finite.
pub fn calibrated_factor(scores: &[f64], level: f64) -> Option<f64> {
    let mut sorted: Vec<f64> = scores.iter().copied().filter(|s| !s.is_nan()).collect();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    let rank = ((n + 1) as f64 * level).ceil() as usize;
    if rank == 0 || rank > n {
        return None;
    }
    Some(sorted[rank - 1]).filter(|f| f.is_finite())
}

/// Whether a measured value lies inside a band (ends included).
pub fn inside((lo, hi): (f64, f64), measured: f64) -> bool {
    lo <= measured && measured <= hi
}
