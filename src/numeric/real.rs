//! The floating-point element types training runs in (`f32`, `f64`), with the numerically
//! safe scalar functions the networks and the physics need. The one definition of softplus
//! (value and slope) is here: the graph backend, the fused step, the physics program and the
//! scalar evaluator ([`crate::vocabulary::softplus`]) all call it.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

/// A floating-point element type of the trainable network.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
{
    /// Zero.
    const ZERO: Self;
    /// One.
    const ONE: Self;
    /// Converts from `f64` (rounding for `f32`).
    fn from_double(value: f64) -> Self;
    /// Converts to `f64` (exact).
    fn to_double(self) -> f64;
    /// `e^x`.
    fn exp(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Hyperbolic tangent.
    fn tanh(self) -> Self;
    /// `self ^ exponent`.
    fn powf(self, exponent: Self) -> Self;

    /// `ln(1 + x)` for `x >= 0` through `ln` (much faster than the libm `log1p`) with
    /// Goldberg's correction `ln(u) * x / (u - 1)`, `u = 1 + x`, which keeps it accurate to a
    /// few ulps however small `x` is.
    fn ln_one_plus(self) -> Self {
        let sum = Self::ONE + self;
        if sum == Self::ONE {
            self
        } else {
            sum.ln() * self / (sum - Self::ONE)
        }
    }
    /// `log(1 + e^x)` and its slope `1 / (1 + e^-x)` from one exponential: written as
    /// `max(x, 0) + ln(1 + e)` and `1 / (1 + e)` or `e / (1 + e)` with `e = e^-|x|`, so
    /// that neither overflows for large positive `x` nor loses the tail for large negative
    /// `x`.
    fn softplus_and_slope(self) -> (Self, Self) {
        let decay = (-self.abs()).exp();
        let positive_part = if self > Self::ZERO { self } else { Self::ZERO };
        let numerator = if self >= Self::ZERO { Self::ONE } else { decay };
        (
            positive_part + decay.ln_one_plus(),
            numerator / (Self::ONE + decay),
        )
    }
    /// `log(1 + e^x)` ([`Real::softplus_and_slope`]'s value).
    fn softplus(self) -> Self {
        self.softplus_and_slope().0
    }
    /// `1 / (1 + e^-x)`, evaluated through `e^-|x|` so it never overflows; it is also the
    /// derivative of [`Real::softplus`] ([`Real::softplus_and_slope`]'s slope).
    fn sigmoid(self) -> Self {
        self.softplus_and_slope().1
    }
}

macro_rules! impl_real {
    ($type:ty) => {
        impl Real for $type {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            fn from_double(value: f64) -> Self {
                value as $type
            }
            fn to_double(self) -> f64 {
                self as f64
            }
            fn exp(self) -> Self {
                <$type>::exp(self)
            }
            fn ln(self) -> Self {
                <$type>::ln(self)
            }
            fn sqrt(self) -> Self {
                <$type>::sqrt(self)
            }
            fn abs(self) -> Self {
                <$type>::abs(self)
            }
            fn tanh(self) -> Self {
                <$type>::tanh(self)
            }
            fn powf(self, exponent: Self) -> Self {
                <$type>::powf(self, exponent)
            }
        }
    };
}

impl_real!(f32);
impl_real!(f64);

/// The inverse of softplus, `ln(e^y - 1)`, for `y > 0`; used to initialise a `positive`
/// param so that its transformed value equals its declared initial guess.
pub fn inverse_softplus(value: f64) -> f64 {
    // ln(e^y - 1) = y + ln(1 - e^-y), exact and overflow-free for large y.
    value + (-(-value).exp_m1()).ln()
}

/// The inverse of the logistic sigmoid, `ln(p / (1 - p))`, for `0 < p < 1`.
pub fn logit(probability: f64) -> f64 {
    (probability / (1.0 - probability)).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Central difference of `f` at `x`.
    fn central_difference(f: impl Fn(f64) -> f64, x: f64) -> f64 {
        let step = 1e-6 * (1.0 + x.abs());
        (f(x + step) - f(x - step)) / (2.0 * step)
    }

    #[test]
    fn softplus_matches_its_definition_where_that_is_safe() {
        for x in [-20.0, -3.0, -0.5, 0.0, 0.7, 4.0, 20.0] {
            let reference = (1.0 + f64::exp(x)).ln();
            assert!((Real::softplus(x) - reference).abs() < 1e-14, "x = {x}");
        }
    }

    #[test]
    fn ln_one_plus_is_accurate_from_tiny_to_one() {
        for x in [0.0, 1e-300, 1e-17, 1e-9, 3e-5, 0.01, 0.5, 1.0] {
            let found = Real::ln_one_plus(x);
            assert!(
                (found - f64::ln_1p(x)).abs() <= 4.0 * f64::EPSILON * f64::ln_1p(x),
                "{x}"
            );
        }
        for x in [1e-30_f32, 1e-6, 0.2, 1.0] {
            let found = Real::ln_one_plus(x);
            assert!(
                (found - f32::ln_1p(x)).abs() <= 4.0 * f32::EPSILON * f32::ln_1p(x),
                "{x}"
            );
        }
    }

    #[test]
    fn softplus_is_finite_and_exact_at_large_arguments() {
        // Naive ln(1 + e^x) overflows to inf at x = 1000 (f64) and x = 100 (f32).
        assert_eq!(Real::softplus(1000.0_f64), 1000.0);
        assert_eq!(Real::softplus(100.0_f32), 100.0);
        // The tail e^x for very negative x is kept, not rounded to zero by 1 + e^x.
        let tail = Real::softplus(-50.0_f64);
        assert!((tail / f64::exp(-50.0) - 1.0).abs() < 1e-12);
        assert_eq!(Real::softplus(-1000.0_f64), 0.0);
    }

    #[test]
    fn sigmoid_is_the_derivative_of_softplus_everywhere() {
        for x in [-30.0, -2.0, -0.1, 0.0, 0.3, 5.0, 30.0] {
            let numeric = central_difference(Real::softplus, x);
            assert!((numeric - Real::sigmoid(x)).abs() < 1e-8, "x = {x}");
        }
        // Far out the derivative saturates without NaN (naive e^x / (1 + e^x) gives NaN).
        assert_eq!(Real::sigmoid(1000.0_f64), 1.0);
        assert_eq!(Real::sigmoid(-1000.0_f64), 0.0);
        assert_eq!(Real::sigmoid(200.0_f32), 1.0);
    }

    #[test]
    fn inverse_transforms_invert_their_transforms() {
        for y in [1e-6, 0.3, 1.0, 40.0, 800.0] {
            let raw = inverse_softplus(y);
            assert!((Real::softplus(raw) / y - 1.0).abs() < 1e-12, "y = {y}");
        }
        for p in [1e-4, 0.25, 0.5, 0.9] {
            assert!((Real::sigmoid(logit(p)) - p).abs() < 1e-12, "p = {p}");
        }
    }
}
