//! The block-arrow normal equations of the balance fit and their solution by eliminating
//! every window's outputs (Schur complement), each block by the shared
//! [`crate::numeric::Cholesky`]: a [`lm::Linearisation`] for the shared Levenberg-Marquardt
//! driver.

use crate::numeric::{lm, solve_spd, Cholesky, Damping};

/// Levenberg-Marquardt damping of each block, with a floor that keeps it invertible where
/// an output does not move any balance (a growth rate while the biomass is zero, or the
/// outputs of a window beyond what its equations fix).
const BLOCK_DAMPING: Damping = Damping {
    min_diagonal: 0.0,
    jitter: 0.0,
    relative_jitter: 1e-9,
};

/// One window's Jacobian blocks, row-major with one row per measured state.
pub(super) struct WindowJacobian {
    /// `K x (intervals * m)`.
    pub(super) outputs: Vec<f64>,
    /// `K x P`.
    pub(super) params: Vec<f64>,
}

/// One window's share of the normal equations.
struct WindowSystem {
    /// Its unknown outputs.
    width: usize,
    /// `width x width`: `J_n' J_n`.
    block: Vec<f64>,
    /// `width x P`: `J_n' J_theta`.
    coupling: Vec<f64>,
    /// `width`: `J_n' r`.
    gradient: Vec<f64>,
}

/// The params' system after eliminating every window's outputs: the Schur complement
/// (`P x P`), its right-hand side, and per window `A^-1 B` and `A^-1 g` for the back
/// substitution.
type Reduced = (Vec<f64>, Vec<f64>, Vec<(Vec<f64>, Vec<f64>)>);

/// The block-arrow normal equations `J'J d = -J'r` of one Levenberg-Marquardt step.
pub(super) struct Normal {
    p: usize,
    /// `P x P`: `sum_w J_theta,w' J_theta,w`.
    params: Vec<f64>,
    /// `P`: `J_theta' r`.
    params_gradient: Vec<f64>,
    windows: Vec<WindowSystem>,
}

impl Normal {
    /// The equations of the window blocks `jacobians` and the residuals `r` (`k` per
    /// window) in `p` params.
    pub(super) fn build(jacobians: &[WindowJacobian], r: &[f64], k: usize, p: usize) -> Self {
        let mut params = vec![0.0; p * p];
        let mut params_gradient = vec![0.0; p];
        let mut windows = Vec::with_capacity(jacobians.len());
        for (w, jacobian) in jacobians.iter().enumerate() {
            let width = jacobian.outputs.len() / k.max(1);
            let jn = |state: usize, a: usize| jacobian.outputs[state * width + a];
            let jp = |state: usize, q: usize| jacobian.params[state * p + q];
            let mut block = vec![0.0; width * width];
            let mut coupling = vec![0.0; width * p];
            let mut gradient = vec![0.0; width];
            for state in 0..k {
                let residual = r[w * k + state];
                for a in 0..width {
                    let ja = jn(state, a);
                    if ja == 0.0 {
                        continue;
                    }
                    gradient[a] += ja * residual;
                    for b in 0..width {
                        block[a * width + b] += ja * jn(state, b);
                    }
                    for q in 0..p {
                        coupling[a * p + q] += ja * jp(state, q);
                    }
                }
                for q in 0..p {
                    params_gradient[q] += jp(state, q) * residual;
                    for s in 0..p {
                        params[q * p + s] += jp(state, q) * jp(state, s);
                    }
                }
            }
            windows.push(WindowSystem {
                width,
                block,
                coupling,
                gradient,
            });
        }
        Normal {
            p,
            params,
            params_gradient,
            windows,
        }
    }

    /// `A^-1 [coupling | gradient]` of one window.
    fn eliminate(window: &WindowSystem, p: usize, lambda: f64) -> Option<(Vec<f64>, Vec<f64>)> {
        let n = window.width;
        let block = Cholesky::factor(&BLOCK_DAMPING.apply(&window.block, n, lambda), n)?;
        let mut inverse_coupling = vec![0.0; n * p];
        for q in 0..p {
            let column: Vec<f64> = (0..n).map(|a| window.coupling[a * p + q]).collect();
            for (a, value) in block.solve(&column).into_iter().enumerate() {
                inverse_coupling[a * p + q] = value;
            }
        }
        Some((inverse_coupling, block.solve(&window.gradient)))
    }

    /// The Schur complement `sum_w (C_w - B_w' A_w^-1 B_w)` (damped by `lambda`) and, with
    /// it, each window's eliminated blocks.
    fn schur(&self, lambda: f64) -> Option<Reduced> {
        let p = self.p;
        let mut schur = BLOCK_DAMPING.apply(&self.params, p, lambda);
        let mut rhs: Vec<f64> = self.params_gradient.iter().map(|g| -g).collect();
        let mut eliminated = Vec::with_capacity(self.windows.len());
        for window in &self.windows {
            let (inverse_coupling, inverse_gradient) = Self::eliminate(window, p, lambda)?;
            for q in 0..p {
                for s in 0..p {
                    schur[q * p + s] -= (0..window.width)
                        .map(|a| window.coupling[a * p + q] * inverse_coupling[a * p + s])
                        .sum::<f64>();
                }
                rhs[q] += (0..window.width)
                    .map(|a| window.coupling[a * p + q] * inverse_gradient[a])
                    .sum::<f64>();
            }
            eliminated.push((inverse_coupling, inverse_gradient));
        }
        Some((schur, rhs, eliminated))
    }

