//! Free-run windows for the multi-step objective: batches of `K`-step rollouts in which the
//! network is fed its own predictions, through the state and through the delay embedding.
//!
//! A window starts at row `r` from the measured states there (and the hidden-state
//! estimates), holds the data's inputs over each step, and is compared with the measured
//! cells of knots `r + 1 ..= r + K` (a knot without a cell weighs nothing). At step `k` and stage fraction `f`, a delayed state
//! sits `q = k + f - lag * delay / h` samples after the window start ([`super::pairs`]
//! explains positions). Where `q <= 0` the value is read from the data as in a one-step
//! pair; where `q > 0` it interpolates between samples `floor(q)` and `floor(q) + 1`, and
//! each of those with index `j >= 1` is the state predicted `j` steps into the window: the
//! backend adds it with its interpolation weight ([`Feedback`]) and gradients flow through
//! it. Sample 0 is the window's measured start. With one step and no `q > 0` a window is
//! exactly a one-step pair.
//!
//! **Plans.** Where each entry of a window comes from ([`Source`]: a held input, the
//! reference at a position, or predictions) is worked out once per window as a
//! [`WindowPlan`], relative to the window's start knot, and then read off the track. On a
//! uniform track positions are arithmetic ([`Track::stage_offset`]), so one plan serves
//! every window of the batch on that track; on an irregular track each window has its own.
//! Consecutive windows of one plan read their predictions alike, so they share its
//! feedback entries, each over their rows (the epoch puts a batch's windows in track
//! order): a batch of `W` windows on one uniform track carries one window's feedback, not
//! `W` copies.

use crate::engine::batch::{Feedback, RolloutBatch};
use crate::ir::{self, Var};
use crate::numeric::rounding;
use crate::record::grid::{interpolate_at, Track};

use super::pairs::PairAt;

/// Where one embedding entry of a window comes from, relative to the window's start knot
/// `s`.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Source {
    /// Input `input` held at knot `s + knot` (clamped to the track).
    Held { input: usize, knot: isize },
    /// A lag-0 state: the stage's own estimate, which the backend supplies (left at zero).
    Stage,
    /// Measured state `state`'s reference at position `s + below + fraction` (clamped to
    /// the track), before the window starts.
    Data {
        state: usize,
        below: isize,
        fraction: f64,
    },
    /// Measured state `state` inside the window: `start_weight` times its value at the
    /// window's start plus the predicted samples of `fed` (a zero weight is no entry).
    Fed {
        state: usize,
        start_weight: f64,
        fed: [(usize, f64); 2],
    },
    /// Not something an embedding reads from a track.
    Absent,
}

impl Source {
    /// The source of an entry of `var` at `offset` knots after the window start (a stage
    /// at `fraction` of its step).
    fn of(var: Var, lag: usize, offset: f64, fraction: f64) -> Source {
        match var {
            Var::Input(input) => {
                // At the end of a step (fraction 1) the value held over the step.
                let knot = if fraction >= 1.0 {
                    rounding::ceil(offset) - 1.0
                } else {
                    rounding::floor(offset)
                };
                Source::Held {
                    input,
                    knot: knot as isize,
                }
            }
            Var::State(_) if lag == 0 => Source::Stage,
            Var::State(state) => {
                let below = rounding::floor(offset);
                let fraction = offset - below;
                if offset <= 0.0 {
                    return Source::Data {
                        state,
                        below: below as isize,
                        fraction,
                    };
                }
                // Samples `below` and `below + 1` of the window; sample 0 is its start.
                let below = below as usize;
                let (mut start_weight, mut fed) = (0.0, [(0, 0.0); 2]);
                for (slot, (sample, weight)) in [(below, 1.0 - fraction), (below + 1, fraction)]
                    .into_iter()
                    .enumerate()
                {
                    if sample == 0 {
                        start_weight += weight;
                    } else {
                        fed[slot] = (sample, weight);
                    }
                }
                Source::Fed {
                    state,
                    start_weight,
                    fed,
                }
            }
            _ => Source::Absent,
        }
    }

    /// The entry's data share in the window starting at knot `start` of `track` (its
    /// predicted shares are [`Source::feed`]'s).
    fn value(self, track: &Track, start: usize) -> f64 {
        match self {
            Source::Held { input, knot } => {
                let values = &track.inputs[input];
                let last = values.len().saturating_sub(1) as isize;
                values[(start as isize + knot).clamp(0, last) as usize]
            }
            Source::Stage => 0.0,
            Source::Data {
                state,
                below,
                fraction,
            } => interpolate_at(&track.states[state], start as isize + below, fraction),
            Source::Fed {
                state,
                start_weight,
                ..
            } if start_weight != 0.0 => start_weight * track.states[state][start],
            Source::Fed { .. } => 0.0,
            Source::Absent => f64::NAN,
        }
    }

