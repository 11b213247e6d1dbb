//! Irregular grids in the network: a step of its own size per batch row and loss weights
//! per target cell (0 where a cell was not measured), checked against separate uniform
//! batches, against the definition of the weighted loss, and by finite differences.

use super::*;
use crate::engine::fixtures::{kitchen_sink, random_batch};
use crate::ir::{self, Activation};

fn setup(step: f64, substeps: usize) -> Setup {
    Setup {
        step,
        substeps,
        precision: Precision::F64,
        seed: 7,
        normalisation: Normalisation {
            state_mean: vec![1.0, 1.2],
            state_std: vec![0.5, 0.8],
            input_mean: vec![0.5],
            input_std: vec![0.3],
            ..Normalisation::default()
        },
        scales: vec![vec![1.0, 0.3, 0.2]],
    }
}

/// Weights of order one on every path (the fresh last layer is near zero).
fn random_weights(network: &Network) -> Vec<NamedTensor> {
    let mut weights = network.weights();
    for (index, value) in weights.iter_mut().flat_map(|t| &mut t.values).enumerate() {
        *value = ((index * 7 % 17) as f64 - 8.0) / 12.0;
    }
    weights
}

/// Row `i` of a batch with its own step predicts what a one-row batch of a network whose
/// nominal step is that step predicts.
#[test]
fn each_row_steps_its_own_size() {
    let model = kitchen_sink(Activation::Tanh);
    for substeps in [1, 2] {
        let nominal = setup(0.5, substeps);
        let mut network = Network::build(&model, &nominal).unwrap();
        let weights = random_weights(&network);
        network.set_weights(&weights).unwrap();
        let mut batch = random_batch(&model, &nominal, 3, 4);
        batch.step_sizes = vec![0.2, 0.5, 0.9];
        let together = network.predict(&batch).unwrap();
        let width = together.next_states.len() / 3;
        for row in 0..3 {
            let mut alone =
                Network::build(&model, &setup(batch.step_sizes[row], substeps)).unwrap();
            alone.set_weights(&weights).unwrap();
            let single = single_row(&batch, row, &model);
            let expected = alone.predict(&single).unwrap().next_states;
            let found = &together.next_states[row * width..(row + 1) * width];
            for (f, e) in found.iter().zip(&expected) {
                assert!((f - e).abs() < 1e-14, "row {row}: {f} vs {e}");
            }
        }
        // A zero step leaves the state where it is.
        batch.step_sizes = vec![0.0; 3];
        let still = network.predict(&batch).unwrap();
        assert_eq!(still.next_states, batch.states);
    }
}

fn single_row(batch: &Batch, row: usize, model: &ir::Model) -> Batch {
    let states = model.states.len() + model.hidden.len();
    let (inputs, measured) = (model.inputs.len(), model.states.len());
    Batch {
        rows: 1,
        states: batch.states[row * states..(row + 1) * states].to_vec(),
        inputs: batch.inputs[row * inputs..(row + 1) * inputs].to_vec(),
        embeddings: (batch.embeddings.iter().zip(&model.closures))
            .map(|(offsets, closure)| {
                let width = closure.embedding.width();
                (offsets.iter())
                    .map(|values| values[row * width..(row + 1) * width].to_vec())
                    .collect()
            })
            .collect(),
        targets: batch.targets[row * measured..(row + 1) * measured].to_vec(),
        ..Batch::default()
    }
}

/// The weighted loss is `sum(w r^2) / #(w > 0)`: unweighted cells do not count, whatever
/// their targets, and doubling every weight doubles the loss.
#[test]
fn loss_weights_count_measured_cells_only() {
    let model = kitchen_sink(Activation::Softplus);
    let nominal = setup(0.5, 1);
    let mut network = Network::build(&model, &nominal).unwrap();
    network.set_weights(&random_weights(&network)).unwrap();
    let batch = random_batch(&model, &nominal, 4, 5);
    let prediction = network.predict(&batch).unwrap();
    let (measured, width) = (2, 3);
    let weights = vec![1.0, 0.0, 0.0, 2.0, 1.0, 1.0, 0.0, 0.0];
    let mut expected = 0.0;
    for row in 0..4 {
        for state in 0..measured {
            let cell = row * measured + state;
            let residual = (prediction.next_states[row * width + state] - batch.targets[cell])
                / [0.5, 0.8][state];
            expected += weights[cell] * residual * residual;
        }
    }
    expected /= 4.0; // four cells of positive weight
    let mut weighted = batch.clone();
    weighted.weights = weights.clone();
    let loss = network.loss(&weighted).unwrap();
    assert!(
        (loss - expected).abs() < 1e-13 * expected,
        "{loss} vs {expected}"
    );
    let mut moved = weighted.clone();
    for (target, weight) in moved.targets.iter_mut().zip(&weights) {
        if *weight == 0.0 {
            *target += 100.0;
        }
    }
    assert_eq!(
        network.gradient(&moved).unwrap(),
        network.gradient(&weighted).unwrap()
    );
    let mut doubled = weighted.clone();
    doubled.weights.iter_mut().for_each(|w| *w *= 2.0);
    assert!((network.loss(&doubled).unwrap() - 2.0 * loss).abs() < 1e-12 * loss);
    // Without weights every cell weighs 1: the plain mean.
    let plain = network.loss(&batch).unwrap();
    weighted.weights = vec![1.0; 8];
    assert!((network.loss(&weighted).unwrap() - plain).abs() < 1e-15);
}

/// The gradient with irregular steps and loss weights against central differences.
#[test]
fn gradient_with_irregular_steps_and_weights_matches_finite_differences() {
    let model = kitchen_sink(Activation::Softplus);
    let nominal = setup(0.5, 2);
    let mut network = Network::build(&model, &nominal).unwrap();
    network.set_weights(&random_weights(&network)).unwrap();
    let mut batch = random_batch(&model, &nominal, 4, 3);
    batch.step_sizes = vec![0.3, 0.7, 0.05, 0.5];
    batch.weights = vec![1.0, 0.0, 0.5, 2.0, 0.0, 0.0, 1.0, 1.0];
    let (loss, gradient) = network.gradient(&batch).unwrap();
    assert!((loss - network.loss(&batch).unwrap()).abs() < 1e-14);
    let weights = network.weights();
    let mut checked = 0;
    for (tensor, analytic) in gradient.iter().enumerate() {
        for (index, &expected) in analytic.iter().enumerate() {
            let delta = 1e-5;
            let mut shifted = weights.clone();
            shifted[tensor].values[index] += delta;
            network.set_weights(&shifted).unwrap();
            let up = network.loss(&batch).unwrap();
            shifted[tensor].values[index] -= 2.0 * delta;
            network.set_weights(&shifted).unwrap();
            let down = network.loss(&batch).unwrap();
            let numeric = (up - down) / (2.0 * delta);
            let tolerance = 1e-6 * (expected.abs() + numeric.abs()) + 1e-9;
            assert!(
                (numeric - expected).abs() < tolerance,
                "{}[{index}]: autodiff {expected}, finite difference {numeric}",
                weights[tensor].name
            );
            checked += 1;
        }
    }
    assert!(checked > 20);
}
