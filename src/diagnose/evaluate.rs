//! Where the error of a run lies: per measured state (free run and one step), per time
//! window and per operating regime.

use super::record::{Normalisation, Record};
use super::report::{Regime, Window};
use super::simulate::{Run, Simulator};
use crate::sim::IntegrationError;
use std::ops::Range;

/// Quantile bins per variable in the regime analysis.
const REGIME_BINS: usize = 5;
/// Variables reported in the regime analysis.
const REGIME_REPORTED: usize = 3;

/// Per measured state, the mean squared z-scored error of `run` against the data over `rows`.
pub fn state_errors(
    run: &Run,
    record: &Record,
    rows: Range<usize>,
    norm: &Normalisation,
) -> Vec<f64> {
    (record.states.iter().enumerate())
        .map(|(k, column)| {
            let sum: f64 = rows
                .clone()
                .map(|row| ((run.row(row)[k] - column[row]) / norm.std[k]).powi(2))
                .sum();
            sum / rows.len().max(1) as f64
        })
        .collect()
}

/// Per row of `rows`, the squared z-scored error summed over measured states.
pub fn row_errors(
    run: &Run,
    record: &Record,
    rows: Range<usize>,
    norm: &Normalisation,
) -> Vec<f64> {
    rows.map(|row| {
        (record.states.iter().enumerate())
            .map(|(k, column)| ((run.row(row)[k] - column[row]) / norm.std[k]).powi(2))
            .sum()
    })
    .collect()
}

/// Per measured state, the mean squared z-scored error of one-step predictions of the rows
/// in `rows` (each from the data one row earlier; row 0 of a record is never predicted).
pub fn offline_errors(
    simulator: &mut Simulator,
    record: &Record,
    rows: Range<usize>,
    norm: &Normalisation,
) -> Result<Vec<f64>, IntegrationError> {
    let (_, predictions) = simulator.one_step(record, rows.end)?;
    let predicted = rows.start.max(1)..rows.end;
    Ok((record.states.iter().enumerate())
        .map(|(k, column)| {
            let sum: f64 = predicted
                .clone()
                .map(|row| ((predictions.row(row - 1)[k] - column[row]) / norm.std[k]).powi(2))
                .sum();
            sum / predicted.len().max(1) as f64
        })
        .collect())
}

/// Whether the mean of `a - b` (per-row errors of two runs over the same rows) lies within
/// two standard errors of zero. Free-run errors are correlated in time, so the standard
/// error comes from the means of `blocks` contiguous blocks.
pub fn indistinguishable(a: &[f64], b: &[f64], blocks: usize) -> bool {
    let length = a.len().min(b.len());
    let blocks = blocks.clamp(2, length.max(2));
    if length < blocks {
        return true;
    }
    let means: Vec<f64> = (0..blocks)
        .map(|k| {
            let (start, end) = (k * length / blocks, (k + 1) * length / blocks);
            (start..end).map(|i| a[i] - b[i]).sum::<f64>() / (end - start) as f64
        })
        .collect();
    let mean = means.iter().sum::<f64>() / blocks as f64;
    let variance = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (blocks - 1) as f64;
    mean.abs() <= 2.0 * (variance / blocks as f64).sqrt()
}

/// Splits `rows` into `count` windows of (nearly) equal length and returns them by share
/// of the squared error `errors` (one entry per row of `rows`), largest first.
pub fn windows(times: &[f64], rows: Range<usize>, errors: &[f64], count: usize) -> Vec<Window> {
    let total: f64 = errors.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let length = rows.len();
    let count = count.clamp(1, length.max(1));
    let mut windows: Vec<Window> = (0..count)
        .map(|w| {
            let (a, b) = (w * length / count, (w + 1) * length / count);
            Window {
                t_start: times[rows.start + a],
                t_end: times[rows.start + b.max(a + 1) - 1],
                share: errors[a..b].iter().sum::<f64>() / total,
            }
        })
        .collect();
    windows.sort_by(|x, y| y.share.total_cmp(&x.share));
    windows
}