    /// Appends the entry's predicted shares to `feedback`, for network input `column` of
    /// batch rows `rows`.
    fn feed(self, rows: &std::ops::Range<usize>, column: usize, feedback: &mut Vec<Feedback>) {
        if let Source::Fed { state, fed, .. } = self {
            for (sample, weight) in fed {
                if weight != 0.0 {
                    feedback.push(Feedback {
                        rows: rows.clone(),
                        column,
                        sample,
                        state,
                        weight,
                    });
                }
            }
        }
    }
}

/// The sources of every embedding entry of a window, `[step][closure][fraction][column]`.
#[derive(Debug, Clone, Default, PartialEq)]
struct WindowPlan {
    sources: Vec<Source>,
}

impl WindowPlan {
    /// The plan of the `steps`-step window from knot `start` of `track` for closures of
    /// `layouts` (layout and delay) at stage `fractions`.
    fn new(
        layouts: &[(Vec<(Var, usize)>, f64)],
        track: &Track,
        start: usize,
        (steps, fractions): (usize, &[f64]),
    ) -> WindowPlan {
        let mut plan = WindowPlan::default();
        plan.lay(layouts, track, start, (steps, fractions));
        plan
    }

    /// Appends the plan's feedback entries, for batch rows `rows`, to
    /// `feedback[step][closure][fraction]`.
    fn feed(
        &self,
        layouts: &[(Vec<(Var, usize)>, f64)],
        rows: std::ops::Range<usize>,
        feedback: &mut [Vec<Vec<Vec<Feedback>>>],
    ) {
        let mut sources = self.sources.iter();
        for per_closure in feedback {
            for (per_fraction, (layout, _)) in per_closure.iter_mut().zip(layouts) {
                for list in per_fraction {
                    for (column, source) in sources.by_ref().take(layout.len()).enumerate() {
                        source.feed(&rows, column, list);
                    }
                }
            }
        }
    }

    /// [`WindowPlan::new`] in place (its buffer kept).
    fn lay(
        &mut self,
        layouts: &[(Vec<(Var, usize)>, f64)],
        track: &Track,
        start: usize,
        (steps, fractions): (usize, &[f64]),
    ) {
        let sources = &mut self.sources;
        sources.clear();
        for step in 0..steps {
            for (layout, delay) in layouts {
                for &fraction in fractions {
                    sources.extend(layout.iter().map(|&(var, lag)| {
                        let offset = track.stage_offset(start, (step, fraction), (lag, *delay));
                        Source::of(var, lag, offset, fraction)
                    }));
                }
            }
        }
    }
}

/// A closure's raw embedding at step `step` (fraction `fraction`) of the window starting at
/// knot `start` of `track`, batch row `row`, with predicted shares left at zero, and those
/// shares as feedback entries.
#[cfg(test)]
pub fn window_embedding(
    closure: &ir::Closure,
    track: &Track,
    (start, row): (usize, usize),
    (step, fraction): (usize, f64),
) -> (Vec<f64>, Vec<Feedback>) {
    let delay = closure.embedding.delay;
    let (mut raw, mut feedback) = (Vec::new(), Vec::new());
    for (column, (var, lag)) in closure.embedding.layout().into_iter().enumerate() {
        let offset = track.stage_offset(start, (step, fraction), (lag, delay));
        let source = Source::of(var, lag, offset, fraction);
        source.feed(&(row..row + 1), column, &mut feedback);
        raw.push(source.value(track, start));
    }
    (raw, feedback)
}

/// What rollouts read: the tracks, the hidden-state estimates per track and knot, the
/// column weights and the measured model outputs.
pub type RolloutData<'a> = (&'a [Track], &'a [Vec<Vec<f64>>], &'a [f64], &'a [usize]);

/// A batch of `steps`-step windows starting at `starts` (track and knot; every
/// `start + steps` must be a knot of its track); `hidden[track][knot]` holds the
/// hidden-state estimates; each measured cell weighs its column's `weights[state]` (empty:
/// 1); `observables` are the measured model outputs (the normalisation's).
#[cfg(test)]
pub fn rollout_batch(
    model: &ir::Model,
    data: RolloutData,
    starts: &[PairAt],
    steps: usize,
    fractions: &[f64],
) -> RolloutBatch {
    let mut batch = RolloutBatch::default();
    rollout_batch_into(&mut batch, model, data, starts, (steps, fractions));
    batch
}

/// [`rollout_batch`] written into `batch`, whose buffers are reused (an epoch builds every
/// batch into one).
pub fn rollout_batch_into(
    batch: &mut RolloutBatch,
    model: &ir::Model,
    (tracks, hidden, weights, observables): RolloutData,
    starts: &[PairAt],
    (steps, fractions): (usize, &[f64]),
) {
    let layouts: Layouts = (model.closures.iter())
        .map(|c| (c.embedding.layout(), c.embedding.delay))
        .collect();
    reset(batch, (starts.len(), steps), &layouts, fractions.len());
    // One plan per uniform track (kept for the batch); an irregular track's per window.
    // A run of consecutive windows with one plan shares its feedback entries.
    let mut plans: Vec<Option<WindowPlan>> = vec![None; tracks.len()];
    let mut irregular = WindowPlan::default();
    let mut shared_until = 0;
    for (window, &(index, start)) in starts.iter().enumerate() {
        let track = &tracks[index];
        let plan = if track.uniform.is_some() {
            plans[index]
                .get_or_insert_with(|| WindowPlan::new(&layouts, track, start, (steps, fractions)))
        } else {
            irregular.lay(&layouts, track, start, (steps, fractions));
            &irregular
        };
        if window >= shared_until {
            let alike = match track.uniform {
                Some(_) => starts[window..].iter().take_while(|s| s.0 == index).count(),
                None => 1,
            };
            shared_until = window + alike;
            plan.feed(&layouts, window..shared_until, &mut batch.feedback);
        }
        batch.states.extend(track.states.iter().map(|s| s[start]));
        let estimates = hidden.get(index).and_then(|h| h.get(start));
        batch.states.extend(estimates.into_iter().flatten());
        push_data(batch, track, start, (weights, observables));
        push_embeddings(batch, plan, (track, start), &layouts);
    }
}

