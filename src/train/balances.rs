//! Params from the balances alone, before any network is trained (beyond the paper).
//!
//! A grey-box model with more measured balances than closure outputs over-determines its
//! rates: in the bioreactor the balances of X, A and B each fix one rate (mu, mu_A, mu_B)
//! from the data, and the substrate balance, with those rates, leaves the yields as the
//! only unknowns. The network is not needed to find them, and a network's small bias in a
//! rate is exactly what moves a weakly identified constant far (`docs/training.md`).
//!
//! Over each interval `[t_i, t_i+1]` of the training rows the balances are evaluated at
//! the interval's midpoint state `xbar_i` (the midpoint rule, second order) with the held
//! input `u_i`, the raw params `theta` shared by all intervals, and the raw network outputs
//! `n_i` of the interval, *free*: one unknown per closure output and interval, entering
//! through the model's own priors and constraints (the backend's physics program). Windows
//! of [`WINDOW`] consecutive intervals then ask, for every measured state `k`,
//!
//! ```text
//! (x_k(end) - x_k(start)) / h = sum over the window's intervals of f_k(xbar_i, u_i, theta, n_i)
//! ```
//!
//! (summing over a window averages measurement noise in the difference quotients; on
//! noise-free data every window fits exactly whatever its length). The residuals, scaled by
//! the spread of each state's window quotient, are minimised by Levenberg-Marquardt over
//! `theta` and every `n_i` at once (the shared driver, [`crate::numeric::lm`]); the normal
//! equations are block-arrow shaped (the outputs of different windows do not interact), so
//! each step eliminates the outputs window by window and solves a `P x P` system for
//! `theta` (Schur complement, every block by the shared Cholesky: [`elimination`]). Jacobians by central
//! differences.
//!
//! Standard errors come from the same linearisation, `s^2 (Schur)^-1`, with `s^2` the
//! residual sum of squares over the equations the outputs cannot absorb, mapped through each
//! param's transform. With noise-free data the residuals are discretisation error and the
//! errors are tiny; with noise they grow, and a constant the data barely see (the
//! bioreactor's Y_X at 1 % noise) is flagged poorly identified. The noisy difference
//! quotients are regressors too (errors in variables), so at high noise the estimate is
//! biased as well as uncertain: the error says how sharply the balances pin a param, not a
//! confidence interval.

use std::convert::Infallible;

use crate::engine::graph::{initial_raw_params, BackendError};
use crate::engine::program::{Program, ProgramInputs};
use crate::ir::{self, Dynamics};
use crate::numeric::lm::{self, central_difference, difference_step};
use crate::numeric::{mean_std, Settings};

use crate::record::Track;

use super::polish::ParamEstimate;
use crate::engine::pairs::PairAt;

mod elimination;

use elimination::{Normal, WindowJacobian};

/// Most Levenberg-Marquardt trial steps.
const MAX_ITERATIONS: usize = 200;
/// The damping schedule: from `1e-3`, divided by 3 on success, multiplied by 5 on failure
/// (10 on a singular system); it stops when a step gains at most `1e-12` of the cost, the
/// cost is zero, or the damping passes `1e12`.
const SETTINGS: Settings = Settings {
    reject_factor: 5.0,
    max_trials: MAX_ITERATIONS,
    max_linearisations: MAX_ITERATIONS,
    tolerance: 1e-12,
    ..Settings::DEFAULT
};
/// Intervals per window: each window's equation sums the balances of this many
/// consecutive intervals against the state change over all of them, which averages
/// measurement noise in the difference quotients (noise-free data fit exactly either way).
pub const WINDOW: usize = 5;

/// The params the balances give.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BalanceFit {
    /// Intervals used.
    pub intervals: usize,
    /// Accepted Levenberg-Marquardt steps.
    pub steps: usize,
    /// Root mean square of the scaled residuals at the end.
    #[serde(with = "crate::json")]
    pub rms_residual: f64,
    /// Each param's value and standard error.
    pub estimates: Vec<ParamEstimate>,
    /// Raw (unconstrained) values, in declaration order.
    #[serde(skip)]
    pub raw: Vec<f64>,
}

/// Whether the balances determine the params without a network: a `der` model with
/// params, no hidden states, and more measured balances than closure outputs.
pub fn applicable(model: &ir::Model) -> bool {
    let outputs: usize = model.closures.iter().map(|c| c.outputs.len()).sum();
    model.dynamics == Dynamics::Continuous
        && model.hidden.is_empty()
        && !model.params.is_empty()
        && outputs < model.states.len()
}

