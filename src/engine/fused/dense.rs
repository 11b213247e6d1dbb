//! The one matrix kernel of the fused step, `out += lhs @ rhs` on small blocks, with the
//! operands copied into packed panels first so that the inner loop has no index arithmetic
//! or bounds checks and keeps a tile of the output in registers: 4 rows by two vector
//! registers (`4 x 8` `f32` in the portable SSE2 build, `4 x 16` in the AVX2 one; the
//! tiling changes no sum's order, so both give the same bits).
//!
//! Every product of a training step has this shape: the affine layers (`z = a W + b`, `out`
//! starting at the bias), the input gradients (`g_a = delta W^T`) and the weight gradients
//! (`dW += a^T delta`); the transposes are only strides of a [`View`], resolved by the
//! packing.

use crate::numeric::Real;

/// Output rows computed together, sharing each load of `rhs`.
const BLOCK: usize = 4;
/// Bytes of the narrowest vector register the builds have (SSE2's, the `x86_64` baseline
/// that the portable build autovectorises for).
const BASELINE_VECTOR: usize = 16;
/// The widest strip of output columns: `16` `f32` columns are two AVX2 registers a row.
const WIDEST: usize = 16;

/// A read-only matrix: entry `(i, j)` is `values[i * row_stride + j * column_stride]`.
#[derive(Debug, Clone, Copy)]
pub struct View<'a, E> {
    /// The backing values.
    pub values: &'a [E],
    /// Distance between consecutive rows.
    pub row_stride: usize,
    /// Distance between consecutive columns.
    pub column_stride: usize,
}

impl<'a, E: Copy> View<'a, E> {
    /// A row-major matrix with `columns` columns.
    pub fn row_major(values: &'a [E], columns: usize) -> Self {
        View {
            values,
            row_stride: columns,
            column_stride: 1,
        }
    }

    /// The transpose of a row-major matrix with `columns` columns.
    pub fn transposed(values: &'a [E], columns: usize) -> Self {
        View {
            values,
            row_stride: 1,
            column_stride: columns,
        }
    }
}

/// Packing buffers reused from product to product.
#[derive(Debug, Clone, Default)]
pub struct Gemm<E> {
    lhs: Vec<E>,
    rhs: Vec<E>,
}

impl<E: Real> Gemm<E> {
    /// `out[r, :] += sum_k lhs(r, k) * rhs(k, :)` for a row-major `out` of shape
    /// `rows x columns`; `lhs` is `rows x inner`, `rhs` is `inner x columns`.
    pub fn multiply_add(
        &mut self,
        out: &mut [E],
        shape: (usize, usize, usize),
        lhs: View<E>,
        rhs: View<E>,
    ) {
        self.product::<true>(out, shape, lhs, rhs);
    }

    /// `out = lhs @ rhs`, shapes as in [`Gemm::multiply_add`] (`out` is overwritten, so it
    /// need not be zeroed first).
    pub fn multiply(
        &mut self,
        out: &mut [E],
        shape: (usize, usize, usize),
        lhs: View<E>,
        rhs: View<E>,
    ) {
        self.product::<false>(out, shape, lhs, rhs);
    }

    fn product<const ADD: bool>(
        &mut self,
        out: &mut [E],
        shape: (usize, usize, usize),
        lhs: View<E>,
        rhs: View<E>,
    ) {
        let work = Product::<E, ADD> {
            gemm: self,
            out,
            shape,
            lhs,
            rhs,
        };
        super::wide::dispatch(work);
    }

    /// The product with strips at most `widest` columns wide: two vector registers per
    /// tile row, so that the `4 x 2` independent sums hide the adds' latency.
    #[inline(always)]
    fn product_portable<const ADD: bool>(
        &mut self,
        out: &mut [E],
        (rows, columns, inner): (usize, usize, usize),
        (lhs, rhs): (View<E>, View<E>),
        widest: usize,
    ) {
        if rows == 0 || columns == 0 {
            return;
        }
        let strips = strips(columns, widest);
        self.rhs.clear();
        for &(start, width) in &strips {
            match width {
                16 => pack_panel::<E, 16>(&mut self.rhs, rhs, start, inner),
                8 => pack_panel::<E, 8>(&mut self.rhs, rhs, start, inner),
                4 => pack_panel::<E, 4>(&mut self.rhs, rhs, start, inner),
                _ => pack_panel::<E, 1>(&mut self.rhs, rhs, start, inner),
            }
        }
        let full = rows / BLOCK * BLOCK;
        for row in (0..full).step_by(BLOCK) {
            let block = &mut out[row * columns..(row + BLOCK) * columns];
            self.row_block::<BLOCK, ADD>(block, lhs, row, (columns, inner), &strips);
        }
        for row in full..rows {
            let block = &mut out[row * columns..(row + 1) * columns];
            self.row_block::<1, ADD>(block, lhs, row, (columns, inner), &strips);
        }
    }

