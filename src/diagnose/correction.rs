//! A free correction at one locus (one let, a group of lets, or a balance): fitted by
//! one-step regression along the training rows of every experiment, then refined on the
//! training free runs ([`super::refine`]) and scored by held-out free runs with the
//! correction in the loop.
//!
//! Along the training rows the model is stepped from each row's measured cells (states not
//! measured there, and hidden ones, carried along as in the offline error), once as it is
//! and once with each correction slot `j` at a small `delta_j`: the sensitivity
//! `s_ijk = d x_k(i+1) / d c_j` and the residual `r_ik = data_k(i+1) - x_k(i+1)` (only where
//! column `k` is measured at rows `i` and `i + 1`; a column is a measured state or an
//! observable, the model output at the stepped state) make the problem linear,
//! `min_w sum_ik ((r_ik - sum_j s_ijk w_j . phi_ij) / std_k)^2 + ridge |w|^2`, solved through
//! the normal equations with the ridge chosen by cross-validation over contiguous blocks of
//! rows. A group's corrections (one per let) are fitted jointly this way. Corrections are
//! held constant over each interval between rows, in fitting and in runs.

use super::features::FeatureMap;
use super::memory::FilterBank;
use crate::eval::Program;
use crate::ir::Constraint;
use crate::numeric::{dot, root_mean_square, NormalEquations};
use crate::record::{Normalisation, Record};
use crate::solve::fit::simulate::{inputs_at, Simulator};
use crate::solve::fit::split::Split;
use crate::solve::ode::IntegrationError;

/// Ridge strengths tried (relative to the mean diagonal of the normal equations).
const RIDGES: [f64; 5] = [1e-9, 1e-7, 1e-5, 1e-3, 1e-1];
/// Cross-validation folds.
const FOLDS: usize = 4;

/// How a corrected quantity's value is read at a state.
#[derive(Debug, Clone)]
pub enum LocusValue {
    /// A let: its (uncorrected) expression.
    Let(Program),
    /// A balance: the value of its state.
    State(usize),
}

/// A model with correction slots at one locus (one per corrected let, or one for a
/// balance).
#[derive(Debug, Clone)]
pub struct Corrected {
    /// The compiled model.
    pub simulator: Simulator,
    /// The corrected quantities, one per slot.
    pub loci: Vec<LocusValue>,
    /// Whether the locus is a balance (its correction is a rate of its state).
    pub balance: bool,
    /// The constraints of the params, then of the fitted starts (free).
    pub constraints: Vec<Constraint>,
}

impl Corrected {
    /// The corrected quantities at `state` with the inputs of `row`.
    pub fn locus_values(&mut self, record: &Record, row: usize, state: &[f64]) -> Vec<f64> {
        let Corrected {
            simulator, loci, ..
        } = self;
        (loci.iter())
            .map(|locus| match locus {
                LocusValue::Let(program) => simulator.evaluate(program, record, row, state),
                LocusValue::State(k) => state[*k],
            })
            .collect()
    }
}

/// What the one-step pass found along one experiment's training rows, per step `i -> i+1`.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordPass {
    /// Index of the record in the split.
    pub record: usize,
    /// Present variables per row: inputs, measured (cells, else carried), hidden (carried).
    pub present: Vec<Vec<f64>>,
    /// The corrected quantities per row, one per slot.
    pub locus: Vec<Vec<f64>>,
    /// Filtered signals per row (inputs, measured states, then one per slot, at each time
    /// constant), empty without history.
    pub filtered: Vec<Vec<f64>>,
    /// Sensitivities `s_ijk` per row, per slot, per measured column (the measured states,
    /// then the observables).
    pub sensitivity: Vec<Vec<Vec<f64>>>,
    /// Residuals `r_ik` per row, per measured column (only where it is measured at both
    /// ends).
    pub residual: Vec<Vec<Option<f64>>>,
}

impl RecordPass {
    /// Steps in the pass.
    pub fn rows(&self) -> usize {
        self.present.len()
    }

    /// The filtered signals slot `slot` sees at `row`: the embedded ones and its own
    /// quantity, at each time constant.
    pub fn filtered_for(&self, row: usize, slot: usize, embedded: usize) -> Vec<f64> {
        filtered_for(&self.filtered[row], slot, embedded, self.locus[row].len())
    }
}

/// From a bank's values over `[embedded..., slot quantities...]` per time constant, the
/// values slot `slot` sees: the embedded signals and its own quantity.
pub fn filtered_for(values: &[f64], slot: usize, embedded: usize, slots: usize) -> Vec<f64> {
    let per = embedded + slots;
    if per == 0 {
        return Vec::new();
    }
    (values.chunks(per))
        .flat_map(|chunk| chunk[..embedded].iter().chain([&chunk[embedded + slot]]))
        .copied()
        .collect()
}