/// For each named variable (values over the rows of `errors`), its quantile bin holding
/// the most error relative to its share of rows; the variables whose best bin concentrates
/// the error most, most first.
pub fn regimes(variables: &[(String, Vec<f64>)], errors: &[f64]) -> Vec<Regime> {
    let total: f64 = errors.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let mut found: Vec<(f64, Regime)> = variables
        .iter()
        .filter_map(|(name, values)| best_bin(name, values, errors, total))
        .collect();
    found.sort_by(|a, b| b.0.total_cmp(&a.0));
    found
        .into_iter()
        .take(REGIME_REPORTED)
        .map(|(_, r)| r)
        .collect()
}

/// The bin of `values` (quantile bins) with the highest error share per row share, with
/// that ratio; `None` for a variable that barely varies.
fn best_bin(name: &str, values: &[f64], errors: &[f64], total: f64) -> Option<(f64, Regime)> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
    let (lowest, highest) = (values[*order.first()?], values[*order.last()?]);
    let spread = highest - lowest;
    if spread.is_nan() || spread <= 1e-12 * highest.abs().max(lowest.abs()).max(1e-300) {
        return None;
    }
    let mut best: Option<(f64, Regime)> = None;
    let mut start = 0;
    for bin in 0..REGIME_BINS {
        let mut end = ((bin + 1) * order.len() / REGIME_BINS).max(start + 1);
        // Keep equal values in one bin so that a range never splits a level.
        while end < order.len() && values[order[end]] == values[order[end - 1]] {
            end += 1;
        }
        if start >= order.len() {
            break;
        }
        let members = &order[start..end.min(order.len())];
        let share = members.iter().map(|&i| errors[i]).sum::<f64>() / total;
        let lift = share / (members.len() as f64 / order.len() as f64);
        let range = [values[members[0]], values[members[members.len() - 1]]];
        if best.as_ref().is_none_or(|(b, _)| lift > *b) {
            let regime = Regime {
                variable: name.to_string(),
                range,
                share,
                row_share: members.len() as f64 / order.len() as f64,
                lowest: start == 0,
                highest: end >= order.len(),
            };
            best = Some((lift, regime));
        }
        start = end;
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_rank_the_error_by_time() {
        let times: Vec<f64> = (0..100).map(|k| k as f64).collect();
        let mut errors = vec![1.0; 40];
        errors[30..40].iter_mut().for_each(|e| *e = 7.0);
        let found = windows(&times, 60..100, &errors, 4);
        assert_eq!(found.len(), 4);
        assert_eq!((found[0].t_start, found[0].t_end), (90.0, 99.0));
        // 70 of 100 units of error lie in the last window.
        assert!((found[0].share - 0.7).abs() < 1e-12);
        assert!((found.iter().map(|w| w.share).sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn paired_test_separates_a_shift_from_noise() {
        // Alternating +-1 differences average to zero; a constant shift of 0.5 does not.
        let a: Vec<f64> = (0..200)
            .map(|i| 2.0 + if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let b = vec![2.0; 200];
        assert!(indistinguishable(&a, &b, 20));
        let shifted: Vec<f64> = a.iter().map(|v| v + 0.5).collect();
        assert!(!indistinguishable(&shifted, &b, 20));
    }

    #[test]
    fn regime_finds_the_range_where_the_error_concentrates() {
        // Error only where u < 0.2; S is unrelated to it.
        let u: Vec<f64> = (0..100).map(|k| (k % 10) as f64 / 10.0).collect();
        let s: Vec<f64> = (0..100).map(|k| (k / 10) as f64).collect();
        let errors: Vec<f64> = u.iter().map(|&v| if v < 0.2 { 1.0 } else { 0.0 }).collect();
        let found = regimes(&[("S".into(), s), ("u".into(), u)], &errors);
        assert_eq!(found[0].variable, "u");
        assert_eq!(found[0].range, [0.0, 0.1]);
        assert!(found[0].lowest && !found[0].highest);
        assert!((found[0].share - 1.0).abs() < 1e-12);
    }
}
