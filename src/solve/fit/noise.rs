//! The measurement noise, estimated from the data alone (or declared, see [`NoiseSource`]).
//!
//! For white noise of standard deviation `sigma` on a signal that is smooth at the sampling
//! scale, take `m = p + 2` consecutive measured cells of one state, `(t_i, x_i)`: their
//! divided difference of order `p + 1`, `d = sum_i c_i x_i` with
//! `c_i = 1 / prod_{j != i} (t_i - t_j)`, vanishes for any polynomial of degree `p` and is
//! the noise's `sum_i c_i e_i`, of variance `sigma^2 sum_i c_i^2`. On uniform rows and
//! `p = 1` this is the second difference (variance `6 sigma^2`). We average
//! `d^2 / sum c_i^2` over the training cells of every experiment after dropping the largest
//! 5 % (input switches bend the signal), and undo the bias that trimming a Gaussian sample
//! introduces. In normalised units (divided by the training std), `sigma^2` is the gap a
//! perfect model would show: the *noise floor*.
//!
//! Sparse assays (a few per batch, hours apart) see the signal's own curvature between
//! cells, which the second difference takes for noise (a rising and falling acetate
//! sampled ten times looked like noise of 94 % of its variance). Curvature falls with the
//! order, noise does not: the estimate is the lowest of orders `p = 1, 2, 3` (an order
//! above 1 needs [`MIN_WINDOWS`] windows). On pure noise the lowest of three correlated
//! estimates errs low by a few per cent; on sparse records the first order errs high many
//! times over. The standard error reported with it is approximate (squares of
//! overlapping windows are correlated: the count of windows is divided by `m / 1.5`).
//!
//! A second bound holds whatever the sampling: the fitted model's own training residual of
//! a state (corrected for the fitted unknowns) is noise plus misfit, so the noise is at
//! most that ([`cap_by_fit`]); so is the best effect's fit (by BIC). Where a few assays
//! follow a curve a model fits well, this bound is the tighter one.

use super::split::Split;

/// Fraction of the largest squared deviations ignored.
const TRIM: f64 = 0.05;
/// `E[z^2 | |z| <= q]` for a standard normal `z` and `q` its two-sided 95 % quantile
/// (1.95996): `1 - 2 q phi(q) / 0.95`.
const TRIMMED_SECOND_MOMENT: f64 = 0.758_547;
/// The highest polynomial order the differences cancel.
const MAX_ORDER: usize = 3;
/// An order is only tried with at least this many windows.
const MIN_WINDOWS: usize = 6;

/// Where a state's noise level comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum NoiseSource {
    /// Differences of consecutive cells cancelling polynomials of this order.
    Differences {
        /// The order cancelled (1: lines, 2: parabolas, 3: cubics).
        order: usize,
        /// How many windows were averaged.
        windows: usize,
    },
    /// Declared in the model (`noise X = ...`) or on the command line (`--noise`).
    Declared(String),
    /// The fitted model's training residual of the state, lower than the differences.
    FitResidual {
        /// The training cells of the state.
        cells: usize,
    },
    /// Fewer than three measured cells: no estimate (taken as 0).
    Unknown,
}

/// A state's estimated noise variance (in its units squared) and how it was reached.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseEstimate {
    /// The variance.
    pub variance: f64,
    /// Its approximate relative standard error (0 when there is none).
    pub relative_error: f64,
    /// How it was estimated.
    pub source: NoiseSource,
}

impl NoiseEstimate {
    /// The estimate in words: `differences of order 2, 112 windows, +-25 %`.
    pub fn describe(&self) -> String {
        match self.source {
            NoiseSource::Differences { order, windows } => format!(
                "estimated from differences cancelling order {order} ({windows} windows, \
                 +-{:.0} %)",
                100.0 * self.relative_error
            ),
            NoiseSource::Declared(ref text) => format!("declared: {text}"),
            NoiseSource::FitResidual { cells } => format!(
                "at most the fitted model's training residual ({cells} cells, +-{:.0} %)",
                100.0 * self.relative_error
            ),
            NoiseSource::Unknown => "fewer than three cells: taken as 0".into(),
        }
    }
}

/// The noise variance of one column of cells at `times` (in its units squared), from its
/// measured cells; 0 with fewer than three.
#[cfg(test)]
pub fn noise_variance(times: &[f64], cells: &[Option<f64>]) -> f64 {
    let samples: Vec<(f64, f64)> = (times.iter().zip(cells))
        .filter_map(|(&t, cell)| cell.map(|v| (t, v)))
        .collect();
    estimate(&[samples]).variance
}

