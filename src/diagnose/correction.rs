//! A free correction at one locus: fitted by one-step regression along the training rows,
//! refined on the training free run, and scored by a held-out free run with the correction
//! in the loop.
//!
//! Along the training rows the model is stepped from each row's measured data (hidden
//! states carried along, as in the offline error), once as it is and once with the
//! correction slot at a small `delta`: the sensitivity `s_ik = d x_k(i+1) / d c` and the
//! residual `r_ik = data_k(i+1) - x_k(i+1)` make the problem linear,
//! `min_w sum_ik ((r_ik - s_ik w . phi_i) / std_k)^2 + ridge |w|^2`, solved through the
//! normal equations with the ridge chosen by cross-validation over contiguous blocks.
//! [`refine`] then fits the model's params and a gain on the correction to the training
//! free run (Levenberg–Marquardt), since small one-step errors add up in a free run and
//! params fitted without the correction compensate for what it now explains. The
//! correction is held constant over each sampling interval, in fitting and in runs.

use super::features::FeatureMap;
use super::fit::{from_theta, to_theta};
use super::record::{Normalisation, Record};
use super::simulate::{Run, Simulator};
use crate::eval::Program;
use crate::ir::Constraint;
use crate::numeric::{dot, root_mean_square, NormalEquations};
use crate::sim::IntegrationError;

/// Ridge strengths tried (relative to the mean diagonal of the correction's block).
const RIDGES: [f64; 5] = [1e-9, 1e-7, 1e-5, 1e-3, 1e-1];
/// Cross-validation folds.
const FOLDS: usize = 4;

/// How the corrected quantity's value is read at a state.
#[derive(Debug, Clone)]
pub enum LocusValue {
    /// A let: its (uncorrected) expression.
    Let(Program),
    /// A balance: the value of its state.
    State(usize),
}

/// A model with a correction slot at one locus.
#[derive(Debug, Clone)]
pub struct Corrected {
    /// The compiled model.
    pub simulator: Simulator,
    /// The corrected quantity.
    pub locus: LocusValue,
    /// Whether the locus is a balance (its correction is a rate of its state).
    pub balance: bool,
    /// The params' constraints.
    pub constraints: Vec<Constraint>,
}

impl Corrected {
    fn locus_value(&mut self, record: &Record, row: usize, state: &[f64]) -> f64 {
        match &self.locus {
            LocusValue::Let(program) => self.simulator.evaluate(program, record, row, state),
            LocusValue::State(k) => state[*k],
        }
    }
}

/// What the one-step pass along the training rows found, per row.
#[derive(Debug, Clone, PartialEq)]
pub struct Pass {
    /// Rows stepped (0..rows).
    pub rows: usize,
    /// Present variables per row: inputs, measured (data), hidden (carried).
    pub present: Vec<Vec<f64>>,
    /// The corrected quantity per row.
    pub locus: Vec<f64>,
    /// Sensitivities `s_ik` per row (measured states).
    pub sensitivity: Vec<Vec<f64>>,
    /// Residuals `r_ik` per row (measured states).
    pub residual: Vec<Vec<f64>>,
}

/// Steps the model (params as set) from every training row with the correction at 0 and
/// at `delta`.
pub fn one_step_pass(
    corrected: &mut Corrected,
    record: &Record,
    end: usize,
) -> Result<Pass, IntegrationError> {
    let measured = record.states.len();
    corrected.simulator.set_correction(0.0);
    let (starts, predictions) = corrected.simulator.one_step(record, end)?;
    let rows = starts.rows();
    let mut pass = Pass {
        rows,
        present: Vec::with_capacity(rows),
        locus: Vec::with_capacity(rows),
        sensitivity: Vec::new(),
        residual: Vec::with_capacity(rows),
    };
    for row in 0..rows {
        let state = starts.row(row);
        pass.present
            .push(record.inputs_at(row).chain(state.iter().copied()).collect());
        pass.locus.push(corrected.locus_value(record, row, state));
        let predicted = predictions.row(row);
        pass.residual.push(
            (0..measured)
                .map(|k| record.states[k][row + 1] - predicted[k])
                .collect(),
        );
    }
    let delta = delta(corrected, &pass, record);
    corrected.simulator.set_correction(delta);
    pass.sensitivity = sensitivities(
        &mut corrected.simulator,
        record,
        (&starts, &predictions),
        delta,
    )?;
    corrected.simulator.set_correction(0.0);
    Ok(pass)
}

