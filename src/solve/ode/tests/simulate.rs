//! Tests of [`simulate`] on hand-built models against closed forms and a reference solution.

use super::models::{self, Builder};
use super::reference::richardson;
use super::{rotation_exact, DECAY, FREQUENCY, START};
use crate::ir::{Dynamics, Model};
use crate::signal::Signal;
use crate::solve::ode::{simulate, SimError, SimOptions};

/// A piecewise-constant signal from `(switch time, value)` pairs.
fn steps(pairs: &[(f64, f64)]) -> Signal {
    Signal {
        breaks: pairs.iter().map(|p| p.0).collect(),
        values: pairs.iter().map(|p| p.1).collect(),
    }
}

fn relative_gap(value: f64, reference: f64, floor: f64) -> f64 {
    (value - reference).abs() / reference.abs().max(floor)
}

#[test]
fn rotation_model_matches_the_matrix_exponential() {
    let model = models::rotation(DECAY, FREQUENCY, START);
    let trajectory = simulate(&model, &[], &SimOptions::new(10.0, 0.05)).unwrap();
    assert_eq!(trajectory.len(), 201);
    for (k, &t) in trajectory.times.iter().enumerate() {
        assert!((t - k as f64 * 0.05).abs() < 1e-12);
        let exact = rotation_exact(DECAY, FREQUENCY, START, t);
        assert!(
            (trajectory.states[0][k] - exact[0]).abs() < 1e-9,
            "x at {t}"
        );
        assert!(
            (trajectory.states[1][k] - exact[1]).abs() < 1e-9,
            "y at {t}"
        );
        let radius_squared = (START[0].powi(2) + START[1].powi(2)) * (-2.0 * DECAY * t).exp();
        assert!((trajectory.outputs[0][k] - radius_squared).abs() < 1e-9);
    }
}

#[test]
fn step_response_is_exact_across_input_switches() {
    let (gain, tau, start) = (2.0, 3.0, 0.5);
    let model = models::first_order_lag(gain, tau, start);
    // Switches on and off the sampling grid.
    let switches = [(0.0, 1.0), (2.5, -0.5), (4.0, 3.0), (7.3, 0.0)];
    let signal = steps(&switches);
    let trajectory = simulate(
        &model,
        std::slice::from_ref(&signal),
        &SimOptions::new(12.0, 0.5),
    )
    .unwrap();
    for (k, &t) in trajectory.times.iter().enumerate() {
        let mut x = start;
        for (i, &(from, u)) in switches.iter().enumerate() {
            let until = switches.get(i + 1).map_or(f64::INFINITY, |s| s.0).min(t);
            if until > from {
                x = gain * u + (x - gain * u) * (-(until - from) / tau).exp();
            }
        }
        assert!((trajectory.states[0][k] - x).abs() < 1e-9, "t = {t}");
        assert_eq!(trajectory.inputs[0][k], signal.value_at(t));
    }
    assert!(trajectory.stats.accepted > 0);
}

#[test]
fn chemostat_settles_on_its_steady_state() {
    let model = models::chemostat();
    let e0 = 0.01;
    let options = SimOptions {
        warmup: 2000.0,
        ..SimOptions::new(60.0, 1.0)
    };
    let trajectory = simulate(&model, &[Signal::constant(0.0, e0)], &options).unwrap();
    let (s0, theta, kcat, k_m) = (3e-2, 20.0, 0.14, 1.5e-2);
    let s = *trajectory.states[0].last().unwrap();
    let e = *trajectory.hidden[0].last().unwrap();
    let inflow = (s0 - s) / theta;
    let consumption = kcat * e * s / (k_m + s);
    assert!(
        relative_gap(consumption, inflow, 0.0) < 1e-8,
        "{inflow} vs {consumption}"
    );
    assert!(relative_gap(e, e0, 0.0) < 1e-8);
    // The positive root of S^2 + (K_M - S0 + theta kcat E0) S - S0 K_M = 0.
    let b = k_m - s0 + theta * kcat * e0;
    let steady = (-b + (b * b + 4.0 * s0 * k_m).sqrt()) / 2.0;
    for k in 0..trajectory.len() {
        assert!(relative_gap(trajectory.states[0][k], steady, 0.0) < 1e-8);
        assert!(relative_gap(trajectory.outputs[0][k], s0 - steady, 0.0) < 1e-8);
        assert!(relative_gap(trajectory.lets[0][k], inflow, 0.0) < 1e-7);
    }
}

