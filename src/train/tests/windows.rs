//! The rollout windows of `crate::engine::windows` against training's own free runs
//! (`train::evaluate::simulate`) and grids: what a window holds is what a free run from its
//! start would see.
use crate::engine::graph::{Feedback, RolloutBatch};
use crate::engine::graph::{Network, Normalisation, Precision, Setup};
use crate::engine::pairs::{embedding_row, first_pair_row, stage_fractions, PairTable};
use crate::engine::windows::*;
use crate::ir;
use crate::ir::Activation;
use crate::record::grid::Track;
use crate::train::evaluate::{simulate, Feed};
use crate::train::fixtures::{ClosureSpec, ModelBuilder, OutputSpec};

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
            let (mut raw, feedback) = window_embedding(closure, &record, (4, 0), (step, fraction));
            for entry in &feedback {
                raw[entry.column] += entry.weight * record.states[entry.state][4 + entry.sample];
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