    /// The step `(d_theta, d_outputs per window)` of `(J'J + lambda diag) d = -J'r`;
    /// `None` when a system is not positive definite.
    pub(super) fn eliminated_step(&self, lambda: f64) -> Option<(Vec<f64>, Vec<Vec<f64>>)> {
        let p = self.p;
        let (schur, rhs, eliminated) = self.schur(lambda)?;
        let d_theta = if p == 0 {
            Vec::new()
        } else {
            solve_spd(&schur, &rhs)?
        };
        let d_windows = (self.windows.iter().zip(&eliminated))
            .map(|(window, (inverse_coupling, inverse_gradient))| {
                (0..window.width)
                    .map(|a| {
                        let coupled: f64 = (0..p)
                            .map(|q| inverse_coupling[a * p + q] * d_theta[q])
                            .sum();
                        -inverse_gradient[a] - coupled
                    })
                    .collect()
            })
            .collect();
        Some((d_theta, d_windows))
    }

    /// `(Schur complement)^-1` without damping: the raw params' covariance up to `s^2`,
    /// with an infinite variance for a param the balances do not determine (its column of
    /// the Jacobian is zero, or the closure outputs and other params absorb it: its Schur
    /// diagonal is nothing next to its own curvature).
    pub(super) fn param_covariance(&self) -> Option<Vec<f64>> {
        let p = self.p;
        let (schur, _, _) = self.schur(0.0)?;
        let floor = BLOCK_DAMPING.apply(&self.params, p, 0.0);
        let factor = Cholesky::factor(&schur, p)?;
        let mut inverse = vec![0.0; p * p];
        for column in 0..p {
            for (row, value) in factor.inverse_column(column).into_iter().enumerate() {
                inverse[row * p + column] = value;
            }
        }
        for q in 0..p {
            let curvature = self.params[q * p + q];
            let left = schur[q * p + q] - (floor[q * p + q] - curvature);
            if !(curvature > 0.0 && left > 1e-8 * curvature) {
                inverse[q * p + q] = f64::INFINITY;
            }
        }
        Some(inverse)
    }
}

impl lm::Linearisation for Normal {
    /// The eliminated step, flattened as the unknowns are: `d_theta`, then the outputs
    /// window by window (the windows cover the intervals in order).
    fn step(&self, damping: f64) -> Option<Vec<f64>> {
        let (d_theta, d_windows) = self.eliminated_step(damping)?;
        Some(
            d_theta
                .into_iter()
                .chain(d_windows.into_iter().flatten())
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal as Gaussian};

    use super::*;

    #[test]
    fn the_eliminated_step_solves_the_full_normal_equations() {
        // Three windows of K = 3 equations, two outputs each, two params: solve the whole
        // damped system densely and compare.
        let (k, p, widths) = (3, 2, [2, 2, 2]);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let unit = Gaussian::new(0.0, 1.0).unwrap();
        let mut draw = |n: usize| -> Vec<f64> { (0..n).map(|_| unit.sample(&mut rng)).collect() };
        let jacobians: Vec<WindowJacobian> = (widths.iter())
            .map(|&w| WindowJacobian {
                outputs: draw(k * w),
                params: draw(k * p),
            })
            .collect();
        let residuals = draw(widths.len() * k);
        let lambda = 0.1;
        let (d_theta, d_windows) = Normal::build(&jacobians, &residuals, k, p)
            .eliminated_step(lambda)
            .unwrap();
        // Dense J: rows = windows x K, columns = params then every window's outputs.
        let columns = p + widths.iter().sum::<usize>();
        let rows = widths.len() * k;
        let mut dense = vec![0.0; rows * columns];
        let mut offset = p;
        for (w, jacobian) in jacobians.iter().enumerate() {
            for state in 0..k {
                let row = w * k + state;
                for q in 0..p {
                    dense[row * columns + q] = jacobian.params[state * p + q];
                }
                for a in 0..widths[w] {
                    dense[row * columns + offset + a] = jacobian.outputs[state * widths[w] + a];
                }
            }
            offset += widths[w];
        }
        let mut normal = vec![0.0; columns * columns];
        let mut gradient = vec![0.0; columns];
        for row in 0..rows {
            for a in 0..columns {
                gradient[a] -= dense[row * columns + a] * residuals[row];
                for b in 0..columns {
                    normal[a * columns + b] += dense[row * columns + a] * dense[row * columns + b];
                }
            }
        }
        // The same damping as `BLOCK_DAMPING`, block by block.
        let mut blocks = vec![(0, p)];
        let mut start = p;
        for &w in &widths {
            blocks.push((start, w));
            start += w;
        }
        let mut damped = normal.clone();
        for &(start, n) in &blocks {
            let trace = (start..start + n)
                .map(|i| normal[i * columns + i])
                .sum::<f64>()
                / n as f64;
            for i in start..start + n {
                damped[i * columns + i] += lambda * normal[i * columns + i] + 1e-9 * trace;
            }
        }
        let expected = solve_spd(&damped, &gradient).unwrap();
        let found: Vec<f64> = d_theta
            .into_iter()
            .chain(d_windows.into_iter().flatten())
            .collect();
        for (a, b) in found.iter().zip(&expected) {
            assert!(
                (a - b).abs() < 1e-9 * b.abs().max(1.0),
                "{found:?} vs {expected:?}"
            );
        }
    }
}
