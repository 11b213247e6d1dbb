//! The Levenberg–Marquardt driver on problems with known answers, its difference
//! Jacobians against analytic ones, and its standard errors against closed forms.

use super::lm::{
    central_difference, forward_differences, grouped_covariance, grouped_standard_errors,
    shaped_covariance, standard_errors, variance_shapes, Function, Jacobian,
};
use super::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal as Gaussian};

const DAMPING: Damping = Damping {
    min_diagonal: 1e-12,
    jitter: 1e-14,
    relative_jitter: 0.0,
};

fn times() -> Vec<f64> {
    (0..30).map(|k| k as f64 * 0.5).collect()
}

/// `a exp(-k t) - y` for the data `y` at `times()`.
fn decay_residuals(data: &[f64], theta: &[f64]) -> Vec<f64> {
    (times().iter().zip(data))
        .map(|(t, y)| theta[0] * (-theta[1] * t).exp() - y)
        .collect()
}

/// Its analytic Jacobian: columns `exp(-k t)` and `-a t exp(-k t)`.
fn decay_jacobian(theta: &[f64]) -> Vec<Vec<f64>> {
    let decay: Vec<f64> = times().iter().map(|t| (-theta[1] * t).exp()).collect();
    let slope = (times().iter().zip(&decay))
        .map(|(t, e)| -theta[0] * t * e)
        .collect();
    vec![decay, slope]
}

fn truth() -> Vec<f64> {
    decay_residuals(&[0.0; 30], &[2.0, 0.3])
}

#[test]
fn an_exponential_decay_is_fitted_to_its_truth() {
    // y = 2 exp(-0.3 t), fitted from (1, 1) with a forward-difference Jacobian.
    let data = truth();
    let residuals = |theta: &[f64]| Some(decay_residuals(&data, theta));
    let function = Function {
        residuals: &residuals,
        jacobian: Jacobian::ForwardDifferences { step: 1e-6 },
        damping: DAMPING,
    };
    let outcome = function.minimise(vec![1.0, 1.0], &Settings::DEFAULT);
    assert!(outcome.cost < 1e-16, "{outcome:?}");
    assert!((outcome.x[0] - 2.0).abs() < 1e-6 && (outcome.x[1] - 0.3).abs() < 1e-6);
    assert!(outcome.initial_cost > 1.0 && outcome.steps > 0);
    assert!(outcome.linearisations == outcome.steps || outcome.linearisations == outcome.steps + 1);
    assert_eq!(outcome.residuals, decay_residuals(&data, &outcome.x));
}

#[test]
fn the_difference_jacobian_matches_the_analytic_one_and_so_does_the_fit() {
    let data = truth();
    let residuals = |theta: &[f64]| Some(decay_residuals(&data, theta));
    let at = [1.3, 0.7];
    let r = decay_residuals(&data, &at);
    let differences = forward_differences(&residuals, &at, &r, 1e-7);
    for (column, analytic) in differences.iter().zip(decay_jacobian(&at)) {
        for (d, a) in column.iter().zip(&analytic) {
            assert!((d - a).abs() < 1e-5 * a.abs().max(1.0), "{d} vs {a}");
        }
    }
    let central = central_difference(
        |shift| Ok::<_, ()>(decay_residuals(&data, &[at[0], at[1] + shift])),
        1e-5,
    )
    .unwrap();
    for (c, a) in central.iter().zip(&decay_jacobian(&at)[1]) {
        assert!((c - a).abs() < 1e-8 * a.abs().max(1.0), "{c} vs {a}");
    }
    // Noisy data: both Jacobians lead to the same least-squares minimum.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let noise = Gaussian::new(0.0, 0.01).unwrap();
    let noisy: Vec<f64> = data.iter().map(|y| y + noise.sample(&mut rng)).collect();
    let residuals = |theta: &[f64]| Some(decay_residuals(&noisy, theta));
    let fit = |jacobian| {
        Function {
            residuals: &residuals,
            jacobian,
            damping: DAMPING,
        }
        .minimise(vec![1.0, 1.0], &Settings::DEFAULT)
    };
    let by_differences = fit(Jacobian::ForwardDifferences { step: 1e-6 });
    let analytic = fit(Jacobian::Analytic(&decay_jacobian));
    for (d, a) in by_differences.x.iter().zip(&analytic.x) {
        assert!((d - a).abs() < 1e-6, "{by_differences:?} vs {analytic:?}");
    }
    // At the minimum the gradient J'r vanishes.
    for column in decay_jacobian(&analytic.x) {
        assert!(
            dot(&column, &analytic.residuals).abs() < 1e-9,
            "{analytic:?}"
        );
    }
}

