//! Explicit Runge–Kutta schemes as Butcher tableaux, and the one training integrates with:
//! the classical fourth-order scheme [`RK4`] of the paper (Lovelett et al. 2020, eq. 4-7).
//!
//! Every coefficient is an integer over a denominator, and every site that steps with a
//! tableau (the graph engine, the fused engine's forward and reverse passes, the ONNX
//! export, the engines' test reference) computes with it in one order:
//!
//! - stage `i` is evaluated at `x + (dt / d_i) (n_i0 k_0 + n_i1 k_1 + ...)`, its row of the
//!   a-matrix being `n_ij / d_i` ([`Tableau::stages`]);
//! - the step is `x + (dt / d_b) (n_0 k_0 + n_1 k_1 + ...)` with the weights `n_i / d_b`
//!   ([`Tableau::weights`]);
//!
//! each sum taken left to right over the stages that enter. For RK4 that is
//! `x + (dt/2) k1`, `x + (dt/2) k2`, `x + dt k3` and `x + (dt/6) (k1 + 2 k2 + 2 k3 + k4)`,
//! to the last bit (weights stored as `[1/6, 1/3, 1/3, 1/6]` would round differently).
//!
//! A step of `K` sub-steps needs the delay embeddings at its distinct stage times
//! ([`Tableau::stage_fractions`]: RK4's second and third stages share `t + dt/2`, so its
//! stage times are `m h / 2K`), and a balance stays stable while `h lambda / K` stays right
//! of [`Tableau::stability_limit`], found from the tableau's stability polynomial.

/// A linear combination of a step's stage slopes with integer coefficients over one
/// denominator: `sum_j (numerators[j] / denominator) k_j`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Combination<const S: usize> {
    /// The coefficient of each stage's slope, times the denominator (0: it does not enter).
    pub numerators: [i32; S],
    /// The common denominator (positive).
    pub denominator: u32,
}

impl<const S: usize> Combination<S> {
    /// The stages that enter, in order, each with its numerator (exact as `f64`).
    pub fn terms(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        (self.numerators.iter().enumerate())
            .filter(|(_, &numerator)| numerator != 0)
            .map(|(stage, &numerator)| (stage, f64::from(numerator)))
    }

    /// Whether no stage enters (the first stage's row).
    pub fn is_empty(&self) -> bool {
        self.numerators.iter().all(|&numerator| numerator == 0)
    }

    /// The denominator as `f64`.
    pub fn divisor(&self) -> f64 {
        f64::from(self.denominator)
    }

    /// The coefficient of stage `stage`'s slope, `numerators[stage] / denominator`.
    pub const fn coefficient(&self, stage: usize) -> f64 {
        self.numerators[stage] as f64 / self.denominator as f64
    }
}

/// An explicit Runge–Kutta scheme of `S` stages: stage times `c`, the strictly lower
/// triangular a-matrix and the weights `b`, all as integers over denominators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tableau<const S: usize> {
    /// The stage times `c_i` as numerators over [`Tableau::time_denominator`] (the first
    /// is 0, none beyond the denominator).
    pub times: [u32; S],
    /// The denominator of the stage times.
    pub time_denominator: u32,
    /// Row `i` of the a-matrix: how stage `i`'s state is reached from the step's start
    /// (only stages before `i` enter; row 0 is empty).
    pub stages: [Combination<S>; S],
    /// The weights `b` of the step.
    pub weights: Combination<S>,
}

/// The classical fourth-order Runge–Kutta scheme.
pub const RK4: Tableau<4> = Tableau {
    times: [0, 1, 1, 2],
    time_denominator: 2,
    stages: [
        Combination {
            numerators: [0, 0, 0, 0],
            denominator: 1,
        },
        Combination {
            numerators: [1, 0, 0, 0],
            denominator: 2,
        },
        Combination {
            numerators: [0, 1, 0, 0],
            denominator: 2,
        },
        Combination {
            numerators: [0, 0, 1, 0],
            denominator: 1,
        },
    ],
    weights: Combination {
        numerators: [1, 2, 2, 1],
        denominator: 6,
    },
};

/// How far left of 0 [`Tableau::stability_limit`] looks for the end of the stable interval.
const FARTHEST_LIMIT: f64 = 1024.0;

impl<const S: usize> Tableau<S> {
    /// Whether a time (as a numerator) is one at which a sub-step needs its embedding: a
    /// stage time, or either end of the sub-step.
    fn is_stage_time(&self, numerator: u32) -> bool {
        numerator == 0 || numerator == self.time_denominator || self.times.contains(&numerator)
    }

