//! The fused step against the graph backend: same loss, same gradient entry by entry, same
//! Adam trajectory, for every activation, sub-steps, `next` models, hidden states, and the
//! shipped bioreactor GB2 model on its own data.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::backend::Normalisation;
use crate::ir::{Activation, Constraint};
use crate::train::fixtures::{chemostat, ClosureSpec, ModelBuilder, OutputSpec};

/// Priors of both kinds, a scaled output, a positive and a bounded param, a hidden state,
/// a power: every path of the physics program carries gradient.
fn kitchen_sink(activation: Activation) -> ir::Model {
    let output = |name, scale, prior| OutputSpec { name, scale, prior };
    ModelBuilder::new("kitchen_sink")
        .input("u")
        .state("X")
        .state("S")
        .hidden("E", 0.2)
        .constant("D", 0.1)
        .param("Y", 0.5, Constraint::Positive)
        .param("k", 1.5, Constraint::Bounds(0.5, 3.0))
        .closure(ClosureSpec {
            name: "rates",
            outputs: vec![
                output("a", None, Some(("*=", "0.5 * S / (1 + S)"))),
                output("b", Some(0.3), Some(("+=", "0.1 * u * X * Y"))),
                output("c", Some(0.2), None),
            ],
            observe: &["X", "S", "u"],
            delay: 1.0,
            dim: 3,
            hidden: vec![5, 4],
            activation,
        })
        .der("X", "(a - D) * X + c")
        .der("S", "D * (2 - S) - a / Y * X + b - 0.1 * E * S ^ k")
        .der("E", "(u - E) / 2")
        .build()
}

fn setup(model: &ir::Model, precision: Precision, substeps: usize) -> Setup {
    let measured = model.states.len();
    Setup {
        step: 0.4,
        substeps,
        precision,
        seed: 5,
        normalisation: Normalisation {
            state_mean: vec![1.0; measured],
            state_std: (0..measured).map(|i| 0.5 + 0.3 * i as f64).collect(),
            input_mean: vec![0.5; model.inputs.len()],
            input_std: vec![0.3; model.inputs.len()],
            ..Normalisation::default()
        },
        scales: (model.closures.iter())
            .map(|c| vec![0.7; c.outputs.len()])
            .collect(),
    }
}

/// Random states in [0.5, 2] (so that `S ^ k` is defined), inputs and embeddings.
fn random_batch(model: &ir::Model, setup: &Setup, rows: usize, seed: u64) -> Batch {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut uniform = |count: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..count).map(|_| rng.gen_range(lo..hi)).collect()
    };
    let states = model.states.len() + model.hidden.len();
    let offsets = setup.stage_offsets(model.dynamics);
    let embeddings = (model.closures.iter())
        .map(|c| {
            (0..offsets)
                .map(|_| uniform(rows * c.embedding.width(), 0.5, 2.0))
                .collect()
        })
        .collect();
    Batch {
        rows,
        states: uniform(rows * states, 0.5, 2.0),
        inputs: uniform(rows * model.inputs.len(), 0.0, 1.0),
        embeddings,
        targets: uniform(rows * model.states.len(), 0.5, 2.0),
    }
}

/// Weights of order one everywhere, so every path carries gradient.
fn random_weights(template: &[NamedTensor], seed: u64) -> Vec<NamedTensor> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut weights = template.to_vec();
    for tensor in &mut weights {
        for value in &mut tensor.values {
            *value = rng.gen_range(-0.8..0.8);
        }
    }
    weights
}

/// Loss and every gradient entry of the fused step against the graph backend, with
/// relative tolerance `tolerance` (entries compared against the largest of their tensor),
/// at random weights of order one or (`initial`) at the initial weights.
fn assert_matches_backend(
    model: &ir::Model,
    setup: &Setup,
    batch: &Batch,
    tolerance: f64,
    initial: bool,
) {
    let mut network = Network::build(model, setup).unwrap();
    let mut fused = FusedNetwork::build(model, setup).unwrap();
    assert_eq!(fused.weights(), network.weights(), "same initial weights");
    let weights = if initial {
        network.weights()
    } else {
        random_weights(&network.weights(), 9)
    };
    network.set_weights(&weights).unwrap();
    fused.set_weights(&weights).unwrap();
    let (expected_loss, expected) = network.gradient(batch).unwrap();
    let (loss, found) = fused.gradient(batch).unwrap();
    assert!(
        (loss - expected_loss).abs() <= tolerance * expected_loss.abs(),
        "loss {loss} vs {expected_loss}"
    );
    for ((tensor, expected), found) in weights.iter().zip(&expected).zip(&found) {
        let largest = expected.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(largest > 0.0, "{} carries no gradient", tensor.name);
        for (index, (e, f)) in expected.iter().zip(found).enumerate() {
            assert!(
                (e - f).abs() <= tolerance * largest,
                "{}[{index}]: fused {f} vs backend {e}",
                tensor.name
            );
        }
    }
}