    /// Rows `row..row + R` of the product, strip by strip.
    #[inline(always)]
    fn row_block<const R: usize, const ADD: bool>(
        &mut self,
        out: &mut [E],
        lhs: View<E>,
        row: usize,
        (columns, inner): (usize, usize),
        strips: &[(usize, usize)],
    ) {
        pack_rows::<E, R>(&mut self.lhs, lhs, row, inner);
        let mut panel_start = 0;
        for &(start, width) in strips {
            let panel = &self.rhs[panel_start..panel_start + inner * width];
            panel_start += inner * width;
            let place = (start, columns);
            match width {
                16 => tile::<E, R, 16, ADD>(out, &self.lhs, panel, place),
                8 => tile::<E, R, 8, ADD>(out, &self.lhs, panel, place),
                4 => tile::<E, R, 4, ADD>(out, &self.lhs, panel, place),
                _ => tile::<E, R, 1, ADD>(out, &self.lhs, panel, place),
            }
        }
    }
}

/// One product, for [`super::wide::dispatch`].
struct Product<'a, E, const ADD: bool> {
    gemm: &'a mut Gemm<E>,
    out: &'a mut [E],
    shape: (usize, usize, usize),
    lhs: View<'a, E>,
    rhs: View<'a, E>,
}

impl<E: Real, const ADD: bool> pulp::WithSimd for Product<'_, E, ADD> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let vector = std::mem::size_of::<S::f32s>().max(BASELINE_VECTOR);
        let widest = (2 * vector / std::mem::size_of::<E>()).min(WIDEST);
        let operands = (self.lhs, self.rhs);
        (self.gemm).product_portable::<ADD>(self.out, self.shape, operands, widest);
    }
}

/// Appends columns `start..start + N` of `rhs` (all `inner` rows) to `out`, row by row.
#[inline(always)]
fn pack_panel<E: Real, const N: usize>(out: &mut Vec<E>, rhs: View<E>, start: usize, inner: usize) {
    let (rows, columns) = (rhs.row_stride, rhs.column_stride);
    for k in 0..inner {
        let first = k * rows + start * columns;
        if columns == 1 {
            let block: &[E] = &rhs.values[first..first + N];
            out.extend_from_slice(block);
        } else {
            out.extend((0..N).map(|c| rhs.values[first + c * columns]));
        }
    }
}

/// Writes rows `row..row + R` of `lhs` into `packed` interleaved: entry `k * R + j` is
/// `lhs(row + j, k)`.
#[inline(always)]
fn pack_rows<E: Real, const R: usize>(packed: &mut Vec<E>, lhs: View<E>, row: usize, inner: usize) {
    packed.resize(inner * R, E::ZERO);
    let (rows, columns) = (lhs.row_stride, lhs.column_stride);
    if rows == 1 {
        for (k, chunk) in packed.chunks_exact_mut(R).enumerate() {
            let first = row + k * columns;
            chunk.copy_from_slice(&lhs.values[first..first + R]);
        }
    } else if columns == 1 && R == BLOCK {
        // Four contiguous rows, interleaved: a 4 x inner transpose without index checks.
        let line = |j: usize| &lhs.values[(row + j) * rows..][..inner];
        let lines = line(0).iter().zip(line(1)).zip(line(2)).zip(line(3));
        for (chunk, (((&a, &b), &c), &d)) in packed.chunks_exact_mut(BLOCK).zip(lines) {
            chunk.copy_from_slice(&[a, b, c, d]);
        }
    } else {
        for j in 0..R {
            let first = (row + j) * rows;
            for k in 0..inner {
                packed[k * R + j] = lhs.values[first + k * columns];
            }
        }
    }
}

/// `(start, width)` of the column strips: as many of the widest (at most `widest`) as fit,
/// then narrower ones (16, 8, 4), then single columns.
fn strips(columns: usize, widest: usize) -> Vec<(usize, usize)> {
    let mut strips = Vec::new();
    let mut start = 0;
    for width in [16, 8, 4, 1] {
        if width > widest {
            continue;
        }
        while columns - start >= width {
            strips.push((start, width));
            start += width;
        }
    }
    strips
}

