//! Backend tests: gradients against central finite differences (f64), the RK4 step against
//! an independent integrator, and the meaning of priors and scales.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::tape::{Graph, Matrix};
use super::*;
use crate::engine::fixtures::{
    kitchen_sink, random_batch, rk4_reference, ClosureSpec, ModelBuilder, OutputSpec,
};
use crate::ir::{self, Activation, Constraint};

fn setup(precision: Precision, step: f64, substeps: usize, scales: Vec<Vec<f64>>) -> Setup {
    Setup {
        step,
        substeps,
        precision,
        seed: 7,
        normalisation: Normalisation {
            state_mean: vec![1.0, 1.2],
            state_std: vec![0.5, 0.8],
            input_mean: vec![0.5],
            input_std: vec![0.3],
            ..Normalisation::default()
        },
        scales,
    }
}

/// Replaces every weight by a random value of order one so that every path carries
/// gradient (the fresh last layer is near zero).
fn randomise_weights(network: &mut Network, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut weights = network.weights();
    for tensor in &mut weights {
        for value in &mut tensor.values {
            *value = rng.gen_range(-0.8..0.8);
        }
    }
    network.set_weights(&weights).unwrap();
}

/// Compares the backend gradient with central differences of the loss, entry by entry.
fn assert_gradient_matches(model: &ir::Model, setup: &Setup) {
    let mut network = Network::build(model, setup).unwrap();
    randomise_weights(&mut network, 11);
    let batch = random_batch(model, setup, 4, 3);
    let (loss, gradient) = network.gradient(&batch).unwrap();
    assert!((loss - network.loss(&batch).unwrap()).abs() < 1e-14);
    let weights = network.weights();
    let mut checked = 0;
    for (tensor, analytic) in weights.iter().zip(&gradient) {
        for (index, &expected) in analytic.iter().enumerate() {
            let step = 1e-5;
            let mut shifted = weights.clone();
            let mut loss_at = |delta: f64| {
                shifted[checked_index(&weights, tensor)].values[index] =
                    tensor.values[index] + delta;
                network.set_weights(&shifted).unwrap();
                network.loss(&batch).unwrap()
            };
            let numeric = (loss_at(step) - loss_at(-step)) / (2.0 * step);
            let tolerance = 1e-6 * (expected.abs() + numeric.abs()) + 1e-9;
            assert!(
                (numeric - expected).abs() < tolerance,
                "{}[{index}]: autodiff {expected}, finite difference {numeric}",
                tensor.name
            );
            checked += 1;
        }
    }
    network.set_weights(&weights).unwrap();
    assert!(checked > 20, "only {checked} entries checked");
}

fn checked_index(weights: &[NamedTensor], tensor: &NamedTensor) -> usize {
    weights.iter().position(|t| t.name == tensor.name).unwrap()
}

#[test]
fn gradient_matches_finite_differences_for_rk4_with_embedding_priors_and_params() {
    let model = kitchen_sink(Activation::Softplus);
    assert_gradient_matches(
        &model,
        &setup(Precision::F64, 0.5, 1, vec![vec![1.0, 0.3, 0.2]]),
    );
}

#[test]
fn gradient_matches_finite_differences_with_substeps() {
    let model = kitchen_sink(Activation::Tanh);
    assert_gradient_matches(
        &model,
        &setup(Precision::F64, 0.5, 2, vec![vec![1.0, 0.3, 0.2]]),
    );
}

#[test]
fn gradient_matches_finite_differences_for_every_activation() {
    for activation in [
        Activation::Relu,
        Activation::Sigmoid,
        Activation::Gelu,
        Activation::Linear,
    ] {
        let model = kitchen_sink(activation);
        assert_gradient_matches(
            &model,
            &setup(Precision::F64, 0.5, 1, vec![vec![1.0, 0.3, 0.2]]),
        );
    }
}

#[test]
fn gradient_matches_finite_differences_for_a_discrete_map() {
    let model = ModelBuilder::new("black_box")
        .input("u")
        .state("X")
        .state("S")
        .closure(ClosureSpec {
            name: "n",
            outputs: vec![
                OutputSpec {
                    name: "nx",
                    scale: Some(0.7),
                    prior: None,
                },
                OutputSpec {
                    name: "ns",
                    scale: Some(0.4),
                    prior: None,
                },
            ],
            observe: &["X", "S", "u"],
            delay: 1.0,
            dim: 2,
            hidden: vec![6],
            activation: Activation::Softplus,
        })
        .next("X", "nx")
        .next("S", "S + ns")
        .build();
    assert_gradient_matches(&model, &setup(Precision::F64, 1.0, 1, vec![vec![0.7, 0.4]]));
}

