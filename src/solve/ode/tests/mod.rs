//! Tests of the integrator on systems with closed-form solutions.

mod models;
mod reference;
mod sensitivities;
mod simulate;
mod stiff;

use super::*;

/// `dx/dt = -a x - w y`, `dy/dt = w x - a y`.
struct Rotation {
    decay: f64,
    frequency: f64,
}

impl OdeSystem for Rotation {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        dydt[0] = -self.decay * y[0] - self.frequency * y[1];
        dydt[1] = self.frequency * y[0] - self.decay * y[1];
    }
}

/// The matrix exponential of the rotation applied to `start`.
fn rotation_exact(decay: f64, frequency: f64, start: [f64; 2], t: f64) -> [f64; 2] {
    let (sin, cos) = (frequency * t).sin_cos();
    let damping = (-decay * t).exp();
    [
        damping * (start[0] * cos - start[1] * sin),
        damping * (start[0] * sin + start[1] * cos),
    ]
}

const DECAY: f64 = 0.3;
const FREQUENCY: f64 = 2.0;
const START: [f64; 2] = [1.0, -0.5];

/// Integrates the rotation over `[0, 10]`, sampling every 0.002; returns the largest error
/// at the samples and the integrator's work.
fn rotation_run(tolerances: Tolerances) -> (f64, Stats) {
    let mut system = Rotation {
        decay: DECAY,
        frequency: FREQUENCY,
    };
    let samples: Vec<f64> = (0..=5000).map(|k| k as f64 * 0.002).collect();
    let mut integrator = Dopri5::new(2, tolerances, 1_000_000);
    let mut y = START;
    let mut worst: f64 = 0.0;
    let mut recorded = 0;
    integrator
        .integrate(&mut system, (0.0, 10.0), &mut y, &samples, |k, value| {
            let exact = rotation_exact(DECAY, FREQUENCY, START, samples[k]);
            worst = worst.max((value[0] - exact[0]).abs().max((value[1] - exact[1]).abs()));
            recorded += 1;
        })
        .unwrap();
    assert_eq!(recorded, samples.len());
    (worst, integrator.stats())
}

#[test]
fn dense_output_matches_the_matrix_exponential() {
    let (worst, stats) = rotation_run(Tolerances {
        rtol: 1e-10,
        atol: 1e-12,
    });
    assert!(worst < 1e-8, "largest error {worst:e}");
    // The samples come from the continuous extension: far fewer steps than samples.
    assert!(stats.accepted < 1000, "{stats:?}");
}

#[test]
fn error_decreases_as_rtol_tightens() {
    let errors: Vec<f64> = [1e-3, 1e-5, 1e-7, 1e-9, 1e-11]
        .into_iter()
        .map(|rtol| {
            rotation_run(Tolerances {
                rtol,
                atol: rtol * 1e-3,
            })
            .0
        })
        .collect();
    for pair in errors.windows(2) {
        assert!(pair[1] < pair[0] / 5.0, "errors {errors:?}");
    }
    assert!(errors[0] > 1e-6 && errors[4] < 1e-9, "errors {errors:?}");
}

#[test]
fn sampling_does_not_change_the_steps() {
    let tolerances = Tolerances::default();
    let run = |samples: &[f64]| {
        let mut system = Rotation {
            decay: DECAY,
            frequency: FREQUENCY,
        };
        let mut integrator = Dopri5::new(2, tolerances, 1_000_000);
        let mut y = START;
        integrator
            .integrate(&mut system, (0.0, 10.0), &mut y, samples, |_, _| {})
            .unwrap();
        (y, integrator.stats())
    };
    let dense: Vec<f64> = (0..=10_000).map(|k| k as f64 * 1e-3).collect();
    let (sampled, sampled_stats) = run(&dense);
    let (bare, bare_stats) = run(&[]);
    assert_eq!(sampled_stats, bare_stats);
    assert_eq!(sampled.map(f64::to_bits), bare.map(f64::to_bits));
    let exact = rotation_exact(DECAY, FREQUENCY, START, 10.0);
    assert!((bare[0] - exact[0]).abs() < 1e-9 && (bare[1] - exact[1]).abs() < 1e-9);
}

/// `dx/dt = x^2`, exploding at `t = 1 / x(0)`.
struct Explosion;

impl OdeSystem for Explosion {
    fn dim(&self) -> usize {
        1
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        dydt[0] = y[0] * y[0];
    }
}

#[test]
fn blow_up_is_reported_at_the_singularity() {
    let mut integrator = Dopri5::new(1, Tolerances::default(), 1_000_000);
    let mut y = [1.0];
    let error = integrator
        .integrate(&mut Explosion, (0.0, 2.0), &mut y, &[], |_, _| {})
        .unwrap_err();
    let t = match error {
        IntegrationError::StepSizeUnderflow { t, .. } | IntegrationError::NonFinite { t, .. } => t,
        other => panic!("unexpected {other:?}"),
    };
    assert!((0.999..=1.0).contains(&t), "stopped at {t}");
}

#[test]
fn step_budget_is_enforced() {
    let mut integrator = Dopri5::new(1, Tolerances::default(), 10);
    let mut y = [1.0];
    let error = integrator
        .integrate(&mut Explosion, (0.0, 0.9), &mut y, &[], |_, _| {})
        .unwrap_err();
    assert!(
        matches!(error, IntegrationError::TooManySteps { steps: 10, t, .. } if t > 0.0 && t < 0.9),
        "{error:?}"
    );
}

/// `dx/dt = ln(x - 2)`: NaN wherever `x < 2`.
struct Undefined;

impl OdeSystem for Undefined {
    fn dim(&self) -> usize {
        1
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        dydt[0] = (y[0] - 2.0).ln();
    }
}

#[test]
fn non_finite_right_hand_side_is_reported() {
    let mut integrator = Dopri5::new(1, Tolerances::default(), 1000);
    let mut y = [1.0];
    let error = integrator
        .integrate(&mut Undefined, (3.0, 4.0), &mut y, &[], |_, _| {})
        .unwrap_err();
    assert_eq!(error, IntegrationError::non_finite(3.0));
}