#[test]
fn the_rosenbrock_valley_is_followed_to_its_minimum() {
    // r = (10 (y - x^2), 1 - x): minimum 0 at (1, 1), from the classic start (-1.2, 1).
    let residuals = |v: &[f64]| Some(vec![10.0 * (v[1] - v[0] * v[0]), 1.0 - v[0]]);
    let jacobian = |v: &[f64]| vec![vec![-20.0 * v[0], -1.0], vec![10.0, 0.0]];
    let settings = Settings {
        tolerance: 0.0,
        ..Settings::DEFAULT
    };
    for jacobian in [
        Jacobian::Analytic(&jacobian),
        Jacobian::ForwardDifferences { step: 1e-7 },
    ] {
        let outcome = Function {
            residuals: &residuals,
            jacobian,
            damping: DAMPING,
        }
        .minimise(vec![-1.2, 1.0], &settings);
        assert!(outcome.cost < 1e-20, "{outcome:?}");
        assert!((outcome.x[0] - 1.0).abs() < 1e-9 && (outcome.x[1] - 1.0).abs() < 1e-9);
    }
}

#[test]
fn standard_errors_match_linear_regression_and_are_infinite_where_undetermined() {
    // y = 1 + 0.5 t + noise: the slope's error is s / sqrt(sum (t - mean)^2), the
    // intercept's s sqrt(1/n + mean^2 / sum (t - mean)^2), s^2 = rss / (n - 2).
    let t = times();
    let n = t.len() as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let noise = Gaussian::new(0.0, 0.1).unwrap();
    let y: Vec<f64> = t
        .iter()
        .map(|t| 1.0 + 0.5 * t + noise.sample(&mut rng))
        .collect();
    let residuals = |c: &[f64]| -> Option<Vec<f64>> {
        Some(t.iter().zip(&y).map(|(t, y)| c[0] + c[1] * t - y).collect())
    };
    let outcome = Function {
        residuals: &residuals,
        jacobian: Jacobian::ForwardDifferences { step: 1e-6 },
        damping: DAMPING,
    }
    .minimise(vec![0.0, 0.0], &Settings::DEFAULT);
    let columns = vec![vec![1.0; t.len()], t.clone()];
    let errors = standard_errors(&columns, &outcome.residuals, 2);
    let mean = t.iter().sum::<f64>() / n;
    let spread: f64 = t.iter().map(|t| (t - mean).powi(2)).sum();
    let s = (dot(&outcome.residuals, &outcome.residuals) / (n - 2.0)).sqrt();
    assert!(
        (errors[1] / (s / spread.sqrt()) - 1.0).abs() < 1e-9,
        "{errors:?}"
    );
    let intercept = s * (1.0 / n + mean * mean / spread).sqrt();
    assert!((errors[0] / intercept - 1.0).abs() < 1e-9, "{errors:?}");
    // Only the first `count` unknowns are reported (the rest are nuisances).
    assert_eq!(
        standard_errors(&columns, &outcome.residuals, 1),
        errors[..1]
    );
    // y = (a + b) t: the data fix a + b, never a and b apart.
    let rank_deficient = vec![t.clone(), t.clone()];
    let errors = standard_errors(&rank_deficient, &outcome.residuals, 2);
    assert!(errors.iter().all(|e| e.is_infinite()), "{errors:?}");
}

