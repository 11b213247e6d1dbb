//! A free correction in the loop: its free runs (the history features fed by the run's own
//! states and corrected quantities), its refinement on the training free runs, and its
//! held-out errors.
//!
//! Small one-step errors add up in a free run, and params fitted without the correction
//! compensate for what it now explains, so [`refine`] fits the model's params (and fitted
//! starts), a gain on each slot's one-step weights and the weights of a few directions per
//! slot ([`FeatureMap::directions`]: a constant, a term proportional to the corrected
//! quantity and, with history, its lags) to the training free runs by Levenberg–Marquardt;
//! the result is kept only if it lowers the training gap. On sparse records (fewer than
//! [`SPARSE_SHARE`] of the cells have a one-step pair), where the one-step correction does
//! worse in the loop than no correction, the refinement starts from no correction (gain 0)
//! and adjusts every present feature's weight ([`FeatureMap::sparse_directions`]).

use super::correction::{filtered_for, Corrected, Solution};
use super::evaluate::{scored_errors, Errors};
use super::features::FeatureMap;
use super::memory::FilterBank;
use crate::numeric::dot;
use crate::record::Record;
use crate::solve::fit::fitter::{polish_within, values};
use crate::solve::fit::simulate::{inputs_at, Run};
use crate::solve::fit::split::Split;
use crate::solve::ode::IntegrationError;

/// Below this share of one-step pairs ([`Split::one_step_share`]) a record is sparse: a
/// one-step correction that does worse in the loop than none is grown from none instead.
pub const SPARSE_SHARE: f64 = 0.5;

/// Most linearisations of a refinement ...
const LINEARISATIONS: usize = 20;
/// ... but one with more unknowns than this is wide ...
const WIDE: usize = 16;
/// ... and gets at most this many linearisations.
const WIDE_LINEARISATIONS: usize = 8;

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
    let problem = Problem {
        corrected,
        map,
        solution,
        split,
    };
    let gains_only = Refinement {
        directions: Vec::new(),
        reference: refinement.reference.clone(),
    };
    let one_step_cost = problem.cost(&gains_only, &problem.start(&gains_only, 1.0));
    let none_cost = if split.one_step_share() < SPARSE_SHARE {
        problem.cost(&gains_only, &problem.start(&gains_only, 0.0))
    } else {
        f64::INFINITY
    };
    let (refined, cost) = if one_step_cost <= none_cost {
        problem.polish(refinement, 1.0)
    } else {
        // The one-step correction does worse in the loop than none at all (a sparse
        // record's few one-step pairs): grow it from none, along every present feature.
        let wide = Refinement {
            directions: map.sparse_directions(),
            reference: refinement.reference.clone(),
        };
        problem.polish(&wide, 0.0)
    };
    if cost < one_step_cost.min(none_cost) {
        refined
    } else if none_cost < one_step_cost {
        problem.apply(&gains_only, &problem.start(&gains_only, 0.0))
    } else {
        solution.clone()
    }
}

/// What [`refine`] works on.
struct Problem<'a> {
    corrected: &'a Corrected,
    map: &'a FeatureMap,
    solution: &'a Solution,
    split: &'a Split,
}

impl Problem<'_> {
    /// The unknowns at the solution's params, one gain for every slot and no move.
    fn start(&self, refinement: &Refinement, gain: f64) -> Vec<f64> {
        let slots = self.corrected.loci.len();
        let mut start = self.solution.theta.clone();
        start.extend(std::iter::repeat_n(gain, slots));
        start.extend(std::iter::repeat_n(
            0.0,
            slots * refinement.directions.len(),
        ));
        start
    }

    /// The solution the unknowns `x` stand for: params, then a gain on each slot's weights,
    /// then per slot the moves along the refinement's directions.
    fn apply(&self, refinement: &Refinement, x: &[f64]) -> Solution {
        let slots = self.corrected.loci.len();
        let width = self.map.width();
        let unknowns = self.solution.theta.len();
        let directions = refinement.directions.len();
        let mut weights = self.solution.weights.clone();
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
    }

    /// The weighted, normalised training residuals of the free runs at `x` (`None` if a
    /// run fails).
    fn residuals(&self, refinement: &Refinement, x: &[f64]) -> Option<Vec<f64>> {
        let split = self.split;
        let scale = (split.training_cells().max(1) as f64).sqrt();
        let mut corrected = self.corrected.clone();
        let candidate = self.apply(refinement, x);
        let mut out = Vec::new();
        for (index, record, rows) in split.training() {
            let run = corrected_run(
                &mut corrected,
                self.map,
                &candidate,
                (split, index),
                rows.end,
            )
            .ok()?;
            for row in rows {
                for (k, cells) in record.columns().enumerate() {
                    if let Some(value) = cells[row] {
                        let weight = split.weight(k, value) / split.normalisation.column_std(k);
                        out.push((run.column(row, k) - value) * weight / scale);
                    }
                }
            }
        }
        out.iter().all(|r| r.is_finite()).then_some(out)
    }

    /// The training cost at `x` (infinite if a run fails).
    fn cost(&self, refinement: &Refinement, x: &[f64]) -> f64 {
        self.residuals(refinement, x)
            .map_or(f64::INFINITY, |r| dot(&r, &r))
    }

    /// Levenberg–Marquardt from the start with `gain`: the solution and its cost.
    fn polish(&self, refinement: &Refinement, gain: f64) -> (Solution, f64) {
        let residuals = |x: &[f64]| self.residuals(refinement, x);
        // A wide refinement's forward differences cost a free run per unknown: fewer
        // linearisations (the first ones do most of the work).
        let start = self.start(refinement, gain);
        let linearisations = if start.len() > WIDE {
            WIDE_LINEARISATIONS
        } else {
            LINEARISATIONS
        };
        let (x, cost) = polish_within(&residuals, start, linearisations);
        (self.apply(refinement, &x), cost)
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
    let mut run = Run::of_states(dim, values);
    corrected.simulator.observe_run(record, &mut run, 0);
    Ok(run)
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
