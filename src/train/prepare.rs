//! Before any network exists: the integration grid (`--dt` and each state's gap limit),
//! each experiment's initial state, the tracks, what trains and how validation is scored,
//! and the normalisation over the training part's measured cells.

use crate::ir::{self, Dynamics};
use crate::record::{GridOptions, Normalisation, Part as Rows, Record, Track};

use super::initial::{initial_state, InitialState};
use super::split::{
    known_intervals, split_training, training_pairs, whole_experiments, Scoring, Training,
    TrainingData,
};
use super::warnings::{dropped_pairs, DroppedPairs};
use super::{History, TrainError, TrainOptions};
use crate::engine::pairs::{stage_fractions, PairAt};

/// Everything the data fix before training.
pub struct Layout {
    /// The grid the tracks are laid on.
    pub grid: GridOptions,
    /// Initial states of the training experiments, then of the validation experiments.
    pub initial: Vec<InitialState>,
    /// The training experiments on their grids.
    pub tracks: Vec<Track>,
    /// What trains on each training track.
    pub trainings: Vec<Training>,
    /// The one-step pairs that train.
    pub pairs: Vec<PairAt>,
    /// The steps with a target that do not train, when some do not.
    pub dropped: Option<DroppedPairs>,
    /// The steps of the training part known from data at both ends (magnitudes,
    /// stiffness, params from the balances).
    pub intervals: Vec<PairAt>,
    /// The validation tracks: the training tracks again when part of them validates, then
    /// the whole validation experiments.
    pub validation_tracks: Vec<Track>,
    /// How each validation track is scored: the validated parts of training tracks
    /// first ([`Layout::part_scorings`] of them), then the whole validation experiments.
    pub scorings: Vec<Scoring>,
    /// How many of `scorings` score the later part of a training track.
    pub part_scorings: usize,
    /// Statistics over the training part.
    pub normalisation: Normalisation,
}

impl Layout {
    /// Lays out `data` for `model`.
    pub fn new(
        model: &ir::Model,
        data: &TrainingData,
        options: &TrainOptions,
    ) -> Result<Layout, TrainError> {
        if data.train.is_empty() {
            return Err(TrainError::NoTrainingExperiment);
        }
        let all: Vec<&Record> = data.train.iter().chain(data.validation).collect();
        let grid = grid_options(model, data.train, options)?;
        if model.dynamics == Dynamics::Discrete {
            check_uniform(&all, grid.max_step)?;
        }
        let initial = (all.iter())
            .map(|record| initial_state(model, record))
            .collect::<Result<Vec<_>, _>>()?;
        let lay =
            |record: &Record, start: &InitialState| Track::lay(record, &grid, &start.values());
        let tracks: Vec<Track> = (data.train.iter().zip(&initial))
            .map(|(r, i)| lay(r, i))
            .collect();
        let fractions = stage_fractions(model.dynamics, options.substeps);
        let (trainings, mut scorings) = split_training(
            model,
            (data.train, &tracks),
            (data.part, !data.validation.is_empty(), options.history),
            &fractions,
        )?;
        let pairs = training_pairs(model, &tracks, &trainings);
        let dropped = dropped_pairs(model, &tracks, &trainings, &grid.gap_limits);
        let intervals = known_intervals(model, &tracks, &trainings);
        let mut validation_tracks = if scorings.is_empty() {
            Vec::new()
        } else {
            tracks.clone()
        };
        let offset = validation_tracks.len();
        let part_scorings = scorings.len();
        let held_out: Vec<Track> = (data.validation.iter())
            .zip(&initial[data.train.len()..])
            .map(|(r, i)| lay(r, i))
            .collect();
        scorings.extend(whole_experiments(
            model,
            &held_out,
            (offset, options.history),
            &fractions,
        ));
        if options.history == History::Measured {
            for track in tracks.iter().chain(&held_out) {
                check_long_enough(model, track)?;
            }
        }
        validation_tracks.extend(held_out);
        let parts: Vec<Rows> = (data.train.iter().zip(&trainings))
            .map(|(record, training)| (record, training.rows.clone()))
            .collect();
        let normalisation = Normalisation::over(&parts, model.states.len(), model.inputs.len());
        Ok(Layout {
            grid,
            initial,
            tracks,
            trainings,
            pairs,
            dropped,
            intervals,
            validation_tracks,
            scorings,
            part_scorings,
            normalisation,
        })
    }
}

