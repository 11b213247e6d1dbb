//! Rollout windows on the fused step against the graph backend (the reference, itself checked
//! against finite differences in `backend::tests_rollout`): the same loss and the same
//! gradient entry by entry in `f64`, through predicted states fed back into the delay
//! embedding, for every shipped trainable model on windows of its shipped record and for
//! fixtures with hidden states, two closures and params on an irregular record with missing
//! cells; sub-steps 1 and 2; and the same training under the one optimiser.

use super::tests::{random_weights, shipped_track, SHIPPED};
use super::*;
use crate::engine::fixtures::{kitchen_sink, ClosureSpec, ModelBuilder, OutputSpec};
use crate::engine::graph::{Feedback, Normalisation};
use crate::engine::pairs::stage_fractions;
use crate::engine::step::{Optimiser, StepBatch};
use crate::engine::windows::rollout_batch;
use crate::ir::{Activation, Constraint};
use crate::record::{GridOptions, Record, Track};

/// Loss and every gradient entry of the fused rollout against the graph backend's at
/// `weights` (each entry against the largest of its tensor, to `tolerance`); returns the
/// loss.
fn assert_rollout_matches(
    model: &ir::Model,
    setup: &Setup,
    batch: &RolloutBatch,
    weights: Option<&[NamedTensor]>,
    tolerance: f64,
) -> f64 {
    let mut network = Network::build(model, setup).unwrap();
    let mut fused = FusedNetwork::build(model, setup).unwrap();
    // Without weights: the initial ones with a last layer near zero (at zero no gradient
    // reaches the hidden layers).
    let weights = weights.map_or_else(
        || super::tests::near_start(&network.weights(), 8),
        <[_]>::to_vec,
    );
    network.set_weights(&weights).unwrap();
    fused.set_weights(&weights).unwrap();
    let (expected_loss, expected) = network.rollout_gradient(batch).unwrap();
    let (loss, found) = fused.rollout_gradient(batch).unwrap();
    let name = &model.name;
    assert!(
        (loss - expected_loss).abs() <= tolerance * expected_loss.abs(),
        "{name}: loss {loss} vs {expected_loss}"
    );
    assert_eq!(fused.rollout_loss(batch).unwrap(), loss, "{name}");
    for ((tensor, expected), found) in weights.iter().zip(&expected).zip(&found) {
        let largest = expected.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(largest > 0.0, "{name}: {} carries no gradient", tensor.name);
        for (index, (e, f)) in expected.iter().zip(found).enumerate() {
            assert!(
                (e - f).abs() <= tolerance * largest,
                "{name}: {}[{index}]: fused {f} vs graph {e}",
                tensor.name
            );
        }
    }
    loss
}

fn feedback_entries(batch: &RolloutBatch) -> usize {
    batch
        .feedback
        .iter()
        .flatten()
        .flatten()
        .map(Vec::len)
        .sum()
}

/// Every row its own step (0.6 to 1.4 of its own) and about one cell in five unmeasured,
/// one in five weighing 2.
fn roughen(batch: &mut RolloutBatch) {
    for (step, sizes) in batch.step_sizes.iter_mut().enumerate() {
        for (row, h) in sizes.iter_mut().enumerate() {
            *h *= 0.6 + 0.1 * ((3 * row + 7 * step) % 9) as f64;
        }
    }
    for (step, weights) in batch.weights.iter_mut().enumerate() {
        for (cell, w) in weights.iter_mut().enumerate() {
            *w = match (cell + 2 * step) % 5 {
                0 => 0.0,
                1 => 2.0,
                _ => *w,
            };
        }
    }
}

/// Every shipped trainable model on three 12-step windows of its shipped record (long
/// enough that the lagged states of every embedding are fed back), with irregular steps
/// and missing cells, sub-steps 1 and 2, at its initial weights: the fused rollout's loss
/// and gradient are the graph backend's to 1e-9 (relative).
#[test]
fn every_shipped_model_rolls_out_as_the_graph_backend_in_f64() {
    let steps = 12;
    for (path, data) in SHIPPED {
        for substeps in [1, 2] {
            let (model, track, first, setup) = shipped_track(
                &format!("models/{path}.gbm"),
                &format!("models/{data}"),
                3 * steps + 1,
                (Precision::F64, substeps),
            );
            let fractions = stage_fractions(model.dynamics, substeps);
            let starts = [(0, first), (0, first + steps + 1), (0, first + 2 * steps)];
            let tracks = [track];
            let data = (&tracks[..], &[][..], &[][..], &[][..]);
            let mut batch = rollout_batch(&model, data, &starts, steps, &fractions);
            roughen(&mut batch);
            assert!(feedback_entries(&batch) > 0, "{path} feeds nothing back");
            assert_rollout_matches(&model, &setup, &batch, None, 1e-9);
        }
    }
}

