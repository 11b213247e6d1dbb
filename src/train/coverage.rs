//! How much of each training record trains: its measured cells, those a one-step pair
//! reaches (a pair needs every measured state known at its start, which off-line assays
//! rarely give), and those the free-run windows of the multi-step objective reach (every
//! measured cell after a training knot: a window starts from the data where they are known
//! and from the model's own run where not). The columns that limit the pairs are named.
//!
//! On a sparse record the one-step warm-up would train on a handful of pairs; the warm-up
//! is then shortened in proportion to the share of cells the pairs reach
//! ([`Coverage::warmup_share`]), so the windows, which reach every cell, train longer.

use super::split::Training;
use crate::engine::pairs::PairAt;
use crate::ir;
use crate::record::Track;

/// Below this share of the windows' cells reached by one-step pairs, a record is sparse:
/// the warm-up shrinks in proportion.
pub const DENSE_SHARE: f64 = 0.5;

/// What of one training experiment trains.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RecordCoverage {
    /// The experiment.
    pub experiment: String,
    /// Measured state cells after the first training knot (what windows are scored on).
    pub cells: usize,
    /// Of those, the targets of one-step pairs.
    pub one_step: usize,
    /// The measured states whose missing cells at a step's start cost the most pairs,
    /// most first, with the number of steps each left without a pair.
    pub limiting: Vec<(String, usize)>,
}

/// What of every training experiment trains.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Coverage {
    /// Per training experiment.
    pub records: Vec<RecordCoverage>,
}

impl Coverage {
    /// The coverage of `tracks` (training knots `trainings`) by `pairs`.
    pub fn of(
        model: &ir::Model,
        (tracks, trainings): (&[Track], &[Training]),
        pairs: &[PairAt],
    ) -> Coverage {
        let records = (tracks.iter().zip(trainings).enumerate())
            .map(|(index, (track, training))| {
                let starts: Vec<usize> = (pairs.iter())
                    .filter(|(t, _)| *t == index)
                    .map(|&(_, knot)| knot)
                    .collect();
                record_coverage(model, track, training, &starts)
            })
            .collect();
        Coverage { records }
    }

    /// The share of the windows' cells that one-step pairs reach (1 without cells).
    pub fn one_step_share(&self) -> f64 {
        let cells: usize = self.records.iter().map(|r| r.cells).sum();
        let reached: usize = self.records.iter().map(|r| r.one_step).sum();
        if cells == 0 {
            1.0
        } else {
            reached as f64 / cells as f64
        }
    }

    /// The warm-up share to train with, from the one asked for: unchanged on dense records,
    /// shrunk by `share / DENSE_SHARE` where pairs reach less than [`DENSE_SHARE`].
    pub fn warmup_share(&self, asked: f64) -> f64 {
        asked * (self.one_step_share() / DENSE_SHARE).min(1.0)
    }
}

/// The coverage of one track.
fn record_coverage(
    model: &ir::Model,
    track: &Track,
    training: &Training,
    starts: &[usize],
) -> RecordCoverage {
    let states = model.states.len();
    let measured_at = |knot: usize| (0..states).filter(|&i| track.measured[i][knot]).count();
    let cells: usize = (training.knots.start + 1..=training.knots.end.min(track.len() - 1))
        .map(measured_at)
        .sum();
    let one_step: usize = (starts.iter())
        .filter(|&&knot| knot + 1 < track.len())
        .map(|&knot| measured_at(knot + 1))
        .sum();
    let mut missing = vec![0usize; states];
    for knot in training.knots.clone() {
        if knot + 1 >= track.len() || starts.contains(&knot) || measured_at(knot + 1) == 0 {
            continue;
        }
        for (i, count) in missing.iter_mut().enumerate() {
            if !track.known[i][knot] {
                *count += 1;
            }
        }
    }
    let mut limiting: Vec<(String, usize)> = (model.states.iter().zip(missing))
        .filter(|(_, count)| *count > 0)
        .map(|(state, count)| (state.name.clone(), count))
        .collect();
    limiting.sort_by_key(|entry| std::cmp::Reverse(entry.1));
    RecordCoverage {
        experiment: track.name.clone(),
        cells,
        one_step,
        limiting,
    }
}

impl std::fmt::Display for RecordCoverage {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            formatter,
            "{}: {} measured cells train in free-run windows, {} of them in one-step pairs",
            self.experiment, self.cells, self.one_step
        )?;
        if let Some((name, steps)) = self.limiting.first() {
            write!(
                formatter,
                " (the pairs are limited by {name}, not known at the start of {steps} steps)"
            )?;
        }
        Ok(())
    }
}
