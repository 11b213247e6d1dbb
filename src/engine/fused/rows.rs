//! The sub-step's combinations of stage slopes, row by row (each batch row steps its own
//! `dt`), in the order the tableau fixes ([`crate::solve::ode::tableau`]): a stage's state
//! estimate and the step forward, and the reverse pass's scaled adjoints.

use crate::numeric::Real;
use crate::solve::ode::tableau::Combination;

use super::buffers::Stage;

/// Row `i`'s sub-step `dt_i` times `multiple / divisor`, as `dt * multiple / divisor`.
pub(super) type RowFactors<'a> = (&'a [f64], f64, f64);

/// The slopes (balances) of the stages that enter `combination`, each with its numerator.
fn terms<'a, E: Real, const S: usize>(
    combination: &Combination<S>,
    stages: &'a [Stage<E>],
) -> Vec<(&'a [E], E)> {
    (combination.terms())
        .map(|(stage, numerator)| (stages[stage].balances.as_slice(), E::from_double(numerator)))
        .collect()
}

/// `n_0 k_0[i] + n_1 k_1[i] + ...`, left to right.
#[inline(always)]
fn combined<E: Real>(terms: &[(&[E], E)], i: usize) -> E {
    let mut sum = terms[0].1 * terms[0].0[i];
    for &(slope, numerator) in &terms[1..] {
        sum += numerator * slope[i];
    }
    sum
}

/// `out = x + (dt_r / d) (n_0 k_0 + n_1 k_1 + ...)` row by row: the state estimate of the
/// stage `combination` leads to, from the sub-step's start `start` and the `stages` before
/// it (`width` values a row; `out` empty on entry).
pub(super) fn stage_estimate_into<E: Real, const S: usize>(
    out: &mut Vec<E>,
    start: &[E],
    (substeps, combination): (&[f64], &Combination<S>),
    stages: &[Stage<E>],
    width: usize,
) {
    let terms = terms(combination, stages);
    for (row, (start_row, &dt)) in start.chunks(width).zip(substeps).enumerate() {
        let factor = E::from_double(dt / combination.divisor());
        let first = row * width;
        let values = start_row.iter().enumerate();
        out.extend(values.map(|(column, &x)| x + factor * combined(&terms, first + column)));
    }
}

/// `state += (dt_r / d) (n_0 k_0 + n_1 k_1 + ...)` row by row: the sub-step along the
/// tableau's weights `combination` from the slopes of `stages`.
pub(super) fn advance_rows<E: Real, const S: usize>(
    state: &mut [E],
    (substeps, combination): (&[f64], &Combination<S>),
    stages: &[Stage<E>],
    width: usize,
) {
    let terms = terms(combination, stages);
    for (row, (state_row, &dt)) in state.chunks_mut(width).zip(substeps).enumerate() {
        let factor = E::from_double(dt / combination.divisor());
        for (column, slot) in state_row.iter_mut().enumerate() {
            *slot += factor * combined(&terms, row * width + column);
        }
    }
}

/// `out = (dt_i * multiple / divisor) values` row by row.
pub(super) fn scaled_rows_into<E: Real>(
    out: &mut Vec<E>,
    values: &[E],
    (substeps, multiple, divisor): RowFactors,
    width: usize,
) {
    out.clear();
    for (row, &dt) in values.chunks(width).zip(substeps) {
        let factor = E::from_double(dt * multiple / divisor);
        out.extend(row.iter().map(|&v| v * factor));
    }
}

/// `target += (dt_i * multiple / divisor) values` row by row.
pub(super) fn add_scaled_rows<E: Real>(
    target: &mut [E],
    (substeps, multiple, divisor): RowFactors,
    values: &[E],
    width: usize,
) {
    for ((slot_row, row), &dt) in target
        .chunks_mut(width)
        .zip(values.chunks(width))
        .zip(substeps)
    {
        let factor = E::from_double(dt * multiple / divisor);
        for (slot, &value) in slot_row.iter_mut().zip(row) {
            *slot += factor * value;
        }
    }
}

/// `target += factor * values`.
pub(super) fn add_scaled<E: Real>(target: &mut [E], factor: f64, values: &[E]) {
    let factor = E::from_double(factor);
    for (slot, &value) in target.iter_mut().zip(values) {
        *slot += factor * value;
    }
}
