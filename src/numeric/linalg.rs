//! Small dense linear algebra: the Cholesky factorisation of a symmetric positive-definite
//! matrix, and weighted least squares through the normal equations. Matrices are row-major
//! `Vec<f64>` of `n x n`.

/// A pivot not above this fraction of its diagonal entry counts as zero: the matrix is not
/// numerically positive definite (the direction it belongs to is not determined to better
/// than about 7 significant digits of the diagonal).
pub const PIVOT_TOLERANCE: f64 = 1e-14;

/// `a . b`.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The Cholesky factor `L` (`a = L L'`) of a symmetric positive-definite matrix, to solve
/// systems with it.
#[derive(Debug, Clone, PartialEq)]
pub struct Cholesky {
    n: usize,
    /// `n x n`, row-major, lower triangle (the upper one is zero).
    lower: Vec<f64>,
}

impl Cholesky {
    /// Factors `a` (`n x n`, row-major; only its lower triangle is read); `None` when `a`
    /// does not have `n * n` entries or is not numerically positive definite: a pivot that
    /// is not finite or not above [`PIVOT_TOLERANCE`] times its diagonal entry.
    pub fn factor(a: &[f64], n: usize) -> Option<Cholesky> {
        if a.len() != n * n {
            return None;
        }
        let mut lower = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..=i {
                let mut sum = a[i * n + j];
                for k in 0..j {
                    sum -= lower[i * n + k] * lower[j * n + k];
                }
                if i == j {
                    if !(sum > PIVOT_TOLERANCE * a[i * n + i].abs() && sum.is_finite()) {
                        return None;
                    }
                    lower[i * n + i] = sum.sqrt();
                } else {
                    lower[i * n + j] = sum / lower[j * n + j];
                }
            }
        }
        Some(Cholesky { n, lower })
    }

    /// `L z`: with `z` standard normal, a draw of zero mean and covariance `a`.
    pub fn times(&self, z: &[f64]) -> Vec<f64> {
        let n = self.n;
        (0..n)
            .map(|i| (0..=i).map(|k| self.lower[i * n + k] * z[k]).sum())
            .collect()
    }

    /// The size `n`.
    #[cfg(test)]
    pub fn size(&self) -> usize {
        self.n
    }

    /// The solution `x` of `a x = b` (`b` has `n` entries: forward then back substitution).
    pub fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (n, lower) = (self.n, &self.lower);
        let mut y = vec![0.0; n];
        for i in 0..n {
            let sum: f64 = (0..i).map(|k| lower[i * n + k] * y[k]).sum();
            y[i] = (b[i] - sum) / lower[i * n + i];
        }
        let mut x = vec![0.0; n];
        for i in (0..n).rev() {
            let sum: f64 = (i + 1..n).map(|k| lower[k * n + i] * x[k]).sum();
            x[i] = (y[i] - sum) / lower[i * n + i];
        }
        x
    }

    /// Column `j` of `a^-1`.
    pub fn inverse_column(&self, j: usize) -> Vec<f64> {
        let mut unit = vec![0.0; self.n];
        unit[j] = 1.0;
        self.solve(&unit)
    }
}

/// Solves `a x = b` for a symmetric positive-definite `a` (`n x n` with `n = b.len()`,
/// row-major) by [`Cholesky`]; `None` when `a` is not numerically positive definite.
pub fn solve_spd(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    Cholesky::factor(a, b.len()).map(|factor| factor.solve(b))
}

/// Accumulated normal equations `A = sum w f f'`, `b = sum w y f` of a weighted least
/// squares problem with `n` unknowns.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalEquations {
    /// Number of unknowns.
    pub n: usize,
    /// `n x n`, row-major (upper and lower triangles both filled by
    /// [`NormalEquations::finish`]).
    pub a: Vec<f64>,
    /// Right-hand side.
    pub b: Vec<f64>,
}

impl NormalEquations {
    /// Empty equations in `n` unknowns.
    pub fn new(n: usize) -> Self {
        NormalEquations {
            n,
            a: vec![0.0; n * n],
            b: vec![0.0; n],
        }
    }

    /// Adds the observation `y ~ f . x` with weight `w` (lower triangle only).
    pub fn add(&mut self, f: &[f64], y: f64, w: f64) {
        let n = self.n;
        for i in 0..n {
            let wi = w * f[i];
            if wi == 0.0 {
                continue;
            }
            self.b[i] += wi * y;
            let row = &mut self.a[i * n..i * n + i + 1];
            for (cell, fj) in row.iter_mut().zip(&f[..=i]) {
                *cell += wi * fj;
            }
        }
    }

    /// Adds another set of equations in the same unknowns.
    pub fn merge(&mut self, other: &NormalEquations) {
        self.a.iter_mut().zip(&other.a).for_each(|(a, o)| *a += o);
        self.b.iter_mut().zip(&other.b).for_each(|(b, o)| *b += o);
    }

    /// Mirrors the lower triangle into the upper one.
    pub fn finish(&mut self) {
        let n = self.n;
        for i in 0..n {
            for j in 0..i {
                self.a[j * n + i] = self.a[i * n + j];
            }
        }
    }

    /// The ridge solution `(A + ridge * mean(diag A) * P) x = b`, where `P` is the identity
    /// on the first `penalised` unknowns and zero on the rest (every diagonal also gets a
    /// relative `1e-12` for stability); `None` if singular.
    pub fn solve(&self, ridge: f64, penalised: usize) -> Option<Vec<f64>> {
        let n = self.n;
        let penalised = penalised.min(n);
        let scale =
            (0..penalised).map(|i| self.a[i * n + i]).sum::<f64>() / penalised.max(1) as f64;
        let mut a = self.a.clone();
        for i in 0..n {
            let ridge = if i < penalised {
                ridge * scale.max(f64::MIN_POSITIVE)
            } else {
                0.0
            };
            a[i * n + i] += ridge + 1e-12 * self.a[i * n + i];
        }
        solve_spd(&a, &self.b)
    }

    /// The least-squares loss `constant - 2 x.b + x.A x` of `x` (after
    /// [`NormalEquations::finish`]), `constant` being the sum of the weighted squared
    /// observations.
    pub fn loss(&self, constant: f64, x: &[f64]) -> f64 {
        let n = self.n;
        let quadratic: f64 = (0..n)
            .map(|i| x[i] * dot(&self.a[i * n..(i + 1) * n], x))
            .sum();
        constant - 2.0 * dot(&self.b, x) + quadratic
    }
}

/// `J'J` (row-major) and `J'r` from the columns of `J`.
pub fn gauss_newton_system(columns: &[Vec<f64>], residuals: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = columns.len();
    let mut normal = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let value = dot(&columns[i], &columns[j]);
            normal[i * n + j] = value;
            normal[j * n + i] = value;
        }
    }
    let gradient = columns.iter().map(|c| dot(c, residuals)).collect();
    (normal, gradient)
}