/// Windows on one uniform track share their feedback entries, each over all their rows;
/// both engines give the loss and gradient of the same entries written out row by row.
#[test]
fn shared_feedback_is_each_windows_own() {
    let steps = 9;
    let (path, data) = SHIPPED[0];
    let (model, track, first, setup) = shipped_track(
        &format!("models/{path}.gbm"),
        &format!("models/{data}"),
        3 * steps + 1,
        (Precision::F64, 1),
    );
    assert!(track.uniform.is_some());
    let fractions = stage_fractions(model.dynamics, 1);
    let starts = [(0, first + 4), (0, first), (0, first + 2 * steps)];
    let tracks = [track];
    let data = (&tracks[..], &[][..], &[][..], &[][..]);
    let shared = rollout_batch(&model, data, &starts, steps, &fractions);
    let entries = || shared.feedback.iter().flatten().flatten().flatten();
    assert!(entries().next().is_some(), "{path} feeds nothing back");
    assert!(entries().all(|f| f.rows == (0..3)));
    let mut own = shared.clone();
    for list in own.feedback.iter_mut().flatten().flatten() {
        *list = (list.iter())
            .flat_map(|f| {
                (f.rows.clone()).map(move |row| Feedback {
                    rows: row..row + 1,
                    ..f.clone()
                })
            })
            .collect();
    }
    assert_eq!(feedback_entries(&own), 3 * feedback_entries(&shared));
    let network = Network::build(&model, &setup).unwrap();
    let mut fused = FusedNetwork::build(&model, &setup).unwrap();
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * (a.abs() + b.abs()).max(1e-300);
    let graph = [&shared, &own].map(|b| network.rollout_gradient(b).unwrap());
    let fast = [&shared, &own].map(|b| fused.rollout_gradient(b).unwrap());
    for (one, other) in [(&graph[0], &graph[1]), (&fast[0], &fast[1])] {
        assert!(close(one.0, other.0), "loss {} vs {}", one.0, other.0);
        for (a, b) in one.1.iter().flatten().zip(other.1.iter().flatten()) {
            assert!(close(*a, *b), "{a} vs {b}");
        }
    }
}

/// Two closures of different delays, activations and depths, a hidden state, a positive and
/// a bounded param.
fn two_closures() -> ir::Model {
    let output = |name, scale, prior| OutputSpec { name, scale, prior };
    ModelBuilder::new("two_closures")
        .input("u")
        .state("X")
        .state("S")
        .hidden("E", 0.4)
        .param("Y", 0.6, Constraint::Positive)
        .param("k", 1.2, Constraint::Bounds(0.5, 3.0))
        .closure(ClosureSpec {
            name: "rates",
            outputs: vec![
                output("a", Some(0.2), Some(("+=", "0.1 * S"))),
                output("b", Some(0.1), None),
            ],
            observe: &["X", "S", "u"],
            delay: 1.5,
            dim: 3,
            hidden: vec![5, 4],
            activation: Activation::Softplus,
        })
        .closure(ClosureSpec {
            name: "uptake",
            outputs: vec![output("q", Some(0.3), Some(("*=", "S / (1 + S)")))],
            observe: &["S"],
            delay: 2.5,
            dim: 2,
            hidden: vec![3],
            activation: Activation::Tanh,
        })
        .der("X", "(a - 0.1) * X + b")
        .der("S", "0.1 * (2 - S) - a / Y * X - q * E ^ k")
        .der("E", "(u - E) / 2")
        .build()
}

