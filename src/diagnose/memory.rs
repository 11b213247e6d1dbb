//! The history the free corrections see: a fading memory of the inputs, the measured states
//! and the corrected quantity itself, as first-order low-pass filters
//! `dy/dt = (x - y) / tau` with time constants from about the sampling step up to a *span*
//! chosen from the data.
//!
//! A lag of any order is a combination of such filters (a two-stage lag with time constants
//! `a` and `b` is `(a F_a - b F_b) / (a - b)`), and a filter needs no grid: between two rows
//! it is updated exactly, for an input held over the interval and for a state or a
//! corrected quantity taken linear between its values at the rows. Before an experiment's
//! first row every filter holds its signal's first value (records spec, section 3).
//!
//! **The span.** The slowest memory a gap can need shows in the residual of the fitted
//! model's free run: a missing lag leaves an error that decays with it. For every training
//! experiment and measured state, the residual at its measured cells is laid on a uniform
//! grid (its median spacing, linear between cells); the lag at which its autocorrelation
//! first falls below `1/e` is its correlation time. The span is [`SPAN_FACTOR`] times their
//! mean weighted by the residuals' variances, clamped to twice the median row spacing and a
//! quarter of the longest training part. Time constants are spaced geometrically from the
//! median row spacing to the span.

use crate::numeric::median;
use crate::solve::fit::simulate::Run;
use crate::solve::fit::split::Split;

/// The span is this many correlation times of the residual.
pub const SPAN_FACTOR: f64 = 2.0;

/// A bank of first-order filters over some signals: `values[tau * signals + signal]`.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterBank {
    taus: Vec<f64>,
    signals: usize,
    values: Vec<f64>,
}

impl FilterBank {
    /// Filters at time constants `taus` over signals whose values before the start are
    /// `first` (every filter starts there).
    pub fn start(taus: &[f64], first: &[f64]) -> FilterBank {
        let values = taus.iter().flat_map(|_| first.iter().copied()).collect();
        FilterBank {
            taus: taus.to_vec(),
            signals: first.len(),
            values,
        }
    }

    /// Advances every filter over a step of length `h`, each signal going from `from` to
    /// `to` linearly (an input held over the step has `from == to`).
    pub fn advance(&mut self, from: &[f64], to: &[f64], h: f64) {
        for (t, &tau) in self.taus.iter().enumerate() {
            let (decay, ramp) = weights(h / tau);
            for s in 0..self.signals {
                let y = &mut self.values[t * self.signals + s];
                *y = *y * decay + from[s] * (1.0 - decay) + (to[s] - from[s]) * ramp;
            }
        }
    }

    /// The filtered values, time-constant-major.
    pub fn values(&self) -> &[f64] {
        &self.values
    }
}

/// `exp(-a)` and the ramp weight `(1 - e^-a) - (1 - e^-a - a e^-a) / a` of a step of `a`
/// time constants (the exact response to a signal linear over the step).
fn weights(a: f64) -> (f64, f64) {
    if a.is_nan() || a <= 0.0 {
        return (1.0, 0.0);
    }
    let decay = (-a).exp();
    let ramp = if a < 1e-4 {
        a / 2.0 - a * a / 6.0
    } else {
        let rise = -(-a).exp_m1();
        rise - (rise - a * decay) / a
    };
    (decay, ramp)
}

/// Time constants spaced geometrically from `step` to `span` (`count` of them; all `step`
/// when the span is not longer).
pub fn time_constants(step: f64, span: f64, count: usize) -> Vec<f64> {
    let count = count.max(1);
    if count == 1 || span <= step {
        return vec![span.max(step)];
    }
    let ratio = (span / step).powf(1.0 / (count - 1) as f64);
    (0..count).map(|k| step * ratio.powi(k as i32)).collect()
}

/// The median spacing of the rows of the training parts.
pub fn median_step(split: &Split) -> f64 {
    let steps: Vec<f64> = (split.training())
        .flat_map(|(_, record, rows)| {
            record.times[rows]
                .windows(2)
                .map(|w| w[1] - w[0])
                .collect::<Vec<_>>()
        })
        .collect();
    median(&steps).filter(|s| *s > 0.0).unwrap_or(1.0)
}

/// The span chosen from the residuals of the training free runs `runs` (one per training
/// record, in [`Split::training`] order; see the module documentation).
pub fn span_from_residuals(split: &Split, runs: &[Option<Run>]) -> f64 {
    let step = median_step(split);
    let longest = (split.training())
        .map(|(_, record, rows)| record.times[rows.end - 1] - record.times[rows.start])
        .fold(0.0, f64::max);
    let (mut weighted, mut weights) = (0.0, 0.0);
    for ((_, record, rows), run) in split.training().zip(runs) {
        let Some(run) = run else { continue };
        for (k, cells) in record.columns().enumerate() {
            let samples: Vec<(f64, f64)> = (rows.clone())
                .filter_map(|row| {
                    let value = cells[row]?;
                    Some((
                        record.times[row],
                        (run.column(row, k) - value) / split.normalisation.column_std(k),
                    ))
                })
                .collect();
            if let Some((time, variance)) = correlation_time(&samples) {
                weighted += variance * time;
                weights += variance;
            }
        }
    }
    let correlation = if weights > 0.0 {
        weighted / weights
    } else {
        step
    };
    (SPAN_FACTOR * correlation).clamp(2.0 * step, (longest / 4.0).max(2.0 * step))
}

