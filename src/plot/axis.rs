//! Axes: "nice" tick positions, compact tick labels, and the map from data values to
//! pixels on a linear or logarithmic scale.

/// A number formatted compactly for tick labels.
pub fn tick_label(value: f64) -> String {
    if value == 0.0 {
        return "0".to_string();
    }
    let magnitude = value.abs();
    if !(1e-3..1e5).contains(&magnitude) {
        return format!("{value:.0e}");
    }
    let text = format!("{value:.4}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    text.to_string()
}

/// "Nice" tick positions covering `[lo, hi]` on a linear axis (steps of 1, 2 or 5 x 10^k).
pub fn linear_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * power);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// Ticks covering `[lo, hi]` (both > 0) on a log axis: the decades, or where fewer than
/// two fall inside, 1, 2 and 5 times the decades, or failing that round linear steps.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    // A range that is not positive and finite has no decades to tick (log10(0) would ask
    // for 2^31 of them).
    if !(lo > 0.0 && lo.is_finite() && hi.is_finite() && hi >= lo) {
        return Vec::new();
    }
    let inside = |t: &f64| (lo..=hi).contains(t);
    let (first, last) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let decades: Vec<f64> = (first..=last).map(|k| 10f64.powi(k)).collect();
    let ticks: Vec<f64> = decades.iter().copied().filter(inside).collect();
    if ticks.len() >= 2 {
        return ticks;
    }
    let ticks: Vec<f64> = (decades.iter())
        .flat_map(|decade| [1.0, 2.0, 5.0].map(|m| m * decade))
        .filter(inside)
        .collect();
    if ticks.len() >= 2 {
        return ticks;
    }
    (linear_ticks(lo, hi, 4).into_iter())
        .filter(|t| *t > 0.0)
        .collect()
}

/// An axis mapping data values in `[lo, hi]` to pixels in `[start, end]` (`end` may be
/// smaller than `start`: a y axis grows upwards).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Axis {
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
    pub start: f64,
    pub end: f64,
}

impl Axis {
    /// The axis covering the finite `values` (positive ones on a log axis), padded by 4 %
    /// of its span (of its logarithm's on a log axis) so that nothing sits on the border; a
    /// single value gets a band around it, no values a unit range.
    pub fn new(values: impl Iterator<Item = f64>, log: bool, start: f64, end: f64) -> Self {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if !lo.is_finite() {
            (lo, hi) = if log { (1.0, 10.0) } else { (0.0, 1.0) };
        }
        if hi <= lo {
            let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
            (lo, hi) = if log {
                (lo / 2.0, hi * 2.0)
            } else {
                (lo - pad, hi + pad)
            };
        } else if log {
            let pad = 10f64.powf((hi / lo).log10() * 0.04);
            (lo, hi) = (lo / pad, hi * pad);
        } else {
            let pad = (hi - lo) * 0.04;
            (lo, hi) = (lo - pad, hi + pad);
        }
        Axis {
            lo,
            hi,
            log,
            start,
            end,
        }
    }

    fn transform(&self, v: f64) -> f64 {
        if self.log {
            v.log10()
        } else {
            v
        }
    }

    /// The pixel of value `v`.
    pub fn pixel(&self, v: f64) -> f64 {
        let (a, b) = (self.transform(self.lo), self.transform(self.hi));
        self.start + (self.transform(v) - a) / (b - a) * (self.end - self.start)
    }

    /// The tick positions: decades on a log axis, about five round steps on a linear one.
    pub fn ticks(&self) -> Vec<f64> {
        if self.log {
            log_ticks(self.lo, self.hi)
        } else {
            linear_ticks(self.lo, self.hi, 5)
        }
    }

    /// Whether `v` can be drawn on this axis (finite, and positive on a log axis).
    pub fn valid(&self, v: f64) -> bool {
        v.is_finite() && (!self.log || v > 0.0)
    }
}
