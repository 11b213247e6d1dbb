//! Free runs with their forward sensitivities: how every state at every row moves with
//! every param and with every state's initial value. The fits' Jacobians are read off
//! these ([`super::fitter::Objective::jacobian`]) instead of differencing free runs: one
//! integration per experiment instead of one per unknown, and derivatives of the very
//! solution the residuals come from (the integrator's own steps, `crate::solve::ode::sensitivity`).
//!
//! Columns: the model's params (declaration order), then the initial values of the states
//! asked for (those whose start is an unknown of the fit). A state that starts from its
//! declared initial value starts with that expression's derivatives by the params; a state
//! asked for starts with a unit entry in its own initial-value column.

use super::simulate::{same_inputs, Run, Simulator};
use crate::ir::Dynamics;
use crate::record::Record;
use crate::solve::ode::{IntegrationError, OdeSystem};

/// The sensitivities of a free run, row by row.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSensitivities {
    /// States per row.
    pub dim: usize,
    /// Columns per state: the params, then one per state's initial value.
    pub columns: usize,
    /// `values[(row * dim + state) * columns + column]`.
    pub values: Vec<f64>,
}

impl RunSensitivities {
    /// The derivatives of `state` at `row` by every column.
    pub fn at(&self, row: usize, state: usize) -> &[f64] {
        let start = (row * self.dim + state) * self.columns;
        &self.values[start..start + self.columns]
    }
}

impl Simulator {
    /// The free run of [`Simulator::free_run`] and its sensitivities at every row, by the
    /// params and by the initial values of the states in `initial` (in that order).
    pub fn sensitive_run(
        &mut self,
        record: &Record,
        overrides: &[Option<f64>],
        end: usize,
        initial: &[usize],
    ) -> Result<(Run, RunSensitivities), IntegrationError> {
        self.integrator.restart();
        self.system.set_extra_columns(initial.len());
        let mut state = self.start_state(record, overrides);
        let mut s = self.initial_sensitivities(record, overrides, initial);
        let (dim, columns) = (state.len(), s.len() / state.len().max(1));
        let mut run = Run {
            dim,
            values: state.clone(),
        };
        let mut sensitivities = RunSensitivities {
            dim,
            columns,
            values: s.clone(),
        };
        let mut first = 0;
        while first + 1 < end {
            // A fit asked to stop needs no more derivatives ([`crate::stop`]).
            if crate::stop::requested() {
                return Err(IntegrationError::Stopped {
                    t: record.times[first],
                });
            }
            let mut last = first + 1;
            while last + 1 < end && same_inputs(record, first, last) {
                last += 1;
            }
            let rows = (first, last);
            let (runs, sens) = (&mut run.values, &mut sensitivities.values);
            let mut push = |y: &[f64], s: &[f64]| {
                runs.extend_from_slice(y);
                sens.extend_from_slice(s);
            };
            self.integrator.renew_budget();
            self.advance_sensitive(record, rows, (&mut state, &mut s), &mut push)?;
            first = last;
        }
        Ok((run, sensitivities))
    }

    /// Advances `state` and its sensitivities `s` from `rows.0` to `rows.1` with the inputs
    /// of `rows.0`, calling `push` at every row after the first.
    fn advance_sensitive(
        &mut self,
        record: &Record,
        (first, last): (usize, usize),
        (state, s): (&mut [f64], &mut [f64]),
        push: &mut dyn FnMut(&[f64], &[f64]),
    ) -> Result<(), IntegrationError> {
        self.load(record, first, state);
        if self.dynamics == Dynamics::Discrete {
            return self.map_sensitive(record, (first, last), (state, s), push);
        }
        let times = &record.times[first + 1..=last];
        let span = (record.times[first], record.times[last]);
        self.integrator.integrate_with_sensitivities(
            &mut self.system,
            span,
            state,
            s,
            times,
            |_, y, s| push(y, s),
        )
    }

    /// A discrete model's map once per row, with `S <- J S + f_p`.
    fn map_sensitive(
        &mut self,
        record: &Record,
        (first, last): (usize, usize),
        (state, s): (&mut [f64], &mut [f64]),
        push: &mut dyn FnMut(&[f64], &[f64]),
    ) -> Result<(), IntegrationError> {
        let (n, p) = (state.len(), s.len() / state.len().max(1));
        let (mut next, mut moved) = (vec![0.0; n], vec![0.0; n * p]);
        let (mut states, mut params) = (vec![0.0; n * n], vec![0.0; n * p]);
        for row in first..last {
            let t = record.times[row];
            self.system.rhs(t, state, &mut next);
            self.system
                .sensitivity_jacobians(t, state, &mut states, &mut params);
            crate::solve::ode::sensitivity::multiply_add(&states, s, &params, n, p, &mut moved);
            if next.iter().chain(&moved).any(|v| !v.is_finite()) {
                return Err(IntegrationError::non_finite(record.times[row + 1]));
            }
            state.copy_from_slice(&next);
            s.copy_from_slice(&moved);
            push(state, s);
        }
        Ok(())
    }

    /// The sensitivities a free run of `record` starts with (see the module documentation).
    fn initial_sensitivities(
        &mut self,
        record: &Record,
        overrides: &[Option<f64>],
        initial: &[usize],
    ) -> Vec<f64> {
        let dim = self.system.dim();
        let params = self.params();
        let columns = params + initial.len();
        let mut derivatives = vec![0.0; dim * params];
        let mut values = vec![0.0; dim];
        let program = &self.init_derivatives;
        program.eval(
            self.system.slots_mut(),
            &mut self.scratch,
            &mut values,
            &mut derivatives,
        );
        let measured = record.states.len();
        let mut s = vec![0.0; dim * columns];
        for k in 0..dim {
            let overridden = overrides.get(k).copied().flatten().is_some();
            let from_cell = k < measured && record.states[k].first().copied().flatten().is_some();
            if !overridden && !from_cell {
                let row = &derivatives[k * params..(k + 1) * params];
                s[k * columns..k * columns + params].copy_from_slice(row);
            }
        }
        for (column, &k) in initial.iter().enumerate() {
            s[k * columns + params + column] = 1.0;
        }
        s
    }
}
