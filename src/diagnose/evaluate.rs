//! Where the error of a run lies: at the measured cells of the scored rows (free run and
//! one step), per state, per time window and per operating regime.

use super::report::{Regime, Window};
use crate::record::measure::{cell_error, StateErrors};
use crate::record::{Normalisation, Record};
use crate::solve::fit::simulate::{Run, Simulator};
use crate::solve::fit::split::Split;
use std::ops::Range;

/// Quantile bins per variable in the regime analysis.
const REGIME_BINS: usize = 5;
/// Variables reported in the regime analysis.
const REGIME_REPORTED: usize = 3;
/// A free run whose gap exceeds this (in normalised units: a hundred standard deviations
/// root mean square) has diverged: its gap is reported as such, not as a number.
pub const DIVERGED_GAP: f64 = 1e4;

/// The squared z-scored errors of one record's free run at its scored cells.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordErrors {
    /// Index of the record in the split.
    pub record: usize,
    /// The scored rows.
    pub rows: Range<usize>,
    /// Per scored row, per measured state: the squared error (`None`: no cell there).
    pub squares: Vec<Vec<Option<f64>>>,
}

impl RecordErrors {
    /// Per scored row, the sum of its squared errors and the number of its cells.
    pub fn row_totals(&self) -> Vec<(f64, usize)> {
        (self.squares.iter())
            .map(|row| {
                row.iter()
                    .flatten()
                    .fold((0.0, 0), |(s, n), e| (s + e, n + 1))
            })
            .collect()
    }
}

/// The errors of free runs at the scored cells of every scored record.
#[derive(Debug, Clone, PartialEq)]
pub struct Errors {
    /// Per scored record.
    pub records: Vec<RecordErrors>,
    /// Whether some run failed or left every sensible range.
    pub diverged: bool,
}

impl Errors {
    /// The gap: mean squared z-scored error over every scored cell (infinite when a run
    /// diverged).
    pub fn gap(&self) -> f64 {
        let (sum, count) = self.sum_count();
        let gap = sum / count.max(1) as f64;
        if self.diverged || !gap.is_finite() || gap > DIVERGED_GAP {
            f64::INFINITY
        } else {
            gap
        }
    }

    fn sum_count(&self) -> (f64, usize) {
        (self.records.iter().flat_map(RecordErrors::row_totals))
            .fold((0.0, 0), |(s, n), (a, b)| (s + a, n + b))
    }

    /// Per measured state, the mean squared error over its scored cells (`None` without
    /// cells; infinite when a run diverged).
    pub fn per_state(&self, states: usize) -> Vec<Option<f64>> {
        let mut sums = StateErrors::new(states);
        for row in self.records.iter().flat_map(|r| &r.squares) {
            for (k, error) in row.iter().enumerate().take(states) {
                if let Some(error) = error {
                    sums.add(k, *error);
                }
            }
        }
        let diverged = self.diverged;
        (sums.nmse().into_iter())
            .map(|nmse| {
                nmse.map(|e| {
                    if diverged || !e.is_finite() {
                        f64::INFINITY
                    } else {
                        e
                    }
                })
            })
            .collect()
    }
}

/// Per scored row of `rows`, the squared z-scored error of `run` at each measured cell.
pub fn cell_errors(
    run: &Run,
    record: &Record,
    rows: Range<usize>,
    norm: &Normalisation,
) -> Vec<Vec<Option<f64>>> {
    rows.map(|row| {
        (record.columns().enumerate())
            .map(|(k, cells)| {
                cells[row].map(|value| cell_error(run.column(row, k), value, norm.column_std(k)))
            })
            .collect()
    })
    .collect()
}

/// Errors of the free runs `runs` (one per scored record, `None` where it failed) at the
/// scored cells of `split`.
pub fn scored_errors(split: &Split, runs: &[Option<Run>]) -> Errors {
    let mut errors = Errors {
        records: Vec::new(),
        diverged: false,
    };
    for ((index, record, rows), run) in split.scored().zip(runs) {
        let squares = match run {
            Some(run) => cell_errors(run, record, rows.clone(), &split.normalisation),
            None => {
                errors.diverged = true;
                rows.clone()
                    .map(|_| vec![None; record.columns().count()])
                    .collect()
            }
        };
        errors.records.push(RecordErrors {
            record: index,
            rows,
            squares,
        });
    }
    errors
}

/// Per measured column (state, then observable), the mean squared z-scored error of
/// one-step predictions at the scored cells whose previous row has a cell of the same
/// column (one step from measured history); `None` for a column with no such cell. Each prediction starts from the
/// previous row's cells (unmeasured states and hidden ones carried from the run's start).
pub fn offline_errors(
    simulator: &mut Simulator,
    split: &Split,
    fitted_starts: &[f64],
) -> Vec<Option<f64>> {
    let columns = split.normalisation.columns();
    let mut sums = vec![(0.0, 0usize, false); columns];
    for (index, record, rows) in split.scored() {
        let overrides = split.overrides(index, fitted_starts, simulator.hidden_count());
        let predictions = simulator.one_step(record, &overrides, rows.end);
        for (k, cells) in record.columns().enumerate() {
            for row in rows.start.max(1)..rows.end {
                let (Some(value), Some(_)) = (cells[row], cells[row - 1]) else {
                    continue;
                };
                let slot = &mut sums[k];
                match &predictions {
                    Ok((_, predicted)) => {
                        let z = (predicted.column(row - 1, k) - value)
                            / split.normalisation.column_std(k);
                        slot.0 += z * z;
                        slot.1 += 1;
                    }
                    Err(_) => slot.2 = true,
                }
            }
        }
    }
    (sums.into_iter())
        .map(|(sum, count, failed)| match (failed, count) {
            (true, _) => Some(f64::INFINITY),
            (false, 0) => None,
            (false, count) => Some(sum / count as f64),
        })
        .collect()
}