/// The sample standard deviation of `values`.
fn sample_deviation(values: &[f64]) -> f64 {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let squares: f64 = values.iter().map(|v| (v - mean).powi(2)).sum();
    (squares / (values.len() - 1) as f64).sqrt()
}

/// The least-squares line through `(t, y)`: its slope and its residuals (fit minus data).
fn line_fit(t: &[f64], y: &[f64]) -> (f64, Vec<f64>) {
    let n = t.len() as f64;
    let mean = t.iter().sum::<f64>() / n;
    let spread: f64 = t.iter().map(|t| (t - mean).powi(2)).sum();
    let y_mean = y.iter().sum::<f64>() / n;
    let slope = (t.iter().zip(y))
        .map(|(t, y)| (t - mean) * (y - y_mean))
        .sum::<f64>()
        / spread;
    let intercept = y_mean - slope * mean;
    let residuals = (t.iter().zip(y))
        .map(|(t, y)| intercept + slope * t - y)
        .collect();
    (slope, residuals)
}

/// A line fitted to two groups of points, those at both ends 20x noisier (where they weigh
/// most on the slope): the grouped errors
/// match the spread of the slope over many simulated data sets (an independent Monte Carlo),
/// where the pooled errors, which assume one noise level, do not; with one group the two
/// agree.
#[test]
fn grouped_standard_errors_match_the_spread_of_refits_under_unequal_noise() {
    let t: Vec<f64> = (0..40).map(|k| k as f64 * 0.25).collect();
    let groups: Vec<usize> = t
        .iter()
        .map(|&t| usize::from(!(2.0..7.75).contains(&t)))
        .collect();
    let sigma = [0.05, 1.0];
    let columns = vec![vec![1.0; t.len()], t.clone()];
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let unit = Gaussian::new(0.0, 1.0).unwrap();
    let (mut slopes, mut grouped, mut pooled) = (Vec::new(), 0.0, 0.0);
    let draws = 4000;
    for _ in 0..draws {
        let y: Vec<f64> = (t.iter().zip(&groups))
            .map(|(t, &g)| 1.0 + 0.5 * t + sigma[g] * unit.sample(&mut rng))
            .collect();
        let (slope, residuals) = line_fit(&t, &y);
        slopes.push(slope);
        grouped += grouped_standard_errors(&columns, &residuals, &groups, 2)[1] / draws as f64;
        pooled += standard_errors(&columns, &residuals, 2)[1] / draws as f64;
    }
    let spread_of_slopes = sample_deviation(&slopes);
    assert!(
        (grouped / spread_of_slopes - 1.0).abs() < 0.05,
        "{grouped} {spread_of_slopes}"
    );
    assert!(
        (pooled / spread_of_slopes - 1.0).abs() > 0.15,
        "{pooled} {spread_of_slopes}"
    );
    let residuals: Vec<f64> = t.iter().map(|t| (t * 7.0).sin()).collect();
    let one = grouped_standard_errors(&columns, &residuals, &vec![0; t.len()], 2);
    let plain = standard_errors(&columns, &residuals, 2);
    for (a, b) in one.iter().zip(&plain) {
        assert!((a / b - 1.0).abs() < 1e-9, "{one:?} {plain:?}");
    }
}

