//! Which experiments and which of their knots train, and how each validation experiment is
//! scored (records spec, section 3: validation).
//!
//! - [`Part::FirstPairs`] is the paper's protocol on one experiment: the first `n` one-step
//!   pairs after the embedding's history train, and (when no other experiment validates)
//!   the pairs after them validate: offline one step at a time, online by a free run that
//!   starts at the first validation pair from the measured history before it.
//! - [`Part::Tail`] holds out the last share of each experiment's rows: its free run starts
//!   at the experiment's first knot (so that a good score means the whole run is good) and
//!   is scored on the tail only.
//! - [`Part::All`] trains on every row; whole experiments (`--val`, `--holdout`) validate,
//!   each by a free run from its first knot.
//!
//! [`History`] says where a free run of a whole experiment starts and where training windows
//! may start: at the first knot, the history before it held at the first values
//! (`held`, the records spec), or at the first knot whose embedding lies inside the record
//! (`measured`, the paper's).

use std::ops::Range;

use crate::ir;
use crate::record::{Record, Track};

use super::TrainError;
use crate::engine::pairs::{has_target, measured_history, PairAt};

/// Share of the pairs that train under [`Part::FirstPairs`] without a count, when nothing
/// else validates.
pub const DEFAULT_TRAIN_SHARE: f64 = 0.7;

/// How much of each training experiment trains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Part {
    /// The first `n` one-step pairs after each experiment's embedding history, experiments
    /// taken in order (`None`: all of them, or with one experiment and nothing else to
    /// validate the first [`DEFAULT_TRAIN_SHARE`]); with one experiment and nothing else
    /// to validate, the pairs after them validate.
    FirstPairs(Option<usize>),
    /// The last share of each experiment's rows validates.
    Tail(f64),
    /// Every row trains.
    All,
}

/// Where free runs of whole experiments, and training windows, start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum History {
    /// At the first knot, the history before it held at the first values.
    #[default]
    Held,
    /// At the first knot whose whole embedding lies inside the record.
    Measured,
}

/// The experiments a training run sees.
#[derive(Debug, Clone, Copy)]
pub struct TrainingData<'a> {
    /// The training experiments.
    pub train: &'a [Record],
    /// Whole experiments that validate.
    pub validation: &'a [Record],
    /// How much of each training experiment trains.
    pub part: Part,
}

/// What of one training track trains.
#[derive(Debug, Clone, PartialEq)]
pub struct Training {
    /// Knots whose steps train (windows start and end inside; pairs start inside).
    pub knots: Range<usize>,
    /// Record rows the normalisation is taken over.
    pub rows: Range<usize>,
}

/// How one validation track is scored.
#[derive(Debug, Clone, PartialEq)]
pub struct Scoring {
    /// What the report calls it.
    pub name: String,
    /// Index of its track among the validation tracks.
    pub track: usize,
    /// The knot its free run starts at.
    pub run_start: usize,
    /// Online scores count knots at or after this time (and after the start).
    pub scored_from: f64,
    /// Its offline pairs (knots of its track).
    pub pairs: Vec<usize>,
}

/// The first knot whose whole embedding (every closure's span) lies inside the track (a
/// knot within the track's time tolerance of the span's end counts as at it).
pub fn first_inside(model: &ir::Model, track: &Track) -> usize {
    let span = (model.closures.iter())
        .map(|c| c.embedding.span())
        .fold(0.0, f64::max);
    let Some(&start) = track.times.first() else {
        return 0;
    };
    let threshold = start + span - 1e-9 * span.max(1.0) - track.tolerance;
    track.times.partition_point(|&t| t < threshold)
}

/// The eligible one-step pairs of `track` among `knots`: measured history and a target.
pub fn eligible_pairs(
    model: &ir::Model,
    track: &Track,
    knots: Range<usize>,
    fractions: &[f64],
) -> Vec<usize> {
    knots
        .filter(|&k| has_target(track, k) && measured_history(model, track, k, fractions))
        .collect()
}

/// The knot of record row `row` on `track`.
pub fn knot_of_row(track: &Track, row: usize) -> usize {
    track
        .rows
        .iter()
        .position(|r| *r == Some(row))
        .unwrap_or(track.len().saturating_sub(1))
}

