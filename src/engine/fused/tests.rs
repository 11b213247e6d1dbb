//! The fused step against the graph backend: same loss, same gradient entry by entry, same
//! Adam trajectory (params at their own learning rate, clipped gradients, Adam state handed
//! over), for every activation, sub-steps, `next` models, hidden states, and the shipped
//! bioreactor GB2 model on its own data.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::engine::fixtures::{chemostat, kitchen_sink, random_batch, setup};
use crate::ir::Activation;

/// Weights of order one everywhere, so every path carries gradient.
pub(super) fn random_weights(template: &[NamedTensor], seed: u64) -> Vec<NamedTensor> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut weights = template.to_vec();
    for tensor in &mut weights {
        for value in &mut tensor.values {
            *value = rng.gen_range(-0.8..0.8);
        }
    }
    weights
}

/// The initial weights with every closure's last layer (which starts at zero, where no
/// gradient reaches the layers before it) drawn as the initialisation once drew it: at
/// 1e-2 of Glorot's scale, a network near its mechanism with gradient on every path.
pub(super) fn near_start(template: &[NamedTensor], seed: u64) -> Vec<NamedTensor> {
    let layer = |name: &str| -> Option<(String, usize)> {
        let rest = name.strip_prefix("closure.")?;
        let (closure, layer) = rest.rsplit_once(".layer")?;
        let index = layer.split('.').next()?.parse().ok()?;
        Some((closure.to_string(), index))
    };
    let last = |closure: &str| {
        (template.iter())
            .filter_map(|t| layer(&t.name))
            .filter(|(c, _)| c == closure)
            .map(|(_, index)| index)
            .max()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut weights = template.to_vec();
    for tensor in &mut weights {
        let Some((closure, index)) = layer(&tensor.name) else {
            continue;
        };
        if last(&closure) == Some(index) {
            let fan: usize = tensor.shape.iter().sum::<usize>().max(1);
            let limit = 1e-2 * (6.0 / fan as f64).sqrt();
            for value in &mut tensor.values {
                *value = rng.gen_range(-limit..limit);
            }
        }
    }
    weights
}

/// Loss and every gradient entry of the fused step against the graph backend, with
/// relative tolerance `tolerance` (entries compared against the largest of their tensor),
/// at random weights of order one or (`initial`) at the initial weights with a last layer
/// near zero ([`near_start`]).
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
        near_start(&network.weights(), 9)
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

/// Rows of their own step size and loss weights with unmeasured cells (irregular grids).
#[test]
fn gradients_match_the_backend_with_irregular_steps_and_loss_weights() {
    let model = kitchen_sink(Activation::Softplus);
    for substeps in [1, 2] {
        let setup = setup(&model, Precision::F64, substeps);
        let mut batch = random_batch(&model, &setup, 5, 8);
        batch.step_sizes = vec![0.3, 1.1, 0.05, 0.6, 0.0];
        batch.weights = vec![1.0, 0.0, 0.5, 2.0, 0.0, 0.0, 1.0, 1.0, 1.0, 3.0];
        assert_matches_backend(&model, &setup, &batch, 1e-11, false);
    }
}

/// `positive` outputs under `*=` and `+=` priors: the `max` joins and the exponential piece
/// of the correction factor, at network outputs on both sides of zero.
#[test]
fn gradients_match_the_backend_for_positive_outputs_under_priors() {
    let model = crate::engine::graph::tests_positive::positive_priors();
    for precision in [Precision::F64, Precision::F32] {
        let setup = setup(&model, precision, 1);
        let batch = random_batch(&model, &setup, 6, 4);
        let tolerance = if precision == Precision::F64 {
            1e-11
        } else {
            2e-5
        };
        assert_matches_backend(&model, &setup, &batch, tolerance, false);
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

/// The shipped GB2 model, a batch of the first `rows` pairs of its shipped record, and the
/// setup `gbc train` would use for them in `precision`.
fn bioreactor_gb2(rows: usize, precision: Precision) -> (ir::Model, Batch, Setup) {
    shipped(
        "models/bioreactor/gb2.gbm",
        "models/bioreactor/data/steps.csv",
        rows,
        precision,
    )
}

/// A shipped model, a batch of the first `rows` pairs of a shipped record, and the setup
/// `gbc train` would use for them in `precision`.
fn shipped(
    model: &str,
    data: &str,
    rows: usize,
    precision: Precision,
) -> (ir::Model, Batch, Setup) {
    use crate::engine::pairs::{stage_fractions, PairTable};
    let (model, track, first, setup) = shipped_track(model, data, rows + 1, (precision, 1));
    let pairs: Vec<(usize, usize)> = (first..first + rows).map(|k| (0, k)).collect();
    let fractions = stage_fractions(model.dynamics, 1);
    let table = PairTable::build(&model, &[track], &pairs, &[], &fractions);
    let batch = table.batch(&(0..rows).collect::<Vec<_>>());
    (model, batch, setup)
}

/// A shipped model, a shipped record laid on its grid, the first knot whose embedding lies
/// in the record, and the setup `gbc train` would use in `precision` with `substeps` for the
/// `knots` knots from there (normalisation over them, closure magnitudes 1).
pub(super) fn shipped_track(
    model: &str,
    data: &str,
    knots: usize,
    (precision, substeps): (Precision, usize),
) -> (ir::Model, crate::record::Track, usize, Setup) {
    use crate::engine::pairs::first_pair_row;
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = crate::driver::compile_file(&root.join(model), &[])
        .unwrap()
        .model;
    let names: Vec<&str> = (model.inputs.iter().map(|v| v.name.as_str()))
        .chain(model.states.iter().map(|v| v.name.as_str()))
        .collect();
    let data = crate::data::read(
        &root.join(data),
        &names,
        crate::data::MinRows::new(2, "one step"),
    )
    .unwrap();
    let record = crate::engine::fixtures::record(&model, &data);
    let track = crate::engine::fixtures::track(&model, &data);
    let step = track.steps[0];
    let first = first_pair_row(&model, step);
    let setup = Setup {
        step,
        substeps,
        precision,
        seed: 0,
        normalisation: crate::engine::fixtures::normalise(&record, first + knots),
        scales: (model.closures.iter())
            .map(|c| vec![1.0; c.outputs.len()])
            .collect(),
    };
    (model, track, first, setup)
}

/// Every shipped trainable model and the record it is trained on.
pub(super) const SHIPPED: [(&str, &str); 10] = [
    ("bioreactor/gb1", "bioreactor/data/steps.csv"),
    ("bioreactor/gb2", "bioreactor/data/steps.csv"),
    ("bioreactor/blackbox", "bioreactor/data/steps.csv"),
    ("bioreactor/blackbox_ode", "bioreactor/data/steps.csv"),
    ("bioreactor/blackbox_residual", "bioreactor/data/steps.csv"),
    ("mm_chemostat/greybox", "mm_chemostat/data/steps.csv"),
    (
        "mm_chemostat/greybox_positive",
        "mm_chemostat/data/steps.csv",
    ),
    ("mm_chemostat/blackbox", "mm_chemostat/data/steps.csv"),
    ("mm_chemostat/blackbox_ode", "mm_chemostat/data/steps.csv"),
    (
        "mm_chemostat/blackbox_residual",
        "mm_chemostat/data/steps.csv",
    ),
];

/// Every shipped trainable model on its shipped record, in `f64` near the initial weights:
/// the fused step's loss and gradient are the graph backend's to 1e-9 (relative).
#[test]
fn every_shipped_model_agrees_with_the_backend_in_f64() {
    for (model, data) in SHIPPED {
        let (model, batch, setup) = shipped(
            &format!("models/{model}.gbm"),
            &format!("models/{data}"),
            30,
            Precision::F64,
        );
        assert_matches_backend(&model, &setup, &batch, 1e-9, true);
    }
}

/// The shipped GB2 model on pairs of its shipped record, with the normalisation `gbc train`
/// would use, at its initial weights (random weights of order one make its gradients of
/// order 1e6, where f32 rounding of the two summation orders differs by 1e-4).
#[test]
fn gradients_match_the_backend_for_the_bioreactor_gb2_model() {
    for (precision, tolerance) in [(Precision::F64, 1e-10), (Precision::F32, 1e-5)] {
        let (model, batch, setup) = bioreactor_gb2(40, precision);
        assert_matches_backend(&model, &setup, &batch, tolerance, true);
    }
}

/// The first Adam step from zero moments moves weight `i` by
/// `rate g_i / (|g_i| + 1e-8)` against the clipped gradient `g = factor * gradient` (the
/// bias corrections cancel): the params at `param_rate`, the network weights at `rate`.
fn assert_first_step(
    before: &[NamedTensor],
    after: &[NamedTensor],
    (gradient, factor): (&[Vec<f64>], f64),
    (rate, param_rate): (f64, f64),
) {
    for ((old, new), gradient) in before.iter().zip(after).zip(gradient) {
        let rate = if old.name == "params" {
            param_rate
        } else {
            rate
        };
        for ((a, b), g) in old.values.iter().zip(&new.values).zip(gradient) {
            let clipped = factor * g;
            let expected = -rate * clipped / (clipped.abs() + 1e-8);
            assert!(
                (b - a - expected).abs() <= 1e-9 * rate,
                "{}: moved by {} instead of {expected}",
                old.name,
                b - a
            );
        }
    }
}

/// GB2 has params: at a param learning rate ten times the network's and a gradient clipped
/// to 1e-4 of its norm (so small that Adam's epsilon shows), the fused step follows the
/// backend step for step (f64), and the first step is the one Adam takes by hand.
#[test]
fn param_learning_rate_and_clipping_follow_the_backend_on_gb2() {
    let (model, batch, setup) = bioreactor_gb2(50, Precision::F64);
    let mut network = Network::build(&model, &setup).unwrap();
    let mut fused = FusedNetwork::build(&model, &setup).unwrap();
    let (_, gradient) = network.gradient(&batch).unwrap();
    let norm = gradient.iter().flatten().map(|g| g * g).sum::<f64>().sqrt();
    let settings = StepSettings {
        learning_rate: 1e-3,
        param_learning_rate: 1e-2,
        max_gradient_norm: Some(norm * 1e-4),
    };
    let initial = network.weights();
    for step in 0..4 {
        let expected = network.train_step_with(&batch, &settings).unwrap();
        let found = fused.train_step_with(&batch, &settings).unwrap();
        assert!(
            (found / expected - 1.0).abs() < 1e-12,
            "step {step}: {found} vs {expected}"
        );
        if step == 0 {
            let rates = (settings.learning_rate, settings.param_learning_rate);
            for weights in [network.weights(), fused.weights()] {
                assert_first_step(&initial, &weights, (&gradient, 1e-4), rates);
            }
        }
    }
    for (a, b) in network.weights().iter().zip(fused.weights()) {
        for (x, y) in a.values.iter().zip(&b.values) {
            assert!(
                (x - y).abs() <= 1e-10 * x.abs().max(1e-3),
                "{}: {x} vs {y}",
                a.name
            );
        }
    }
    let (graph_state, fused_state) = (network.adam_state(), fused.adam_state());
    assert_eq!((graph_state.steps, fused_state.steps), (4, 4));
    let pairs = (graph_state.second.iter().flatten()).zip(fused_state.second.iter().flatten());
    for (a, b) in pairs {
        assert!((a - b).abs() <= 1e-10 * a.abs(), "second moment {a} vs {b}");
    }
}

/// Weights and Adam state handed from the backend to the fused step mid-way: the next steps
/// are the ones the backend takes itself (a fresh Adam state would make the step sizes of
/// a first step instead).
#[test]
fn adam_state_hands_over_between_the_engines() {
    let model = kitchen_sink(Activation::Softplus);
    let setup = setup(&model, Precision::F32, 1);
    let mut network = Network::build(&model, &setup).unwrap();
    for step in 0..3 {
        network
            .train_step(&random_batch(&model, &setup, 8, step), 1e-2)
            .unwrap();
    }
    let mut fused = FusedNetwork::build(&model, &setup).unwrap();
    fused.set_weights(&network.weights()).unwrap();
    fused.set_adam_state(&network.adam_state()).unwrap();
    assert_eq!(
        fused.adam_state(),
        network.adam_state(),
        "f32 moments survive f64 exactly"
    );
    let mut fresh = FusedNetwork::build(&model, &setup).unwrap();
    fresh.set_weights(&network.weights()).unwrap();
    let batch = random_batch(&model, &setup, 8, 3);
    network.train_step(&batch, 1e-2).unwrap();
    fused.train_step(&batch, 1e-2).unwrap();
    fresh.train_step(&batch, 1e-2).unwrap();
    let distance = |a: &[NamedTensor], b: &[NamedTensor]| {
        (a.iter().zip(b))
            .flat_map(|(x, y)| x.values.iter().zip(&y.values).map(|(p, q)| (p - q).abs()))
            .fold(0.0_f64, f64::max)
    };
    assert!(distance(&network.weights(), &fused.weights()) < 1e-5);
    assert!(distance(&network.weights(), &fresh.weights()) > 1e-3);
    let mut wrong = network.adam_state();
    wrong.first.pop();
    assert!(matches!(
        fused.set_adam_state(&wrong),
        Err(BackendError::WeightsMismatch(_))
    ));
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