/// With one noise group the sandwich is `s^2 (J'J)^-1`: for a straight line `a + b t`, the
/// closed forms `var b = s^2 / Sxx`, `cov(a, b) = -s^2 mean / Sxx` and
/// `var a = s^2 (1 / n + mean^2 / Sxx)`.
#[test]
fn the_grouped_covariance_of_a_line_is_its_closed_form() {
    let t: Vec<f64> = (0..25).map(|k| 0.3 * k as f64 + 1.0).collect();
    let residuals: Vec<f64> = t.iter().map(|t| (t * 5.0).cos() * 0.2).collect();
    let columns = vec![vec![1.0; t.len()], t.clone()];
    let n = t.len() as f64;
    let mean = t.iter().sum::<f64>() / n;
    let sxx: f64 = t.iter().map(|t| (t - mean).powi(2)).sum();
    let s2 = residuals.iter().map(|r| r * r).sum::<f64>() / (n - 2.0);
    let c = grouped_covariance(&columns, &residuals, &vec![0; t.len()]).unwrap();
    let expected = [
        s2 * (1.0 / n + mean * mean / sxx),
        -s2 * mean / sxx,
        -s2 * mean / sxx,
        s2 / sxx,
    ];
    for (got, want) in c.iter().zip(expected) {
        assert!((got / want - 1.0).abs() < 1e-9, "{c:?} {expected:?}");
    }
    // Two identical columns leave J'J singular: no covariance.
    let twins = vec![t.clone(), t.clone()];
    assert!(grouped_covariance(&twins, &residuals, &vec![0; t.len()]).is_none());
}

#[test]
fn steps_are_clipped_and_budgets_respected() {
    // r = x - 100 from 0: one trial moves x by at most max_move.
    let residuals = |x: &[f64]| Some(vec![x[0] - 100.0]);
    let function = Function {
        residuals: &residuals,
        jacobian: Jacobian::ForwardDifferences { step: 1e-6 },
        damping: DAMPING,
    };
    let settings = Settings {
        max_move: 3.0,
        max_trials: 1,
        ..Settings::DEFAULT
    };
    let outcome = function.minimise(vec![0.0], &settings);
    assert_eq!(
        (outcome.x[0], outcome.steps, outcome.linearisations),
        (3.0, 1, 1)
    );
    let unclipped = function.minimise(vec![0.0], &Settings::DEFAULT);
    assert!((unclipped.x[0] - 100.0).abs() < 1e-6, "{unclipped:?}");
    // Residuals that fail at the start: nothing moves, the cost is infinite.
    let failing = |_: &[f64]| None;
    let outcome = Function {
        residuals: &failing,
        ..function
    }
    .minimise(vec![1.0], &Settings::DEFAULT);
    assert!(outcome.cost.is_infinite() && outcome.x == [1.0] && outcome.steps == 0);
}

#[test]
fn a_trial_where_residuals_fail_is_rejected_and_a_shorter_one_taken() {
    // r = atan(x - 2) from 0: the Gauss-Newton step overshoots to 5.5, where the residuals
    // are not defined (x >= 4); damped steps get to the root.
    let residuals = |x: &[f64]| (x[0] < 4.0).then(|| vec![(x[0] - 2.0).atan()]);
    let outcome = Function {
        residuals: &residuals,
        jacobian: Jacobian::ForwardDifferences { step: 1e-6 },
        damping: DAMPING,
    }
    .minimise(vec![0.0], &Settings::DEFAULT);
    assert!((outcome.x[0] - 2.0).abs() < 1e-6, "{outcome:?}");
    // A forward difference across the edge falls back to the backward one: the slope of
    // atan(x - 2) at 4 is 1 / 5.
    let at = [4.0 - 1e-7];
    let r = residuals(&at).unwrap();
    let column = forward_differences(&residuals, &at, &r, 1e-6);
    assert!((column[0][0] - 0.2).abs() < 1e-6, "{column:?}");
    // With no side defined the column is zero.
    let nowhere = |x: &[f64]| (x[0] == 1.0).then(|| vec![x[0]]);
    assert_eq!(
        forward_differences(&nowhere, &[1.0], &[1.0], 1e-6),
        vec![vec![0.0]]
    );
}

/// A problem whose evaluation fails after a number of calls.
struct Failing {
    calls: usize,
}

impl Problem for Failing {
    type Error = String;
    type Linear = GaussNewton;

