//! Statistics and linear algebra against hand-computed values and independent checks.

use super::linalg::gauss_newton_system;
use super::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

fn close(a: f64, b: f64, tolerance: f64) -> bool {
    (a - b).abs() <= tolerance * b.abs().max(1.0)
}

#[test]
fn mean_std_is_the_population_one() {
    // The classic example: mean 5, population deviation 2.
    assert_eq!(
        mean_std(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]),
        (5.0, 2.0)
    );
    let (mean, std) = mean_std(&[1.0, 2.0, 3.0, 4.0]);
    assert!(close(mean, 2.5, 1e-15) && close(std, 1.25f64.sqrt(), 1e-15));
}

#[test]
fn a_constant_or_non_finite_column_normalises_by_one() {
    assert_eq!(mean_std(&[2.0, 2.0, 2.0]), (2.0, 1.0));
    assert_eq!(mean_std(&[0.0; 5]), (0.0, 1.0));
    assert_eq!(mean_std(&[]), (0.0, 1.0));
    // Seven copies of 0.1: rounding leaves a deviation that is not 0 (checked here), yet
    // far below 1e-12 of the mean; it is a constant column.
    let column = [0.1; 7];
    let mean = column.iter().sum::<f64>() / 7.0;
    let raw = (column.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 7.0).sqrt();
    assert!(raw > 0.0 && raw < 1e-15, "{raw}");
    assert_eq!(mean_std(&column).1, 1.0);
    assert_eq!(mean_std(&[1.0, f64::INFINITY]).1, 1.0);
    assert_eq!(mean_std(&[1.0, f64::NAN]).1, 1.0);
    // A small variation that is real (1e-9 of the mean) is kept.
    let (_, std) = mean_std(&[1e6, 1e6 + 2e-3]);
    assert!((std / 1e-3 - 1.0).abs() < 1e-6, "{std}");
    // Around zero the bound is absolute and tiny.
    let (_, std) = mean_std(&[-1e-100, 1e-100]);
    assert!((std / 1e-100 - 1.0).abs() < 1e-12, "{std}");
}

#[test]
fn medians_and_order_statistics() {
    assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
    assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
    assert_eq!(median(&[f64::NAN, 1.0, 5.0, f64::NAN]), Some(3.0));
    assert_eq!(
        median(&[1.0, f64::INFINITY, f64::INFINITY]),
        Some(f64::INFINITY)
    );
    assert_eq!(median(&[f64::MAX, f64::MAX]), Some(f64::MAX));
    assert_eq!(median(&[f64::NAN]), None);
    assert_eq!(median(&[]), None);
    let values: Vec<f64> = (0..300).rev().map(f64::from).collect();
    assert_eq!(order_statistic(&values, 0.5), Some(150.0));
    assert_eq!(order_statistic(&values, 0.01), Some(3.0));
    assert_eq!(order_statistic(&values, 0.0), Some(0.0));
    assert_eq!(order_statistic(&values, 1.0), Some(299.0));
    assert_eq!(order_statistic(&[], 0.5), None);
    // floor(n * 0.01) is exactly the integer n / 100 (callers rely on it).
    for n in 0..200_000usize {
        assert_eq!((0.01 * n as f64).floor() as usize, n / 100, "{n}");
    }
    assert!(close(root_mean_square(&[3.0, 4.0]), 12.5f64.sqrt(), 1e-15));
    assert_eq!(root_mean_square(&[]), 0.0);
}

#[test]
fn cholesky_solves_a_hand_computed_system() {
    // A = L L' with L = [[2, 0, 0], [6, 1, 0], [-8, 5, 3]]; x = [1, 2, 3].
    let a = [4.0, 12.0, -16.0, 12.0, 37.0, -43.0, -16.0, -43.0, 98.0];
    let b = [-20.0, -43.0, 192.0];
    let x = solve_spd(&a, &b).unwrap();
    for (found, want) in x.iter().zip([1.0, 2.0, 3.0]) {
        assert!(close(*found, want, 1e-13), "{x:?}");
    }
    let factor = Cholesky::factor(&a, 3).unwrap();
    assert_eq!(factor.size(), 3);
    // Columns of the inverse: A times column j is the unit vector e_j.
    for j in 0..3 {
        let column = factor.inverse_column(j);
        for i in 0..3 {
            let entry = dot(&a[i * 3..i * 3 + 3], &column);
            assert!(close(entry, f64::from(u8::from(i == j)), 1e-12), "{i} {j}");
        }
    }
}

#[test]
fn cholesky_solves_random_spd_systems() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for n in [1, 2, 5, 12, 30] {
        let mut draw = || -> f64 { StandardNormal.sample(&mut rng) };
        let b_matrix: Vec<f64> = (0..n * n).map(|_| draw()).collect();
        // A = B B' + 0.1 I is symmetric positive definite.
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = dot(&b_matrix[i * n..(i + 1) * n], &b_matrix[j * n..(j + 1) * n]);
            }
            a[i * n + i] += 0.1;
        }
        let rhs: Vec<f64> = (0..n).map(|_| draw()).collect();
        let x = solve_spd(&a, &rhs).unwrap();
        let scale = a.iter().map(|v| v.abs()).fold(0.0, f64::max)
            * x.iter().map(|v| v.abs()).fold(0.0, f64::max);
        for i in 0..n {
            let residual = dot(&a[i * n..(i + 1) * n], &x) - rhs[i];
            assert!(residual.abs() < 1e-12 * scale.max(1.0), "n {n}: {residual}");
        }
    }
}