/// The noise of one state from its measured `(time, value)` cells, one list per experiment
/// (windows never span two experiments).
pub fn estimate(experiments: &[Vec<(f64, f64)>]) -> NoiseEstimate {
    let at_order = |order: usize| -> Option<(f64, f64, usize)> {
        let squares: Vec<f64> = (experiments.iter())
            .flat_map(|samples| samples.windows(order + 2).filter_map(deviation))
            .collect();
        let windows = squares.len();
        if windows == 0 || (order > 1 && windows < MIN_WINDOWS) {
            return None;
        }
        let (mean, spread) = trimmed_mean(squares);
        let effective = windows as f64 / ((order + 2) as f64 / 1.5);
        Some((mean, spread / effective.sqrt(), windows))
    };
    let Some(mut best) = at_order(1).map(|e| (1, e)) else {
        return NoiseEstimate {
            variance: 0.0,
            relative_error: 0.0,
            source: NoiseSource::Unknown,
        };
    };
    for order in 2..=MAX_ORDER {
        if let Some(next) = at_order(order).filter(|next| next.0 < best.1 .0) {
            best = (order, next);
        }
    }
    let (order, (variance, error, windows)) = best;
    NoiseEstimate {
        variance,
        relative_error: if variance > 0.0 {
            error / variance
        } else {
            0.0
        },
        source: NoiseSource::Differences { order, windows },
    }
}

/// `d^2 / sum c_i^2` of a window of samples (`None` if two share a time).
fn deviation(window: &[(f64, f64)]) -> Option<f64> {
    let origin = window[0].0;
    let span = window[window.len() - 1].0 - origin;
    let increasing = |a: f64, b: f64| a.partial_cmp(&b) == Some(std::cmp::Ordering::Less);
    if !increasing(0.0, span) || window.windows(2).any(|w| !increasing(w[0].0, w[1].0)) {
        return None;
    }
    // Times on [0, 1]: the divided difference's scale cancels in d^2 / sum c^2.
    let t: Vec<f64> = window.iter().map(|&(t, _)| (t - origin) / span).collect();
    let (mut d, mut norm) = (0.0, 0.0);
    for (i, &(_, x)) in window.iter().enumerate() {
        let product: f64 = (0..t.len())
            .filter(|&j| j != i)
            .map(|j| t[i] - t[j])
            .product();
        let c = 1.0 / product;
        d += c * x;
        norm += c * c;
    }
    Some(d * d / norm)
}

/// The trimmed mean of `squares`, corrected for trimming, and the spread (standard
/// deviation) of the kept squares on the same scale.
fn trimmed_mean(mut squares: Vec<f64>) -> (f64, f64) {
    if squares.is_empty() {
        return (0.0, 0.0);
    }
    squares.sort_by(f64::total_cmp);
    let keep = ((squares.len() as f64) * (1.0 - TRIM)).ceil().max(1.0) as usize;
    let kept = &squares[..keep.min(squares.len())];
    let mean = kept.iter().sum::<f64>() / kept.len() as f64;
    let variance = kept.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / kept.len() as f64;
    (
        mean / TRIMMED_SECOND_MOMENT,
        variance.sqrt() / TRIMMED_SECOND_MOMENT,
    )
}

/// Per measured column (state, then observable), the sum of the squares of its cells'
/// residuals (rescaled to normalised units) and their count, from the residuals as
/// [`super::fitter::Objective::residuals`] gives them (row by row, column by column, scaled
/// by the square root of the training cells).
pub fn by_state(split: &Split, residuals: &[f64]) -> Vec<(f64, usize)> {
    let columns = split.normalisation.columns();
    let mut sums = vec![(0.0, 0usize); columns];
    let mut cells = residuals.iter();
    let total = residuals.len() as f64;
    for (_, record, rows) in split.training() {
        for row in rows {
            for (sum, column) in sums.iter_mut().zip(record.columns()) {
                if column[row].is_some() {
                    let r = cells.next().copied().unwrap_or(f64::NAN);
                    sum.0 += r * r * total;
                    sum.1 += 1;
                }
            }
        }
    }
    sums
}

/// Bounds each estimated (not declared) state's noise, normalised, by a fitted model's
/// mean squared training residual of that state ([`by_state`]) times
/// `cells / (cells - unknowns)`: noise plus misfit is at least the noise.
pub fn cap_by_fit(estimates: &mut [NoiseEstimate], squares: &[(f64, usize)], unknowns: usize) {
    let total: usize = squares.iter().map(|s| s.1).sum();
    let correction = total as f64 / (total as f64 - unknowns as f64).max(1.0);
    for (estimate, &(sum, count)) in estimates.iter_mut().zip(squares) {
        if count == 0 {
            continue;
        }
        let bound = sum / count as f64 * correction;
        let declared = matches!(estimate.source, NoiseSource::Declared(_));
        if !declared && bound.is_finite() && bound < estimate.variance {
            estimate.variance = bound;
            estimate.relative_error = (2.0 / count as f64).sqrt();
            estimate.source = NoiseSource::FitResidual { cells: count };
        }
    }
}