/// The one-step pass over every training experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Pass {
    /// One per training record.
    pub records: Vec<RecordPass>,
}

impl Pass {
    /// Steps in all.
    pub fn rows(&self) -> usize {
        self.records.iter().map(RecordPass::rows).sum()
    }
}

/// Steps the model (params as in `x`: params, then fitted starts) from every training row
/// with each correction at 0 and at a probe; filters the signals at `taus` (none: no
/// history).
pub fn one_step_pass(
    corrected: &mut Corrected,
    split: &Split,
    x: &[f64],
    taus: &[f64],
) -> Result<Pass, IntegrationError> {
    corrected.simulator.set_params(x);
    let fitted = &x[corrected.simulator.params().min(x.len())..];
    let mut records = Vec::new();
    for (index, record, rows) in split.training() {
        let overrides = split.overrides(index, fitted, corrected.simulator.hidden_count());
        records.push(record_pass(
            corrected,
            (index, record, rows.end),
            &overrides,
            taus,
        )?);
    }
    Ok(Pass { records })
}

fn record_pass(
    corrected: &mut Corrected,
    (index, record, end): (usize, &Record, usize),
    overrides: &[Option<f64>],
    taus: &[f64],
) -> Result<RecordPass, IntegrationError> {
    let measured = record.states.len();
    let columns = record.columns().count();
    let slots = corrected.loci.len();
    corrected.simulator.clear_corrections();
    let (starts, predictions) = corrected.simulator.one_step(record, overrides, end)?;
    let rows = starts.rows();
    let mut pass = RecordPass {
        record: index,
        present: Vec::with_capacity(rows),
        locus: Vec::with_capacity(rows),
        filtered: Vec::new(),
        sensitivity: Vec::with_capacity(rows),
        residual: Vec::with_capacity(rows),
    };
    for row in 0..rows {
        let state = starts.row(row);
        pass.present.push(
            inputs_at(record, row)
                .chain(state.iter().copied())
                .collect(),
        );
        pass.locus.push(corrected.locus_values(record, row, state));
        pass.residual.push(
            (0..columns)
                .map(
                    |k| match (record.column(k)[row], record.column(k)[row + 1]) {
                        (Some(_), Some(next)) => Some(next - predictions.column(row, k)),
                        _ => None,
                    },
                )
                .collect(),
        );
    }
    if !taus.is_empty() && rows > 0 {
        pass.filtered = filter_along(&pass, record, measured, taus);
    }
    let deltas: Vec<f64> = (0..slots)
        .map(|slot| probe(corrected.balance, &pass, slot, record))
        .collect();
    let mut sensitivity = vec![vec![vec![0.0; columns]; slots]; rows];
    for (slot, &delta) in deltas.iter().enumerate() {
        let mut values = vec![0.0; slots];
        values[slot] = delta;
        corrected.simulator.set_corrections(&values);
        for (row, per_row) in sensitivity.iter_mut().enumerate() {
            let mut state = starts.row(row).to_vec();
            corrected.simulator.step(record, row, &mut state)?;
            let observed = corrected.simulator.observe_state(record, row + 1, &state);
            let moved = |k: usize| match k.checked_sub(measured) {
                None => state[k],
                Some(j) => observed[j],
            };
            per_row[slot] = (0..columns)
                .map(|k| (moved(k) - predictions.column(row, k)) / delta)
                .collect();
        }
    }
    corrected.simulator.clear_corrections();
    pass.sensitivity = sensitivity;
    Ok(pass)
}

/// The filtered signals at each row of a pass: inputs held, measured states and corrected
/// quantities linear between rows (their pass values).
fn filter_along(
    pass: &RecordPass,
    record: &Record,
    measured: usize,
    taus: &[f64],
) -> Vec<Vec<f64>> {
    let inputs = record.inputs.len();
    let signal = |row: usize| -> Vec<f64> {
        let present = &pass.present[row];
        let mut values = present[..inputs + measured].to_vec();
        values.extend_from_slice(&pass.locus[row]);
        values
    };
    let mut bank = FilterBank::start(taus, &signal(0));
    let mut filtered = vec![bank.values().to_vec()];
    for row in 1..pass.rows() {
        let from = signal(row - 1);
        let mut to = signal(row);
        to[..inputs].copy_from_slice(&from[..inputs]);
        bank.advance(&from, &to, record.times[row] - record.times[row - 1]);
        filtered.push(bank.values().to_vec());
    }
    filtered
}

