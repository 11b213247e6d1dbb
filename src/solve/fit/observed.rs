//! Starts read through observables: a state that an experiment does not measure at its
//! first row, and whose declared start is a fixed guess, starts where the first row's
//! observables put it, as a measured state starts at its first cell.
//!
//! A state qualifies in one experiment when the experiment has no first cell for it, no
//! fitted or fixed start overrides it, its declared initial value reads no `param` (a
//! start written as a param is already an unknown of the fit, with the observables' cells
//! among its residuals), and an observable measured at the first row reads it and no other
//! state that qualifies (an optical density `OD = X / k_OD` gives the biomass's start; a
//! dissolved-oxygen signal that reads biomass and substrate gives neither). The state is
//! then the least-squares solution, by Gauss–Newton in that one value, of its observables'
//! first-row cells, each weighted by the inverse square of its cell's size; the others
//! stay where they are. Its sensitivities at the start follow from the implicit function
//! theorem: how the observables move with the params and the other states' starts, divided
//! by how they move with it.

use super::simulate::Simulator;
use crate::record::Record;

/// Most Gauss–Newton iterations of one start.
const ITERATIONS: usize = 50;

/// One state whose start the first row's observables give.
#[derive(Debug, Clone, PartialEq)]
struct ObservedStart {
    /// The state (model order).
    state: usize,
    /// The observables that read it, with their first-row cells.
    cells: Vec<(usize, f64)>,
}

impl Simulator {
    /// Moves the states of `state` (the start of a free run of `record` under
    /// `overrides`) that the first row's observables give (see the module documentation).
    pub(super) fn solve_observed_starts(
        &mut self,
        record: &Record,
        overrides: &[Option<f64>],
        state: &mut [f64],
    ) {
        for start in self.observed_starts(record, overrides) {
            if let Some(value) = self.solve_one(record, &start, state) {
                state[start.state] = value;
            }
        }
    }

    /// The states of `record` that start where the first row's observables put them
    /// under `overrides` (model order).
    pub fn observed_start_states(&self, record: &Record, overrides: &[Option<f64>]) -> Vec<usize> {
        (self.observed_starts(record, overrides).iter())
            .map(|start| start.state)
            .collect()
    }

    /// The sensitivities (`columns` per state, row-major) at the start `state` of the
    /// states the first row's observables give: the derivative of each observable by the
    /// columns through everything but the state, divided by its derivative by the state
    /// (weighted least squares over its observables).
    pub(super) fn observed_start_sensitivities(
        &mut self,
        record: &Record,
        overrides: &[Option<f64>],
        state: &[f64],
        s: &mut [f64],
    ) {
        let starts = self.observed_starts(record, overrides);
        if starts.is_empty() {
            return;
        }
        let Some(observation) = self.observation.take() else {
            return;
        };
        let (count, dim) = (observation.count, state.len());
        let columns = s.len() / dim.max(1);
        let (mut values, mut jacobian) = (
            vec![0.0; count],
            vec![0.0; count * observation.program.columns()],
        );
        self.load(record, 0, state);
        let slots = self.system.slots_mut();
        (observation.program).eval(slots, &mut self.scratch, &mut values, &mut jacobian);
        for start in &starts {
            s[start.state * columns..(start.state + 1) * columns].fill(0.0);
        }
        let mut through = vec![0.0; count * columns];
        let slots = self.system.slots_mut();
        (observation.program).eval_product(slots, &mut self.scratch, s, columns, &mut through);
        let width = observation.program.columns();
        for start in &starts {
            let (mut curvature, mut row) = (0.0, vec![0.0; columns]);
            for &(j, cell) in &start.cells {
                let (w, slope) = (weight(cell), jacobian[j * width + start.state]);
                curvature += w * slope * slope;
                for (r, &t) in row.iter_mut().zip(&through[j * columns..(j + 1) * columns]) {
                    *r -= w * slope * t;
                }
            }
            if curvature > 0.0 && curvature.is_finite() {
                let target = &mut s[start.state * columns..(start.state + 1) * columns];
                for (t, r) in target.iter_mut().zip(row) {
                    *t = r / curvature;
                }
            }
        }
        self.observation = Some(observation);
    }

