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

use crate::backend::{Feedback, RolloutBatch};
use crate::ir::{self, Var};
use crate::record::grid::{hold, interpolate, snap, Track};

use super::pairs::PairAt;

/// A closure's raw embedding at step `step` (fraction `fraction`) of the window starting at
/// knot `start` of `track`, batch row `row`, with predicted shares left at zero, and those
/// shares as feedback entries.
pub fn window_embedding(
    closure: &ir::Closure,
    track: &Track,
    (start, row): (usize, usize),
    (step, fraction): (usize, f64),
) -> (Vec<f64>, Vec<Feedback>) {
    let layout = closure.embedding.layout();
    let (mut raw, mut feedback) = (Vec::with_capacity(layout.len()), Vec::new());
    let at = (start, row, step, fraction);
    let into = (&mut raw, &mut feedback);
    window_embedding_into((&layout, closure.embedding.delay), track, at, into);
    (raw, feedback)
}

/// [`window_embedding`] for an embedding `layout` of delay `delay`, appended to `raw` and
/// `feedback`.
fn window_embedding_into(
    (layout, delay): (&[(Var, usize)], f64),
    track: &Track,
    (start, row, step, fraction): (usize, usize, usize, f64),
    (raw, feedback): (&mut Vec<f64>, &mut Vec<Feedback>),
) {
    for (column, &(var, lag)) in layout.iter().enumerate() {
        let position = track.stage_position(start + step, fraction, (lag, delay));
        let value = match var {
            Var::Input(i) => hold(&track.inputs[i], position, fraction >= 1.0),
            Var::State(_) if lag == 0 => 0.0,
            Var::State(i) => {
                let offset = snap(position - start as f64);
                if offset <= 0.0 {
                    interpolate(&track.states[i], position)
                } else {
                    let below = crate::numeric::rounding::floor(offset);
                    let weight_above = offset - below;
                    let below = below as usize;
                    let mut data_share = 0.0;
                    for (sample, weight) in [(below, 1.0 - weight_above), (below + 1, weight_above)]
                    {
                        if weight == 0.0 {
                            continue;
                        }
                        if sample == 0 {
                            data_share += weight * track.states[i][start];
                        } else {
                            feedback.push(Feedback {
                                row,
                                column,
                                sample,
                                state: i,
                                weight,
                            });
                        }
                    }
                    data_share
                }
            }
            _ => f64::NAN,
        };
        raw.push(value);
    }
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
    (tracks, hidden, weights, observables): RolloutData,
    starts: &[PairAt],
    steps: usize,
    fractions: &[f64],
) -> RolloutBatch {
    let closures = model.closures.len();
    let rows = starts.len();
    let layouts: Vec<_> = (model.closures.iter())
        .map(|c| (c.embedding.layout(), c.embedding.delay))
        .collect();
    // Each embedding block sized once (a clone would drop the capacity).
    let embeddings = || -> Vec<Vec<Vec<f64>>> {
        (layouts.iter())
            .map(|(layout, _)| {
                (fractions.iter())
                    .map(|_| Vec::with_capacity(rows * layout.len()))
                    .collect()
            })
            .collect()
    };
    let mut batch = RolloutBatch {
        rows,
        steps,
        states: Vec::new(),
        inputs: vec![Vec::new(); steps],
        embeddings: (0..steps).map(|_| embeddings()).collect(),
        feedback: vec![vec![vec![Vec::new(); fractions.len()]; closures]; steps],
        targets: vec![Vec::new(); steps],
        step_sizes: vec![Vec::new(); steps],
        weights: vec![Vec::new(); steps],
        observed: vec![Vec::new(); steps],
        observed_weights: vec![Vec::new(); steps],
    };
    for (window, &(index, start)) in starts.iter().enumerate() {
        let track = &tracks[index];
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
            for (closure, (layout, delay)) in layouts.iter().enumerate() {
                for (offset, &fraction) in fractions.iter().enumerate() {
                    let at = (start, window, step, fraction);
                    let into = (
                        &mut batch.embeddings[step][closure][offset],
                        &mut batch.feedback[step][closure][offset],
                    );
                    window_embedding_into((layout, *delay), track, at, into);
                }
            }
        }
    }
    batch
}

/// Window starts for one pass of multiple shooting over the knots `first..first + pairs`
/// of a track: consecutive non-overlapping windows of `steps` steps from `first + phase`,
/// each ending inside that range.
pub fn shooting_starts(first: usize, pairs: usize, steps: usize, phase: usize) -> Vec<usize> {
    let steps = steps.max(1);
    if pairs < steps {
        return Vec::new();
    }
    let phase = phase % steps;
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
        let batch = rollout_batch(
            &model,
            (&tracks, &[], &[], &[]),
            &[(0, start)],
            steps,
            &fractions,
        );
        let rolled = network.rollout_predict(&batch).unwrap();
        let run = simulate(
            &network,
            &model,
            &record,
            &fractions,
            (start, start + steps - 1),
            &[],
            (Feed::Own, None),
        )
        .unwrap();
        for (step, predicted) in rolled.iter().enumerate() {
            let expected = run.next_states[step][0];
            assert!(
                (predicted[0] - expected).abs() < 1e-12,
                "step {step}: {} vs {expected}",
                predicted[0]
            );
        }
        // One step: the rollout loss is the one-step loss of the same pair.
        let pairs = [(0, start), (0, start + 2)];
        let single = rollout_batch(&model, (&tracks, &[], &[], &[]), &pairs, 1, &fractions);
        let table = PairTable::build(&model, &tracks, &pairs, &[], &fractions);
        let one_step = network.loss(&table.batch(&[0, 1])).unwrap();
        assert!((network.rollout_loss(&single).unwrap() - one_step).abs() < 1e-14);
    }

    #[test]
    fn shooting_windows_tile_the_training_pairs() {
        assert_eq!(shooting_starts(3, 10, 4, 0), vec![3, 7]);
        assert_eq!(shooting_starts(3, 10, 4, 2), vec![5, 9]);
        assert_eq!(shooting_starts(3, 10, 4, 6), vec![5, 9]);
        assert_eq!(shooting_starts(0, 3, 4, 0), Vec::<usize>::new());
        assert_eq!(shooting_starts(0, 5, 1, 0), vec![0, 1, 2, 3, 4]);
    }
}