/// A probe size well inside the linear range: 1e-4 of the quantity's typical size (for a
/// balance, of its state per median step).
fn probe(balance: bool, pass: &RecordPass, slot: usize, record: &Record) -> f64 {
    let values: Vec<f64> = pass.locus.iter().map(|l| l[slot]).collect();
    let typical = root_mean_square(&values);
    let size = if balance {
        let steps: Vec<f64> = record.times.windows(2).map(|w| w[1] - w[0]).collect();
        typical
            / crate::numeric::median(&steps)
                .unwrap_or(1.0)
                .max(f64::MIN_POSITIVE)
    } else {
        typical
    };
    if size > 0.0 && size.is_finite() {
        1e-4 * size
    } else {
        1e-8
    }
}

/// A fitted correction: weights (one block per slot) and the params (and fitted starts) it
/// goes with, transformed.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// Weights of the features, slot-major.
    pub weights: Vec<f64>,
    /// Params then fitted starts (transformed).
    pub theta: Vec<f64>,
}

/// Fits the weights of a correction with features `map` to the pass (params `theta`, as
/// the pass ran); `None` if the normal equations are singular at every ridge.
pub fn fit(pass: &Pass, map: &FeatureMap, norm: &Normalisation, theta: &[f64]) -> Option<Solution> {
    let slots = pass.records.first()?.locus.first().map_or(1, Vec::len);
    let n = map.width() * slots;
    let folds = normal_equations(pass, map, norm, slots);
    let ridge = choose_ridge(&folds, n)?;
    let mut all = NormalEquations::new(n);
    folds.iter().for_each(|f| all.merge(&f.0));
    Some(Solution {
        weights: all.solve(ridge, n)?,
        theta: theta.to_vec(),
    })
}

/// The features of every slot at one row of a pass, slot-major.
pub fn row_features(pass: &RecordPass, map: &FeatureMap, row: usize) -> Vec<Vec<f64>> {
    let slots = pass.locus[row].len();
    (0..slots)
        .map(|slot| {
            let filtered = if map.taus.is_some() {
                pass.filtered_for(row, slot, map.embedded)
            } else {
                Vec::new()
            };
            let mut phi = Vec::new();
            map.features(
                &pass.present[row],
                pass.locus[row][slot],
                &filtered,
                &mut phi,
            );
            phi
        })
        .collect()
}

/// The normal equations, one set per fold, with each fold's constant `sum r^2 / std^2`.
fn normal_equations(
    pass: &Pass,
    map: &FeatureMap,
    norm: &Normalisation,
    slots: usize,
) -> Vec<(NormalEquations, f64)> {
    let width = map.width();
    let n = width * slots;
    let mut folds: Vec<(NormalEquations, f64)> =
        (0..FOLDS).map(|_| (NormalEquations::new(n), 0.0)).collect();
    let weights: Vec<f64> = (0..norm.columns())
        .map(|k| norm.column_std(k).powi(-2))
        .collect();
    let total = pass.rows().max(1);
    let mut position = 0;
    let mut stacked = vec![0.0; n];
    for record in &pass.records {
        for row in 0..record.rows() {
            let (normal, constant) = &mut folds[position * FOLDS / total];
            position += 1;
            let r = &record.residual[row];
            if r.iter().all(Option::is_none) {
                continue;
            }
            let phi = row_features(record, map, row);
            let s = &record.sensitivity[row];
            *constant += (0..r.len())
                .filter_map(|k| r[k].map(|v| v * v * weights[k]))
                .sum::<f64>();
            if slots == 1 {
                let weight: f64 = (0..r.len())
                    .filter(|&k| r[k].is_some())
                    .map(|k| s[0][k] * s[0][k] * weights[k])
                    .sum();
                let target: f64 = (0..r.len())
                    .filter_map(|k| r[k].map(|v| s[0][k] * v * weights[k]))
                    .sum();
                if weight > 0.0 && weight.is_finite() {
                    normal.add(&phi[0], target / weight, weight);
                }
                continue;
            }
            for (k, residual) in r.iter().enumerate() {
                let Some(residual) = residual else { continue };
                for (slot, features) in phi.iter().enumerate() {
                    for (cell, f) in stacked[slot * width..(slot + 1) * width]
                        .iter_mut()
                        .zip(features)
                    {
                        *cell = s[slot][k] * f;
                    }
                }
                if stacked.iter().all(|v| v.is_finite()) {
                    normal.add(&stacked, *residual, weights[k]);
                }
            }
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

/// One slot's correction values along a pass.
pub fn values_along(pass: &Pass, map: &FeatureMap, weights: &[f64], slot: usize) -> Vec<f64> {
    let width = map.width();
    let block = &weights[slot * width..(slot + 1) * width];
    (pass.records.iter())
        .flat_map(|record| (0..record.rows()).map(move |row| (record, row)))
        .map(|(record, row)| dot(&row_features(record, map, row)[slot], block))
        .collect()
}