/// The loss of `softplus(x)` through the graph: value and gradient at large |x|.
#[test]
fn softplus_activation_is_safe_in_value_and_gradient() {
    let device = dfdx::tensor::Cpu::default();
    let inputs = [-1000.0, -40.0, -1.0, 0.0, 2.0, 40.0, 1000.0];
    let mut graph = Graph::<f64>::new(&device);
    let x: Matrix<f64> = graph.matrix(1, inputs.len(), inputs.to_vec());
    let y = graph.softplus(&x).unwrap();
    let values = y.as_vec();
    assert_eq!(values[0], 0.0);
    assert!((values[1] / f64::exp(-40.0) - 1.0).abs() < 1e-12);
    assert!((values[3] - std::f64::consts::LN_2).abs() < 1e-15);
    assert_eq!(values[6], 1000.0);
    // loss = mean(y^2): d loss / dx = 2 y sigmoid(x) / n.
    let zeros = vec![0.0; inputs.len()];
    let ones = vec![1.0; inputs.len()];
    let block = super::tape::LossBlock {
        prediction: &y,
        targets: &zeros,
        weights: None,
        inverse_std: &ones,
    };
    let loss = graph.normalised_mse(&[block]).unwrap();
    let mut grads = graph.backward(loss).unwrap();
    let gradient = super::tape::gradient_of(&mut grads, &x).unwrap();
    for ((g, &x), &y) in gradient.iter().zip(&inputs).zip(&values) {
        let sigmoid = 1.0 / (1.0 + f64::exp(-x));
        let expected = 2.0 * y * sigmoid / inputs.len() as f64;
        assert!(g.is_finite());
        assert!(
            (g - expected).abs() <= 1e-12 * expected.abs().max(1e-300),
            "x = {x}"
        );
    }
}

const S0: f64 = 3e-2;
const THETA: f64 = 20.0;
const KCAT: f64 = 0.14;
const K_M: f64 = 1.5e-2;

/// The chemostat truth (paper 3.1) with its rate law as a `let` and `kcat` trainable.
fn chemostat_with_exact_law() -> ir::Model {
    ModelBuilder::new("chemostat_exact")
        .input("E0")
        .state("S")
        .hidden("E", 0.01)
        .constant("S0", S0)
        .constant("theta", THETA)
        .constant("K_M", K_M)
        .param("kcat", KCAT, Constraint::Positive)
        .define("r", "kcat * E * S / (K_M + S)")
        .der("S", "(S0 - S) / theta - r")
        .der("E", "(E0 - E) / theta")
        .build()
}

fn chemostat_rhs(state: &[f64], inlet: f64) -> Vec<f64> {
    let (s, e) = (state[0], state[1]);
    vec![
        (S0 - s) / THETA - KCAT * e * s / (K_M + s),
        (inlet - e) / THETA,
    ]
}

fn chemostat_setup(step: f64, substeps: usize, scales: Vec<Vec<f64>>) -> Setup {
    Setup {
        step,
        substeps,
        precision: Precision::F64,
        seed: 1,
        normalisation: Normalisation {
            state_mean: vec![0.015],
            state_std: vec![0.005],
            input_mean: vec![0.01],
            input_std: vec![0.005],
            ..Normalisation::default()
        },
        scales,
    }
}

fn one_step(model: &ir::Model, setup: &Setup, state: [f64; 2], inlet: f64) -> Prediction {
    let network = Network::build(model, setup).unwrap();
    let offsets = setup.stage_offsets(model.dynamics);
    let embeddings = (model.closures.iter())
        .map(|c| vec![vec![0.01; c.embedding.width()]; offsets])
        .collect();
    let batch = Batch {
        rows: 1,
        states: state.to_vec(),
        inputs: vec![inlet],
        embeddings,
        targets: vec![0.0],
        ..Batch::default()
    };
    network.predict(&batch).unwrap()
}

