//! How sure a ranking is: a block bootstrap of the held-out errors.
//!
//! Free-run errors are correlated in time, so cells are not resampled one by one: the scored
//! data are cut into [`Blocks`] — whole experiments when at least [`EXPERIMENT_BLOCKS`] are
//! scored, otherwise each scored part into spans of equal duration, about [`BLOCKS`] in
//! all — and [`RESAMPLES`] times a sample of as many blocks is drawn with replacement. Every
//! candidate is scored on the same draws (a paired comparison), which gives, for each, the
//! standard error of its gap's difference from the best's, the share of draws in which it
//! is best, and the share in which it does at least as well as the best. A candidate is
//! *told apart* from the best when the best has the smaller gap in at least [`CONFIDENCE`]
//! of the draws (a one-sided percentile bootstrap test): the best's lead exceeds the
//! ranking's uncertainty.

use super::evaluate::Errors;
use crate::solve::fit::split::Split;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::ops::Range;

/// Bootstrap draws.
pub const RESAMPLES: usize = 400;
/// Time blocks in all, when experiments are too few to be the blocks.
pub const BLOCKS: usize = 16;
/// From this many scored experiments on, the blocks are whole experiments.
pub const EXPERIMENT_BLOCKS: usize = 6;
/// Share of draws in which the best must beat a candidate to be told apart from it.
pub const CONFIDENCE: f64 = 0.95;

/// The blocks of the scored data: per block, the index of its record among the scored
/// records and its rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Blocks {
    /// `(scored record, rows)` of each block.
    pub blocks: Vec<(usize, Range<usize>)>,
}

impl Blocks {
    /// The blocks of `split`'s scored parts.
    pub fn new(split: &Split) -> Blocks {
        let scored: Vec<_> = split.scored().collect();
        if scored.len() >= EXPERIMENT_BLOCKS {
            let blocks = (scored.into_iter().enumerate())
                .map(|(slot, (_, _, rows))| (slot, rows))
                .collect();
            return Blocks { blocks };
        }
        let duration = |record: &crate::record::Record, rows: &Range<usize>| {
            record.times[rows.end - 1] - record.times[rows.start]
        };
        let total: f64 = scored.iter().map(|(_, r, rows)| duration(r, rows)).sum();
        let mut blocks = Vec::new();
        for (slot, (_, record, rows)) in scored.iter().enumerate() {
            let span = duration(record, rows);
            let count = if total > 0.0 {
                ((BLOCKS as f64 * span / total).round() as usize).max(1)
            } else {
                1
            };
            let start = record.times[rows.start];
            let mut first = rows.start;
            for block in 0..count {
                let end_time = start + span * (block + 1) as f64 / count as f64;
                let mut last = first;
                while last < rows.end && (record.times[last] < end_time || block + 1 == count) {
                    last += 1;
                }
                if last > first {
                    blocks.push((slot, first..last));
                }
                first = last;
            }
        }
        Blocks { blocks }
    }

    /// Per block, the sum of the squared errors and the number of cells (an infinite sum
    /// when the run diverged).
    pub fn sums(&self, errors: &Errors) -> Vec<(f64, usize)> {
        (self.blocks.iter())
            .map(|(slot, rows)| {
                let Some(record) = errors.records.get(*slot) else {
                    return (f64::INFINITY, 0);
                };
                let totals = record.row_totals();
                let (sum, count) = (rows.clone())
                    .map(|row| totals[row - record.rows.start])
                    .fold((0.0, 0), |(s, n), (a, b)| (s + a, n + b));
                (if errors.diverged { f64::INFINITY } else { sum }, count)
            })
            .collect()
    }
}

/// The paired bootstrap comparison of candidates.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// Per candidate: its gap over every block.
    pub gaps: Vec<f64>,
    /// The candidate with the smallest gap, if any is finite.
    pub best: Option<usize>,
    /// Per candidate: the standard error of its gap minus the best's (0 for the best,
    /// infinite for a candidate whose run diverged).
    pub spread: Vec<f64>,
    /// Per candidate: the share of draws in which it has the smallest gap.
    pub probability_best: Vec<f64>,
    /// Per candidate: the share of draws in which its gap is at most the best's (1 for the
    /// best).
    pub as_good: Vec<f64>,
}

impl Comparison {
    /// Whether candidate `index` cannot be told apart from the best (the best beats it in
    /// fewer than [`CONFIDENCE`] of the draws).
    pub fn tied_with_best(&self, index: usize) -> bool {
        self.best.is_some()
            && self.gaps[index].is_finite()
            && self.as_good[index] > 1.0 - CONFIDENCE
    }
}