/// Per row, `(step from the row's start - base prediction) / size` for each measured state.
fn sensitivities(
    simulator: &mut Simulator,
    record: &Record,
    (starts, predictions): (&Run, &Run),
    size: f64,
) -> Result<Vec<Vec<f64>>, IntegrationError> {
    let measured = record.states.len();
    (0..starts.rows())
        .map(|row| {
            let mut state = starts.row(row).to_vec();
            simulator.step(record, row, &mut state)?;
            let base = predictions.row(row);
            Ok((0..measured).map(|k| (state[k] - base[k]) / size).collect())
        })
        .collect()
}

/// The constrained params of transformed values.
pub fn params_of(constraints: &[Constraint], theta: &[f64]) -> Vec<f64> {
    constraints
        .iter()
        .zip(theta)
        .map(|(c, &t)| from_theta(*c, t))
        .collect()
}

/// The transformed values of constrained params.
pub fn theta_of(constraints: &[Constraint], params: &[f64]) -> Vec<f64> {
    constraints
        .iter()
        .zip(params)
        .map(|(c, &p)| to_theta(*c, p))
        .collect()
}

/// A probe size well inside the linear range: 1e-4 of the quantity's typical size (for a
/// balance, of its state per sampling step).
fn delta(corrected: &Corrected, pass: &Pass, record: &Record) -> f64 {
    let typical = root_mean_square(&pass.locus);
    let size = if corrected.balance {
        typical / record.step
    } else {
        typical
    };
    if size > 0.0 && size.is_finite() {
        1e-4 * size
    } else {
        1e-8
    }
}

/// The embedded variables (inputs, then measured states) at each lag `1..dim` before `row`,
/// lag-major, from the record's inputs and the measured `history` (rows before the start
/// repeat row 0).
fn lagged(
    map: &FeatureMap,
    record: &Record,
    history: &dyn Fn(usize, usize) -> f64,
    row: usize,
    out: &mut Vec<f64>,
) {
    out.clear();
    let Some(lags) = map.lags else { return };
    for lag in 1..lags.dim {
        let at = row.saturating_sub(lag * lags.delay);
        out.extend(record.inputs_at(at));
        out.extend((0..record.states.len()).map(|k| history(at, k)));
    }
}

/// A fitted correction: weights and the params it goes with.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Weights of the features.
    pub weights: Vec<f64>,
    /// Params (transformed).
    pub theta: Vec<f64>,
}

/// Fits the weights of a correction with features `map` to the pass (params `theta`, as
/// the pass ran); `None` if the normal equations are singular at every ridge.
pub fn fit(
    pass: &Pass,
    map: &FeatureMap,
    record: &Record,
    norm: &Normalisation,
    theta: &[f64],
) -> Option<Solution> {
    let n = map.width();
    let folds = normal_equations(pass, map, record, norm);
    let ridge = choose_ridge(&folds, n)?;
    let mut all = NormalEquations::new(n);
    folds.iter().for_each(|f| all.merge(&f.0));
    Some(Solution {
        weights: all.solve(ridge, n)?,
        theta: theta.to_vec(),
    })
}

/// The normal equations, one set per fold, with each fold's constant `sum r^2 / std^2`.
fn normal_equations(
    pass: &Pass,
    map: &FeatureMap,
    record: &Record,
    norm: &Normalisation,
) -> Vec<(NormalEquations, f64)> {
    let n = map.width();
    let mut folds: Vec<(NormalEquations, f64)> =
        (0..FOLDS).map(|_| (NormalEquations::new(n), 0.0)).collect();
    let (mut phi, mut lag) = (Vec::new(), Vec::new());
    let data = |row: usize, k: usize| record.states[k][row];
    let weights: Vec<f64> = norm.std.iter().map(|s| 1.0 / (s * s)).collect();
    for row in 0..pass.rows {
        lagged(map, record, &data, row, &mut lag);
        map.features(&pass.present[row], pass.locus[row], &lag, &mut phi);
        let (s, r) = (&pass.sensitivity[row], &pass.residual[row]);
        let (normal, constant) = &mut folds[row * FOLDS / pass.rows.max(1)];
        let weight: f64 = (0..s.len()).map(|k| s[k] * s[k] * weights[k]).sum();
        let target: f64 = (0..s.len()).map(|k| s[k] * r[k] * weights[k]).sum();
        *constant += (0..r.len()).map(|k| r[k] * r[k] * weights[k]).sum::<f64>();
        if weight > 0.0 && weight.is_finite() {
            normal.add(&phi, target / weight, weight);
        }
    }
    folds.iter_mut().for_each(|f| f.0.finish());
    folds
}

