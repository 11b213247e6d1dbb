//! Hidden-layer activations evaluated in place over a whole layer, value and slope together.
//!
//! Softplus, the activation of every shipped model, dominates the transcendental work of a
//! training step (about 12,000 evaluations per GB2 step). In `f32` it runs through
//! branch-free polynomial versions of `exp` and `ln(1 + e)` that the compiler vectorises
//! (the libm calls it replaces cannot be), one exponential shared by the value and the slope;
//! `f64` (and the graph backend in both precisions) uses [`Real::softplus_and_slope`], the
//! one definition; the `f32` lane approximates it within the bound its tests state.

use crate::ir::Activation;
use crate::numeric::Real;

/// An element type with a whole-layer softplus.
pub trait Lane: Real {
    /// Replaces each `z` in `values` by `softplus(z)` and writes `sigmoid(z)` (its slope)
    /// into `slopes` (same length).
    fn softplus_with_slope(values: &mut [Self], slopes: &mut [Self]);
}

impl Lane for f64 {
    fn softplus_with_slope(values: &mut [f64], slopes: &mut [f64]) {
        for (value, slope) in values.iter_mut().zip(slopes.iter_mut()) {
            (*value, *slope) = value.softplus_and_slope();
        }
    }
}

impl Lane for f32 {
    fn softplus_with_slope(values: &mut [f32], slopes: &mut [f32]) {
        super::wide::dispatch(SoftplusLayer { values, slopes });
    }
}

/// One `f32` softplus layer, for [`super::wide::dispatch`].
struct SoftplusLayer<'a> {
    values: &'a mut [f32],
    slopes: &'a mut [f32],
}

impl pulp::WithSimd for SoftplusLayer<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        softplus_layer(self.values, self.slopes);
    }
}

/// The `f32` softplus layer (inlined into each build that [`super::wide::dispatch`] makes).
#[inline(always)]
fn softplus_layer(values: &mut [f32], slopes: &mut [f32]) {
    for (value, slope) in values.iter_mut().zip(slopes.iter_mut()) {
        // e = exp(-|z|); one division serves 1 / (1 + e) and e / (2 + e).
        let z = *value;
        let decay = exp_nonpositive(-z.abs());
        let (one_plus, two_plus) = (1.0 + decay, 2.0 + decay);
        let reciprocal = 1.0 / (one_plus * two_plus);
        let numerator = if z >= 0.0 { 1.0 } else { decay };
        *slope = numerator * two_plus * reciprocal;
        let positive_part = if z > 0.0 { z } else { 0.0 };
        *value = positive_part + two_atanh(decay * one_plus * reciprocal);
    }
}

/// Applies `activation` in place to a layer's pre-activations and writes the slopes
/// `d activation / d z` (needed by the reverse pass) into `slopes`.
pub fn activate<E: Lane>(activation: Activation, values: &mut [E], slopes: &mut [E]) {
    match activation {
        Activation::Softplus => E::softplus_with_slope(values, slopes),
        Activation::Linear => slopes.fill(E::ONE),
        Activation::Tanh => map(values, slopes, |z| {
            let y = z.tanh();
            (y, E::ONE - y * y)
        }),
        Activation::Sigmoid => map(values, slopes, |z| {
            let y = z.sigmoid();
            (y, y * (E::ONE - y))
        }),
        Activation::Relu => map(values, slopes, |z| {
            if z > E::ZERO {
                (z, E::ONE)
            } else {
                (E::ZERO, E::ZERO)
            }
        }),
        Activation::Gelu => map(values, slopes, gelu),
    }
}

fn map<E: Real>(values: &mut [E], slopes: &mut [E], f: impl Fn(E) -> (E, E)) {
    for (value, slope) in values.iter_mut().zip(slopes.iter_mut()) {
        let (y, dy) = f(*value);
        *value = y;
        *slope = dy;
    }
}

/// The tanh approximation of GELU, `x/2 (1 + tanh(sqrt(2/pi) (x + 0.044715 x^3)))`, and its
/// derivative (dfdx's `fast_gelu`, which the graph backend uses).
fn gelu<E: Real>(x: E) -> (E, E) {
    let half = E::from_double(0.5);
    let kappa = E::from_double(0.044715);
    let beta = E::from_double((2.0 / std::f64::consts::PI).sqrt());
    let inner = (beta * (x + kappa * x * x * x)).tanh();
    let value = half * x * (E::ONE + inner);
    let slope = half * (E::ONE + inner)
        + half
            * x
            * (E::ONE - inner * inner)
            * beta
            * (E::ONE + E::from_double(3.0) * kappa * x * x);
    (value, slope)
}