    /// How many distinct stage times of a sub-step lie before `numerator`.
    fn times_before(&self, numerator: u32) -> usize {
        (0..numerator).filter(|&n| self.is_stage_time(n)).count()
    }

    /// The distinct stage times of a step of `substeps` sub-steps (both ends included),
    /// as fractions of the step, in order: `m / 2K` for `m = 0..=2K` for [`RK4`].
    pub fn stage_fractions(&self, substeps: usize) -> Vec<f64> {
        let substeps = substeps.max(1);
        let denominator = self.time_denominator as usize;
        let whole = substeps * denominator;
        let within = (0..denominator).filter(|&n| self.is_stage_time(n as u32));
        let numerators: Vec<usize> = (0..substeps)
            .flat_map(|substep| within.clone().map(move |n| substep * denominator + n))
            .chain([whole])
            .collect();
        (numerators.into_iter())
            .map(|m| m as f64 / whole as f64)
            .collect()
    }

    /// How many distinct stage times a step of `substeps` sub-steps has:
    /// [`Tableau::stage_fractions`]'s length (`2K + 1` for [`RK4`]).
    pub fn stage_times(&self, substeps: usize) -> usize {
        substeps.max(1) * self.times_before(self.time_denominator) + 1
    }

    /// The index into [`Tableau::stage_fractions`] of stage `stage` of sub-step `substep`.
    pub fn stage_offset(&self, substep: usize, stage: usize) -> usize {
        substep * self.times_before(self.time_denominator) + self.times_before(self.times[stage])
    }

    /// One step of `y' = f(t, y)` from `(t, y)` by `h`: the reference stepper tests take
    /// their fine integrations with (the engines loop over the tableau themselves).
    #[cfg(test)]
    pub fn step(
        &self,
        f: &mut dyn FnMut(f64, &[f64]) -> Vec<f64>,
        t: f64,
        y: &[f64],
        h: f64,
    ) -> Vec<f64> {
        let combine = |slopes: &[Vec<f64>], row: &Combination<S>| -> Vec<f64> {
            let mut state = y.to_vec();
            for (stage, numerator) in row.terms() {
                for (value, slope) in state.iter_mut().zip(&slopes[stage]) {
                    *value += h * numerator / row.divisor() * slope;
                }
            }
            state
        };
        let mut slopes: Vec<Vec<f64>> = Vec::with_capacity(S);
        for stage in 0..S {
            let time = t + h * f64::from(self.times[stage]) / f64::from(self.time_denominator);
            let state = combine(&slopes, &self.stages[stage]);
            slopes.push(f(time, &state));
        }
        combine(&slopes, &self.weights)
    }

    /// The stability function `R(z) = 1 + z b^T (I - z A)^-1 1`: one step of
    /// `y' = lambda y` from `y = 1` with `h lambda = z`, by forward substitution (the
    /// a-matrix is strictly lower triangular).
    pub const fn amplification(&self, z: f64) -> f64 {
        let mut stage_values = [0.0; S];
        let mut stage = 0;
        let mut step_sum = 0.0;
        while stage < S {
            let mut sum = 0.0;
            let mut earlier = 0;
            while earlier < stage {
                sum += self.stages[stage].coefficient(earlier) * stage_values[earlier];
                earlier += 1;
            }
            stage_values[stage] = 1.0 + z * sum;
            step_sum += self.weights.coefficient(stage) * stage_values[stage];
            stage += 1;
        }
        1.0 + z * step_sum
    }

    /// Whether `|R(-x)| <= 1`.
    const fn stable_at(&self, x: f64) -> bool {
        let r = self.amplification(-x);
        -1.0 <= r && r <= 1.0
    }

    /// The stability limit on the negative real axis: the largest `r` with `|R(x)| <= 1`
    /// on all of `[-r, 0]` (walked in steps of 1/64 from 0, then bisected to the last
    /// bit), 2.7853 for [`RK4`]. A scheme stable beyond 1024 reports 1024.
    pub const fn stability_limit(&self) -> f64 {
        let walk = 1.0 / 64.0;
        let mut stable = 0.0;
        while stable < FARTHEST_LIMIT && self.stable_at(stable + walk) {
            stable += walk;
        }
        if stable >= FARTHEST_LIMIT {
            return FARTHEST_LIMIT;
        }
        let mut unstable = stable + walk;
        loop {
            let middle = 0.5 * (stable + unstable);
            if middle <= stable || middle >= unstable {
                return stable;
            }
            if self.stable_at(middle) {
                stable = middle;
            } else {
                unstable = middle;
            }
        }
    }
}

#[cfg(test)]
mod tests;