#[test]
fn exact_rate_law_reproduces_the_trajectory_to_rk4_accuracy() {
    let model = chemostat_with_exact_law();
    let (state, inlet) = ([0.02, 0.004], 0.018);
    let mut errors = Vec::new();
    for step in [1.0, 2.0, 4.0] {
        let predicted = one_step(&model, &chemostat_setup(step, 1, vec![]), state, inlet);
        let exact = rk4_reference(|x| chemostat_rhs(x, inlet), &state, step, 4000);
        let single = rk4_reference(|x| chemostat_rhs(x, inlet), &state, step, 1);
        // The network's RK4 step is the textbook step to rounding...
        for (p, s) in predicted.next_states.iter().zip(&single) {
            assert!((p - s).abs() < 1e-15, "step {step}: {p} vs {s}");
        }
        errors.push((predicted.next_states[0] - exact[0]).abs());
    }
    // ...and its local error shrinks as h^5.
    assert!(errors[0] < 1e-9, "one-step error {}", errors[0]);
    for pair in errors.windows(2) {
        let order = (pair[1] / pair[0]).log2();
        assert!(
            (4.5..5.6).contains(&order),
            "local order {order}: {errors:?}"
        );
    }
}

#[test]
fn substeps_shrink_the_step_error_as_h_to_the_fourth() {
    let model = chemostat_with_exact_law();
    let (state, inlet) = ([0.02, 0.004], 0.018);
    let exact = rk4_reference(|x| chemostat_rhs(x, inlet), &state, 8.0, 4000);
    let error = |substeps| {
        let predicted = one_step(
            &model,
            &chemostat_setup(8.0, substeps, vec![]),
            state,
            inlet,
        );
        (predicted.next_states[0] - exact[0]).abs()
    };
    let ratio = error(1) / error(4);
    // h^5 locally per sub-step, four sub-steps: 4^5 / 4 = 256.
    assert!((150.0..400.0).contains(&ratio), "ratio {ratio}");
}

#[test]
fn a_multiplicative_prior_with_a_silent_network_is_its_prior() {
    let exact = chemostat_with_exact_law();
    let grey = ModelBuilder::new("chemostat_prior")
        .input("E0")
        .state("S")
        .hidden("E", 0.01)
        .constant("S0", S0)
        .constant("theta", THETA)
        .constant("K_M", K_M)
        .param("kcat", KCAT, Constraint::Positive)
        .closure(ClosureSpec {
            name: "rate",
            outputs: vec![OutputSpec {
                name: "r",
                scale: None,
                prior: Some(("*=", "kcat * E * S / (K_M + S)")),
            }],
            observe: &["S", "E0"],
            delay: 10.0,
            dim: 5,
            hidden: vec![20, 20, 20],
            activation: Activation::Softplus,
        })
        .der("S", "(S0 - S) / theta - r")
        .der("E", "(E0 - E) / theta")
        .build();
    let setup = chemostat_setup(1.0, 1, vec![vec![1.0]]);
    let mut network = Network::build(&grey, &setup).unwrap();
    let mut weights = network.weights();
    let last = weights
        .iter()
        .position(|t| t.name == "closure.rate.layer3.weight")
        .unwrap();
    weights[last].values.fill(0.0);
    network.set_weights(&weights).unwrap();
    let (state, inlet) = ([0.02, 0.004], 0.018);
    let embeddings = vec![vec![vec![0.01; 10]; 3]];
    let batch = Batch {
        rows: 1,
        states: state.to_vec(),
        inputs: vec![inlet],
        embeddings,
        targets: vec![0.0],
        ..Batch::default()
    };
    let grey_prediction = network.predict(&batch).unwrap();
    let exact_prediction = one_step(&exact, &chemostat_setup(1.0, 1, vec![]), state, inlet);
    assert!((grey_prediction.next_states[0] - exact_prediction.next_states[0]).abs() < 1e-16);
    let law = KCAT * state[1] * state[0] / (K_M + state[0]);
    assert!((grey_prediction.closure_outputs[0] - law).abs() < 1e-16);
    // A fresh network is close to its prior: the last layer starts near zero.
    let fresh = Network::build(&grey, &setup)
        .unwrap()
        .predict(&batch)
        .unwrap();
    assert!((fresh.closure_outputs[0] / law - 1.0).abs() < 0.05);
}