#[test]
fn bioreactor_agrees_with_a_high_accuracy_reference() {
    let model = models::bioreactor();
    // Switches on multiples of the reference step (1/64 h), one between samples.
    let light = steps(&[
        (0.0, 0.5),
        (10.0, 0.2),
        (25.5, 0.9),
        (40.0, 0.0),
        (52.0, 1.0),
    ]);
    let options = SimOptions::new(70.0, 1.0);
    let trajectory = simulate(&model, std::slice::from_ref(&light), &options).unwrap();
    let y0 = [1.0, 0.5, 0.5, 10.0, 0.5, 0.2, 0.5, 0.2];
    let reference = richardson(&model, &[light], &y0, &trajectory.times, 1.0 / 64.0);
    let mut worst: f64 = 0.0;
    for (k, expected) in reference.iter().enumerate() {
        let columns = trajectory.states.iter().chain(&trajectory.hidden);
        for (column, &value) in columns.zip(expected) {
            worst = worst.max(relative_gap(column[k], value, 1e-3));
        }
    }
    assert!(worst < 1e-6, "largest relative gap {worst:e}");
    // The run is not trivial: the light switches move every state.
    let biomass = &trajectory.states[0];
    assert!((biomass[69] - biomass[0]).abs() > 0.1);
}

#[test]
fn warmup_equals_starting_earlier() {
    let model = models::bioreactor();
    let light = steps(&[(0.0, 0.3), (12.0, 0.8)]);
    let warmed = SimOptions {
        warmup: 30.0,
        ..SimOptions::new(24.0, 1.0)
    };
    let earlier = SimOptions {
        t_start: -30.0,
        ..SimOptions::new(24.0, 1.0)
    };
    let a = simulate(&model, std::slice::from_ref(&light), &warmed).unwrap();
    let b = simulate(&model, &[light], &earlier).unwrap();
    assert_eq!(a.times[0], 0.0);
    assert_eq!(a.len(), 25);
    for (column_a, column_b) in a.states.iter().zip(&b.states) {
        for k in 0..a.len() {
            assert!(relative_gap(column_a[k], column_b[k + 30], 1e-3) < 1e-7);
        }
    }
}

/// `next x = a x + b u`, `x(0) = 1`.
fn linear_map(a: f64, b: f64) -> Model {
    let mut builder = Builder::new("map", Dynamics::Discrete);
    let u = builder.input("u");
    let x = builder.state("x", Some(1.0));
    builder.balance(&x, a * x.clone() + b * u);
    builder.model
}

#[test]
fn discrete_model_iterates_its_map_once_per_step() {
    let model = linear_map(0.5, 2.0);
    let input = steps(&[(0.0, 1.0), (3.0, 0.0)]);
    let trajectory = simulate(
        &model,
        std::slice::from_ref(&input),
        &SimOptions::new(6.0, 1.0),
    )
    .unwrap();
    let mut x = 1.0;
    for k in 0..trajectory.len() {
        assert_eq!(trajectory.states[0][k], x);
        x = 0.5 * x + 2.0 * input.value_at(k as f64);
    }
    // Warm-up: 40 steps at u = 1 settle on the fixed point x = 4.
    let options = SimOptions {
        warmup: 40.0,
        ..SimOptions::new(2.0, 1.0)
    };
    let settled = simulate(&model, &[input], &options).unwrap();
    assert!((settled.states[0][0] - 4.0).abs() < 1e-10);
}

#[test]
fn sample_grid_stops_at_the_last_step_before_t_end() {
    let model = models::first_order_lag(1.0, 1.0, 0.0);
    let options = SimOptions {
        t_start: 1.0,
        ..SimOptions::new(2.0, 0.3)
    };
    let trajectory = simulate(&model, &[Signal::constant(0.0, 1.0)], &options).unwrap();
    assert_eq!(trajectory.len(), 4);
    assert!((trajectory.times[3] - 1.9).abs() < 1e-12);
    let exact = 1.0 - (-0.9f64).exp();
    assert!((trajectory.states[0][3] - exact).abs() < 1e-9);
}