    fn residuals(&mut self, x: &[f64]) -> Result<Option<Vec<f64>>, String> {
        self.calls += 1;
        if self.calls > 2 {
            return Err(format!("failed at call {}", self.calls));
        }
        Ok(Some(vec![x[0] - 1.0, 2.0 * x[0]]))
    }

    fn linearise(&mut self, _: &[f64], residuals: &[f64]) -> Result<GaussNewton, String> {
        Ok(GaussNewton::new(&[vec![1.0, 2.0]], residuals, DAMPING))
    }
}

#[test]
fn an_evaluation_error_ends_the_fit() {
    let error = minimise(&mut Failing { calls: 0 }, vec![5.0], &Settings::DEFAULT).unwrap_err();
    assert_eq!(error, "failed at call 3");
}

/// Three measured series of one nonlinear model (a shared decay rate `k`, amplitudes `a` and
/// `b`), each with its own noise level, as a diagnosis's states are: `a e^{-kt}` (sd 0.01),
/// `a b (1 - e^{-kt})` (sd 0.4) and `b t e^{-kt}` (sd 0.05).
fn three_series(theta: &[f64], t: &[f64]) -> Vec<f64> {
    let (a, k, b) = (theta[0], theta[1], theta[2]);
    let e = |t: f64| (-k * t).exp();
    let first = t.iter().map(|&t| a * e(t));
    let second = t.iter().map(|&t| a * b * (1.0 - e(t)));
    let third = t.iter().map(|&t| b * t * e(t));
    first.chain(second).chain(third).collect()
}

/// Its analytic Jacobian (columns for `a`, `k`, `b`).
fn three_series_jacobian(theta: &[f64], t: &[f64]) -> Vec<Vec<f64>> {
    let (a, k, b) = (theta[0], theta[1], theta[2]);
    let e: Vec<f64> = t.iter().map(|&t| (-k * t).exp()).collect();
    let pairs = || t.iter().copied().zip(e.iter().copied());
    let column = |f: &dyn Fn(f64, f64) -> [f64; 3]| -> Vec<f64> {
        let rows: Vec<[f64; 3]> = pairs().map(|(t, e)| f(t, e)).collect();
        (0..3)
            .flat_map(|g| rows.iter().map(move |r| r[g]))
            .collect()
    };
    vec![
        column(&|_, e| [e, b * (1.0 - e), 0.0]),
        column(&|t, e| [-a * t * e, a * b * t * e, -b * t * t * e]),
        column(&|t, e| [0.0, a * (1.0 - e), t * e]),
    ]
}

/// The grouped errors of a nonlinear fit with three groups of unequal noise match the spread
/// of the Levenberg–Marquardt refits over simulated data sets (an independent Monte Carlo),
/// for every param; the pooled errors, which assume one noise level, do not.
#[test]
fn grouped_standard_errors_match_the_refits_of_a_nonlinear_fit_with_three_groups() {
    let t: Vec<f64> = (1..=20).map(|k| k as f64 * 0.5).collect();
    let truth = [2.0, 0.3, 1.5];
    let sigma = [0.01, 0.4, 0.05];
    let groups: Vec<usize> = (0..3).flat_map(|g| vec![g; t.len()]).collect();
    let clean = three_series(&truth, &t);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let unit = Gaussian::new(0.0, 1.0).unwrap();
    let draws = 1500;
    let (mut fits, mut grouped, mut pooled) = (Vec::new(), [0.0; 3], [0.0; 3]);
    for _ in 0..draws {
        let y: Vec<f64> = (clean.iter().zip(&groups))
            .map(|(c, &g)| c + sigma[g] * unit.sample(&mut rng))
            .collect();
        let residuals = |theta: &[f64]| {
            let model = three_series(theta, &t);
            Some(model.iter().zip(&y).map(|(m, y)| m - y).collect())
        };
        let jacobian = |theta: &[f64]| three_series_jacobian(theta, &t);
        let function = Function {
            residuals: &residuals,
            jacobian: Jacobian::Analytic(&jacobian),
            damping: DAMPING,
        };
        let outcome = function.minimise(truth.to_vec(), &Settings::DEFAULT);
        let columns = three_series_jacobian(&outcome.x, &t);
        let errors = grouped_standard_errors(&columns, &outcome.residuals, &groups, 3);
        let plain = standard_errors(&columns, &outcome.residuals, 3);
        for i in 0..3 {
            grouped[i] += errors[i] / draws as f64;
            pooled[i] += plain[i] / draws as f64;
        }
        fits.push(outcome.x);
    }
    for i in 0..3 {
        let mean = fits.iter().map(|x| x[i]).sum::<f64>() / draws as f64;
        let spread =
            (fits.iter().map(|x| (x[i] - mean).powi(2)).sum::<f64>() / (draws - 1) as f64).sqrt();
        assert!(
            (grouped[i] / spread - 1.0).abs() < 0.1,
            "param {i}: grouped {} against the refits' spread {spread}",
            grouped[i]
        );
        assert!(
            (pooled[i] / spread - 1.0).abs() > 0.3,
            "param {i}: pooled {} against the refits' spread {spread}",
            pooled[i]
        );
    }
}