/// The correlation time of a residual sampled at `(time, value)` points, and its variance;
/// `None` with fewer than 8 points or no variation.
pub fn correlation_time(samples: &[(f64, f64)]) -> Option<(f64, f64)> {
    if samples.len() < 8 {
        return None;
    }
    let spacings: Vec<f64> = samples.windows(2).map(|w| w[1].0 - w[0].0).collect();
    let step = median(&spacings).filter(|s| *s > 0.0)?;
    let (start, end) = (samples[0].0, samples[samples.len() - 1].0);
    let count = ((end - start) / step).floor() as usize + 1;
    let mut grid = Vec::with_capacity(count);
    let mut j = 0;
    for i in 0..count {
        let t = start + i as f64 * step;
        while j + 2 < samples.len() && samples[j + 1].0 < t {
            j += 1;
        }
        let ((ta, va), (tb, vb)) = (samples[j], samples[(j + 1).min(samples.len() - 1)]);
        let fraction = if tb > ta {
            ((t - ta) / (tb - ta)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        grid.push(va + (vb - va) * fraction);
    }
    let mean = grid.iter().sum::<f64>() / grid.len() as f64;
    let centred: Vec<f64> = grid.iter().map(|v| v - mean).collect();
    let variance = centred.iter().map(|v| v * v).sum::<f64>();
    if variance.is_nan() || variance <= 0.0 {
        return None;
    }
    let mut previous = 1.0;
    for lag in 1..centred.len() / 2 {
        let sum: f64 = (0..centred.len() - lag)
            .map(|i| centred[i] * centred[i + lag])
            .sum();
        let acf = sum / variance;
        let threshold = (-1.0f64).exp();
        if acf < threshold {
            let fraction = (previous - threshold) / (previous - acf);
            return Some((
                (lag as f64 - 1.0 + fraction) * step,
                variance / grid.len() as f64,
            ));
        }
        previous = acf;
    }
    Some((
        (centred.len() / 2) as f64 * step,
        variance / grid.len() as f64,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::ode::tableau::RK4;

    /// The exact update of a filter agrees with a fine fourth-order Runge–Kutta
    /// integration, for a held and a ramping signal, over a short and a long step.
    #[test]
    fn filters_are_updated_exactly() {
        for (h, tau) in [(0.3, 2.0), (5.0, 1.5), (1e-6, 1.0)] {
            let mut bank = FilterBank::start(&[tau], &[0.2, 1.0]);
            bank.advance(&[0.5, 1.0], &[0.5, 3.0], h);
            let integrate = |y0: f64, x: &dyn Fn(f64) -> f64| {
                let steps = 2000;
                let dt = h / steps as f64;
                let f = |t: f64, y: f64| (x(t) - y) / tau;
                let mut y = vec![y0];
                for i in 0..steps {
                    let mut slope = |t: f64, y: &[f64]| vec![f(t, y[0])];
                    y = RK4.step(&mut slope, i as f64 * dt, &y, dt);
                }
                y[0]
            };
            let held = integrate(0.2, &|_| 0.5);
            let ramp = integrate(1.0, &|t| 1.0 + 2.0 * t / h);
            let values = bank.values();
            assert!(
                (values[0] - held).abs() < 1e-12,
                "{h} {tau}: {} {held}",
                values[0]
            );
            assert!(
                (values[1] - ramp).abs() < 1e-12,
                "{h} {tau}: {} {ramp}",
                values[1]
            );
        }
    }

    #[test]
    fn time_constants_are_geometric_from_the_step_to_the_span() {
        let taus = time_constants(1.0, 16.0, 5);
        for (tau, expected) in taus.iter().zip([1.0, 2.0, 4.0, 8.0, 16.0]) {
            assert!((tau - expected).abs() < 1e-12);
        }
        assert_eq!(time_constants(2.0, 1.0, 3), vec![2.0]);
    }

    /// An AR(1) sequence `x[i+1] = phi x[i] + e` has autocorrelation `phi^lag`: it falls to
    /// `1/e` after `-1 / ln(phi)` steps.
    #[test]
    fn the_correlation_time_of_an_autoregression() {
        let phi: f64 = 0.95;
        let mut x = 0.0;
        let mut state: u64 = 7;
        let mut samples = Vec::new();
        for i in 0..40_000 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let uniform = (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            x = phi * x + uniform;
            samples.push((2.0 * i as f64, x));
        }
        let (time, _) = correlation_time(&samples).unwrap();
        let expected = -2.0 / phi.ln();
        assert!((time / expected - 1.0).abs() < 0.1, "{time} {expected}");
    }
}
