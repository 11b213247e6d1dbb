//! The tableau on its own: RK4's order conditions, its stage times, its stability limit
//! against the stability polynomial written out, and one step on `y' = lambda y`.

use super::*;

/// Kutta's third-order scheme: a negative coefficient and a stage time of 1.
const KUTTA3: Tableau<3> = Tableau {
    times: [0, 1, 2],
    time_denominator: 2,
    stages: [
        Combination {
            numerators: [0, 0, 0],
            denominator: 1,
        },
        Combination {
            numerators: [1, 0, 0],
            denominator: 2,
        },
        Combination {
            numerators: [-1, 2, 0],
            denominator: 1,
        },
    ],
    weights: Combination {
        numerators: [1, 4, 1],
        denominator: 6,
    },
};

/// Heun's third-order scheme: no stage at the end of the step.
const HEUN3: Tableau<3> = Tableau {
    times: [0, 1, 2],
    time_denominator: 3,
    stages: [
        Combination {
            numerators: [0, 0, 0],
            denominator: 1,
        },
        Combination {
            numerators: [1, 0, 0],
            denominator: 3,
        },
        Combination {
            numerators: [0, 2, 0],
            denominator: 3,
        },
    ],
    weights: Combination {
        numerators: [1, 0, 3],
        denominator: 4,
    },
};

/// The forward Euler scheme.
const EULER: Tableau<1> = Tableau {
    times: [0],
    time_denominator: 1,
    stages: [Combination {
        numerators: [0],
        denominator: 1,
    }],
    weights: Combination {
        numerators: [1],
        denominator: 1,
    },
};

/// `c`, `A` and `b` as values.
fn values<const S: usize>(tableau: &Tableau<S>) -> (Vec<f64>, Vec<Vec<f64>>, Vec<f64>) {
    let c = (tableau.times.iter())
        .map(|&n| f64::from(n) / f64::from(tableau.time_denominator))
        .collect();
    let a = (tableau.stages.iter())
        .map(|row| (0..S).map(|j| row.coefficient(j)).collect())
        .collect();
    let b = (0..S).map(|i| tableau.weights.coefficient(i)).collect();
    (c, a, b)
}

fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(a, b)| a * b).sum()
}

fn times_matrix(a: &[Vec<f64>], x: &[f64]) -> Vec<f64> {
    a.iter().map(|row| dot(row, x)).collect()
}

fn close(found: f64, expected: f64) {
    assert!((found - expected).abs() < 1e-14, "{found} vs {expected}");
}

#[test]
fn rk4_meets_the_order_conditions_up_to_fourth_order() {
    let (c, a, b) = values(&RK4);
    let ones = vec![1.0; 4];
    let power = |k: i32| -> Vec<f64> { c.iter().map(|x| x.powi(k)).collect() };
    let ac = times_matrix(&a, &c);
    close(dot(&b, &ones), 1.0);
    close(dot(&b, &c), 1.0 / 2.0);
    close(dot(&b, &power(2)), 1.0 / 3.0);
    close(dot(&b, &ac), 1.0 / 6.0);
    close(dot(&b, &power(3)), 1.0 / 4.0);
    let c_ac: Vec<f64> = c.iter().zip(&ac).map(|(x, y)| x * y).collect();
    close(dot(&b, &c_ac), 1.0 / 8.0);
    close(dot(&b, &times_matrix(&a, &power(2))), 1.0 / 12.0);
    close(dot(&b, &times_matrix(&a, &ac)), 1.0 / 24.0);
    let empty: Vec<bool> = RK4.stages.iter().map(Combination::is_empty).collect();
    assert_eq!(empty, [true, false, false, false]);
    assert!(!RK4.weights.is_empty());
}

#[test]
fn stage_times_are_the_row_sums_of_the_a_matrix() {
    for (c, a) in [values(&RK4), values(&KUTTA3), values(&HEUN3)].map(|(c, a, _)| (c, a)) {
        for (time, row) in c.iter().zip(&a) {
            close(row.iter().sum(), *time);
        }
    }
}