/// Compares candidates by their block sums (one vector per candidate, same blocks), with
/// draws from a generator seeded with `seed`.
pub fn compare(sums: &[Vec<(f64, usize)>], seed: u64) -> Comparison {
    let gap = |candidate: &[(f64, usize)], weights: &dyn Fn(usize) -> f64| {
        let (s, n) = (candidate.iter().enumerate())
            .fold((0.0, 0.0), |(s, n), (b, (sum, count))| {
                (s + weights(b) * sum, n + weights(b) * *count as f64)
            });
        if n > 0.0 {
            s / n
        } else {
            f64::INFINITY
        }
    };
    let gaps: Vec<f64> = sums.iter().map(|c| gap(c, &|_| 1.0)).collect();
    let best = (0..gaps.len())
        .filter(|&i| gaps[i].is_finite())
        .min_by(|&a, &b| gaps[a].total_cmp(&gaps[b]));
    let mut spread = vec![f64::INFINITY; sums.len()];
    let mut probability_best = vec![0.0; sums.len()];
    let mut as_good = vec![0.0; sums.len()];
    let Some(best) = best else {
        return Comparison {
            gaps,
            best: None,
            spread,
            probability_best,
            as_good,
        };
    };
    let blocks = sums[best].len();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut differences: Vec<Vec<f64>> = vec![Vec::with_capacity(RESAMPLES); sums.len()];
    for _ in 0..RESAMPLES {
        let mut weights = vec![0.0; blocks];
        for _ in 0..blocks {
            weights[rng.gen_range(0..blocks)] += 1.0;
        }
        let drawn: Vec<f64> = sums.iter().map(|c| gap(c, &|b| weights[b])).collect();
        let winner = (0..drawn.len())
            .filter(|&i| drawn[i].is_finite())
            .min_by(|&a, &b| drawn[a].total_cmp(&drawn[b]));
        if let Some(winner) = winner {
            probability_best[winner] += 1.0;
        }
        for (i, value) in drawn.iter().enumerate() {
            differences[i].push(value - drawn[best]);
            if value.is_finite() && *value <= drawn[best] {
                as_good[i] += 1.0;
            }
        }
    }
    let share = |counts: Vec<f64>| -> Vec<f64> {
        counts.into_iter().map(|c| c / RESAMPLES as f64).collect()
    };
    let (probability_best, as_good) = (share(probability_best), share(as_good));
    for (i, values) in differences.iter().enumerate() {
        if gaps[i].is_finite() {
            let (_, std) = population_std(values);
            spread[i] = if i == best { 0.0 } else { std };
        }
    }
    Comparison {
        gaps,
        best: Some(best),
        spread,
        probability_best,
        as_good,
    }
}

/// Mean and population standard deviation (0 for a constant or empty sample).
fn population_std(values: &[f64]) -> (f64, f64) {
    let count = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / count;
    let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / count;
    (
        mean,
        if variance.is_finite() {
            variance.sqrt()
        } else {
            f64::INFINITY
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blocks whose errors alternate around 2 for one candidate and sit at 2 for another
    /// cannot be told apart; a shift of 1 can.
    #[test]
    fn a_shift_is_told_apart_from_noise() {
        let noisy: Vec<(f64, usize)> = (0..16)
            .map(|b| (10.0 * (2.0 + if b % 2 == 0 { 1.0 } else { -1.0 }), 10))
            .collect();
        let flat = vec![(20.0, 10); 16];
        let same = compare(&[noisy.clone(), flat.clone()], 1);
        assert!(same.tied_with_best(0) && same.tied_with_best(1), "{same:?}");
        let shifted: Vec<(f64, usize)> = noisy.iter().map(|(s, n)| (s + 10.0, *n)).collect();
        let apart = compare(&[shifted, flat], 1);
        assert_eq!(apart.best, Some(1));
        assert!(!apart.tied_with_best(0), "{apart:?}");
        assert!(apart.probability_best[1] > 0.95 && apart.as_good[0] < 0.05);
        // The best's gap over all blocks is the pooled mean.
        assert_eq!(apart.gaps[1], 2.0);
    }

    #[test]
    fn a_diverged_candidate_is_never_best_and_never_tied() {
        let finite = vec![(1.0, 1); 4];
        let diverged = vec![(f64::INFINITY, 1); 4];
        let comparison = compare(&[diverged, finite], 3);
        assert_eq!(comparison.best, Some(1));
        assert!(!comparison.tied_with_best(0));
        assert_eq!(comparison.probability_best, vec![0.0, 1.0]);
        assert_eq!(comparison.as_good, vec![0.0, 1.0]);
    }

    /// The bootstrap standard error of a difference of means over blocks matches the
    /// textbook one, `std(d_b) / sqrt(B)` for equal blocks (within resampling error).
    #[test]
    fn the_spread_is_the_standard_error_of_the_paired_difference() {
        let differences: Vec<f64> = (0..16)
            .map(|b| ((b * 37 % 16) as f64 - 7.5) / 4.0)
            .collect();
        let base = vec![(100.0, 10); 16];
        let other: Vec<(f64, usize)> = differences
            .iter()
            .map(|d| (100.0 + 10.0 * (d + 3.0), 10))
            .collect();
        let comparison = compare(&[base, other], 7);
        let (_, std) = population_std(&differences);
        let expected = std / 16f64.sqrt();
        assert!(
            (comparison.spread[1] / expected - 1.0).abs() < 0.15,
            "{comparison:?} {expected}"
        );
    }
}