/// The grid: the longest step is `--dt`, or the median spacing of the densest measured
/// column of the training experiments; either at most the shortest embedding delay (a
/// delayed value must not come from inside the step it predicts).
fn grid_options(
    model: &ir::Model,
    train: &[Record],
    options: &TrainOptions,
) -> Result<GridOptions, TrainError> {
    let delays: Vec<f64> = (model.closures.iter())
        .filter(|c| c.embedding.dim > 1)
        .map(|c| c.embedding.delay)
        .collect();
    let shortest = delays.iter().copied().fold(f64::INFINITY, f64::min);
    let max_step = match options.dt {
        Some(dt) => {
            if let Some(closure) = (model.closures.iter())
                .find(|c| c.embedding.dim > 1 && c.embedding.delay < dt * (1.0 - 1e-9))
            {
                return Err(TrainError::DelayBelowStep {
                    closure: closure.name.clone(),
                    delay: closure.embedding.delay,
                    step: dt,
                });
            }
            dt
        }
        None => densest_spacing(train).min(shortest),
    };
    if !(max_step > 0.0 && max_step.is_finite()) {
        return Err(TrainError::BadOption {
            option: "dt".into(),
            expected: "a positive step (the data need two distinct times)".into(),
            found: max_step.to_string(),
        });
    }
    Ok(grid_for(model, max_step))
}

pub use crate::record::grid::grid_for;

/// The median spacing of the measured column with the most cells per unit time, over the
/// experiments (the median row spacing when no state is measured twice).
fn densest_spacing(records: &[Record]) -> f64 {
    let columns = records.first().map_or(0, |r| r.states.len());
    let mut best: Option<(f64, f64)> = None;
    for column in 0..columns {
        let mut spacings = Vec::new();
        let (mut cells, mut span) = (0usize, 0.0);
        for record in records {
            let times: Vec<f64> = (record.times.iter().zip(&record.states[column]))
                .filter(|(_, cell)| cell.is_some())
                .map(|(t, _)| *t)
                .collect();
            spacings.extend(times.windows(2).map(|w| w[1] - w[0]));
            cells += times.len();
            span += times.last().zip(times.first()).map_or(0.0, |(b, a)| b - a);
        }
        let Some(median) = crate::numeric::median(&spacings) else {
            continue;
        };
        let density = cells as f64 / span.max(f64::MIN_POSITIVE);
        if best.is_none_or(|(d, _)| density > d) {
            best = Some((density, median));
        }
    }
    best.map(|(_, median)| median).unwrap_or_else(|| {
        let spacings: Vec<f64> = (records.iter())
            .flat_map(|r| r.times.windows(2).map(|w| w[1] - w[0]).collect::<Vec<_>>())
            .collect();
        crate::numeric::median(&spacings).unwrap_or(f64::NAN)
    })
}

/// Under `--history measured` an experiment must outlast the embedding's history by a step.
fn check_long_enough(model: &ir::Model, track: &Track) -> Result<(), TrainError> {
    if super::split::first_inside(model, track) + 1 < track.len() {
        return Ok(());
    }
    let span = (model.closures.iter())
        .map(|c| c.embedding.span())
        .fold(0.0, f64::max);
    let found = track
        .times
        .last()
        .zip(track.times.first())
        .map_or(0.0, |(b, a)| b - a);
    Err(TrainError::ExperimentTooShort {
        experiment: track.name.clone(),
        needed: span,
        found,
    })
}

/// A `next` model steps from row to row: every experiment must share one uniform step.
fn check_uniform(records: &[&Record], step: f64) -> Result<(), TrainError> {
    for record in records {
        let found = match record.uniform_step() {
            Some(h) if (h - step).abs() <= record.time_tolerance() => continue,
            Some(h) => format!("a step of {h:.6} where others step {step:.6}"),
            None => {
                let steps: Vec<f64> = record.times.windows(2).map(|w| w[1] - w[0]).collect();
                let low = steps.iter().copied().fold(f64::INFINITY, f64::min);
                let high = steps.iter().copied().fold(0.0, f64::max);
                format!("irregular times (steps from {low:.6} to {high:.6})")
            }
        };
        return Err(TrainError::IrregularForNext {
            experiment: record.name.clone(),
            found,
        });
    }
    Ok(())
}