/// Twenty rows at uneven times (cut into knots of at most 0.7), two cells missing: windows
/// differ in their steps, their feedback weights and their loss weights.
fn irregular_track() -> Track {
    let rows = 20;
    let times: Vec<f64> = (0..rows)
        .map(|i| 0.8 * i as f64 + 0.3 * ((i * 7 % 5) as f64 / 4.0))
        .collect();
    let mut record = Record::complete(
        "r",
        times.clone(),
        vec![(0..rows).map(|i| ((i / 3) % 2) as f64).collect()],
        vec![
            times.iter().map(|t| 1.0 + 0.2 * t.sin()).collect(),
            times.iter().map(|t| 1.5 - 0.03 * t).collect(),
        ],
    );
    record.states[0][6] = None;
    record.states[1][9] = None;
    let grid = GridOptions {
        max_step: 0.7,
        gap_limits: vec![1.5, 1.5],
        subdivide: true,
    };
    Track::lay(&record, &grid, &[])
}

fn fixture_setup(model: &ir::Model, substeps: usize) -> Setup {
    let measured = model.states.len();
    Setup {
        step: 0.7,
        substeps,
        precision: Precision::F64,
        seed: 5,
        normalisation: Normalisation {
            state_mean: vec![1.0; measured],
            state_std: (0..measured).map(|i| 0.3 + 0.2 * i as f64).collect(),
            input_mean: vec![0.5; model.inputs.len()],
            input_std: vec![0.5; model.inputs.len()],
            ..Normalisation::default()
        },
        scales: (model.closures.iter())
            .map(|c| vec![0.5; c.outputs.len()])
            .collect(),
    }
}

/// Windows of `steps` steps of `model` on the irregular track, with hidden-state estimates
/// at every knot.
fn fixture_batch(model: &ir::Model, substeps: usize, steps: usize) -> RolloutBatch {
    let tracks = [irregular_track()];
    let knots = tracks[0].times.len();
    let hidden: Vec<Vec<Vec<f64>>> = vec![(0..knots)
        .map(|k| vec![0.3 + 0.02 * k as f64; model.hidden.len()])
        .collect()];
    let fractions = stage_fractions(model.dynamics, substeps);
    let starts = [(0, 2), (0, 5), (0, 9), (0, 12)];
    let data = (&tracks[..], &hidden[..], &[1.0, 1.5][..], &[][..]);
    rollout_batch(model, data, &starts, steps, &fractions)
}

/// The fixtures (hidden states, one and two closures, params) on the irregular record at
/// random weights of order one, sub-steps 1 and 2: to 1e-9 of the graph backend; and the
/// feedback matters (the loss without it differs).
#[test]
fn fixtures_roll_out_as_the_graph_backend_on_an_irregular_record() {
    for model in [two_closures(), kitchen_sink(Activation::Gelu)] {
        for substeps in [1, 2] {
            let setup = fixture_setup(&model, substeps);
            let batch = fixture_batch(&model, substeps, 7);
            let sizes = batch.step_sizes.iter().flatten();
            assert!(sizes.clone().any(|&h| (h - 0.7).abs() > 0.05), "irregular");
            assert!(batch.weights.iter().flatten().any(|&w| w == 0.0));
            assert!(feedback_entries(&batch) > 0);
            let template = Network::build(&model, &setup).unwrap().weights();
            let weights = random_weights(&template, 4);
            let loss = assert_rollout_matches(&model, &setup, &batch, Some(&weights), 1e-9);
            let mut without = batch.clone();
            without
                .feedback
                .iter_mut()
                .flatten()
                .flatten()
                .for_each(Vec::clear);
            let mut fused = FusedNetwork::build(&model, &setup).unwrap();
            fused.set_weights(&weights).unwrap();
            let blind = fused.rollout_loss(&without).unwrap();
            assert!((blind / loss - 1.0).abs() > 1e-6, "{loss} vs {blind}");
        }
    }
}