#[test]
fn closure_outputs_follow_the_prior_and_scale_rules() {
    let model = kitchen_sink(Activation::Softplus);
    let scales = vec![vec![1.0, 0.3, 0.2]];
    let program = crate::engine::program::Program::compile(&model, &scales).unwrap();
    let (x, s, e, u) = (1.5, 0.8, 0.3, 0.6);
    let nets = [0.25, -0.5, 2.0];
    let raw_params = [
        crate::numeric::real::inverse_softplus(0.5),
        crate::numeric::real::logit((1.5 - 0.5) / 2.5),
    ];
    let values = program.forward(&crate::engine::program::ProgramInputs {
        rows: 1,
        states: &[x, s, e],
        inputs: &[u],
        params: &raw_params,
        nets: &[&nets],
    });
    let outputs = program.read(&values, 1, &program.closure_outputs);
    let prior_a = 0.5 * s / (1.0 + s);
    let prior_b = 0.1 * u * x * 0.5;
    assert!((outputs[0] - prior_a * (1.0 + 0.25)).abs() < 1e-15);
    assert!((outputs[1] - (prior_b + 0.3 * -0.5)).abs() < 1e-15);
    assert!((outputs[2] - 0.2 * 2.0).abs() < 1e-15);
    let params = program.read(&values, 1, &program.param_values);
    assert!((params[0] - 0.5).abs() < 1e-14 && (params[1] - 1.5).abs() < 1e-14);
    let balances = program.read(&values, 1, &program.balances);
    let (a, b, c) = (outputs[0], outputs[1], outputs[2]);
    let expected_s = 0.1 * (2.0 - s) - a / 0.5 * x + b - 0.1 * e * s.powf(1.5);
    assert!((balances[0] - ((a - 0.1) * x + c)).abs() < 1e-15);
    assert!((balances[1] - expected_s).abs() < 1e-14);
    assert!((balances[2] - (u - e) / 2.0).abs() < 1e-15);
}

#[test]
fn single_precision_agrees_with_double() {
    let model = kitchen_sink(Activation::Softplus);
    let scales = vec![vec![1.0, 0.3, 0.2]];
    let double = setup(Precision::F64, 0.5, 1, scales.clone());
    let single = setup(Precision::F32, 0.5, 1, scales);
    let batch = random_batch(&model, &double, 5, 9);
    let loss64 = Network::build(&model, &double)
        .unwrap()
        .loss(&batch)
        .unwrap();
    let loss32 = Network::build(&model, &single)
        .unwrap()
        .loss(&batch)
        .unwrap();
    assert!((loss64 / loss32 - 1.0).abs() < 1e-5, "{loss64} vs {loss32}");
}

#[test]
fn mismatched_weights_are_rejected() {
    let model = kitchen_sink(Activation::Softplus);
    let mut network = Network::build(
        &model,
        &setup(Precision::F64, 0.5, 1, vec![vec![1.0, 0.3, 0.2]]),
    )
    .unwrap();
    let mut weights = network.weights();
    weights[0].shape = vec![1, 1];
    assert!(matches!(
        network.set_weights(&weights),
        Err(BackendError::WeightsMismatch(_))
    ));
    weights.pop();
    assert!(network.set_weights(&weights).is_err());
}

/// The same one step through `crate::solve::ode` (adaptive Dormand-Prince, tight tolerances) on the
/// truth with `kcat` a const: the network agrees to RK4 accuracy, and to far better with
/// sub-steps.
#[test]
fn one_step_matches_the_adaptive_simulator() {
    let truth = ModelBuilder::new("chemostat_truth")
        .input("E0")
        .state("S")
        .hidden("E", 0.01)
        .constant("S0", S0)
        .constant("theta", THETA)
        .constant("K_M", K_M)
        .constant("kcat", KCAT)
        .der("S", "(S0 - S) / theta - kcat * E * S / (K_M + S)")
        .der("E", "(E0 - E) / theta")
        .build();
    let (state, inlet, step) = ([0.02, 0.004], 0.018, 2.0);
    let options = crate::solve::ode::SimOptions {
        tolerances: crate::solve::ode::Tolerances {
            rtol: 1e-12,
            atol: 1e-15,
        },
        initial: vec![Some(state[0]), Some(state[1])],
        ..crate::solve::ode::SimOptions::new(step, step)
    };
    let signal = crate::signal::Signal::constant(0.0, inlet);
    let simulated = crate::solve::ode::simulate(&truth, &[signal], &options).unwrap();
    let reference = [simulated.states[0][1], simulated.hidden[0][1]];
    let model = chemostat_with_exact_law();
    let relative_error = |substeps| {
        let predicted = one_step(
            &model,
            &chemostat_setup(step, substeps, vec![]),
            state,
            inlet,
        );
        (predicted.next_states.iter().zip(&reference))
            .map(|(p, r)| ((p - r) / r).abs())
            .fold(0.0, f64::max)
    };
    let (single, four) = (relative_error(1), relative_error(4));
    assert!(
        single < 1e-6,
        "one RK4 step of {step}: relative error {single}"
    );
    // Local error h^5 per sub-step, four sub-steps: about 4^4 = 256 times smaller.
    assert!(four < single / 100.0, "four sub-steps: {four} vs {single}");
}