/// Estimates the params from the intervals that start at `pairs` (track and knot) and whose
/// ends are known from data; `None` when [`applicable`] says no or the fit does not converge
/// to finite values.
pub fn estimate(
    model: &ir::Model,
    scales: &[Vec<f64>],
    tracks: &[Track],
    pairs: &[PairAt],
) -> Result<Option<BalanceFit>, BackendError> {
    if !applicable(model) {
        return Ok(None);
    }
    let measured = model.states.len();
    let intervals: Vec<PairAt> = (pairs.iter().copied())
        .filter(|&(index, knot)| {
            let track = &tracks[index];
            knot + 1 < track.len()
                && (0..measured).all(|i| track.known[i][knot] && track.known[i][knot + 1])
        })
        .collect();
    let program = Program::compile(model, scales)?;
    let problem = Problem::new(model, program, tracks, &intervals);
    Ok(problem.and_then(|p| p.fit(model)))
}

/// Where each free raw output of a row starts, in the program's order: 0 (the prior, or 0
/// without one), except a `positive` output without a prior, `s |n|`, which starts at
/// `n = 1` (its magnitude): at its kink `n = 0` the central differences of the Jacobian
/// are 0 and the fit would never move it.
fn free_output_start(model: &ir::Model) -> Vec<f64> {
    (model.closures.iter())
        .flat_map(|closure| closure.outputs.iter())
        .map(|output| {
            let kinked =
                output.prior.is_none() && matches!(output.constraint, ir::Constraint::Positive);
            if kinked {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// The data of the fit.
struct Problem {
    program: Program,
    /// Intervals.
    rows: usize,
    /// Measured states `K`.
    measured: usize,
    /// Per closure, its width; `m` is their sum.
    widths: Vec<usize>,
    /// `rows x K` midpoint states.
    states: Vec<f64>,
    /// `rows x inputs` held inputs.
    inputs: Vec<f64>,
    /// Per interval, its step over the typical step: its balances' share of a window's
    /// change.
    spans: Vec<f64>,
    /// Windows of consecutive intervals, `[first, last)` interval indices.
    windows: Vec<(usize, usize)>,
    /// `windows x K` difference quotients `(x(end) - x(start)) / h` of each window.
    targets: Vec<f64>,
    /// Per measured state, 1 / spread of its window quotient.
    weights: Vec<f64>,
}

/// The unknowns: raw params and per-interval raw network outputs (`rows x m`).
#[derive(Clone)]
struct Point {
    theta: Vec<f64>,
    outputs: Vec<f64>,
}

impl Problem {
    fn new(
        model: &ir::Model,
        program: Program,
        tracks: &[Track],
        intervals: &[PairAt],
    ) -> Option<Self> {
        let measured = model.states.len();
        let widths = program.shape().nets.clone();
        measured.checked_sub(widths.iter().sum())?;
        let steps: Vec<f64> = (intervals.iter())
            .map(|&(index, knot)| tracks[index].steps[knot])
            .collect();
        let typical = crate::numeric::median(&steps)?;
        let (mut states, mut inputs, mut spans) = (Vec::new(), Vec::new(), Vec::new());
        let mut windows: Vec<(usize, usize)> = Vec::new();
        for (index, &(track_index, knot)) in intervals.iter().enumerate() {
            let track = &tracks[track_index];
            for values in &track.states {
                states.push(0.5 * (values[knot] + values[knot + 1]));
            }
            inputs.extend(track.inputs.iter().map(|u| u[knot]));
            spans.push(track.steps[knot] / typical);
            let follows = index > 0 && intervals[index - 1] == (track_index, knot.wrapping_sub(1));
            match windows.last_mut() {
                Some((first, last)) if *last == index && index - *first < WINDOW && follows => {
                    *last = index + 1
                }
                _ => windows.push((index, index + 1)),
            }
        }
        if windows.len() * (measured - widths.iter().sum::<usize>()) <= model.params.len() {
            return None;
        }
        let mut targets = Vec::with_capacity(windows.len() * measured);
        for &(first, last) in &windows {
            let (track_index, start) = intervals[first];
            let end = intervals[last - 1].1 + 1;
            let track = &tracks[track_index];
            targets.extend((track.states.iter()).map(|v| (v[end] - v[start]) / typical));
        }
        let weights = (0..measured)
            .map(|k| {
                let column: Vec<f64> = (0..windows.len())
                    .map(|w| targets[w * measured + k])
                    .collect();
                1.0 / mean_std(&column).1
            })
            .collect();
        Some(Problem {
            program,
            rows: intervals.len(),
            measured,
            widths,
            states,
            inputs,
            spans,
            windows,
            targets,
            weights,
        })
    }

    fn outputs_per_row(&self) -> usize {
        self.widths.iter().sum()
    }

    /// The measured balances `f` of every interval, `rows x K`.
    fn balances(&self, point: &Point) -> Vec<f64> {
        let m = self.outputs_per_row();
        let nets: Vec<Vec<f64>> = (0..self.widths.len())
            .map(|c| {
                let offset: usize = self.widths[..c].iter().sum();
                (0..self.rows)
                    .flat_map(|r| (0..self.widths[c]).map(move |j| (r, j)))
                    .map(|(r, j)| point.outputs[r * m + offset + j])
                    .collect()
            })
            .collect();
        let slices: Vec<&[f64]> = nets.iter().map(Vec::as_slice).collect();
        let values = self.program.forward(&ProgramInputs {
            rows: self.rows,
            states: &self.states,
            inputs: &self.inputs,
            params: &point.theta,
            nets: &slices,
        });
        let all = self
            .program
            .read(&values, self.rows, &self.program.balances);
        let width = self.program.balances.len();
        (0..self.rows)
            .flat_map(|r| (0..self.measured).map(move |k| (r, k)))
            .map(|(r, k)| all[r * width + k])
            .collect()
    }

    /// Scaled residuals, `windows x K`: each window's quotient minus the sum of its
    /// intervals' balances.
    fn residuals(&self, point: &Point) -> Vec<f64> {
        let balances = self.balances(point);
        let k = self.measured;
        let mut residuals = Vec::with_capacity(self.windows.len() * k);
        for (w, &(first, last)) in self.windows.iter().enumerate() {
            for state in 0..k {
                let sum: f64 = (first..last)
                    .map(|l| self.spans[l] * balances[l * k + state])
                    .sum();
                residuals.push((self.targets[w * k + state] - sum) * self.weights[state]);
            }
        }
        residuals
    }

    /// Central-difference derivatives of the interval balances (`rows x K` each): per raw
    /// param, and per output slot `j` (slot `j` of every interval moved at once: an
    /// interval's balances read only its own outputs).
    fn jacobian(&self, point: &Point) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let difference = |shift: &dyn Fn(&mut Point, f64), delta: f64| {
            let shifted = |by: f64| {
                let mut moved = point.clone();
                shift(&mut moved, by);
                Ok::<_, Infallible>(self.balances(&moved))
            };
            let Ok(column) = central_difference(shifted, delta);
            column
        };
        let params = (0..point.theta.len())
            .map(|p| {
                let delta = difference_step(point.theta[p], 1e-6);
                difference(&|moved, by| moved.theta[p] += by, delta)
            })
            .collect();
        let m = self.outputs_per_row();
        let slots = (0..m)
            .map(|j| {
                let shift = |moved: &mut Point, by: f64| {
                    for r in 0..self.rows {
                        moved.outputs[r * m + j] += by;
                    }
                };
                difference(&shift, 1e-6)
            })
            .collect();
        (params, slots)
    }

    /// The unknowns of a point, raw params first.
    fn point(&self, x: &[f64], params: usize) -> Point {
        Point {
            theta: x[..params].to_vec(),
            outputs: x[params..].to_vec(),
        }
    }

    /// The window blocks of the residuals' Jacobian: per window, `K x (intervals * m)` for
    /// its outputs and `K x P` for the params (row-major).
    fn window_jacobians(&self, point: &Point) -> Vec<WindowJacobian> {
        let (dp, dn) = self.jacobian(point);
        let (k, m) = (self.measured, self.outputs_per_row());
        (self.windows.iter())
            .map(|&(first, last)| {
                let width = (last - first) * m;
                let mut outputs = vec![0.0; k * width];
                let mut params = vec![0.0; k * dp.len()];
                for state in 0..k {
                    let weight = -self.weights[state];
                    for l in first..last {
                        let share = weight * self.spans[l];
                        for j in 0..m {
                            outputs[state * width + (l - first) * m + j] =
                                share * dn[j][l * k + state];
                        }
                        for (q, column) in dp.iter().enumerate() {
                            params[state * dp.len() + q] += share * column[l * k + state];
                        }
                    }
                }
                WindowJacobian { outputs, params }
            })
            .collect()
    }

    fn fit(&self, model: &ir::Model) -> Option<BalanceFit> {
        let (p, m, k) = (model.params.len(), self.outputs_per_row(), self.measured);
        let mut start = initial_raw_params(model);
        let row_start = free_output_start(model);
        for _ in 0..self.rows {
            start.extend_from_slice(&row_start);
        }
        let mut unknowns = Unknowns {
            problem: self,
            params: p,
        };
        let Ok(outcome) = lm::minimise(&mut unknowns, start, &SETTINGS);
        let (point, residuals, cost) = (self.point(&outcome.x, p), outcome.residuals, outcome.cost);
        let system = Normal::build(&self.window_jacobians(&point), &residuals, k, p);
        // Residual degrees of freedom: the windows' equations less what the outputs can
        // absorb (at most K - 1 of a window's K equations) and the params.
        let absorbed: usize = (self.windows.iter())
            .map(|(first, last)| ((last - first) * m).min(k - 1))
            .sum();
        let freedom = (self.windows.len() * k).saturating_sub(absorbed + p).max(1) as f64;
        let variance = cost / freedom;
        let covariance = system.param_covariance();
        let values = self.param_values(&point.theta);
        let estimates = (0..p)
            .map(|i| {
                let slope = self.transform_slope(&point.theta, i);
                let raw_variance = covariance.as_ref().map_or(f64::INFINITY, |c| c[i * p + i]);
                let std_error = (variance * raw_variance).sqrt() * slope.abs();
                ParamEstimate::fitted(model.params[i].name.clone(), values[i], std_error)
            })
            .collect::<Vec<_>>();
        if !estimates.iter().all(|e| e.value.is_finite()) {
            return None;
        }
        Some(BalanceFit {
            intervals: self.rows,
            steps: outcome.steps,
            rms_residual: (cost / residuals.len().max(1) as f64).sqrt(),
            estimates,
            raw: point.theta,
        })
    }

    /// Constrained param values for raw `theta` (through the program's transforms).
    fn param_values(&self, theta: &[f64]) -> Vec<f64> {
        let nets: Vec<Vec<f64>> = self.widths.iter().map(|&w| vec![0.0; w]).collect();
        let slices: Vec<&[f64]> = nets.iter().map(Vec::as_slice).collect();
        let values = self.program.forward(&ProgramInputs {
            rows: 1,
            states: &self.states[..self.measured],
            inputs: &self.inputs[..self.inputs.len() / self.rows],
            params: theta,
            nets: &slices,
        });
        self.program.read(&values, 1, &self.program.param_values)
    }

    /// `d value_i / d raw_i` by central differences.
    fn transform_slope(&self, theta: &[f64], i: usize) -> f64 {
        let delta = 1e-6 * theta[i].abs().max(1.0);
        let (mut up, mut down) = (theta.to_vec(), theta.to_vec());
        up[i] += delta;
        down[i] -= delta;
        (self.param_values(&up)[i] - self.param_values(&down)[i]) / (2.0 * delta)
    }
}

/// The balance fit as a least-squares problem in the raw params followed by every
/// interval's outputs.
struct Unknowns<'a> {
    problem: &'a Problem,
    params: usize,
}

impl lm::Problem for Unknowns<'_> {
    type Error = Infallible;
    type Linear = Normal;

    fn residuals(&mut self, x: &[f64]) -> Result<Option<Vec<f64>>, Infallible> {
        let point = self.problem.point(x, self.params);
        Ok(Some(self.problem.residuals(&point)))
    }

    fn linearise(&mut self, x: &[f64], residuals: &[f64]) -> Result<Normal, Infallible> {
        let jacobians = self
            .problem
            .window_jacobians(&self.problem.point(x, self.params));
        let k = self.problem.measured;
        Ok(Normal::build(&jacobians, residuals, k, self.params))
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal as Gaussian};

    use super::*;
    use crate::train::fixtures::chemostat;

    /// A shipped bioreactor model and the shipped record (noise-free, from truth.gbm) on
    /// its grid.
    fn bioreactor(model: &str) -> (ir::Model, Track) {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let model = crate::driver::compile_file(&root.join(model), &[])
            .unwrap()
            .model;
        let data = crate::data::read(
            &root.join("models/bioreactor/data/steps.csv"),
            &["u", "X", "A", "B", "S"],
            crate::data::MinRows::new(2, "one step"),
        )
        .unwrap();
        let track = crate::train::fixtures::track(&model, &data);
        (model, track)
    }

    /// The intervals starting at `rows` of the one track.
    fn at(rows: std::ops::Range<usize>) -> Vec<PairAt> {
        rows.map(|r| (0, r)).collect()
    }

    fn unit_scales(model: &ir::Model) -> Vec<Vec<f64>> {
        (model.closures.iter())
            .map(|c| c.outputs.iter().map(|o| o.scale.unwrap_or(1.0)).collect())
            .collect()
    }

    const TRUTH: [f64; 3] = [0.435, 0.607, 0.3];

    #[test]
    fn the_bioreactor_yields_come_from_the_balances_alone() {
        // Truth (table 2): Y_X 0.435, Y_A 0.607, Y_B 0.3; both models start them at 0.5.
        for file in ["models/bioreactor/gb1.gbm", "models/bioreactor/gb2.gbm"] {
            let (model, track) = bioreactor(file);
            let fit = estimate(&model, &unit_scales(&model), &[track], &at(50..550))
                .unwrap()
                .expect("the balances determine the yields");
            assert_eq!(fit.intervals, 500);
            for (estimate, truth) in fit.estimates.iter().zip(TRUTH) {
                assert!(
                    (estimate.value / truth - 1.0).abs() < 1e-6,
                    "{file}: {estimate:?}"
                );
                assert!(estimate.identified, "{file}: {estimate:?}");
            }
        }
    }

    #[test]
    fn with_measurement_noise_the_yields_stay_close_and_their_errors_grow() {
        let (model, mut track) = bioreactor("models/bioreactor/gb1.gbm");
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let noise = Gaussian::new(0.0, 1e-3).unwrap();
        for column in &mut track.states {
            for value in column.iter_mut() {
                *value *= 1.0 + noise.sample(&mut rng);
            }
        }
        let fit = estimate(&model, &unit_scales(&model), &[track], &at(50..1050))
            .unwrap()
            .unwrap();
        let [y_x, y_a, y_b] = [0, 1, 2].map(|i| &fit.estimates[i]);
        // Y_A and Y_B carry most of the substrate uptake and stay within 2 %; Y_X, a few
        // per cent of it, within 10 %, and its standard error says it is the weak one.
        assert!((y_a.value / TRUTH[1] - 1.0).abs() < 0.02, "{y_a:?}");
        assert!((y_b.value / TRUTH[2] - 1.0).abs() < 0.02, "{y_b:?}");
        assert!((y_x.value / TRUTH[0] - 1.0).abs() < 0.1, "{y_x:?}");
        assert!(
            y_x.relative_error > y_a.relative_error.map(|r| 3.0 * r),
            "{fit:?}"
        );
        assert!(
            (y_x.value - TRUTH[0]).abs() < 3.0 * y_x.std_error.unwrap(),
            "{y_x:?}"
        );
    }

    #[test]
    fn a_param_outside_the_balances_is_flagged_not_identified() {
        // `unused` enters only an output: the balances say nothing about it, however
        // exactly they fit (a flat record fits them to rounding).
        let model = crate::driver::compile(
            "t.gbm",
            "model t\ntime h\ninput u\nstate X\nstate S\nparam k = 0.3 positive\n\
             param unused = 2 positive\nclosure c {\n  outputs r ~ 0.1\n  observe X, S, u\n}\n\
             output o = unused * X\nder X = r * X - 0.05 * X\n\
             der S = 0.05 * (1 - S) - r * X / k\n",
            &[],
        )
        .unwrap()
        .model;
        let record = crate::record::Record::complete(
            "flat",
            (0..30).map(f64::from).collect(),
            vec![vec![0.5; 30]],
            vec![vec![1.0; 30], vec![0.5; 30]],
        );
        let grid = crate::train::prepare::grid_for(&model, 1.0);
        let track = Track::lay(&record, &grid, &[]);
        let fit = estimate(&model, &unit_scales(&model), &[track], &at(0..29))
            .unwrap()
            .unwrap();
        // Steady state: r = 0.05 from X, then 0.05 * 0.5 = 0.05 / k from S, so k = 2.
        assert!((fit.estimates[0].value - 2.0).abs() < 1e-6, "{fit:?}");
        assert!(fit.estimates[0].identified, "{fit:?}");
        let unused = &fit.estimates[1];
        assert!(
            unused.std_error == Some(f64::INFINITY) && !unused.identified,
            "{unused:?}"
        );
        assert_eq!(unused.value, 2.0);
    }

    #[test]
    fn only_models_whose_balances_overdetermine_their_rates_qualify() {
        let (gb1, _) = bioreactor("models/bioreactor/gb1.gbm");
        assert!(applicable(&gb1));
        // One balance, one closure output, no params.
        assert!(!applicable(&chemostat::grey_box()));
        // A discrete map.
        assert!(!applicable(&chemostat::black_box()));
        let mut hidden = gb1.clone();
        hidden.hidden.push(hidden.states[0].clone());
        assert!(!applicable(&hidden));
    }
}