/// Each closure's embedding layout and delay.
type Layouts = Vec<(Vec<(Var, usize)>, f64)>;

/// Empties `batch` for `rows` windows of `steps` steps (buffers kept), with one embedding
/// block and feedback list per closure of `layouts` and stage fraction.
fn reset(
    batch: &mut RolloutBatch,
    (rows, steps): (usize, usize),
    layouts: &Layouts,
    fractions: usize,
) {
    batch.rows = rows;
    batch.steps = steps;
    batch.states.clear();
    for lists in [
        &mut batch.inputs,
        &mut batch.targets,
        &mut batch.step_sizes,
        &mut batch.weights,
        &mut batch.observed,
        &mut batch.observed_weights,
    ] {
        cleared(lists, steps);
    }
    batch.embeddings.resize_with(steps, Vec::new);
    batch.feedback.resize_with(steps, Vec::new);
    for (embeddings, feedback) in batch.embeddings.iter_mut().zip(&mut batch.feedback) {
        embeddings.resize_with(layouts.len(), Vec::new);
        feedback.resize_with(layouts.len(), Vec::new);
        for ((embedding, feedback), (layout, _)) in
            embeddings.iter_mut().zip(feedback.iter_mut()).zip(layouts)
        {
            cleared(embedding, fractions);
            cleared(feedback, fractions);
            for block in embedding.iter_mut() {
                block.reserve(rows * layout.len());
            }
        }
    }
}

/// Appends what each step of the window from knot `start` of `track` reads from the data:
/// held inputs, targets and their weights (each measured cell its column's `weights`, 1
/// where none is given), step sizes, and the measured `observables`.
fn push_data(
    batch: &mut RolloutBatch,
    track: &Track,
    start: usize,
    (weights, observables): (&[f64], &[usize]),
) {
    for step in 0..batch.steps {
        let knot = start + step;
        batch.inputs[step].extend(track.inputs.iter().map(|u| u[knot]));
        batch.targets[step].extend(track.states.iter().map(|s| s[knot + 1]));
        (batch.weights[step]).extend(
            track
                .measured
                .iter()
                .enumerate()
                .map(|(i, m)| f64::from(m[knot + 1]) * weights.get(i).copied().unwrap_or(1.0)),
        );
        batch.step_sizes[step].push(track.steps[knot]);
        for &output in observables {
            let cell = track.observed_cell(output, knot + 1);
            batch.observed[step].push(cell.unwrap_or(0.0));
            batch.observed_weights[step].push(f64::from(cell.is_some()));
        }
    }
}

/// Appends the data shares of the window's embeddings, read off `track` from knot `start`
/// as `plan` lays them out (step, closure, stage fraction, column).
fn push_embeddings(
    batch: &mut RolloutBatch,
    plan: &WindowPlan,
    (track, start): (&Track, usize),
    layouts: &Layouts,
) {
    let mut sources = plan.sources.iter();
    for per_step in &mut batch.embeddings {
        for (per_closure, (layout, _)) in per_step.iter_mut().zip(layouts) {
            for raw in per_closure {
                let block = sources.by_ref().take(layout.len());
                raw.extend(block.map(|source| source.value(track, start)));
            }
        }
    }
}

/// `lists` as `count` empty lists (their capacity kept).
fn cleared<T>(lists: &mut Vec<Vec<T>>, count: usize) {
    lists.resize_with(count, Vec::new);
    lists.iter_mut().for_each(Vec::clear);
}

/// Window starts for one pass of multiple shooting over the knots `first..first + pairs`
/// of a track: consecutive non-overlapping windows of `steps` steps from `first + phase`,
/// each ending inside that range. The phase is taken modulo the window and modulo the
/// room the range leaves (`pairs - steps + 1` starts), so every range at least one window
/// long holds a window whatever the phase.
pub fn shooting_starts(first: usize, pairs: usize, steps: usize, phase: usize) -> Vec<usize> {
    let steps = steps.max(1);
    if pairs < steps {
        return Vec::new();
    }
    let phase = phase % steps.min(pairs - steps + 1);
    (0..)
        .map(|window| first + phase + window * steps)
        .take_while(|start| start + steps <= first + pairs)
        .collect()
}
