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

use super::simulate::{input_runs, Run, Simulator};
use crate::record::Record;
use crate::solve::ode::{IntegrationError, Observer, OdeSystem, Renewal, Segment, Stepper};

/// The sensitivities of a free run, row by row.
#[derive(Debug, Clone, PartialEq)]
pub struct RunSensitivities {
    /// States per row.
    pub dim: usize,
    /// Columns per state: the params, then one per state's initial value.
    pub columns: usize,
    /// `values[(row * dim + state) * columns + column]`.
    pub values: Vec<f64>,
    /// Measured states per row (the data columns before the observables).
    pub measured: usize,
    /// Observables per row.
    pub observables: usize,
    /// The observables' derivatives, `observed[(row * observables + j) * columns + column]`
    /// (empty where nothing is observed).
    pub observed: Vec<f64>,
}

impl RunSensitivities {
    /// The derivatives of `state` at `row` by every column.
    pub fn at(&self, row: usize, state: usize) -> &[f64] {
        let start = (row * self.dim + state) * self.columns;
        &self.values[start..start + self.columns]
    }

    /// The derivatives of data column `k` at `row` (a measured state, then an observable,
    /// [`crate::record::Record::columns`] order) by every column.
    pub fn column_at(&self, row: usize, k: usize) -> &[f64] {
        match k.checked_sub(self.measured) {
            None => self.at(row, k),
            Some(j) => {
                let start = (row * self.observables + j) * self.columns;
                &self.observed[start..start + self.columns]
            }
        }
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
        self.observed_start_sensitivities(record, overrides, &state, &mut s);
        let (dim, columns) = (state.len(), s.len() / state.len().max(1));
        let mut sensitive = Sensitive {
            run: Run::of_states(dim, state.clone()),
            sensitivities: RunSensitivities {
                dim,
                columns,
                values: s.clone(),
                measured: dim,
                observables: 0,
                observed: Vec::new(),
            },
        };
        let how = (Renewal::Budget, Some(&mut s[..]));
        let segments = input_runs(record, end);
        self.run(record, segments, &mut state, how, &mut sensitive)?;
        let Sensitive {
            mut run,
            mut sensitivities,
        } = sensitive;
        self.observe_run(record, &mut run, 0);
        self.observe_sensitivities(record, &run, &mut sensitivities);
        Ok((run, sensitivities))
    }

    /// The observables' derivatives at every row of `run` by the chain rule: their
    /// derivatives by the states times the states' sensitivities, plus their own by the
    /// params (none where nothing is observed).
    fn observe_sensitivities(
        &mut self,
        record: &Record,
        run: &Run,
        sensitivities: &mut RunSensitivities,
    ) {
        let Some(observation) = self.observation.take() else {
            return;
        };
        let (dim, columns) = (sensitivities.dim, sensitivities.columns);
        let mut out = vec![0.0; observation.count * columns];
        sensitivities.measured = run.measured;
        sensitivities.observables = observation.count;
        sensitivities.observed.clear();
        for row in 0..run.rows() {
            self.load(record, row, run.row(row));
            let m = &sensitivities.values[row * dim * columns..(row + 1) * dim * columns];
            let slots = self.system.slots_mut();
            (observation.program).eval_product(slots, &mut self.scratch, m, columns, &mut out);
            sensitivities.observed.extend_from_slice(&out);
        }
        self.observation = Some(observation);
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

/// What a sensitive run keeps: the states and their sensitivities at every row.
struct Sensitive {
    run: Run,
    sensitivities: RunSensitivities,
}

impl<S: Stepper<Error = IntegrationError>> Observer<S> for Sensitive {
    /// A fit asked to stop needs no more derivatives ([`crate::stop`]).
    fn before(&mut self, segment: &Segment<'_>, _: &[f64]) -> Result<(), IntegrationError> {
        if crate::stop::requested() {
            return Err(IntegrationError::Stopped { t: segment.span.0 });
        }
        Ok(())
    }

    fn sample(&mut self, state: &[f64], sensitivities: &[f64]) {
        self.run.values.extend_from_slice(state);
        self.sensitivities.values.extend_from_slice(sensitivities);
    }
}
