//! The Dormand–Prince 5(4) scheme's coefficients (Dormand and Prince 1980; Hairer,
//! Nørsett and Wanner I, section II.5): the stages, the 5th-order solution, the embedded
//! error estimate and the 4th-order continuous extension (Hairer's CONTD5), with the two
//! combinations every step makes of them. The integrator ([`super::Dopri5`]) applies them
//! to the states, the explicit sensitivities ([`super::sensitivity::Explicit`]) to the
//! states' derivatives, entry by entry alike.

// Butcher tableau of Dormand and Prince (1980).
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
// Difference between the 5th- and 4th-order weights.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
// Dense output of order 4 (Hairer's CONTD5).
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// The stages of one step: the slope at the step's start, five inner stages, and the
/// slope at the 5th-order solution (the next step's first: FSAL).
pub(super) type Stages = [Vec<f64>; 7];

/// Stages 2 to 6: their time fraction and their weights on the earlier stages.
pub(super) const TABLEAU: [(f64, &[(usize, f64)]); 5] = [
    (C2, &[(0, A21)]),
    (C3, &[(0, A31), (1, A32)]),
    (C4, &[(0, A41), (1, A42), (2, A43)]),
    (C5, &[(0, A51), (1, A52), (2, A53), (3, A54)]),
    (1.0, &[(0, A61), (1, A62), (2, A63), (3, A64), (4, A65)]),
];
/// The 5th-order solution's weights (the 7th stage is evaluated there: FSAL).
pub(super) const SOLUTION: [(usize, f64); 5] = [(0, A71), (2, A73), (3, A74), (4, A75), (5, A76)];

/// Sets `out = y + h * sum_j weight_j * stages[j]`, entry by entry.
#[inline]
pub(super) fn combine(
    out: &mut [f64],
    y: &[f64],
    h: f64,
    stages: &Stages,
    weights: &[(usize, f64)],
) {
    for (i, value) in out.iter_mut().enumerate() {
        let increment: f64 = weights.iter().map(|&(j, w)| w * stages[j][i]).sum();
        *value = y[i] + h * increment;
    }
}

/// Entry `i` of the embedded error estimate of a step of size `h` with stages `k` (the
/// 5th-order solution less the 4th-order one).
#[inline]
pub(super) fn local_error(h: f64, k: &Stages, i: usize) -> f64 {
    h * (E1 * k[0][i] + E3 * k[2][i] + E4 * k[3][i] + E5 * k[4][i] + E6 * k[5][i] + E7 * k[6][i])
}

/// The continuous extension at fraction `theta` of a step of size `h` from `y` to `next`
/// with stages `k`, entry by entry (states or their sensitivities alike).
pub(super) fn dense(theta: f64, h: f64, y: &[f64], next: &[f64], k: &Stages, out: &mut [f64]) {
    let theta1 = 1.0 - theta;
    for i in 0..y.len() {
        let difference = next[i] - y[i];
        let slope_gap = h * k[0][i] - difference;
        let curvature = difference - h * k[6][i] - slope_gap;
        let correction = h
            * (D1 * k[0][i]
                + D3 * k[2][i]
                + D4 * k[3][i]
                + D5 * k[4][i]
                + D6 * k[5][i]
                + D7 * k[6][i]);
        out[i] = y[i]
            + theta
                * (difference + theta1 * (slope_gap + theta * (curvature + theta1 * correction)));
    }
}
