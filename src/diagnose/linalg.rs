//! Small dense linear algebra: symmetric positive-definite solves and (ridge) least squares
//! through the normal equations. Matrices are row-major `Vec<f64>` of `n x n`.

/// Solves `a x = b` for a symmetric positive-definite `a` (`n x n`, row-major) by Cholesky
/// factorisation; `None` when `a` is not numerically positive definite.
pub fn solve_spd(a: &[f64], b: &[f64]) -> Option<Vec<f64>> {
    let n = b.len();
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut sum = a[i * n + j];
            for k in 0..j {
                sum -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if sum.is_nan() || sum <= 0.0 || !sum.is_finite() {
                    return None;
                }
                l[i * n + i] = sum.sqrt();
            } else {
                l[i * n + j] = sum / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        let sum: f64 = (0..i).map(|k| l[i * n + k] * y[k]).sum();
        y[i] = (b[i] - sum) / l[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let sum: f64 = (i + 1..n).map(|k| l[k * n + i] * x[k]).sum();
        x[i] = (y[i] - sum) / l[i * n + i];
    }
    Some(x)
}

/// Accumulated normal equations `A = sum w f f^T`, `b = sum w y f` of a weighted least
/// squares problem with `n` unknowns.
#[derive(Debug, Clone, PartialEq)]
pub struct Normal {
    /// Number of unknowns.
    pub n: usize,
    /// `n x n`, row-major (upper and lower triangles both filled by [`Normal::finish`]).
    pub a: Vec<f64>,
    /// Right-hand side.
    pub b: Vec<f64>,
}

impl Normal {
    /// Empty equations in `n` unknowns.
    pub fn new(n: usize) -> Self {
        Normal {
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
    pub fn merge(&mut self, other: &Normal) {
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

    /// The least-squares loss `constant - 2 x.b + x.A x` of `x` (after [`Normal::finish`]),
    /// `constant` being the sum of the weighted squared observations.
    pub fn loss(&self, constant: f64, x: &[f64]) -> f64 {
        let n = self.n;
        let mut quadratic = 0.0;
        for i in 0..n {
            let row: f64 = (0..n).map(|j| self.a[i * n + j] * x[j]).sum();
            quadratic += x[i] * row;
        }
        let linear: f64 = self.b.iter().zip(x).map(|(b, v)| b * v).sum();
        constant - 2.0 * linear + quadratic
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_known_system() {
        // A = [[4, 2], [2, 3]], x = [1, -2] => b = [0, -4].
        let x = solve_spd(&[4.0, 2.0, 2.0, 3.0], &[0.0, -4.0]).unwrap();
        assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] + 2.0).abs() < 1e-12);
        assert!(solve_spd(&[1.0, 2.0, 2.0, 1.0], &[1.0, 1.0]).is_none());
    }

    #[test]
    fn least_squares_recovers_a_line() {
        let mut normal = Normal::new(2);
        for k in 0..20 {
            let x = k as f64 / 4.0;
            normal.add(&[1.0, x], 3.0 - 0.5 * x, 1.0);
        }
        normal.finish();
        let fit = normal.solve(0.0, 2).unwrap();
        assert!((fit[0] - 3.0).abs() < 1e-9 && (fit[1] + 0.5).abs() < 1e-9);
        // The data lie on the line: the loss at the fit is zero, elsewhere it is the sum of
        // squared misfits (intercept off by 1 at each of 20 points: 20).
        let constant: f64 = (0..20).map(|k| (3.0 - 0.5 * k as f64 / 4.0).powi(2)).sum();
        assert!(normal.loss(constant, &fit).abs() < 1e-8);
        assert!((normal.loss(constant, &[4.0, -0.5]) - 20.0).abs() < 1e-8);
    }

    #[test]
    fn ridge_spares_the_unpenalised_unknowns() {
        // y = 2 + x exactly; a huge ridge on the slope alone leaves the intercept to fit the mean.
        let mut normal = Normal::new(2);
        for k in 0..10 {
            let x = k as f64 - 4.5;
            normal.add(&[x, 1.0], 2.0 + x, 1.0);
        }
        normal.finish();
        let fit = normal.solve(1e12, 1).unwrap();
        assert!(fit[0].abs() < 1e-9 && (fit[1] - 2.0).abs() < 1e-9);
    }
}