#[test]
fn gradients_match_the_backend_for_every_activation_in_f64() {
    for activation in Activation::ALL {
        let model = kitchen_sink(activation);
        let setup = setup(&model, Precision::F64, 1);
        let batch = random_batch(&model, &setup, 6, 1);
        assert_matches_backend(&model, &setup, &batch, 1e-11, false);
    }
}

#[test]
fn gradients_match_the_backend_in_f32() {
    let model = kitchen_sink(Activation::Softplus);
    let setup = setup(&model, Precision::F32, 1);
    let batch = random_batch(&model, &setup, 7, 2);
    assert_matches_backend(&model, &setup, &batch, 2e-5, false);
}

#[test]
fn gradients_match_the_backend_with_substeps_and_for_next_models() {
    let model = kitchen_sink(Activation::Tanh);
    let setup_two = setup(&model, Precision::F64, 2);
    let batch = random_batch(&model, &setup_two, 5, 3);
    assert_matches_backend(&model, &setup_two, &batch, 1e-11, false);
    let discrete = chemostat::black_box();
    let setup_next = setup(&discrete, Precision::F64, 1);
    let batch = random_batch(&discrete, &setup_next, 5, 4);
    assert_matches_backend(&discrete, &setup_next, &batch, 1e-11, false);
}

/// The shipped GB2 model on pairs of its shipped record, with the normalisation `gbc train`
/// would use, at its initial weights (random weights of order one make its gradients of
/// order 1e6, where f32 rounding of the two summation orders differs by 1e-4).
#[test]
fn gradients_match_the_backend_for_the_bioreactor_gb2_model() {
    use crate::train::pairs::{first_pair_row, stage_fractions, PairTable};
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = crate::driver::compile_file(&root.join("models/bioreactor/gb2.gbm"), &[])
        .unwrap()
        .model;
    let names = ["u", "X", "A", "B", "S"];
    let data = crate::data::read(
        &root.join("models/bioreactor/data/steps.csv"),
        &names,
        crate::data::MinRows::new(2, "one step"),
    )
    .unwrap();
    let record = crate::train::record_of(&model, &data).unwrap();
    let first = first_pair_row(&model, record.step);
    let rows: Vec<usize> = (first..first + 40).collect();
    let fractions = stage_fractions(model.dynamics, 1);
    let table = PairTable::build(&model, &record, &rows, &[], &fractions);
    let batch = table.batch(&(0..40).collect::<Vec<_>>());
    for (precision, tolerance) in [(Precision::F64, 1e-10), (Precision::F32, 1e-5)] {
        let setup = Setup {
            step: record.step,
            substeps: 1,
            precision,
            seed: 0,
            normalisation: crate::train::normalise(&record, first + 41),
            scales: vec![vec![1.0; 3]],
        };
        assert_matches_backend(&model, &setup, &batch, tolerance, true);
    }
}

#[test]
fn adam_steps_follow_the_backend() {
    let model = kitchen_sink(Activation::Softplus);
    let setup = setup(&model, Precision::F64, 1);
    let mut network = Network::build(&model, &setup).unwrap();
    let mut fused = FusedNetwork::build(&model, &setup).unwrap();
    for step in 0..5 {
        let batch = random_batch(&model, &setup, 8, 10 + step);
        let expected = network.train_step(&batch, 1e-2).unwrap();
        let found = fused.train_step(&batch, 1e-2).unwrap();
        assert!((found - expected).abs() <= 1e-12 * expected, "step {step}");
    }
    let moved = network.weights() != Network::build(&model, &setup).unwrap().weights();
    assert!(moved, "training moved the weights");
    for (a, b) in network.weights().iter().zip(fused.weights()) {
        for (x, y) in a.values.iter().zip(&b.values) {
            assert!((x - y).abs() < 1e-10, "{}: {x} vs {y}", a.name);
        }
    }
}

#[test]
fn foreign_weights_and_batches_are_refused() {
    let model = kitchen_sink(Activation::Softplus);
    let setup = setup(&model, Precision::F32, 1);
    let mut fused = FusedNetwork::build(&model, &setup).unwrap();
    let mut weights = fused.weights();
    weights[0].name = "closure.other.layer0.weight".to_string();
    assert!(matches!(
        fused.set_weights(&weights),
        Err(BackendError::WeightsMismatch(_))
    ));
    assert!(fused.set_weights(&weights[1..]).is_err());
    let mut batch = random_batch(&model, &setup, 3, 0);
    batch.targets.pop();
    assert!(fused.train_step(&batch, 1e-3).is_err());
}
