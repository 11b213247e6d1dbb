//! The Radau IIA scheme of order 5 (Hairer and Wanner II, section IV.8): its stage times
//! and matrix, the real block form of the matrix's inverse that decouples the Newton
//! iterations, the embedded error weights and the collocation polynomial. The integrator
//! ([`super::Radau`]) and the implicit sensitivities
//! ([`super::sensitivity::Implicit`]) both build on them.

use crate::numeric::Complex;

const S6: f64 = 2.449_489_742_783_178; // sqrt(6)
/// Stage times as fractions of the step.
pub(super) const C: [f64; 3] = [(4.0 - S6) / 10.0, (4.0 + S6) / 10.0, 1.0];
/// The method's matrix `A` (Butcher tableau).
pub(super) const A: [[f64; 3]; 3] = [
    [
        (88.0 - 7.0 * S6) / 360.0,
        (296.0 - 169.0 * S6) / 1800.0,
        (-2.0 + 3.0 * S6) / 225.0,
    ],
    [
        (296.0 + 169.0 * S6) / 1800.0,
        (88.0 + 7.0 * S6) / 360.0,
        (-2.0 - 3.0 * S6) / 225.0,
    ],
    [(16.0 - S6) / 36.0, (16.0 + S6) / 36.0, 1.0 / 9.0],
];
/// Error estimate weights on the stage increments.
pub(super) const E: [f64; 3] = [
    (-13.0 - 7.0 * S6) / 3.0,
    (-13.0 + 7.0 * S6) / 3.0,
    -1.0 / 3.0,
];
/// The real eigenvalue of `A^-1`: `3 + 3^(2/3) - 3^(1/3)`.
pub(super) const MU_REAL: f64 = 3.637_834_252_744_496;
/// The complex eigenvalue of `A^-1`.
pub(super) const MU_COMPLEX: Complex = Complex::new(2.681_082_873_627_752, -3.050_430_199_247_411);
/// `A^-1 = T diag(MU_REAL, MU_COMPLEX) T^-1` in real block form (digits as published).
#[allow(clippy::excessive_precision)]
pub(super) const T: [[f64; 3]; 3] = [
    [
        0.094_438_762_488_975_24,
        -0.141_255_295_020_954_21,
        0.030_029_194_105_147_42,
    ],
    [
        0.250_213_122_965_333_32,
        0.204_129_352_293_799_94,
        -0.382_942_112_757_261_92,
    ],
    [1.0, 1.0, 0.0],
];
/// `T^-1`.
#[allow(clippy::excessive_precision)]
pub(super) const TI: [[f64; 3]; 3] = [
    [
        4.178_718_591_551_904_28,
        0.327_682_820_761_062_37,
        0.523_376_445_499_449_51,
    ],
    [
        -4.178_718_591_551_904_28,
        -0.327_682_820_761_062_37,
        0.476_623_554_500_550_44,
    ],
    [
        0.502_872_634_945_786_82,
        -2.571_926_949_855_605_22,
        0.596_039_204_828_224_92,
    ],
];
/// The collocation polynomial: `y(t + x h) = y + sum_j (sum_s Z_s P[s][j]) x^(j+1)`.
pub(super) const P: [[f64; 3]; 3] = [
    [
        13.0 / 3.0 + 7.0 * S6 / 3.0,
        -23.0 / 3.0 - 22.0 * S6 / 3.0,
        10.0 / 3.0 + 5.0 * S6,
    ],
    [
        13.0 / 3.0 - 7.0 * S6 / 3.0,
        -23.0 / 3.0 + 22.0 * S6 / 3.0,
        10.0 / 3.0 - 5.0 * S6,
    ],
    [1.0 / 3.0, -8.0 / 3.0, 10.0 / 3.0],
];
/// `sum_j q[j][i] x^(j+1)`.
pub(super) fn polynomial(q: &[Vec<f64>; 3], i: usize, x: f64) -> f64 {
    let mut power = x;
    let mut value = 0.0;
    for column in q {
        value += column[i] * power;
        power *= x;
    }
    value
}
