//! The implicit method and the automatic choice on stiff systems, against closed forms and
//! known values; the step budget's diagnostic.

use super::{rotation_exact, Rotation, DECAY, FREQUENCY, START};
use crate::solve::ode::{Dopri5, IntegrationError, Integrator, Method, OdeSystem, Tolerances};

/// `y' = A y` with `A = V diag(-1, -fast) V^-1`, `V = [[1, 1], [1, -1]]`: a slow and a fast
/// mode, mixed in both components (stiff once `fast` is large).
struct TwoModes {
    fast: f64,
}

impl TwoModes {
    fn matrix(&self) -> [f64; 4] {
        let (a, b) = ((-1.0 - self.fast) / 2.0, (-1.0 + self.fast) / 2.0);
        [a, b, b, a]
    }

    fn exact(&self, start: [f64; 2], t: f64) -> [f64; 2] {
        let slow = (start[0] + start[1]) / 2.0 * (-t).exp();
        let fast = (start[0] - start[1]) / 2.0 * (-self.fast * t).exp();
        [slow + fast, slow - fast]
    }
}

impl OdeSystem for TwoModes {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        let m = self.matrix();
        dydt[0] = m[0] * y[0] + m[1] * y[1];
        dydt[1] = m[2] * y[0] + m[3] * y[1];
    }
    fn jacobian(&mut self, _t: f64, _y: &[f64], jacobian: &mut [f64]) {
        jacobian.copy_from_slice(&self.matrix());
    }
}

/// The Robertson kinetics (Hairer and Wanner II, section IV.1).
struct Robertson;

impl OdeSystem for Robertson {
    fn dim(&self) -> usize {
        3
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        let (a, b, c) = (0.04 * y[0], 1e4 * y[1] * y[2], 3e7 * y[1] * y[1]);
        dydt[0] = -a + b;
        dydt[1] = a - b - c;
        dydt[2] = c;
    }
}

const TIGHT: Tolerances = Tolerances {
    rtol: 1e-10,
    atol: 1e-12,
};

fn run(
    system: &mut impl OdeSystem,
    method: Method,
    start: &[f64],
    samples: &[f64],
) -> (Vec<Vec<f64>>, crate::solve::ode::Stats) {
    let mut integrator = Integrator::new(start.len(), TIGHT, 1_000_000, method);
    let mut y = start.to_vec();
    let mut recorded = Vec::new();
    let end = *samples.last().unwrap();
    integrator
        .integrate(system, (0.0, end), &mut y, samples, |_, y| {
            recorded.push(y.to_vec())
        })
        .unwrap();
    assert_eq!(recorded.len(), samples.len());
    (recorded, integrator.stats())
}

#[test]
fn implicit_method_follows_the_closed_form_of_a_stiff_system() {
    let mut system = TwoModes { fast: 1e6 };
    let samples: Vec<f64> = (0..=50).map(|k| k as f64 * 0.2).collect();
    let start = [2.0, 0.5];
    let (values, stats) = run(&mut system, Method::Implicit, &start, &samples);
    for (value, &t) in values.iter().zip(&samples) {
        let exact = system.exact(start, t);
        for k in 0..2 {
            assert!(
                (value[k] - exact[k]).abs() < 1e-9,
                "t = {t}: {value:?} vs {exact:?}"
            );
        }
    }
    // The fast mode settles in about 1e-5; stability alone would need ~3e6 explicit steps
    // (accuracy at rtol 1e-10 takes about a thousand).
    assert!(stats.accepted < 3_000, "{stats:?}");
    assert_eq!(stats.implicit, stats.accepted);
}

#[test]
fn automatic_choice_switches_on_stiffness_and_stays_exact() {
    let mut system = TwoModes { fast: 1e5 };
    let samples: Vec<f64> = (0..=40).map(|k| k as f64 * 0.25).collect();
    let start = [1.0, -1.0];
    let (values, stats) = run(&mut system, Method::Auto, &start, &samples);
    for (value, &t) in values.iter().zip(&samples) {
        let exact = system.exact(start, t);
        for k in 0..2 {
            assert!(
                (value[k] - exact[k]).abs() < 1e-9,
                "t = {t}: {value:?} vs {exact:?}"
            );
        }
    }
    assert!(stats.switches >= 1 && stats.implicit > 0, "{stats:?}");
    let (_, explicit) = run(&mut system, Method::Explicit, &start, &samples);
    assert!(
        stats.accepted * 20 < explicit.accepted,
        "{stats:?} vs {explicit:?}"
    );
}

#[test]
fn a_system_that_is_not_stiff_runs_explicit_bit_for_bit() {
    let samples: Vec<f64> = (0..=100).map(|k| k as f64 * 0.1).collect();
    let mut rotation = Rotation {
        decay: DECAY,
        frequency: FREQUENCY,
    };
    let (auto, stats) = run(&mut rotation, Method::Auto, &START, &samples);
    assert_eq!(stats.implicit, 0);
    let mut dopri = Dopri5::new(2, TIGHT, 1_000_000);
    let mut y = START;
    let mut alone = Vec::new();
    dopri
        .integrate(&mut rotation, (0.0, 10.0), &mut y, &samples, |_, y| {
            alone.push(y.to_vec())
        })
        .unwrap();
    assert_eq!(auto, alone);
    let exact = rotation_exact(DECAY, FREQUENCY, START, 10.0);
    assert!((auto[100][0] - exact[0]).abs() < 1e-9);
}