/// Columns `start..start + N` of the `R` rows of `out`, from the packed `lhs` (`inner x R`)
/// and the packed `panel` (`inner x N`): `R x N` independent sums in registers, starting
/// from `out` (`ADD`) or from zero.
#[inline(always)]
fn tile<E: Real, const R: usize, const N: usize, const ADD: bool>(
    out: &mut [E],
    lhs: &[E],
    panel: &[E],
    (start, columns): (usize, usize),
) {
    let mut acc = [[E::ZERO; N]; R];
    if ADD {
        for (row, sums) in acc.iter_mut().enumerate() {
            sums.copy_from_slice(&out[row * columns + start..][..N]);
        }
    }
    for (scales, block) in lhs.chunks_exact(R).zip(panel.chunks_exact(N)) {
        for (sums, &scale) in acc.iter_mut().zip(scales) {
            for (sum, &value) in sums.iter_mut().zip(block) {
                *sum += scale * value;
            }
        }
    }
    for (row, sums) in acc.iter().enumerate() {
        out[row * columns + start..][..N].copy_from_slice(sums);
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

    /// The textbook triple loop on explicit `(i, j)` accessors.
    fn reference(
        lhs: impl Fn(usize, usize) -> f64,
        rhs: impl Fn(usize, usize) -> f64,
        (rows, columns, inner): (usize, usize, usize),
    ) -> Vec<f64> {
        let mut out = vec![0.0; rows * columns];
        for r in 0..rows {
            for c in 0..columns {
                for k in 0..inner {
                    out[r * columns + c] += lhs(r, k) * rhs(k, c);
                }
            }
        }
        out
    }

    #[test]
    fn multiply_add_matches_the_triple_loop_for_every_block_and_strip_split() {
        let mut gemm = Gemm::default();
        for (rows, columns, inner) in [(3, 20, 5), (1, 1, 1), (4, 3, 7), (9, 8, 3), (5, 17, 2)] {
            let lhs: Vec<f64> = (0..rows * inner).map(|i| (i as f64 * 0.37).sin()).collect();
            let rhs: Vec<f64> = (0..inner * columns)
                .map(|i| (i as f64 * 0.11).cos())
                .collect();
            let start: Vec<f64> = (0..rows * columns).map(|i| i as f64).collect();
            let shape = (rows, columns, inner);
            let mut out = start.clone();
            let (a, b) = (View::row_major(&lhs, inner), View::row_major(&rhs, columns));
            gemm.multiply_add(&mut out, shape, a, b);
            let product = reference(
                |r, k| lhs[r * inner + k],
                |k, c| rhs[k * columns + c],
                shape,
            );
            for (index, &found) in out.iter().enumerate() {
                let expected = start[index] + product[index];
                assert!((found - expected).abs() < 1e-12, "{shape:?}");
            }
            // The same operands stored transposed give the same product.
            let lhs_t: Vec<f64> = (0..inner * rows)
                .map(|i| lhs[(i % rows) * inner + i / rows])
                .collect();
            let rhs_t: Vec<f64> = (0..columns * inner)
                .map(|i| rhs[(i % inner) * columns + i / inner])
                .collect();
            let mut out_t = start.clone();
            let (a, b) = (
                View::transposed(&lhs_t, rows),
                View::transposed(&rhs_t, inner),
            );
            gemm.multiply_add(&mut out_t, shape, a, b);
            assert_eq!(out_t, out, "{shape:?} transposed");
            // Overwriting ignores what `out` held.
            let mut fresh = vec![f64::NAN; rows * columns];
            let (a, b) = (View::row_major(&lhs, inner), View::row_major(&rhs, columns));
            gemm.multiply(&mut fresh, shape, a, b);
            for (found, expected) in fresh.iter().zip(&product) {
                assert!((found - expected).abs() < 1e-12, "{shape:?} overwritten");
            }
        }
    }

    /// The build `pulp` picks for this CPU (AVX2 where there is one) and the baseline
    /// build give the same bits: the same operations in the same order, only wider.
    #[test]
    fn the_wide_build_gives_the_portable_numbers_bit_for_bit() {
        use pulp::WithSimd;
        for (rows, columns, inner) in [(50, 20, 50), (7, 3, 20), (13, 17, 5), (6, 37, 9)] {
            let lhs: Vec<f32> = (0..rows * inner).map(|i| (i as f32 * 0.37).sin()).collect();
            let rhs: Vec<f32> = (0..inner * columns)
                .map(|i| (i as f32 * 0.11).cos())
                .collect();
            let start: Vec<f32> = (0..rows * columns).map(|i| i as f32 * 0.01).collect();
            let (mut wide, mut portable) = (start.clone(), start.clone());
            let (mut first, mut second) = (Gemm::default(), Gemm::default());
            let shape = (rows, columns, inner);
            let (a, b) = (View::row_major(&lhs, inner), View::row_major(&rhs, columns));
            pulp::Arch::new().dispatch(Product::<f32, true> {
                gemm: &mut first,
                out: &mut wide,
                shape,
                lhs: a,
                rhs: b,
            });
            let product = Product::<f32, true> {
                gemm: &mut second,
                out: &mut portable,
                shape,
                lhs: a,
                rhs: b,
            };
            product.with_simd(pulp::Scalar::new());
            assert_eq!(wide, portable, "{rows} x {columns} x {inner}");
            assert_ne!(wide, start);
        }
    }

    #[test]
    fn strips_cover_the_columns_widest_first() {
        assert_eq!(strips(20, 16), [(0, 16), (16, 4)]);
        assert_eq!(strips(20, 8), [(0, 8), (8, 8), (16, 4)]);
        assert_eq!(
            strips(31, 16),
            [(0, 16), (16, 8), (24, 4), (28, 1), (29, 1), (30, 1)]
        );
        assert_eq!(strips(3, 4), [(0, 1), (1, 1), (2, 1)]);
    }

    #[test]
    fn column_sums_add_up_each_column() {
        let matrix = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let mut sums = [1.0, 1.0, 1.0];
        add_column_sums(&mut sums, &matrix, 3);
        assert_eq!(sums, [6.0, 8.0, 10.0]);
    }
}