/// `4 % + 0.01` (in the state's unit).
fn declared_text(noise: &crate::ir::Noise) -> String {
    use crate::numeric::text::num;
    let relative = (noise.relative > 0.0).then(|| format!("{} %", num(100.0 * noise.relative)));
    let absolute = (noise.absolute > 0.0).then(|| num(noise.absolute));
    [relative, absolute]
        .into_iter()
        .flatten()
        .collect::<Vec<_>>()
        .join(" + ")
}

/// How many standard deviations of its noise a fitted start may move from its measured
/// cell: a measurement is a value with its noise, and a start 3 standard deviations off its
/// cell is no longer that measurement (a fitted start unbounded takes the place of a
/// missing lag or a wrong inoculum the model should be blamed for).
pub const START_WIDTH: f64 = 3.0;

/// Makes the first row's measured cells of every training experiment unknowns of the fit
/// ([`Split::fit_measured_starts`], the diagnosis's default), each bounded to its cell plus
/// or minus [`START_WIDTH`] standard deviations of its noise ([`start_sigma`]); a cell
/// whose noise is not known to be above zero stays the exact start it was.
pub fn fit_uncertain_starts(split: &mut Split, model: &crate::ir::Model) {
    let floors = noise_floors(split);
    let sigmas: Vec<Vec<Option<f64>>> = (0..split.records.len())
        .map(|record| {
            (0..model.states.len())
                .map(|k| start_sigma(split, &floors, record, k))
                .collect()
        })
        .collect();
    let uncertain: Vec<Vec<bool>> = (sigmas.iter())
        .map(|row| row.iter().map(Option::is_some).collect())
        .collect();
    split.fit_measured_starts(model, &uncertain);
    split.start_bounds = (split.fitted_starts.iter())
        .map(|&(record, k)| {
            let cell = split.records[record].states[k].first().copied().flatten()?;
            let sigma = sigmas[record][k]?;
            Some((cell - START_WIDTH * sigma, cell + START_WIDTH * sigma))
        })
        .collect();
}

/// The standard deviation of the noise of `record`'s first cell of state `k` (`None`
/// where there is no cell or its noise is not known to be above zero): the declared noise
/// at the cell's value; else the estimate from the data (`floors`) at the lower end of its
/// one-standard-error interval (differences over a few sparse assays count curvature as
/// noise; a start bounded by an inflated noise absorbs misfit), read the tighter of two
/// ways, as absolute (the pooled deviation) or relative (scaled by the cell over the
/// column's root mean square): the estimate does not say which, and a small first value
/// (an inoculum) under relative noise is far more certain than the pooled deviation says.
fn start_sigma(split: &Split, floors: &[NoiseEstimate], record: usize, k: usize) -> Option<f64> {
    let cell = split.records[record].states[k].first().copied().flatten()?;
    let norm = &split.normalisation;
    let sigma = match &split.declared[k] {
        Some((noise, _)) => noise.sigma(cell),
        None => {
            let floor = &floors[k];
            let low = floor.variance * (1.0 - floor.relative_error).max(0.0);
            let absolute = low.sqrt() * norm.state_std[k];
            let rms = norm.state_mean[k].hypot(norm.state_std[k]);
            absolute.min(absolute * cell.abs() / rms)
        }
    };
    (sigma > 0.0 && sigma.is_finite()).then_some(sigma)
}

