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

use crate::backend::{Feedback, RolloutBatch};
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
    let rows = starts.len();
    let layouts: Vec<_> = (model.closures.iter())
        .map(|c| (c.embedding.layout(), c.embedding.delay))
        .collect();
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
            embeddings.iter_mut().zip(feedback.iter_mut()).zip(&layouts)
        {
            cleared(embedding, fractions.len());
            cleared(feedback, fractions.len());
            for block in embedding.iter_mut() {
                block.reserve(rows * layout.len());
            }
        }
    }
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
        let mut sources = plan.sources.iter();
        batch.states.extend(track.states.iter().map(|s| s[start]));
        let estimates = hidden.get(index).and_then(|h| h.get(start));
        batch.states.extend(estimates.into_iter().flatten());
        for step in 0..steps {
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
            for (closure, (layout, _)) in layouts.iter().enumerate() {
                for raw in &mut batch.embeddings[step][closure] {
                    let block = sources.by_ref().take(layout.len());
                    raw.extend(block.map(|source| source.value(track, start)));
                }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::{Network, Normalisation, Precision, Setup};
    use crate::ir::Activation;
    use crate::train::evaluate::{simulate, Feed};
    use crate::train::fixtures::{ClosureSpec, ModelBuilder, OutputSpec};
    use crate::train::pairs::{embedding_row, first_pair_row, stage_fractions, PairTable};

    /// A model whose closure looks back 1.5 samples, so that stage times fall between
    /// samples and every window step past the first mixes data and predictions.
    fn model() -> ir::Model {
        ModelBuilder::new("m")
            .input("u")
            .state("x")
            .closure(ClosureSpec {
                name: "c",
                outputs: vec![OutputSpec {
                    name: "o",
                    scale: Some(0.5),
                    prior: None,
                }],
                observe: &["x", "u"],
                delay: 3.0,
                dim: 3,
                hidden: vec![4],
                activation: Activation::Tanh,
            })
            .der("x", "o - 0.1 * x")
            .build()
    }

    fn record() -> Track {
        let record = crate::record::Record::complete(
            "r",
            (0..12).map(|i| 2.0 * i as f64).collect(),
            vec![(0..12).map(|i| (i % 3) as f64).collect()],
            vec![(0..12).map(|i| 1.0 + 0.1 * i as f64).collect()],
        );
        Track::lay(
            &record,
            &crate::train::prepare::grid_for(&model(), 2.0),
            &[],
        )
    }

    /// Recombining data share and feedback with the data in place of predictions gives
    /// the one-step embedding read from the data.
    #[test]
    fn data_share_plus_feedback_is_the_interpolated_embedding() {
        let model = model();
        let record = record();
        let closure = &model.closures[0];
        for step in 0..4 {
            for fraction in [0.0, 0.5, 1.0] {
                let (mut raw, feedback) =
                    window_embedding(closure, &record, (4, 0), (step, fraction));
                for entry in &feedback {
                    raw[entry.column] +=
                        entry.weight * record.states[entry.state][4 + entry.sample];
                }
                let expected = embedding_row(closure, &record, 4 + step, fraction);
                for (column, (found, wanted)) in raw.iter().zip(&expected).enumerate() {
                    if column == 0 {
                        continue; // lag-0 state: the stage estimate
                    }
                    assert!((found - wanted).abs() < 1e-12, "step {step} f {fraction}");
                }
            }
        }
        // Step 0 never feeds back; at step 1, f = 0.5 the lag-1 state (1.5 samples back)
        // sits at q = 0: data only; at step 2, f = 1 it sits at q = 1.5: half sample 1,
        // half sample 2.
        assert!(window_embedding(closure, &record, (4, 0), (0, 1.0))
            .1
            .is_empty());
        let (_, feedback) = window_embedding(closure, &record, (4, 0), (2, 1.0));
        let lag_one: Vec<_> = feedback.iter().filter(|f| f.column == 2).collect();
        assert_eq!(lag_one.len(), 2);
        assert_eq!((lag_one[0].sample, lag_one[0].weight), (1, 0.5));
        assert_eq!((lag_one[1].sample, lag_one[1].weight), (2, 0.5));
    }

    fn network(model: &ir::Model, record: &Track) -> Network {
        let setup = Setup {
            step: record.steps[0],
            substeps: 1,
            precision: Precision::F64,
            seed: 3,
            normalisation: Normalisation {
                state_mean: vec![1.5],
                state_std: vec![0.4],
                input_mean: vec![1.0],
                input_std: vec![0.8],
                ..Normalisation::default()
            },
            scales: vec![vec![0.5]],
        };
        let mut network = Network::build(model, &setup).unwrap();
        let mut weights = network.weights();
        for (index, value) in weights.iter_mut().flat_map(|t| &mut t.values).enumerate() {
            *value = ((index * 7 % 11) as f64 - 5.0) / 6.0;
        }
        network.set_weights(&weights).unwrap();
        network
    }

    /// Each window of `batch`, starting at knot `starts[row]` of `track`, is the
    /// evaluator's free run from that knot (to 1e-12); the evaluator feeds predictions back
    /// by rewriting the record.
    fn assert_free_runs(
        network: &Network,
        (model, track): (&ir::Model, &Track),
        starts: &[usize],
        batch: &RolloutBatch,
    ) {
        let fractions = stage_fractions(model.dynamics, 1);
        let rolled = network.rollout_predict(batch).unwrap();
        for (row, &from) in starts.iter().enumerate() {
            let last = from + batch.steps - 1;
            let run = simulate(
                network,
                model,
                track,
                &fractions,
                (from, last),
                &[],
                (Feed::Own, None, crate::train::stepping::Stepping::Fixed),
            )
            .unwrap();
            for (step, predicted) in rolled.iter().enumerate() {
                let expected = run.next_states[step][0];
                assert!(
                    (predicted[row] - expected).abs() < 1e-12,
                    "window {row}, step {step}: {} vs {expected}",
                    predicted[row]
                );
            }
        }
    }

    /// A rollout batch reproduces the step-by-step free run of the evaluator, which feeds
    /// predictions back by rewriting the record.
    #[test]
    fn a_rollout_is_the_free_run_of_the_evaluator() {
        let model = model();
        let record = record();
        let network = network(&model, &record);
        let fractions = stage_fractions(model.dynamics, 1);
        let start = first_pair_row(&model, record.steps[0]);
        let steps = 5;
        let tracks = [record.clone()];
        // Three windows on one uniform track: they share one plan and its feedback entries.
        let starts = [start, start + 1, start + 3];
        let batch = rollout_batch(
            &model,
            (&tracks, &[], &[], &[]),
            &starts.map(|s| (0, s)),
            steps,
            &fractions,
        );
        let entries: Vec<&Feedback> = batch
            .feedback
            .iter()
            .flatten()
            .flatten()
            .flatten()
            .collect();
        assert!(!entries.is_empty());
        assert!(entries.iter().all(|f| f.rows == (0..3)));
        assert_free_runs(&network, (&model, &record), &starts, &batch);
        // One step: the rollout loss is the one-step loss of the same pair.
        let pairs = [(0, start), (0, start + 2)];
        let single = rollout_batch(&model, (&tracks, &[], &[], &[]), &pairs, 1, &fractions);
        let table = PairTable::build(&model, &tracks, &pairs, &[], &fractions);
        let one_step = network.loss(&table.batch(&[0, 1])).unwrap();
        assert!((network.rollout_loss(&single).unwrap() - one_step).abs() < 1e-14);
    }

    /// On an irregular track each window has its own plan and feedback entries of its
    /// own row; every window is still the evaluator's free run from its start.
    #[test]
    fn rollouts_on_an_irregular_track_are_free_runs_of_the_evaluator() {
        let model = model();
        // Gaps of 2.7 and 1.3 among gaps of 2; the grid cuts the 2.7 ones in two.
        let times = (0..14).map(|i| 2.0 * i as f64 + if i % 3 == 1 { 0.7 } else { 0.0 });
        let record = crate::record::Record::complete(
            "r",
            times.collect(),
            vec![(0..14).map(|i| (i % 3) as f64).collect()],
            vec![(0..14).map(|i| 1.0 + 0.1 * i as f64).collect()],
        );
        let grid = crate::train::prepare::grid_for(&model, 2.0);
        let track = Track::lay(&record, &grid, &[]);
        assert!(track.uniform.is_none());
        let network = network(&model, &track);
        let fractions = stage_fractions(model.dynamics, 1);
        let steps = 5;
        let starts = [4, 5, 8];
        let tracks = [track.clone()];
        let at = starts.map(|s| (0, s));
        let batch = rollout_batch(&model, (&tracks, &[], &[], &[]), &at, steps, &fractions);
        let entries = || batch.feedback.iter().flatten().flatten().flatten();
        assert!(entries().next().is_some());
        assert!(entries().all(|f| f.rows.len() == 1));
        assert_free_runs(&network, (&model, &track), &starts, &batch);
    }

    #[test]
    fn shooting_windows_tile_the_training_pairs() {
        assert_eq!(shooting_starts(3, 10, 4, 0), vec![3, 7]);
        assert_eq!(shooting_starts(3, 10, 4, 2), vec![5, 9]);
        assert_eq!(shooting_starts(3, 10, 4, 6), vec![5, 9]);
        assert_eq!(shooting_starts(0, 3, 4, 0), Vec::<usize>::new());
        assert_eq!(shooting_starts(0, 5, 1, 0), vec![0, 1, 2, 3, 4]);
        // A range barely longer than the window holds one window at every phase.
        for phase in 0..8 {
            let starts = shooting_starts(0, 10, 8, phase);
            assert_eq!(starts.len(), 1, "phase {phase}");
            assert!(starts[0] + 8 <= 10);
        }
        assert_eq!(shooting_starts(0, 8, 8, 5), vec![0]);
    }
}
