//! Rollout tests: the gradient of a multi-step loss, through predicted states fed back
//! into the delay embedding, against central finite differences (f64); param learning
//! rates and gradient clipping.

use super::*;
use crate::engine::fixtures::{ClosureSpec, ModelBuilder, OutputSpec};
use crate::engine::pairs::stage_fractions;
use crate::engine::windows::rollout_batch;
use crate::ir::{self, Activation, Constraint};
use crate::record::{GridOptions, Record, Track};

/// Two states, a bounded param, a delay of 1.5 samples (stage times between samples).
fn model() -> ir::Model {
    ModelBuilder::new("rollout")
        .input("u")
        .state("X")
        .state("S")
        .param("Y", 0.6, Constraint::Positive)
        .closure(ClosureSpec {
            name: "rates",
            outputs: vec![
                OutputSpec {
                    name: "a",
                    scale: Some(0.2),
                    prior: Some(("+=", "0.1 * S")),
                },
                OutputSpec {
                    name: "b",
                    scale: Some(0.1),
                    prior: None,
                },
            ],
            observe: &["X", "S", "u"],
            delay: 1.5,
            dim: 3,
            hidden: vec![5],
            activation: Activation::Tanh,
        })
        .der("X", "(a - 0.1) * X + b")
        .der("S", "0.1 * (2 - S) - a / Y * X")
        .build()
}

/// Fourteen rows a unit apart, or (`irregular`) at uneven times with missing cells, so
/// that windows differ in their steps, their feedback and their loss weights.
fn record(irregular: bool) -> Track {
    let rows = 14;
    let times: Vec<f64> = if irregular {
        (0..rows)
            .map(|i| i as f64 + 0.3 * ((i * 7 % 5) as f64 / 4.0))
            .collect()
    } else {
        (0..rows).map(|i| i as f64).collect()
    };
    let mut record = Record::complete(
        "r",
        times.clone(),
        vec![(0..rows).map(|i| ((i / 3) % 2) as f64).collect()],
        vec![
            times.iter().map(|t| 1.0 + 0.05 * t.sin()).collect(),
            times.iter().map(|t| 1.5 - 0.03 * t).collect(),
        ],
    );
    if irregular {
        record.states[0][6] = None;
        record.states[1][9] = None;
    }
    let grid = GridOptions {
        max_step: 1.0,
        gap_limits: vec![1.5, 1.5],
        subdivide: true,
    };
    Track::lay(&record, &grid, &[])
}

fn network(model: &ir::Model, substeps: usize) -> Network {
    let setup = Setup {
        step: 1.0,
        substeps,
        precision: Precision::F64,
        seed: 5,
        normalisation: Normalisation {
            state_mean: vec![1.0, 1.3],
            state_std: vec![0.1, 0.2],
            input_mean: vec![0.5],
            input_std: vec![0.5],
            ..Normalisation::default()
        },
        scales: vec![vec![0.2, 0.1]],
    };
    let mut network = Network::build(model, &setup).unwrap();
    let mut weights = network.weights();
    for (index, value) in weights.iter_mut().flat_map(|t| &mut t.values).enumerate() {
        *value = ((index * 5 % 13) as f64 - 6.0) / 10.0;
    }
    network.set_weights(&weights).unwrap();
    network
}

fn assert_rollout_gradient_matches(substeps: usize, irregular: bool) {
    let model = model();
    let tracks = [record(irregular)];
    let network = network(&model, substeps);
    let fractions = stage_fractions(model.dynamics, substeps);
    let batch = rollout_batch(
        &model,
        (&tracks, &[], &[], &[]),
        &[(0, 3), (0, 5)],
        6,
        &fractions,
    );
    if irregular {
        let steps: Vec<f64> = batch.step_sizes.iter().flatten().copied().collect();
        assert!(steps.iter().any(|&h| (h - 1.0).abs() > 0.05), "{steps:?}");
        assert!(batch.weights.iter().flatten().any(|&w| w == 0.0));
    }
    assert!(batch
        .feedback
        .iter()
        .flatten()
        .flatten()
        .any(|f| !f.is_empty()));
    let (loss, gradient) = network.rollout_gradient(&batch).unwrap();
    assert!((loss - network.rollout_loss(&batch).unwrap()).abs() < 1e-14);
    let weights = network.weights();
    let mut probe = network_clone(&model, substeps, &weights);
    for (tensor, analytic) in gradient.iter().enumerate() {
        for (index, &expected) in analytic.iter().enumerate() {
            let step = 1e-6;
            let mut shifted = weights.clone();
            shifted[tensor].values[index] += step;
            probe.set_weights(&shifted).unwrap();
            let up = probe.rollout_loss(&batch).unwrap();
            shifted[tensor].values[index] -= 2.0 * step;
            probe.set_weights(&shifted).unwrap();
            let down = probe.rollout_loss(&batch).unwrap();
            let numeric = (up - down) / (2.0 * step);
            let tolerance = 1e-6 * (1.0 + numeric.abs());
            assert!(
                (numeric - expected).abs() < tolerance,
                "{}[{index}]: analytic {expected}, numeric {numeric}",
                weights[tensor].name
            );
        }
    }
}

fn network_clone(model: &ir::Model, substeps: usize, weights: &[NamedTensor]) -> Network {
    let mut copy = network(model, substeps);
    copy.set_weights(weights).unwrap();
    copy
}

#[test]
fn rollout_gradient_matches_finite_differences() {
    assert_rollout_gradient_matches(1, false);
}

#[test]
fn rollout_gradient_matches_finite_differences_with_substeps() {
    assert_rollout_gradient_matches(2, false);
}

/// Windows of their own steps and feedback weights per row, with unmeasured cells.
#[test]
fn rollout_gradient_matches_finite_differences_on_an_irregular_record() {
    assert_rollout_gradient_matches(1, true);
}

/// With a zero network learning rate only the params move, and clipping to a tiny norm
/// leaves Adam's first step (about one learning rate per weight) unchanged in direction.
#[test]
fn params_train_at_their_own_rate() {
    let model = model();
    let tracks = [record(false)];
    let fractions = stage_fractions(model.dynamics, 1);
    let batch = rollout_batch(
        &model,
        (&tracks, &[], &[], &[]),
        &[(0, 3), (0, 5)],
        4,
        &fractions,
    );
    let mut network = network(&model, 1);
    let before = network.weights();
    let settings = StepSettings {
        learning_rate: 0.0,
        param_learning_rate: 0.01,
        max_gradient_norm: Some(1e-4),
    };
    network.rollout_step(&batch, &settings).unwrap();
    let after = network.weights();
    for (old, new) in before.iter().zip(&after) {
        let moved = (old.values.iter().zip(&new.values)).any(|(a, b)| a != b);
        assert_eq!(moved, old.name == "params", "{}", old.name);
    }
    let change = after.last().unwrap().values[0] - before.last().unwrap().values[0];
    assert!(
        (change.abs() - 0.01).abs() < 1e-4,
        "param moved by {change}"
    );
}
