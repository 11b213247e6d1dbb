//! The tolerance times of a record are compared with, and the uniform grid it implies.

use super::times::{decimal_quantum, grid_step, time_tolerance, uniform_step, OffGrid};

/// `x` printed with nine decimals and read back, as a plate reader's export gives it.
fn printed(x: f64) -> f64 {
    format!("{x:.9}").parse().unwrap()
}

/// A jitter of `size` for row `i`, of alternating sign and 0.8 to 1 of `size` (a fixed
/// scrambling of `i`), so that steps scatter by up to about twice `size`.
fn jitter(i: usize, size: f64) -> f64 {
    let scrambled = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
    let share = 0.8 + 0.2 * scrambled as f64 / (1u64 << 53) as f64;
    let sign = if i.is_multiple_of(2) { 1.0 } else { -1.0 };
    sign * size * share
}

#[test]
fn printed_precision_is_the_last_decimal_written() {
    assert_eq!(decimal_quantum(&[0.0, 0.166666736, 0.5]), 1e-9);
    assert_eq!(decimal_quantum(&[0.0, 1.0, 2.0, 300.0]), 1.0);
    assert_eq!(decimal_quantum(&[0.167, 0.333, 0.5]), 1e-3);
    assert_eq!(decimal_quantum(&[2.5e-4]), 1e-5);
    assert_eq!(decimal_quantum(&[]), 1.0);
}

/// Times that jitter by 1e-7 around a grid of 1/6 lie on it; the steps scatter by more
/// than the relative 1e-6 that was the whole tolerance before.
#[test]
fn times_that_jitter_around_a_grid_are_uniform() {
    let h = 1.0 / 6.0;
    let times: Vec<f64> = (0..2478)
        .map(|i| printed(i as f64 * h + jitter(i, 1e-7)))
        .collect();
    let widest = (times.windows(2))
        .map(|w| (w[1] - w[0] - h).abs())
        .fold(0.0, f64::max);
    assert!(
        widest > 1e-6 * h,
        "the jitter must exceed the old tolerance: {widest}"
    );
    let tolerance = time_tolerance(&times);
    assert!(tolerance >= widest && tolerance < 2e-5 * h, "{tolerance}");
    let step = uniform_step(&times).unwrap();
    assert!((step - h).abs() < 1e-9, "{step}");
    // Times printed with three decimals are uniform too: their steps scatter by the last
    // decimal.
    let rounded: Vec<f64> = (0..600)
        .map(|i| (i as f64 * h * 1e3).round() / 1e3)
        .collect();
    assert!((uniform_step(&rounded).unwrap() - h).abs() < 1e-5);
}

/// An exact grid keeps the tolerance it had (a relative 1e-6 of the step), and a missing
/// row, an irregular record or a drift away from the grid stay irregular.
#[test]
fn irregular_times_stay_irregular() {
    let whole: Vec<f64> = (0..100).map(|i| i as f64).collect();
    let tolerance = time_tolerance(&whole);
    assert!((tolerance - 1e-6).abs() < 1e-12, "{tolerance}");
    let mut gap = whole.clone();
    gap.remove(40);
    let found = grid_step(&gap, time_tolerance(&gap));
    assert_eq!(
        found,
        Err(OffGrid {
            sample: 40,
            expected: 1.0
        })
    );
    let h = 1.0 / 6.0;
    let jittered_gap: Vec<f64> = (0..300)
        .filter(|&i| i != 120)
        .map(|i| printed(i as f64 * h + jitter(i, 1e-7)))
        .collect();
    assert_eq!(uniform_step(&jittered_gap), None);
    // Sampling by hand: steps that scatter by 20 % get at most 1 % of the step.
    let irregular: Vec<f64> = (0..200)
        .map(|i| i as f64 * h + 0.2 * h * (i as f64 * 1.7).sin())
        .collect();
    assert!(time_tolerance(&irregular) <= 0.011 * h);
    assert_eq!(uniform_step(&irregular), None);
    // Each step within tolerance, but the times drift off the grid: not uniform.
    let drift: Vec<f64> = (0..1000)
        .map(|i| i as f64 * (1.0 + 5e-7 * (i as f64 / 1000.0)))
        .collect();
    assert!(matches!(grid_step(&drift, 1e-6), Err(OffGrid { .. })));
    assert_eq!(uniform_step(&[0.0]), None);
    assert_eq!(uniform_step(&[0.0, 1.0, 2.5]), None);
}
