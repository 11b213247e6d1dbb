//! Eigenvalues and eigenvectors of a small symmetric matrix by the cyclic Jacobi method:
//! plane rotations zero the off-diagonal entries one by one until they are negligible. It
//! is exact to rounding for the few-by-few matrices gbc meets (the curvature of a fit in its
//! params), and needs no pivoting or shifts.

/// Sweeps over every off-diagonal pair before giving up.
const MAX_SWEEPS: usize = 100;

/// The eigen-decomposition of a symmetric `n x n` matrix (row-major, only its symmetric
/// part is read): eigenvalues in ascending order, and the unit eigenvector of each
/// (`vectors[k]` belongs to `values[k]`).
pub fn symmetric_eigen(matrix: &[f64], n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut a: Vec<f64> = (0..n * n)
        .map(|index| {
            let (i, j) = (index / n, index % n);
            0.5 * (matrix[i * n + j] + matrix[j * n + i])
        })
        .collect();
    let mut v: Vec<f64> = (0..n * n)
        .map(|index| if index / n == index % n { 1.0 } else { 0.0 })
        .collect();
    for _ in 0..MAX_SWEEPS {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * n + j].powi(2))
            .sum();
        let diagonal: f64 = (0..n).map(|i| a[i * n + i].powi(2)).sum();
        if off <= 1e-30 * diagonal.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                rotate(&mut a, &mut v, n, (p, q));
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&x, &y| a[x * n + x].total_cmp(&a[y * n + y]));
    let values = order.iter().map(|&k| a[k * n + k]).collect();
    let vectors = (order.iter())
        .map(|&k| (0..n).map(|i| v[i * n + k]).collect())
        .collect();
    (values, vectors)
}

/// One Jacobi rotation zeroing `a[p][q]`, accumulated into the eigenvector columns `v`.
fn rotate(a: &mut [f64], v: &mut [f64], n: usize, (p, q): (usize, usize)) {
    let apq = a[p * n + q];
    if apq == 0.0 {
        return;
    }
    let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
    let t = if theta == 0.0 { 1.0 } else { t };
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    for k in 0..n {
        let (akp, akq) = (a[k * n + p], a[k * n + q]);
        a[k * n + p] = c * akp - s * akq;
        a[k * n + q] = s * akp + c * akq;
    }
    for k in 0..n {
        let (apk, aqk) = (a[p * n + k], a[q * n + k]);
        a[p * n + k] = c * apk - s * aqk;
        a[q * n + k] = s * apk + c * aqk;
    }
    for k in 0..n {
        let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
        v[k * n + p] = c * vkp - s * vkq;
        v[k * n + q] = s * vkp + c * vkq;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pair satisfies `A v = lambda v`, the vectors are orthonormal, and the values
    /// of a known matrix come out: [[2, 1], [1, 2]] has 1 and 3.
    #[test]
    fn decomposes_symmetric_matrices() {
        let (values, vectors) = symmetric_eigen(&[2.0, 1.0, 1.0, 2.0], 2);
        assert!((values[0] - 1.0).abs() < 1e-14 && (values[1] - 3.0).abs() < 1e-14);
        assert!((vectors[0][0] + vectors[0][1]).abs() < 1e-14);
        let n = 4;
        let m: Vec<f64> = (0..n * n)
            .map(|k| {
                let (i, j) = ((k / n) as f64, (k % n) as f64);
                1.0 / (1.0 + i + j) + if i == j { 0.1 * i } else { 0.0 }
            })
            .collect();
        let (values, vectors) = symmetric_eigen(&m, n);
        for (value, vector) in values.iter().zip(&vectors) {
            for i in 0..n {
                let product: f64 = (0..n).map(|j| m[i * n + j] * vector[j]).sum();
                assert!((product - value * vector[i]).abs() < 1e-12);
            }
            let norm: f64 = vector.iter().map(|x| x * x).sum();
            assert!((norm - 1.0).abs() < 1e-12);
        }
        assert!(values.windows(2).all(|w| w[0] <= w[1]));
        let dot: f64 = vectors[0].iter().zip(&vectors[1]).map(|(a, b)| a * b).sum();
        assert!(dot.abs() < 1e-12);
    }
}