#[test]
fn rk4_stage_times_are_half_sub_steps() {
    for substeps in 1..=4 {
        let fractions = RK4.stage_fractions(substeps);
        let halves = 2 * substeps;
        let expected: Vec<f64> = (0..=halves).map(|m| m as f64 / halves as f64).collect();
        assert_eq!(fractions, expected);
        assert_eq!(RK4.stage_times(substeps), halves + 1);
        for substep in 0..substeps {
            for (stage, &time) in RK4.times.iter().enumerate() {
                let offset = RK4.stage_offset(substep, stage);
                assert_eq!(offset, 2 * substep + time as usize);
                let at = (substep as f64 + f64::from(time) / 2.0) / substeps as f64;
                close(fractions[offset], at);
            }
        }
    }
    assert_eq!(RK4.stage_fractions(0), vec![0.0, 0.5, 1.0]);
}

#[test]
fn a_scheme_without_a_stage_at_the_end_still_reads_the_end() {
    let thirds = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];
    assert_eq!(HEUN3.stage_fractions(1), thirds.to_vec());
    assert_eq!(HEUN3.stage_times(2), 7);
    assert_eq!(HEUN3.stage_offset(1, 2), 5);
    assert_eq!(KUTTA3.stage_fractions(1), vec![0.0, 0.5, 1.0]);
    assert_eq!(
        EULER.stage_fractions(3),
        vec![0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0]
    );
}

/// RK4's stability polynomial written out.
fn rk4_by_hand(z: f64) -> f64 {
    1.0 + z + z * z / 2.0 + z.powi(3) / 6.0 + z.powi(4) / 24.0
}

#[test]
fn the_stability_function_is_the_truncated_exponential() {
    for z in [-3.0, -2.785, -1.0, -0.25, 0.0, 0.5] {
        close(RK4.amplification(z), rk4_by_hand(z));
        let kutta = 1.0 + z + z * z / 2.0 + z.powi(3) / 6.0;
        close(KUTTA3.amplification(z), kutta);
        close(EULER.amplification(z), 1.0 + z);
    }
}

#[test]
fn rk4_is_stable_to_2_7853_on_the_negative_real_axis() {
    let limit = RK4.stability_limit();
    assert!((limit - 2.785_293_563_405_282).abs() < 1e-12, "{limit}");
    assert!((rk4_by_hand(-limit) - 1.0).abs() < 1e-12);
    assert!(rk4_by_hand(-limit - 1e-6) > 1.0);
    for i in 0..=1000 {
        let x = -limit * f64::from(i) / 1000.0 * (1.0 - 1e-9);
        assert!(rk4_by_hand(x).abs() <= 1.0, "unstable at {x}");
    }
    assert_eq!(EULER.stability_limit(), 2.0);
    assert!((KUTTA3.stability_limit() - 2.512_745_326_618_329).abs() < 1e-12);
}

/// One step of `y' = lambda y` from `y`, computed as every engine computes a step.
fn step<const S: usize>(tableau: &Tableau<S>, lambda: f64, y: f64, h: f64) -> f64 {
    let mut slopes = Vec::with_capacity(S);
    for row in &tableau.stages {
        let sum: f64 = row.terms().map(|(j, n)| n * slopes[j]).sum();
        let estimate = y + h / row.divisor() * sum;
        slopes.push(lambda * estimate);
    }
    let sum: f64 = tableau.weights.terms().map(|(j, n)| n * slopes[j]).sum();
    y + h / tableau.weights.divisor() * sum
}

#[test]
fn a_step_on_the_linear_test_equation_multiplies_by_the_stability_function() {
    for (lambda, h) in [(-1.3, 0.4), (-7.0, 0.39), (0.8, 0.1), (-2.0, 1.39)] {
        for y in [1.0, -0.37, 12.5] {
            let expected = RK4.amplification(h * lambda) * y;
            let found = step(&RK4, lambda, y, h);
            assert!((found - expected).abs() < 1e-13 * (1.0 + expected.abs()));
            let kutta = KUTTA3.amplification(h * lambda) * y;
            assert!((step(&KUTTA3, lambda, y, h) - kutta).abs() < 1e-13 * (1.0 + kutta.abs()));
        }
    }
}