/// What trains on each training track and how the training tracks are scored, for `part`.
pub fn split_training(
    model: &ir::Model,
    (records, tracks): (&[Record], &[Track]),
    (part, has_validation, history): (Part, bool, History),
    fractions: &[f64],
) -> Result<(Vec<Training>, Vec<Scoring>), TrainError> {
    match part {
        Part::FirstPairs(count) => {
            let mut trainings = Vec::new();
            let mut scorings = Vec::new();
            let mut left = count;
            for (index, (record, track)) in records.iter().zip(tracks).enumerate() {
                let only = records.len() == 1;
                let (training, scoring) = first_pairs(
                    model,
                    (record, track),
                    (left, only && !has_validation),
                    fractions,
                )?;
                if let Some(left) = left.as_mut() {
                    *left -= training_pairs(
                        model,
                        std::slice::from_ref(track),
                        std::slice::from_ref(&training),
                    )
                    .len();
                }
                trainings.push(training);
                scorings.extend(scoring.map(|s| Scoring { track: index, ..s }));
            }
            if let Some(requested) = count.filter(|_| left.is_some_and(|l| l > 0)) {
                let available = requested - left.unwrap_or(0);
                return Err(TrainError::TooManyTrainPoints {
                    available,
                    requested,
                });
            }
            Ok((trainings, scorings))
        }
        Part::Tail(share) => {
            let mut trainings = Vec::new();
            let mut scorings = Vec::new();
            for (index, (record, track)) in records.iter().zip(tracks).enumerate() {
                let (training, scoring) =
                    tail(model, (record, track), (share, history), index, fractions)?;
                trainings.push(training);
                scorings.push(scoring);
            }
            Ok((trainings, scorings))
        }
        Part::All => {
            let trainings = (records.iter().zip(tracks))
                .map(|(record, track)| Training {
                    knots: window_start(model, track, history)..track.len().saturating_sub(1),
                    rows: 0..record.len(),
                })
                .collect();
            Ok((trainings, Vec::new()))
        }
    }
}

/// Where training windows and whole-experiment free runs start on `track`.
pub fn window_start(model: &ir::Model, track: &Track, history: History) -> usize {
    match history {
        History::Held => 0,
        History::Measured => first_inside(model, track).min(track.len().saturating_sub(1)),
    }
}

/// The first `count` pairs of one experiment after its embedding's history (all of them
/// when `count` is `None` and nothing is to validate; the first
/// [`DEFAULT_TRAIN_SHARE`] when the rest validates), and with `validate_rest` the scoring
/// of the pairs after them.
fn first_pairs(
    model: &ir::Model,
    (record, track): (&Record, &Track),
    (count, validate_rest): (Option<usize>, bool),
    fractions: &[f64],
) -> Result<(Training, Option<Scoring>), TrainError> {
    let first = first_inside(model, track);
    if track.len() < first + 2 {
        return Err(TrainError::TooFewRows {
            file: record.source.clone(),
            needed: first + 2,
            found: track.len(),
            reason: format!("{first} rows of embedding history and one step"),
        });
    }
    let available = track.len() - 1 - first;
    let end = match count {
        // A size counts the pairs that train (on a complete uniform record, every knot).
        Some(requested) => {
            let observed = observed_states(model, track);
            let pair_knots = (first..track.len() - 1)
                .filter(|&k| trains_at(track, &observed, k))
                .take(requested);
            pair_knots.last().map_or(first, |k| k + 1)
        }
        None if !validate_rest => first + available,
        None => {
            let share = (available as f64 * DEFAULT_TRAIN_SHARE).round() as usize;
            first + share.clamp(1, available)
        }
    };
    let count = end - first;
    let last_row = if count == 0 {
        0
    } else {
        track.rows[end].unwrap_or(record.len() - 1) + 1
    };
    let training = Training {
        knots: first..end,
        rows: 0..last_row.min(record.len()),
    };
    let scoring = (validate_rest && end + 1 < track.len()).then(|| Scoring {
        name: format!("{} (rest)", record.source),
        track: 0,
        run_start: end,
        scored_from: f64::NEG_INFINITY,
        pairs: eligible_pairs(model, track, end..track.len() - 1, fractions),
    });
    Ok((training, scoring))
}