/// `1.5 * 2^23`: adding it rounds an `f32` of magnitude below `2^22` to an integer, which
/// then sits in the low mantissa bits.
const ROUNDING_SHIFT: f32 = 12_582_912.0;

/// `e^x` for `x <= 0` in `f32` without branches (Cephes' `expf`: `x = n ln 2 + r`,
/// `|r| <= ln 2 / 2`, a degree-6 polynomial for `e^r`, `2^n` assembled from bits). Below
/// `-86` it returns `e^-86` (about `4.5e-38`, still a normal number) rather than go
/// through subnormals: an absolute error under `5e-38`. Within 2 ulps of the exact
/// exponential over `[-86, 0]` (tested against libm on a million points over every binade).
#[inline(always)]
pub fn exp_nonpositive(x: f32) -> f32 {
    let x = if x > -86.0 { x } else { -86.0 };
    let shifted = x * std::f32::consts::LOG2_E + ROUNDING_SHIFT;
    let n = shifted - ROUNDING_SHIFT;
    let r = x - n * 0.693_359_4 - n * -2.121_944_4e-4;
    let mut p = 1.987_569_2e-4_f32;
    for coefficient in [1.398_2e-3, 8.333_452e-3, 4.166_579_6e-2, 0.166_666_65, 0.5] {
        p = p * r + coefficient;
    }
    let polynomial = p * r * r + r + 1.0;
    let exponent = (shifted.to_bits() as i32).wrapping_sub(ROUNDING_SHIFT.to_bits() as i32);
    let scale = f32::from_bits(((exponent + 127) << 23) as u32);
    polynomial * scale
}

/// `ln(1 + e)` for `0 <= e <= 1` in `f32` without branches, as `2 atanh(s)` with
/// `s = e / (2 + e)`; it keeps full relative accuracy for tiny `e`: within 2 ulps of the
/// exact value for `e` in `[e^-86, 1]`, the range softplus feeds it (tested on a million
/// points over every binade; subnormal `e` lose relative accuracy and never occur).
#[cfg(test)]
pub fn ln_one_plus_unit(e: f32) -> f32 {
    two_atanh(e / (2.0 + e))
}