#[test]
fn missing_initial_value_is_an_error_unless_given() {
    let mut model = models::chemostat();
    model.hidden[0].init = None;
    let input = [Signal::constant(0.0, 0.01)];
    let error = simulate(&model, &input, &SimOptions::new(5.0, 1.0)).unwrap_err();
    assert_eq!(
        error,
        SimError::MissingInitial {
            state: "E".to_string()
        }
    );
    assert_eq!(error.to_string(), "state `E` has no initial value");
    let options = SimOptions {
        initial: vec![Some(0.025), Some(0.01)],
        ..SimOptions::new(5.0, 1.0)
    };
    let trajectory = simulate(&model, &input, &options).unwrap();
    assert_eq!(trajectory.states[0][0], 0.025);
    assert_eq!(trajectory.hidden[0][0], 0.01);
}

#[test]
fn invalid_requests_are_errors() {
    let model = models::first_order_lag(1.0, 1.0, 0.0);
    let input = [Signal::constant(0.0, 1.0)];
    let options = |dt: f64, t_end: f64| SimOptions::new(t_end, dt);
    let cases = [
        simulate(&model, &[], &options(1.0, 5.0)),
        simulate(&model, &input, &options(0.0, 5.0)),
        simulate(&model, &input, &options(1.0, -5.0)),
        simulate(&model, &input, &options(f64::NAN, 5.0)),
    ];
    assert!(matches!(
        cases[0],
        Err(SimError::InputCount {
            expected: 1,
            found: 0
        })
    ));
    for case in &cases[1..] {
        assert!(matches!(case, Err(SimError::Options(_))), "{case:?}");
    }
}

#[test]
fn model_with_closures_is_refused() {
    let mut model = models::first_order_lag(1.0, 1.0, 0.0);
    model.closures.push(crate::ir::Closure {
        name: "rate".into(),
        outputs: vec![],
        embedding: crate::ir::Embedding {
            observe: vec![],
            delay: 1.0,
            dim: 1,
        },
        network: crate::ir::Network {
            hidden: vec![],
            activation: crate::ir::Activation::Linear,
        },
    });
    let error = simulate(
        &model,
        &[Signal::constant(0.0, 1.0)],
        &SimOptions::new(1.0, 1.0),
    );
    assert!(matches!(error, Err(SimError::HasClosures { closures, .. }) if closures == "rate"));
}

fn shipped(file: &str) -> Model {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    crate::driver::compile_file(&path, &[]).unwrap().model
}

#[test]
fn shipped_truth_models_match_the_hand_built_ones() {
    let cases = [
        (
            "models/bioreactor/truth.gbm",
            models::bioreactor(),
            steps(&[(0.0, 0.5), (7.0, 0.1), (19.0, 0.95), (33.0, 0.4)]),
        ),
        (
            "models/mm_chemostat/truth.gbm",
            models::chemostat(),
            steps(&[(0.0, 0.005), (20.0, 0.018), (45.0, 0.002)]),
        ),
    ];
    for (file, hand_built, signal) in cases {
        let parsed = shipped(file);
        let signals = std::slice::from_ref(&signal);
        let reference = simulate(&hand_built, signals, &SimOptions::new(60.0, 1.0)).unwrap();
        let columns = || reference.states.iter().chain(&reference.hidden);
        let options = SimOptions {
            initial: columns().map(|column| Some(column[0])).collect(),
            ..SimOptions::new(60.0, 1.0)
        };
        let trajectory = simulate(&parsed, signals, &options).unwrap();
        let parsed_columns = trajectory.states.iter().chain(&trajectory.hidden);
        for (expected, found) in columns().zip(parsed_columns) {
            for (a, b) in expected.iter().zip(found) {
                assert!(relative_gap(*b, *a, 1e-3) < 1e-7, "{file}: {b} vs {a}");
            }
        }
    }
}

#[test]
fn shipped_truth_models_start_at_their_steady_state() {
    let cases = [
        ("models/bioreactor/truth.gbm", 0.5),
        ("models/mm_chemostat/truth.gbm", 0.011),
    ];
    for (file, level) in cases {
        let model = shipped(file);
        let signal = [Signal::constant(0.0, level)];
        let trajectory = simulate(&model, &signal, &SimOptions::new(200.0, 10.0)).unwrap();
        for column in trajectory.states.iter().chain(&trajectory.hidden) {
            let drift = relative_gap(*column.last().unwrap(), column[0], 1e-3);
            assert!(drift < 1e-6, "{file}: drift {drift:e}");
        }
    }
}