    /// The states of `record` whose start the first row's observables give, under
    /// `overrides` (see the module documentation).
    fn observed_starts(&self, record: &Record, overrides: &[Option<f64>]) -> Vec<ObservedStart> {
        let Some(observation) = self.observation.as_ref() else {
            return Vec::new();
        };
        let open: Vec<bool> = (0..self.measured_count())
            .map(|k| {
                overrides.get(k).copied().flatten().is_none()
                    && record.states[k].first().copied().flatten().is_none()
                    && !self.init_reads_params(k)
            })
            .collect();
        let mut starts: Vec<ObservedStart> = Vec::new();
        for (j, observable) in record
            .observables
            .iter()
            .enumerate()
            .take(observation.count)
        {
            let Some(cell) = observable.cells.first().copied().flatten() else {
                continue;
            };
            let read: Vec<usize> = (observation.program.structure())
                .filter(|&(row, column)| row == j && column < open.len() && open[column])
                .map(|(_, column)| column)
                .collect();
            let [state] = read[..] else { continue };
            match starts.iter_mut().find(|s| s.state == state) {
                Some(start) => start.cells.push((j, cell)),
                None => starts.push(ObservedStart {
                    state,
                    cells: vec![(j, cell)],
                }),
            }
        }
        starts
    }

    /// The value of `start.state` that fits its observables' first-row cells, the other
    /// states at `state`; `None` where no finite solution is found.
    fn solve_one(&mut self, record: &Record, start: &ObservedStart, state: &[f64]) -> Option<f64> {
        let mut trial = state.to_vec();
        let k = start.state;
        let mut cost = self.observed_cost(record, start, &trial)?.0;
        for _ in 0..ITERATIONS {
            let (_, step) = self.observed_cost(record, start, &trial)?;
            let x = trial[k];
            let mut accepted = false;
            let mut scale = 1.0;
            for _ in 0..30 {
                trial[k] = x + scale * step;
                match self.observed_cost(record, start, &trial) {
                    Some((c, _)) if c <= cost => {
                        cost = c;
                        accepted = true;
                        break;
                    }
                    _ => scale *= 0.5,
                }
            }
            if !accepted {
                trial[k] = x;
                break;
            }
            if (trial[k] - x).abs() <= 1e-13 * (1.0 + x.abs()) || cost == 0.0 {
                break;
            }
        }
        trial[k].is_finite().then_some(trial[k])
    }

    /// The weighted squared misfit of `start`'s observables at `state`, and the
    /// Gauss–Newton step of its state; `None` where not finite.
    fn observed_cost(
        &mut self,
        record: &Record,
        start: &ObservedStart,
        state: &[f64],
    ) -> Option<(f64, f64)> {
        let observation = self.observation.take()?;
        let width = observation.program.columns();
        let (mut values, mut jacobian) = (
            vec![0.0; observation.count],
            vec![0.0; observation.count * width],
        );
        self.load(record, 0, state);
        let slots = self.system.slots_mut();
        (observation.program).eval(slots, &mut self.scratch, &mut values, &mut jacobian);
        self.observation = Some(observation);
        let (mut cost, mut gradient, mut curvature) = (0.0, 0.0, 0.0);
        for &(j, cell) in &start.cells {
            let (w, residual, slope) = (
                weight(cell),
                values[j] - cell,
                jacobian[j * width + start.state],
            );
            cost += w * residual * residual;
            gradient += w * slope * residual;
            curvature += w * slope * slope;
        }
        let step = if curvature > 0.0 {
            -gradient / curvature
        } else {
            0.0
        };
        (cost.is_finite() && step.is_finite()).then_some((cost, step))
    }
}

/// The weight of an observable's cell: the inverse square of its size (a relative misfit),
/// bounded for a cell at zero.
fn weight(cell: f64) -> f64 {
    1.0 / cell.abs().max(1e-12).powi(2)
}