/// `2 atanh(s) = ln((1 + s) / (1 - s))` for `0 <= s <= 1/3`: the odd series summed to
/// `s^13` (truncation below `1.5e-8` relative).
#[inline(always)]
fn two_atanh(s: f32) -> f32 {
    let s2 = s * s;
    let mut sum = 1.0 / 13.0_f32;
    for odd in [11.0_f32, 9.0, 7.0, 5.0, 3.0, 1.0] {
        sum = sum * s2 + 1.0 / odd;
    }
    2.0 * s * sum
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Relative distance in units of `f32::EPSILON`.
    fn ulps(found: f32, expected: f64) -> f64 {
        (found as f64 - expected).abs() / (expected.abs() * f32::EPSILON as f64)
    }

    /// Every 997th `f32` of `[lo, hi]` (both non-negative) by bit pattern: about a million
    /// points covering every binade of the range, the ends included.
    fn sweep(lo: f32, hi: f32) -> impl Iterator<Item = f32> {
        let (first, last) = (lo.to_bits(), hi.to_bits());
        (first..=last)
            .step_by(997)
            .chain([last])
            .map(f32::from_bits)
    }

    /// The stated bound over the whole range softplus uses, `[-86, 0]`: within 2 ulps of
    /// the exact exponential (libm's `f64` `exp`, itself within 1 ulp of `f64`).
    #[test]
    fn fast_exp_is_within_two_ulps_of_libm_over_its_whole_range() {
        let mut worst: f64 = 0.0;
        let mut count = 0;
        for magnitude in sweep(0.0, 86.0) {
            let x = -magnitude;
            worst = worst.max(ulps(exp_nonpositive(x), (x as f64).exp()));
            count += 1;
        }
        assert!(count > 1_000_000, "{count} points");
        assert!(worst < 2.0, "worst {worst} ulps");
        assert!(exp_nonpositive(-1000.0) < 5e-38 && exp_nonpositive(-1000.0) > 0.0);
        assert_eq!(exp_nonpositive(0.0), 1.0);
    }

    /// `ln(1 + e)` over the whole range softplus uses, `e` in `[e^-86, 1]` (what
    /// [`exp_nonpositive`] returns; every binade): within 2 ulps of libm's `f64` `ln_1p`.
    #[test]
    fn fast_ln_one_plus_is_within_two_ulps_of_libm_over_its_whole_range() {
        let mut worst: f64 = 0.0;
        for e in sweep(exp_nonpositive(-86.0), 1.0) {
            worst = worst.max(ulps(ln_one_plus_unit(e), (e as f64).ln_1p()));
        }
        assert!(worst < 2.0, "worst {worst} ulps");
        assert_eq!(ln_one_plus_unit(0.0), 0.0);
    }

    /// Both element types against the f64 definition `ln(1 + e^z)` and its derivative.
    #[test]
    fn softplus_and_slope_match_the_definition_in_both_precisions() {
        let points: Vec<f64> = (-400..=400).map(|i| i as f64 * 0.25).collect();
        let mut double = points.clone();
        let mut double_slopes = vec![0.0; points.len()];
        activate(Activation::Softplus, &mut double, &mut double_slopes);
        let mut single: Vec<f32> = points.iter().map(|&z| z as f32).collect();
        let mut single_slopes = vec![0.0_f32; points.len()];
        activate(Activation::Softplus, &mut single, &mut single_slopes);
        for (index, &z) in points.iter().enumerate() {
            let value = if z > 30.0 { z } else { z.exp().ln_1p() };
            let slope = 1.0 / (1.0 + (-z).exp());
            assert!(
                (double[index] - value).abs() <= 1e-14 * value.max(1e-300),
                "{z}"
            );
            assert!((double_slopes[index] - slope).abs() <= 1e-15, "{z}");
            // Below z = -86 the value stays at e^-86 instead of going subnormal.
            let absolute = (single[index] as f64 - value).abs();
            let close = ulps(single[index], value) < 3.0 || absolute < 5e-38;
            assert!(close, "{z}: {}", single[index]);
            let slope_ulps = ulps(single_slopes[index], slope);
            assert!(slope_ulps < 3.0 || slope < 1e-37, "{z}: {slope_ulps} ulps");
        }
    }

    /// The softplus layer in the build `pulp` picks for this CPU and in the baseline build
    /// gives the same bits.
    #[test]
    fn the_wide_softplus_gives_the_portable_numbers_bit_for_bit() {
        use pulp::WithSimd;
        let points: Vec<f32> = (-2000..=2000).map(|i| i as f32 * 0.0517).collect();
        let (mut wide, mut portable) = (points.clone(), points.clone());
        let (mut wide_slopes, mut portable_slopes) = (vec![0.0; 4001], vec![0.0; 4001]);
        pulp::Arch::new().dispatch(SoftplusLayer {
            values: &mut wide,
            slopes: &mut wide_slopes,
        });
        SoftplusLayer {
            values: &mut portable,
            slopes: &mut portable_slopes,
        }
        .with_simd(pulp::Scalar::new());
        assert_eq!(wide, portable);
        assert_eq!(wide_slopes, portable_slopes);
    }

    #[test]
    fn values_are_the_textbook_ones() {
        let cases = [
            (Activation::Tanh, 0.5, 0.5_f64.tanh()),
            (Activation::Sigmoid, 0.5, 1.0 / (1.0 + (-0.5_f64).exp())),
            (Activation::Relu, -0.5, 0.0),
            (Activation::Relu, 0.5, 0.5),
            (Activation::Linear, -0.5, -0.5),
            (Activation::Gelu, 1.0, 0.841_191_990_6),
        ];
        for (activation, z, expected) in cases {
            let (mut value, mut slope) = ([z], [0.0]);
            activate(activation, &mut value, &mut slope);
            assert!((value[0] - expected).abs() < 1e-9, "{activation:?}({z})");
        }
    }

    /// Every activation's slope against central differences of its value (f64).
    #[test]
    fn slopes_are_derivatives_of_values() {
        for activation in Activation::ALL {
            for z in [-2.3, -0.4, 0.3, 1.7] {
                let eval = |x: f64| {
                    let (mut value, mut slope) = ([x], [0.0]);
                    activate(activation, &mut value, &mut slope);
                    (value[0], slope[0])
                };
                let step = 1e-6;
                let numeric = (eval(z + step).0 - eval(z - step).0) / (2.0 * step);
                assert!(
                    (eval(z).1 - numeric).abs() < 1e-8,
                    "{activation:?} at {z}: {} vs {numeric}",
                    eval(z).1
                );
            }
        }
    }
}