/// Under relative noise (each cell's error 10 % of what it reads) a line's slope rests most
/// on its largest, noisiest cells: the shaped sandwich ([`variance_shapes`] fitted to the
/// residuals) matches the spread of 4000 refits, the pooled one does not; under absolute
/// noise the shapes stay near 1.
#[test]
fn shaped_standard_errors_match_the_refits_under_relative_noise() {
    let t: Vec<f64> = (0..40).map(|k| k as f64 * 0.25).collect();
    let columns = vec![vec![1.0; t.len()], t.clone()];
    let groups = vec![0; t.len()];
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let unit = Gaussian::new(0.0, 1.0).unwrap();
    let (mut slopes, mut shaped, mut pooled) = (Vec::new(), 0.0, 0.0);
    let draws = 4000;
    let slope_error = |covariance: Option<Vec<f64>>| covariance.unwrap()[3].sqrt();
    for _ in 0..draws {
        let y: Vec<f64> = (t.iter())
            .map(|t| (0.2 + t) * (1.0 + 0.1 * unit.sample(&mut rng)))
            .collect();
        let (slope, residuals) = line_fit(&t, &y);
        slopes.push(slope);
        let values: Vec<Option<f64>> = y.iter().map(|&v| Some(v)).collect();
        let shapes = variance_shapes(&residuals, &groups, &values);
        let covariance = shaped_covariance(&columns, &residuals, (&groups, &shapes));
        shaped += slope_error(covariance) / draws as f64;
        pooled += slope_error(grouped_covariance(&columns, &residuals, &groups)) / draws as f64;
    }
    let spread_of_slopes = sample_deviation(&slopes);
    let (shaped, pooled) = (shaped / spread_of_slopes, pooled / spread_of_slopes);
    assert!(
        (shaped - 1.0).abs() < 0.06,
        "shaped {shaped}, pooled {pooled}"
    );
    assert!(
        pooled < 0.93 && (shaped - 1.0).abs() < (pooled - 1.0).abs() / 2.0,
        "shaped {shaped}, pooled {pooled}"
    );
    // Absolute noise: the fitted shapes stay flat.
    let residuals: Vec<f64> = (0..400).map(|_| 0.3 * unit.sample(&mut rng)).collect();
    let values: Vec<Option<f64>> = (0..400).map(|k| Some(k as f64 * 0.1)).collect();
    let shapes = variance_shapes(&residuals, &vec![0; 400], &values);
    let (low, high) = (
        shapes[..40].iter().sum::<f64>() / 40.0,
        shapes[360..].iter().sum::<f64>() / 40.0,
    );
    assert!(
        (low - 1.0).abs() < 0.35 && (high - 1.0).abs() < 0.35,
        "{low} {high}"
    );
}
