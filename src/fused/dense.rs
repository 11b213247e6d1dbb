//! The one matrix kernel of the fused step, `out += lhs @ rhs` on small row-major blocks,
//! written so that the compiler keeps a strip of each output row in registers.
//!
//! Every product of a training step has this shape once its operands are laid out for it:
//! the affine layers (`z = a W + b`, `out` starting at the bias), the input gradients
//! (`g_a = delta W^T`, with `W^T` copied once per step) and the weight gradients
//! (`dW += a^T delta`, with `a` transposed first).

use crate::backend::real::Real;

/// Columns of `out` accumulated in registers at once.
const STRIP: usize = 8;
/// Width of the strips that cover what is left after the wide ones.
const NARROW: usize = 4;
/// Output rows computed together, sharing each load of `rhs`.
const BLOCK: usize = 4;

/// `out[r, :] += sum_k lhs[r, k] * rhs[k, :]` for `out` of shape `rows x columns`, `lhs` of
/// shape `rows x inner` and `rhs` of shape `inner x columns`, all row-major.
pub fn multiply_add<E: Real>(out: &mut [E], lhs: &[E], rhs: &[E], inner: usize, columns: usize) {
    if columns == 0 || inner == 0 {
        return;
    }
    let mut out_blocks = out.chunks_exact_mut(BLOCK * columns);
    let mut lhs_blocks = lhs.chunks_exact(BLOCK * inner);
    for (out_block, lhs_block) in (&mut out_blocks).zip(&mut lhs_blocks) {
        row_block::<E, BLOCK>(out_block, lhs_block, rhs, inner, columns);
    }
    let (out_rest, lhs_rest) = (out_blocks.into_remainder(), lhs_blocks.remainder());
    for (out_row, lhs_row) in out_rest.chunks_exact_mut(columns).zip(lhs_rest.chunks_exact(inner)) {
        row_block::<E, 1>(out_row, lhs_row, rhs, inner, columns);
    }
}

/// `R` consecutive rows: strips of `STRIP`, then `NARROW` columns, then single columns.
#[inline(always)]
fn row_block<E: Real, const R: usize>(
    out: &mut [E],
    lhs: &[E],
    rhs: &[E],
    inner: usize,
    columns: usize,
) {
    let wide = columns / STRIP * STRIP;
    let narrow = wide + (columns - wide) / NARROW * NARROW;
    for start in (0..wide).step_by(STRIP) {
        tile::<E, R, STRIP>(out, lhs, rhs, start, inner, columns);
    }
    for start in (wide..narrow).step_by(NARROW) {
        tile::<E, R, NARROW>(out, lhs, rhs, start, inner, columns);
    }
    for start in narrow..columns {
        tile::<E, R, 1>(out, lhs, rhs, start, inner, columns);
    }
}

/// Columns `start..start + N` of `R` output rows, accumulated in registers: `R x N`
/// independent sums hide the latency of the additions.
#[inline(always)]
fn tile<E: Real, const R: usize, const N: usize>(
    out: &mut [E],
    lhs: &[E],
    rhs: &[E],
    start: usize,
    inner: usize,
    columns: usize,
) {
    let mut acc = [[E::ZERO; N]; R];
    for (row, sums) in acc.iter_mut().enumerate() {
        sums.copy_from_slice(&out[row * columns + start..][..N]);
    }
    for (k, rhs_row) in rhs.chunks_exact(columns).take(inner).enumerate() {
        let block = &rhs_row[start..start + N];
        for (row, sums) in acc.iter_mut().enumerate() {
            let scale = lhs[row * inner + k];
            for lane in 0..N {
                sums[lane] += scale * block[lane];
            }
        }
    }
    for (row, sums) in acc.iter().enumerate() {
        out[row * columns + start..][..N].copy_from_slice(sums);
    }
}

/// Writes the transpose of the `rows x columns` block `matrix` into `out`
/// (`columns x rows`).
pub fn transpose<E: Real>(out: &mut [E], matrix: &[E], rows: usize, columns: usize) {
    for (row, values) in matrix.chunks_exact(columns).take(rows).enumerate() {
        for (column, &value) in values.iter().enumerate() {
            out[column * rows + row] = value;
        }
    }
}

/// Adds each column's sum over the rows of `matrix` (`rows x columns`) to `out`.
pub fn add_column_sums<E: Real>(out: &mut [E], matrix: &[E], columns: usize) {
    for row in matrix.chunks_exact(columns) {
        for (slot, &value) in out.iter_mut().zip(row) {
            *slot += value;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook triple loop.
    fn reference(lhs: &[f64], rhs: &[f64], rows: usize, inner: usize, columns: usize) -> Vec<f64> {
        let mut out = vec![0.0; rows * columns];
        for r in 0..rows {
            for c in 0..columns {
                for k in 0..inner {
                    out[r * columns + c] += lhs[r * inner + k] * rhs[k * columns + c];
                }
            }
        }
        out
    }

    #[test]
    fn multiply_add_matches_the_triple_loop_for_every_strip_split() {
        for (rows, inner, columns) in [(3, 5, 20), (1, 1, 1), (4, 7, 3), (2, 3, 8), (5, 2, 17)] {
            let lhs: Vec<f64> = (0..rows * inner).map(|i| (i as f64 * 0.37).sin()).collect();
            let rhs: Vec<f64> = (0..inner * columns).map(|i| (i as f64 * 0.11).cos()).collect();
            let start: Vec<f64> = (0..rows * columns).map(|i| i as f64).collect();
            let mut out = start.clone();
            multiply_add(&mut out, &lhs, &rhs, inner, columns);
            let product = reference(&lhs, &rhs, rows, inner, columns);
            for (index, &found) in out.iter().enumerate() {
                let expected = start[index] + product[index];
                assert!((found - expected).abs() < 1e-12, "{rows}x{inner}x{columns}");
            }
        }
    }

    #[test]
    fn transpose_and_column_sums_rearrange_and_add() {
        let matrix = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let mut out = [0.0; 6];
        transpose(&mut out, &matrix, 2, 3);
        assert_eq!(out, [1.0, 4.0, 2.0, 5.0, 3.0, 6.0]);
        let mut sums = [1.0, 1.0, 1.0];
        add_column_sums(&mut sums, &matrix, 3);
        assert_eq!(sums, [6.0, 8.0, 10.0]);
    }
}
