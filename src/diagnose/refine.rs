//! A free correction in the loop: its free runs (the history features fed by the run's own
//! states and corrected quantities), its refinement on the training free runs, and its
//! held-out errors.
//!
//! Small one-step errors add up in a free run, and params fitted without the correction
//! compensate for what it now explains, so [`refine`] fits the model's params (and fitted
//! starts), a gain on each slot's one-step weights and the weights of a few directions per
//! slot ([`FeatureMap::directions`]: a constant, a term proportional to the corrected
//! quantity and, with history, its lags) to the training free runs by Levenberg–Marquardt;
//! the result is kept only if it lowers the training gap.

use super::correction::{filtered_for, Corrected, Solution};
use super::evaluate::{scored_errors, Errors};
use super::features::FeatureMap;
use super::fit::{polish, values};
use super::memory::FilterBank;
use super::simulate::{inputs_at, Run};
use super::split::Split;
use crate::numeric::dot;
use crate::record::Record;
use crate::sim::IntegrationError;

/// What a free-run refinement may change besides the params: a gain on each slot's one-step
/// weights and the weights of some features of each slot.
#[derive(Debug, Clone, PartialEq)]
pub struct Refinement {
    /// Feature indices whose weights are fitted, in every slot.
    pub directions: Vec<usize>,
    /// Per slot: the size of a unit move of those weights (a typical correction value).
    pub reference: Vec<f64>,
}

/// Refines a solution on the training free runs of `split` (see the module documentation).
pub fn refine(
    corrected: &Corrected,
    map: &FeatureMap,
    solution: &Solution,
    refinement: &Refinement,
    split: &Split,
) -> Solution {
    let slots = corrected.loci.len();
    let width = map.width();
    let unknowns = solution.theta.len();
    let directions = refinement.directions.len();
    let apply = |x: &[f64]| {
        let mut weights = solution.weights.clone();
        for slot in 0..slots {
            let gain = x[unknowns + slot];
            let block = &mut weights[slot * width..(slot + 1) * width];
            block.iter_mut().for_each(|w| *w *= gain);
            let extra = &x[unknowns + slots + slot * directions..][..directions];
            for (&index, move_by) in refinement.directions.iter().zip(extra) {
                block[index] += refinement.reference[slot] * move_by;
            }
        }
        Solution {
            weights,
            theta: x[..unknowns].to_vec(),
        }
    };
    let scale = (split.training_cells().max(1) as f64).sqrt();
    let residuals = |x: &[f64]| -> Option<Vec<f64>> {
        let mut corrected = corrected.clone();
        let candidate = apply(x);
        let mut out = Vec::new();
        for (index, record, rows) in split.training() {
            let run =
                corrected_run(&mut corrected, map, &candidate, (split, index), rows.end).ok()?;
            for row in rows {
                for (k, cells) in record.states.iter().enumerate() {
                    if let Some(value) = cells[row] {
                        out.push(
                            (run.row(row)[k] - value) / split.normalisation.state_std[k] / scale,
                        );
                    }
                }
            }
        }
        out.iter().all(|r| r.is_finite()).then_some(out)
    };
    let mut start = solution.theta.clone();
    start.extend(std::iter::repeat_n(1.0, slots));
    start.extend(std::iter::repeat_n(0.0, slots * directions));
    let (x, cost) = polish(&residuals, start.clone());
    let before = residuals(&start).map_or(f64::INFINITY, |r| dot(&r, &r));
    if cost < before {
        apply(&x)
    } else {
        solution.clone()
    }
}

/// The free run of record `index` of `split` from its row 0 to `end - 1` with the
/// correction in the loop and the solution's params and fitted starts.
pub fn corrected_run(
    corrected: &mut Corrected,
    map: &FeatureMap,
    solution: &Solution,
    (split, index): (&Split, usize),
    end: usize,
) -> Result<Run, IntegrationError> {
    let x = values(&corrected.constraints, &solution.theta);
    corrected.simulator.set_params(&x);
    let fitted = &x[corrected.simulator.params().min(x.len())..];
    let overrides = split.overrides(index, fitted, corrected.simulator.hidden_count());
    run_with(
        corrected,
        map,
        solution,
        &split.records[index],
        &overrides,
        end,
    )
}

fn run_with(
    corrected: &mut Corrected,
    map: &FeatureMap,
    solution: &Solution,
    record: &Record,
    overrides: &[Option<f64>],
    end: usize,
) -> Result<Run, IntegrationError> {
    let mut state = corrected.simulator.start_state(record, overrides);
    let dim = state.len();
    let (inputs, measured) = (record.inputs.len(), record.states.len());
    let slots = corrected.loci.len();
    let width = map.width();
    let mut values = Vec::with_capacity(end * dim);
    values.extend_from_slice(&state);
    let mut locus = corrected.locus_values(record, 0, &state);
    let signal = |row: usize, state: &[f64], locus: &[f64]| -> Vec<f64> {
        let mut s: Vec<f64> = inputs_at(record, row).collect();
        s.extend_from_slice(&state[..measured]);
        s.extend_from_slice(locus);
        s
    };
    let mut bank =
        (map.taus.as_ref()).map(|taus| FilterBank::start(taus, &signal(0, &state, &locus)));
    let (mut phi, mut present, mut corrections) = (Vec::new(), Vec::new(), vec![0.0; slots]);
    for row in 0..end.saturating_sub(1) {
        present.clear();
        present.extend(inputs_at(record, row));
        present.extend_from_slice(&state);
        for (slot, correction) in corrections.iter_mut().enumerate() {
            let filtered = bank.as_ref().map_or(Vec::new(), |b| {
                filtered_for(b.values(), slot, map.embedded, slots)
            });
            map.features(&present, locus[slot], &filtered, &mut phi);
            *correction = dot(&phi, &solution.weights[slot * width..(slot + 1) * width]);
        }
        corrected.simulator.set_corrections(&corrections);
        let before = bank.as_ref().map(|_| signal(row, &state, &locus));
        corrected.simulator.step(record, row, &mut state)?;
        values.extend_from_slice(&state);
        let next = corrected.locus_values(record, row + 1, &state);
        if let (Some(bank), Some(from)) = (bank.as_mut(), before) {
            let mut to = signal(row, &state, &next);
            to[..inputs].copy_from_slice(&from[..inputs]);
            bank.advance(&from, &to, record.times[row + 1] - record.times[row]);
        }
        locus = next;
    }
    corrected.simulator.clear_corrections();
    Ok(Run { dim, values })
}

/// The errors at the scored cells of `split` of free runs with the correction in the loop.
pub fn score(
    corrected: &mut Corrected,
    map: &FeatureMap,
    solution: &Solution,
    split: &Split,
) -> Errors {
    let indices: Vec<(usize, usize)> = split.scored().map(|(i, _, rows)| (i, rows.end)).collect();
    let runs: Vec<Option<Run>> = (indices.into_iter())
        .map(|(index, end)| corrected_run(corrected, map, solution, (split, index), end).ok())
        .collect();
    scored_errors(split, &runs)
}