#[test]
fn cholesky_refuses_what_is_not_positive_definite() {
    for (a, n) in [
        (vec![1.0, 1.0, 1.0, 1.0], 2),      // singular
        (vec![1.0, 2.0, 2.0, 1.0], 2),      // indefinite
        (vec![-1.0], 1),                    // negative
        (vec![0.0; 9], 3),                  // zero
        (vec![1.0, 0.0, 0.0, f64::NAN], 2), // not a number
        (vec![1.0, 0.0, 0.0], 2),           // wrong size
    ] {
        assert!(Cholesky::factor(&a, n).is_none(), "{a:?}");
    }
    // Rank one plus rounding: the second pivot is ~1e-16 of its diagonal, numerically zero.
    let v = [1.0, 1.0 / 3.0];
    let a: Vec<f64> = (0..4).map(|k| v[k / 2] * v[k % 2]).collect();
    assert!(Cholesky::factor(&a, 2).is_none());
}

#[test]
fn normal_equations_recover_a_line() {
    let mut normal = NormalEquations::new(2);
    for k in 0..20 {
        let x = k as f64 / 4.0;
        normal.add(&[1.0, x], 3.0 - 0.5 * x, 1.0);
    }
    normal.finish();
    let fit = normal.solve(0.0, 2).unwrap();
    assert!((fit[0] - 3.0).abs() < 1e-9 && (fit[1] + 0.5).abs() < 1e-9);
    // The data lie on the line: the loss at the fit is zero, elsewhere it is the sum of
    // squared misfits (intercept off by 1 at each of 20 points: 20).
    let constant: f64 = (0..20).map(|k| (3.0 - 0.5 * k as f64 / 4.0).powi(2)).sum();
    assert!(normal.loss(constant, &fit).abs() < 1e-8);
    assert!((normal.loss(constant, &[4.0, -0.5]) - 20.0).abs() < 1e-8);
    // Merging two halves gives the whole.
    let (mut first, mut second) = (NormalEquations::new(2), NormalEquations::new(2));
    for k in 0..20 {
        let x = k as f64 / 4.0;
        let half = if k < 10 { &mut first } else { &mut second };
        half.add(&[1.0, x], 3.0 - 0.5 * x, 1.0);
    }
    first.merge(&second);
    first.finish();
    assert_eq!(first, normal);
}

#[test]
fn a_ridge_spares_the_unpenalised_unknowns() {
    // y = 2 + x exactly; a huge ridge on the slope alone leaves the intercept to fit the mean.
    let mut normal = NormalEquations::new(2);
    for k in 0..10 {
        let x = k as f64 - 4.5;
        normal.add(&[x, 1.0], 2.0 + x, 1.0);
    }
    normal.finish();
    let fit = normal.solve(1e12, 1).unwrap();
    assert!(fit[0].abs() < 1e-9 && (fit[1] - 2.0).abs() < 1e-9);
}

#[test]
fn gauss_newton_system_is_jt_j_and_jt_r() {
    // J = [[1, 2], [3, 4], [5, 6]] (columns [1, 3, 5] and [2, 4, 6]), r = [1, 0, -1].
    let columns = vec![vec![1.0, 3.0, 5.0], vec![2.0, 4.0, 6.0]];
    let (normal, gradient) = gauss_newton_system(&columns, &[1.0, 0.0, -1.0]);
    assert_eq!(normal, vec![35.0, 44.0, 44.0, 56.0]);
    assert_eq!(gradient, vec![-4.0, -4.0]);
}

#[test]
fn normal_cdf_matches_the_integrated_density() {
    // Simpson's rule on the density from -12 (where the mass left out is below 1e-32).
    let density = |x: f64| (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
    for x in [-4.0, -1.6448536, -0.3, 0.0, 0.7, 1.2815516, 2.5, 5.0] {
        let steps = 20_000;
        let h = (x + 12.0) / steps as f64;
        let simpson: f64 = (0..=steps)
            .map(|k| {
                let weight = match k {
                    0 => 1.0,
                    k if k == steps => 1.0,
                    k if k % 2 == 1 => 4.0,
                    _ => 2.0,
                };
                weight * density(-12.0 + k as f64 * h)
            })
            .sum::<f64>()
            * h
            / 3.0;
        let phi = super::normal_cdf(x);
        assert!(
            (phi - simpson).abs() <= 1e-12 * simpson.min(1.0 - simpson).max(1e-300) + 1e-15,
            "Phi({x}) = {phi}, integrated {simpson}"
        );
    }
    assert!(super::normal_cdf(f64::NAN).is_nan());
    assert_eq!(super::normal_cdf(-40.0), 0.0);
}