#[test]
fn robertson_matches_its_published_values() {
    // t = 40: Hairer and Wanner II, section IV.1 (7 digits); t = 1e11: the reference
    // solution of the Bari test set for IVP solvers (problem ROBER).
    let samples = [0.0, 40.0, 1e11];
    let want = [
        [0.715_827_1, 0.918_553_5e-5, 0.284_163_7],
        [
            0.208_334_014_970_125_5e-7,
            0.833_336_077_033_471_3e-13,
            0.999_999_979_166_505,
        ],
    ];
    let tolerances = Tolerances {
        rtol: 1e-10,
        atol: 1e-20,
    };
    for method in [Method::Auto, Method::Implicit] {
        let mut integrator = Integrator::new(3, tolerances, 100_000, method);
        let mut y = [1.0, 0.0, 0.0];
        let mut values = Vec::new();
        integrator
            .integrate(&mut Robertson, (0.0, 1e11), &mut y, &samples, |_, y| {
                values.push(y.to_vec())
            })
            .unwrap();
        for (row, (want, digits)) in values[1..].iter().zip(want.iter().zip([2e-7, 1e-6])) {
            for k in 0..3 {
                let relative = (row[k] - want[k]).abs() / want[k];
                assert!(relative < digits, "{method:?}: {row:?} vs {want:?}");
            }
        }
        let stats = integrator.stats();
        // Explicit steps alone would need about 1e14 (a time scale of 1e-4 over 1e11).
        assert!(
            stats.accepted < 10_000 && stats.implicit > 0,
            "{method:?}: {stats:?}"
        );
    }
}

#[test]
fn a_spent_budget_names_the_fastest_balance() {
    let mut integrator = Integrator::new(3, TIGHT, 500, Method::Explicit);
    let mut y = [1.0, 0.0, 0.0];
    let error = integrator
        .integrate(&mut Robertson, (0.0, 4e5), &mut y, &[], |_, _| {})
        .unwrap_err();
    let IntegrationError::TooManySteps { steps, stuck, .. } = &error else {
        panic!("unexpected {error:?}");
    };
    assert_eq!(*steps, 500);
    // y2's balance, with its 3e7 y2^2 and 1e4 y3 terms, is the fast one.
    assert_eq!(stuck.state, Some(1));
    assert!(stuck.time_scale < 1e-3, "{stuck:?}");
    let named = error.named(&["y1".into(), "y2".into(), "y3".into()]);
    assert!(named.to_string().contains("balance of `y2`"), "{named}");
}

#[test]
fn the_budget_counts_the_whole_run_across_stretches() {
    let mut integrator = Integrator::new(3, TIGHT, 3_000, Method::Explicit);
    let mut y = [1.0, 0.0, 0.0];
    let mut spent = false;
    for k in 0..100 {
        let span = (k as f64 * 10.0, (k + 1) as f64 * 10.0);
        if integrator
            .integrate(&mut Robertson, span, &mut y, &[], |_, _| {})
            .is_err()
        {
            spent = true;
            break;
        }
    }
    assert!(spent, "100 stretches of Robertson in 3000 explicit steps");
    integrator.restart();
    let mut y = [1.0, 0.0, 0.0];
    integrator
        .integrate(&mut Robertson, (0.0, 1e-3), &mut y, &[], |_, _| {})
        .unwrap();
}

/// An oscillator `x'' = -w^2 x` that a fast lag `z' = -k (z - x)` follows: stiff for the
/// explicit method's stability, yet the oscillation keeps every method's steps short.
struct FollowedOscillator {
    frequency: f64,
    rate: f64,
}

impl FollowedOscillator {
    /// `(x, v, z)` at `t` from `(1, 0, 1)`.
    fn exact(&self, t: f64) -> [f64; 3] {
        let (w, k) = (self.frequency, self.rate);
        let (sin, cos) = (w * t).sin_cos();
        let (a, b) = (k * k / (k * k + w * w), k * w / (k * k + w * w));
        [
            cos,
            -w * sin,
            a * cos + b * sin + (1.0 - a) * (-k * t).exp(),
        ]
    }
}

impl OdeSystem for FollowedOscillator {
    fn dim(&self) -> usize {
        3
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        dydt[0] = y[1];
        dydt[1] = -self.frequency.powi(2) * y[0];
        dydt[2] = -self.rate * (y[2] - y[0]);
    }
    fn jacobian(&mut self, _t: f64, _y: &[f64], jacobian: &mut [f64]) {
        let (w2, k) = (self.frequency.powi(2), self.rate);
        jacobian.copy_from_slice(&[0.0, 1.0, 0.0, -w2, 0.0, 0.0, k, 0.0, -k]);
    }
}

#[test]
fn the_implicit_method_hands_back_a_stretch_it_is_not_worth() {
    // The explicit steps are held at the lag's stability limit (3.3 / 5000), the implicit
    // ones at the oscillation's accuracy limit, not much longer: each trial is lost after
    // twenty steps (the first check of a stretch only sees the steps grow), and the
    // explicit method waits four times longer before the next (after 100, 400, 1600,
    // 6400 steps).
    let mut system = FollowedOscillator {
        frequency: 10.0,
        rate: 5000.0,
    };
    let tolerances = Tolerances {
        rtol: 1e-10,
        atol: 1e-12,
    };
    let mut integrator = Integrator::new(3, tolerances, 1_000_000, Method::Auto);
    let mut y = [1.0, 0.0, 1.0];
    let mut last = Vec::new();
    integrator
        .integrate(&mut system, (0.0, 5.0), &mut y, &[5.0], |_, y| {
            last = y.to_vec()
        })
        .unwrap();
    let stats = integrator.stats();
    let trials = stats.switches / 2;
    assert!((1..=4).contains(&trials), "{stats:?}");
    assert_eq!(stats.implicit, 20 * trials, "{stats:?}");
    let exact = system.exact(5.0);
    for k in 0..3 {
        assert!((last[k] - exact[k]).abs() < 1e-8, "{last:?} vs {exact:?}");
    }
}