/// Per measured column (state, then observable), the noise estimate in normalised units
/// (variance divided by the training variance), pooled over the training parts of every
/// experiment.
pub fn noise_floors(split: &Split) -> Vec<NoiseEstimate> {
    let norm = &split.normalisation;
    (0..norm.columns())
        .map(|k| {
            let experiments: Vec<Vec<(f64, f64)>> = (split.training())
                .map(|(_, record, rows)| {
                    (rows.clone())
                        .filter_map(|row| record.column(k)[row].map(|v| (record.times[row], v)))
                        .collect()
                })
                .collect();
            let mut estimate = match &split.declared[k] {
                Some((noise, rms)) => NoiseEstimate {
                    variance: rms * rms,
                    relative_error: 0.0,
                    source: NoiseSource::Declared(declared_text(noise)),
                },
                None => estimate(&experiments),
            };
            estimate.variance /= norm.column_std(k).powi(2);
            estimate
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn recovers_white_noise_on_a_smooth_signal() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let sigma = 0.05;
        let column: Vec<f64> = (0..4000)
            .map(|k| {
                let t = k as f64 * 0.01;
                let noise: f64 = StandardNormal.sample(&mut rng);
                (t).sin() * 3.0 + 1.0 + sigma * noise
            })
            .collect();
        let times: Vec<f64> = (0..column.len()).map(|k| k as f64).collect();
        let cells: Vec<Option<f64>> = column.iter().copied().map(Some).collect();
        let estimate = noise_variance(&times, &cells).sqrt();
        assert!((estimate / sigma - 1.0).abs() < 0.05, "estimate {estimate}");
    }

    #[test]
    fn a_noise_free_smooth_signal_has_almost_no_noise() {
        let column: Vec<f64> = (0..500).map(|k| (k as f64 * 0.01).exp()).collect();
        // Second differences of exp(0.01 k) are about 1e-4 exp(0.01 k): tiny against the
        // signal's spread (its std is about 36).
        let (_, std) = crate::numeric::mean_std(&column);
        let times: Vec<f64> = (0..column.len()).map(|k| k as f64).collect();
        let cells: Vec<Option<f64>> = column.iter().copied().map(Some).collect();
        assert!(noise_variance(&times, &cells).sqrt() < 1e-3 * std);
    }

    #[test]
    fn recovers_white_noise_on_irregular_times_with_missing_cells() {
        // A slow sine sampled at random times (gaps of 1 to 4), a third of the cells empty.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let sigma = 0.02;
        let (mut times, mut cells) = (Vec::new(), Vec::new());
        let mut t = 0.0;
        for k in 0..6000 {
            t += 1.0 + 3.0 * ((k * 7919 % 1000) as f64 / 1000.0);
            let noise: f64 = StandardNormal.sample(&mut rng);
            times.push(t);
            cells.push((k % 3 != 0).then_some((t * 0.002).sin() + sigma * noise));
        }
        let estimate = noise_variance(&times, &cells).sqrt();
        assert!((estimate / sigma - 1.0).abs() < 0.05, "estimate {estimate}");
    }

    /// A rise and fall (acetate in a fed-batch) assayed every 2-3 h over 30 h in 4 batches:
    /// second differences take the curvature for noise several times over; the lowest
    /// order is within a factor of 2 of the truth.
    #[test]
    fn sparse_assays_of_a_curved_signal_do_not_pass_for_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let sigma = 0.02;
        let signal = |t: f64| 0.7 * (-((t - 14.0) / 5.0).powi(2)).exp();
        let experiments: Vec<Vec<(f64, f64)>> = (0..4)
            .map(|batch| {
                let mut t = 0.3 * batch as f64;
                let mut cells = Vec::new();
                while t < 30.0 {
                    let noise: f64 = StandardNormal.sample(&mut rng);
                    cells.push((t, signal(t) + sigma * noise));
                    t += 2.0 + ((batch * 31 + cells.len() * 17) % 10) as f64 / 10.0;
                }
                cells
            })
            .collect();
        let second: Vec<f64> = (experiments.iter())
            .flat_map(|e| e.windows(3).filter_map(deviation))
            .collect();
        let naive = trimmed_mean(second).0.sqrt();
        let found = estimate(&experiments);
        let sd = found.variance.sqrt();
        assert!(
            naive > 2.5 * sigma,
            "the naive estimate {naive} should err high"
        );
        assert!(
            sd < 2.0 * sigma && sd > 0.5 * sigma,
            "{sd} against {sigma}: {found:?}"
        );
        assert!(matches!(found.source, NoiseSource::Differences { order, .. } if order > 1));
    }

    /// Differences of every order cancel a polynomial of that order exactly.
    #[test]
    fn divided_differences_cancel_polynomials_of_their_order() {
        let times: [f64; 5] = [0.0, 0.7, 2.1, 2.5, 4.0];
        for order in 1..=3 {
            let window: Vec<(f64, f64)> = times[..order + 2]
                .iter()
                .map(|&t| {
                    (
                        t,
                        (0..=order)
                            .map(|p| (p as f64 + 1.0) * t.powi(p as i32))
                            .sum(),
                    )
                })
                .collect();
            assert!(deviation(&window).unwrap() < 1e-20, "order {order}");
            let mut bumped = window.clone();
            bumped[1].1 += 1.0;
            assert!(deviation(&bumped).unwrap() > 1e-3);
        }
    }
}