/// The windows of one scored record: its scored time span cut into `count` windows of equal
/// duration, each with the share of the total squared error `total` that falls into it.
/// A window with fewer than two measured rows is not a window (it is left out).
pub fn windows(record: &Record, errors: &RecordErrors, count: usize, total: f64) -> Vec<Window> {
    let rows = errors.rows.clone();
    let totals = errors.row_totals();
    let (first, last) = (record.times[rows.start], record.times[rows.end - 1]);
    let span = last - first;
    let count = count.max(1);
    let mut found = Vec::new();
    if span <= 0.0 {
        return found;
    }
    for w in 0..count {
        let (a, b) = (
            first + span * w as f64 / count as f64,
            first + span * (w + 1) as f64 / count as f64,
        );
        let inside: Vec<usize> = (rows.clone())
            .filter(|&row| {
                let t = record.times[row];
                t >= a && (t < b || (w + 1 == count && t <= b))
            })
            .collect();
        let measured: Vec<usize> = (inside.iter().copied())
            .filter(|&row| totals[row - rows.start].1 > 0)
            .collect();
        if measured.len() < 2 {
            continue;
        }
        let share = inside
            .iter()
            .map(|&row| totals[row - rows.start].0)
            .sum::<f64>()
            / total.max(f64::MIN_POSITIVE);
        found.push(Window {
            experiment: record.name.clone(),
            t_start: record.times[measured[0]],
            t_end: record.times[measured[measured.len() - 1]],
            share,
        });
    }
    found
}

/// A variable of the regime analysis: its name, and its value and the squared error at each
/// scored row where it has a value.
pub type Variable = (String, Vec<f64>, Vec<f64>);

/// For each variable, its quantile bin holding the most error relative to its share of
/// rows; the variables whose best bin concentrates the error most, most first.
pub fn regimes(variables: &[Variable]) -> Vec<Regime> {
    let mut found: Vec<(f64, Regime)> = variables
        .iter()
        .filter_map(|(name, values, errors)| {
            let total = errors.iter().sum::<f64>().max(f64::MIN_POSITIVE);
            best_bin(name, values, errors, total)
        })
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

    fn record(times: Vec<f64>) -> Record {
        let rows = times.len();
        Record::complete("e", times, vec![vec![0.0; rows]], vec![vec![1.0; rows]])
    }

    #[test]
    fn windows_cut_the_scored_time_into_equal_spans() {
        // Scored rows 60..100 at t = 60..99 (one window per 10 time units); error 7 in the
        // last window, 1 elsewhere.
        let times: Vec<f64> = (0..100).map(|k| k as f64).collect();
        let squares: Vec<Vec<Option<f64>>> = (60..100)
            .map(|row| vec![Some(if row >= 90 { 7.0 } else { 1.0 })])
            .collect();
        let errors = RecordErrors {
            record: 0,
            rows: 60..100,
            squares,
        };
        let found = windows(&record(times), &errors, 4, 100.0);
        assert_eq!(found.len(), 4);
        let last = &found[3];
        assert_eq!((last.t_start, last.t_end), (90.0, 99.0));
        assert!((last.share - 0.7).abs() < 1e-12);
        assert!((found.iter().map(|w| w.share).sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_window_with_one_measured_row_is_not_a_window() {
        // Irregular times: 0, 1, 2, 3 then one row at 10; the second half holds one row.
        let times = vec![0.0, 1.0, 2.0, 3.0, 10.0];
        let squares = vec![vec![Some(1.0)]; 5];
        let errors = RecordErrors {
            record: 0,
            rows: 0..5,
            squares,
        };
        let found = windows(&record(times), &errors, 2, 5.0);
        assert_eq!(found.len(), 1);
        assert_eq!((found[0].t_start, found[0].t_end), (0.0, 3.0));
    }

    #[test]
    fn the_gap_is_the_mean_over_measured_cells_and_divergence_is_not_a_number() {
        let errors = Errors {
            records: vec![RecordErrors {
                record: 0,
                rows: 0..2,
                squares: vec![vec![Some(1.0), None], vec![Some(2.0), Some(6.0)]],
            }],
            diverged: false,
        };
        assert_eq!(errors.gap(), 3.0);
        assert_eq!(errors.per_state(2), vec![Some(1.5), Some(6.0)]);
        let huge = Errors {
            records: vec![RecordErrors {
                record: 0,
                rows: 0..1,
                squares: vec![vec![Some(2.1e100)]],
            }],
            diverged: false,
        };
        assert_eq!(huge.gap(), f64::INFINITY);
    }

    #[test]
    fn regime_finds_the_range_where_the_error_concentrates() {
        // Error only where u < 0.2; S is unrelated to it.
        let u: Vec<f64> = (0..100).map(|k| (k % 10) as f64 / 10.0).collect();
        let s: Vec<f64> = (0..100).map(|k| (k / 10) as f64).collect();
        let errors: Vec<f64> = u.iter().map(|&v| if v < 0.2 { 1.0 } else { 0.0 }).collect();
        let found = regimes(&[("S".into(), s, errors.clone()), ("u".into(), u, errors)]);
        assert_eq!(found[0].variable, "u");
        assert_eq!(found[0].range, [0.0, 0.1]);
        assert!(found[0].lowest && !found[0].highest);
        assert!((found[0].share - 1.0).abs() < 1e-12);
    }
}