fn tail(
    model: &ir::Model,
    (record, track): (&Record, &Track),
    (share, history): (f64, History),
    index: usize,
    fractions: &[f64],
) -> Result<(Training, Scoring), TrainError> {
    let rows = record.len();
    let held = ((rows as f64) * share).round() as usize;
    let first_test = rows.saturating_sub(held);
    if held < MIN_PART_ROWS || first_test < MIN_PART_ROWS {
        return Err(TrainError::SplitTooSmall {
            experiment: record.name.clone(),
            share,
            needed: MIN_PART_ROWS,
            train: first_test,
            test: held,
        });
    }
    let boundary = knot_of_row(track, first_test);
    let last_training = knot_of_row(track, first_test - 1);
    let start = window_start(model, track, history);
    let training = Training {
        knots: start.min(last_training)..last_training,
        rows: 0..first_test,
    };
    let scoring = Scoring {
        name: format!("{} (tail)", record.name),
        track: index,
        run_start: start,
        scored_from: track.times[boundary],
        pairs: eligible_pairs(model, track, last_training..track.len() - 1, fractions),
    };
    Ok((training, scoring))
}

/// The fewest rows in each part of a tail split.
pub const MIN_PART_ROWS: usize = 2;

/// How whole validation experiments are scored: a free run from their first knot (or first
/// full history), offline on their eligible pairs.
pub fn whole_experiments(
    model: &ir::Model,
    tracks: &[Track],
    (first_index, history): (usize, History),
    fractions: &[f64],
) -> Vec<Scoring> {
    (tracks.iter().enumerate())
        .map(|(offset, track)| {
            let start = window_start(model, track, history);
            Scoring {
                name: track.name.clone(),
                track: first_index + offset,
                run_start: start,
                scored_from: f64::NEG_INFINITY,
                pairs: eligible_pairs(
                    model,
                    track,
                    start..track.len().saturating_sub(1),
                    fractions,
                ),
            }
        })
        .collect()
}

/// The pairs of `tracks` that train: inside each training range, every step whose start
/// states are known from data (those the experiment measures at all) and whose end has a
/// measured cell. Their embeddings read the
/// reference, the model's fill included where the data are too sparse (records spec,
/// section 3); on a complete record these are exactly the pairs of measured history.
pub fn training_pairs(model: &ir::Model, tracks: &[Track], trainings: &[Training]) -> Vec<PairAt> {
    let mut pairs = Vec::new();
    for (index, (track, training)) in tracks.iter().zip(trainings).enumerate() {
        let observed = observed_states(model, track);
        let knots = (training.knots.clone()).filter(|&k| trains_at(track, &observed, k));
        pairs.extend(knots.map(|k| (index, k)));
    }
    pairs
}

/// The states `track` measures at all (a state never measured starts from the model's own
/// run, so it does not hold a step back from training).
fn observed_states(model: &ir::Model, track: &Track) -> Vec<usize> {
    (0..model.states.len())
        .filter(|&i| track.measured[i].iter().any(|&m| m))
        .collect()
}

/// Whether the step at `knot` trains: its end has a measured cell and its start is known
/// from data for every `observed` state.
fn trains_at(track: &Track, observed: &[usize], knot: usize) -> bool {
    has_target(track, knot) && observed.iter().all(|&i| track.known[i][knot])
}

/// The steps inside each training range whose two ends are known from data for every
/// measured state: the intervals the balances see.
pub fn known_intervals(model: &ir::Model, tracks: &[Track], trainings: &[Training]) -> Vec<PairAt> {
    let measured = model.states.len();
    let mut intervals = Vec::new();
    for (index, (track, training)) in tracks.iter().zip(trainings).enumerate() {
        let knots = (training.knots.clone()).filter(|&k| {
            k + 1 < track.len() && (0..measured).all(|i| track.known[i][k] && track.known[i][k + 1])
        });
        intervals.extend(knots.map(|k| (index, k)));
    }
    intervals
}
