//! `round`, `floor` and `ceil` of `f64` that give exactly `f64::round`'s, `f64::floor`'s and
//! `f64::ceil`'s results without a library call.
//!
//! On the `x86_64` baseline (SSE2, no SSE4.1 `roundsd`) the standard methods are calls into
//! a software routine; the grid arithmetic of records (`record::grid::snap`, interpolation,
//! zero-order hold) calls them for every embedding entry of every rollout window, a few
//! per cent of a training run. Here a truncating conversion to `i64` (one SSE2 instruction,
//! exact for `|x| < 2^63`) does the work for `|x| < 2^52`; larger magnitudes are integers
//! already, and NaN and infinities pass through as the standard methods pass them.

/// Below this magnitude an `f64` may have a fractional part.
const FRACTIONAL: f64 = 4_503_599_627_370_496.0; // 2^52

/// Whether `x` may have a fractional part (false for NaN, infinities and `|x| >= 2^52`).
#[inline(always)]
fn fractional(x: f64) -> bool {
    x.abs() < FRACTIONAL
}

/// `x` rounded toward zero, for `|x| < 2^52`.
#[inline(always)]
fn truncate(x: f64) -> f64 {
    // Exact: `|x| < 2^52 < 2^63`, and every integer below 2^52 is an f64. `-0.5 as i64`
    // is 0, so keep the sign of zero as `trunc` does.
    ((x as i64) as f64).copysign(x)
}

/// Exactly `x.round()` (half away from zero).
#[inline(always)]
pub fn round(x: f64) -> f64 {
    if !fractional(x) {
        return x;
    }
    let whole = truncate(x);
    // `x - whole` is exact (both share the exponent range), so the half test is too.
    if (x - whole).abs() >= 0.5 {
        whole + 1.0_f64.copysign(x)
    } else {
        whole
    }
}

/// Exactly `x.floor()`.
#[inline(always)]
pub fn floor(x: f64) -> f64 {
    if !fractional(x) {
        return x;
    }
    let whole = truncate(x);
    if whole > x {
        whole - 1.0
    } else {
        whole
    }
}

/// Exactly `x.ceil()`.
#[inline(always)]
pub fn ceil(x: f64) -> f64 {
    if !fractional(x) {
        return x;
    }
    let whole = truncate(x);
    if whole < x {
        whole + 1.0
    } else {
        whole
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Same bits as the standard methods: halves, neighbours of integers and halves,
    /// signed zeros, the 2^52 boundary, huge values, infinities and NaN, and a sweep of
    /// bit patterns over every binade.
    #[test]
    fn results_are_the_standard_methods_bit_for_bit() {
        let mut cases = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            FRACTIONAL,
            -FRACTIONAL,
            FRACTIONAL - 0.5,
            -(FRACTIONAL - 0.5),
            FRACTIONAL * 2.0 + 2.0,
            1e300,
            -1e300,
            f64::MIN_POSITIVE,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for k in -40..40 {
            let k = k as f64;
            for delta in [0.0, 0.5, 1e-9, -1e-9, 0.5 + 1e-12, 0.5 - 1e-12] {
                cases.push(k + delta);
            }
        }
        let steps = (0..u64::MAX / 2).step_by(1 << 40).map(f64::from_bits);
        cases.extend(steps.clone().chain(steps.map(|x| -x)));
        for x in cases {
            if x.is_nan() {
                // Any NaN stays a NaN (the standard methods also quiet a signalling one).
                assert!(round(x).is_nan() && floor(x).is_nan() && ceil(x).is_nan());
                continue;
            }
            assert_eq!(round(x).to_bits(), x.round().to_bits(), "round({x:e})");
            assert_eq!(floor(x).to_bits(), x.floor().to_bits(), "floor({x:e})");
            assert_eq!(ceil(x).to_bits(), x.ceil().to_bits(), "ceil({x:e})");
        }
        assert!(round(f64::NAN).is_nan() && floor(f64::NAN).is_nan() && ceil(f64::NAN).is_nan());
    }
}