/// A `next` model (one stage a step, feedback through its delay embedding).
#[test]
fn next_models_roll_out_as_the_graph_backend() {
    let model = ModelBuilder::new("next_map")
        .input("u")
        .state("X")
        .state("S")
        .param("Y", 0.6, Constraint::Positive)
        .closure(ClosureSpec {
            name: "map",
            outputs: vec![
                OutputSpec {
                    name: "a",
                    scale: Some(0.2),
                    prior: None,
                },
                OutputSpec {
                    name: "b",
                    scale: Some(0.1),
                    prior: Some(("+=", "0.1 * u")),
                },
            ],
            observe: &["X", "S", "u"],
            delay: 1.5,
            dim: 3,
            hidden: vec![6],
            activation: Activation::Sigmoid,
        })
        .next("X", "X + 0.1 * a * Y")
        .next("S", "S + b - 0.05 * X")
        .build();
    let batch = fixture_batch(&model, 1, 8);
    assert!(feedback_entries(&batch) > 0);
    let setup = fixture_setup(&model, 1);
    let template = Network::build(&model, &setup).unwrap().weights();
    let weights = random_weights(&template, 6);
    assert_rollout_matches(&model, &setup, &batch, Some(&weights), 1e-9);
}

/// In `f32` the two engines round differently but agree to single precision.
#[test]
fn rollouts_agree_in_f32() {
    let model = two_closures();
    let setup = Setup {
        precision: Precision::F32,
        ..fixture_setup(&model, 1)
    };
    let batch = fixture_batch(&model, 1, 5);
    assert_rollout_matches(&model, &setup, &batch, None, 2e-4);
}

/// Under the one optimiser, a run of one-step batches then rollout batches of growing
/// length (the curriculum) on the fused engine follows the graph engine to rounding (f64),
/// with the params at their own rate and clipping.
#[test]
fn a_multi_step_run_on_the_fused_engine_follows_the_graph_engine() {
    let model = two_closures();
    let setup = fixture_setup(&model, 1);
    let settings = StepSettings {
        learning_rate: 0.01,
        param_learning_rate: 0.003,
        max_gradient_norm: Some(0.5),
    };
    let mut graph = Network::build(&model, &setup).unwrap();
    let mut fused = FusedNetwork::build(&model, &setup).unwrap();
    let mut on_graph = Optimiser::new(&graph, Precision::F64);
    let mut on_fused = Optimiser::new(&graph, Precision::F64);
    let pairs = crate::engine::fixtures::random_batch(&model, &setup, 6, 1);
    for steps in [1, 1, 2, 3, 5, 7, 7] {
        let windows = fixture_batch(&model, 1, steps);
        let batch = match steps {
            1 => StepBatch::Pairs(&pairs),
            _ => StepBatch::Windows(&windows),
        };
        let a = on_graph.step(&mut graph, batch, &settings).unwrap();
        let b = on_fused.step(&mut fused, batch, &settings).unwrap();
        assert!(
            (a - b).abs() <= 1e-10 * a.abs(),
            "{steps} steps: {a} vs {b}"
        );
    }
    let initial = Optimiser::new(&graph, Precision::F64).weights();
    assert_ne!(on_graph.weights(), initial, "training moved the weights");
    for (a, b) in on_graph.weights().iter().zip(on_fused.weights()) {
        assert!((a - b).abs() <= 1e-9 * (1.0 + a.abs()), "{a} vs {b}");
    }
}

/// Feedback that names a sample the window has not reached, rows outside the batch (or
/// none) or a column outside the embedding is refused, as a missing step is.
#[test]
fn malformed_windows_are_refused() {
    let model = two_closures();
    let setup = fixture_setup(&model, 1);
    let mut fused = FusedNetwork::build(&model, &setup).unwrap();
    let batch = fixture_batch(&model, 1, 4);
    assert!(fused.rollout_loss(&batch).is_ok());
    let entry = Feedback {
        rows: 0..1,
        column: 1,
        sample: 1,
        state: 0,
        weight: 0.5,
    };
    let bad = [
        Feedback {
            sample: 2,
            ..entry.clone()
        },
        Feedback {
            rows: 3..9,
            ..entry.clone()
        },
        Feedback {
            rows: 1..1,
            ..entry.clone()
        },
        Feedback {
            column: 99,
            ..entry.clone()
        },
    ];
    for wrong in bad {
        let mut broken = batch.clone();
        broken.feedback[1][0][0].push(wrong.clone());
        assert!(fused.rollout_loss(&broken).is_err(), "{wrong:?}");
    }
    let mut short = batch.clone();
    short.targets.pop();
    assert!(fused.rollout_gradient(&short).is_err());
    // A well-formed entry at step 1 is accepted.
    let mut fine = batch;
    fine.feedback[1][0][0].push(entry);
    assert!(fused.rollout_loss(&fine).is_ok());
}