/// The ridge with the least cross-validated one-step loss.
fn choose_ridge(folds: &[(NormalEquations, f64)], penalised: usize) -> Option<f64> {
    let mut best: Option<(f64, f64)> = None;
    for ridge in RIDGES {
        let mut loss = 0.0;
        for held in 0..folds.len() {
            let mut train = NormalEquations::new(folds[held].0.n);
            (folds.iter().enumerate())
                .filter(|(f, _)| *f != held)
                .for_each(|(_, f)| train.merge(&f.0));
            match train.solve(ridge, penalised) {
                Some(x) => loss += folds[held].0.loss(folds[held].1, &x),
                None => loss = f64::INFINITY,
            }
        }
        if loss.is_finite() && best.is_none_or(|(_, l)| loss < l) {
            best = Some((ridge, loss));
        }
    }
    best.map(|(ridge, _)| ridge)
}

/// The correction's values along a pass.
pub fn values_along(pass: &Pass, map: &FeatureMap, record: &Record, weights: &[f64]) -> Vec<f64> {
    let (mut phi, mut lag) = (Vec::new(), Vec::new());
    let data = |row: usize, k: usize| record.states[k][row];
    (0..pass.rows)
        .map(|row| {
            lagged(map, record, &data, row, &mut lag);
            map.features(&pass.present[row], pass.locus[row], &lag, &mut phi);
            dot(&phi, weights)
        })
        .collect()
}

/// What a free-run refinement may change besides the params: a gain on the one-step
/// weights and the weights of some features.
#[derive(Debug, Clone, PartialEq)]
pub struct Refinement {
    /// Feature indices whose weights are fitted (see [`FeatureMap::directions`]).
    pub directions: Vec<usize>,
    /// The size of a unit move of those weights (a typical correction value).
    pub reference: f64,
}

/// Refines a solution on the free run over the training rows: Levenberg–Marquardt over the
/// params (transformed), a gain on the one-step weights and the weights of the
/// refinement's directions; the result is kept only if it lowers the training gap.
pub fn refine(
    corrected: &Corrected,
    map: &FeatureMap,
    solution: &Solution,
    refinement: &Refinement,
    fitting: (&Record, std::ops::Range<usize>, &Normalisation),
) -> Solution {
    let (record, rows, norm) = fitting;
    let params = solution.theta.len();
    let scale = ((rows.len() * record.states.len()).max(1) as f64).sqrt();
    let apply = |x: &[f64]| {
        let mut weights: Vec<f64> = solution.weights.iter().map(|w| w * x[params]).collect();
        for (&index, extra) in refinement.directions.iter().zip(&x[params + 1..]) {
            weights[index] += refinement.reference * extra;
        }
        Solution {
            weights,
            theta: x[..params].to_vec(),
        }
    };
    let residuals = |x: &[f64]| -> Option<Vec<f64>> {
        let mut corrected = corrected.clone();
        let run = corrected_run(&mut corrected, map, &apply(x), record, rows.end).ok()?;
        let mut out = Vec::with_capacity(rows.len() * record.states.len());
        for row in rows.clone() {
            for (k, column) in record.states.iter().enumerate() {
                out.push((run.row(row)[k] - column[row]) / norm.std[k] / scale);
            }
        }
        out.iter().all(|r| r.is_finite()).then_some(out)
    };
    let mut start = solution.theta.clone();
    start.push(1.0);
    start.extend(refinement.directions.iter().map(|_| 0.0));
    let (x, cost) = super::fit::levenberg_marquardt(&residuals, start.clone());
    let before = residuals(&start).map_or(f64::INFINITY, |r| dot(&r, &r));
    if cost < before {
        apply(&x)
    } else {
        solution.clone()
    }
}

/// The free run from row 0 to `end - 1` of `record` with the correction in the loop (its
/// embedding fed by the run's own measured states) and the solution's params.
pub fn corrected_run(
    corrected: &mut Corrected,
    map: &FeatureMap,
    solution: &Solution,
    record: &Record,
    end: usize,
) -> Result<Run, IntegrationError> {
    let params = params_of(&corrected.constraints, &solution.theta);
    corrected.simulator.set_params(&params);
    let mut state = corrected.simulator.start_state(record, 0);
    let dim = state.len();
    let mut values = Vec::with_capacity(end * dim);
    values.extend_from_slice(&state);
    let (mut phi, mut lag, mut present) = (Vec::new(), Vec::new(), Vec::new());
    for row in 0..end.saturating_sub(1) {
        let own = |at: usize, k: usize| values[at * dim + k];
        lagged(map, record, &own, row, &mut lag);
        present.clear();
        present.extend(record.inputs_at(row));
        present.extend_from_slice(&state);
        let locus = corrected.locus_value(record, row, &state);
        map.features(&present, locus, &lag, &mut phi);
        corrected
            .simulator
            .set_correction(dot(&phi, &solution.weights));
        corrected.simulator.step(record, row, &mut state)?;
        values.extend_from_slice(&state);
    }
    corrected.simulator.set_correction(0.0);
    Ok(Run { dim, values })
}
