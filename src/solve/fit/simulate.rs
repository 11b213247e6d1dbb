//! Running a mechanistic model along an experiment's record (spec section 5, records spec
//! section 3): the *free run* from the first row (measured states from their cells there,
//! else as [`super::split::Start`] says; hidden states from their declared initial values;
//! driven by the data's inputs alone) and *one-step* predictions from the measured history.
//!
//! Rows may be irregularly spaced and cells missing. Inputs are held from each row to the
//! next (zero-order hold, as the record holds them). Continuous models are integrated by
//! [`crate::solve::ode::Integrator`] (Dormand–Prince, Radau IIA where the balances are stiff),
//! which reports the state at every row's time whatever the spacing, restarted wherever an
//! input changes; discrete models apply their map once per row. Optional *correction* slots
//! (outputs of a synthesised closure: the loci of `crate::diagnose`) are held constant over each
//! interval. [`Simulator::sensitive_run`] carries the forward sensitivities to the params
//! and the initial values along a free run ([`super::sensitivity`]).

use super::FitError;
use crate::eval::{JacobianProgram, Program};
use crate::ir::{Dynamics, Model, Var};
use crate::record::Record;
use crate::solve::ode::{IntegrationError, Integrator, Method, ModelSystem, OdeSystem, Tolerances};

/// Most integration steps between two input switches (or over one interval of a one-step
/// prediction) before a run is declared failed (wild params): a failing run costs no more.
const MAX_STEPS: usize = 20_000;

/// States along a record, row-major: `values[row * dim + k]` is state `k` (measured, then
/// hidden) at that row.
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// States per row.
    pub dim: usize,
    /// The values.
    pub values: Vec<f64>,
}

impl Run {
    /// The state at `row`.
    pub fn row(&self, row: usize) -> &[f64] {
        &self.values[row * self.dim..(row + 1) * self.dim]
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.values.len() / self.dim.max(1)
    }
}

/// A compiled model ready to run along records with chosen param values.
#[derive(Debug, Clone)]
pub struct Simulator {
    pub(super) system: ModelSystem,
    pub(super) dynamics: Dynamics,
    measured_init: Vec<Option<Program>>,
    hidden_init: Vec<Program>,
    /// The declared initial values and their derivatives by the params (measured states
    /// without a declaration give zero rows).
    pub(super) init_derivatives: JacobianProgram,
    measured: usize,
    params: usize,
    correction_slots: Vec<usize>,
    pub(super) integrator: Integrator,
    tolerances: Tolerances,
    pub(super) scratch: Vec<f64>,
    names: Vec<String>,
}

impl Simulator {
    /// Compiles `model`; `corrections` are the closure outputs whose slots
    /// [`Simulator::set_corrections`] writes (none for a plain mechanistic model).
    pub fn new(
        model: &Model,
        corrections: &[Var],
        tolerances: Tolerances,
    ) -> Result<Self, FitError> {
        let internal = |e: crate::eval::CompileError| FitError::internal(e.to_string());
        let mut system = ModelSystem::new(model).map_err(internal)?;
        let params: Vec<usize> = system.layout().param_range().collect();
        let dim = system.dim();
        system
            .differentiate_by(model, &params, dim)
            .map_err(internal)?;
        let zero = crate::ir::Expr::Num(0.0);
        let inits = (model.states.iter().chain(&model.hidden))
            .map(|state| state.init.as_ref().unwrap_or(&zero));
        let init_derivatives =
            JacobianProgram::compile(inits, system.layout(), &params).map_err(internal)?;
        let hidden_init = (model.hidden.iter())
            .map(|state| match &state.init {
                Some(init) => Program::compile(init, system.layout()).map_err(internal),
                None => Err(FitError::MissingInitial {
                    state: state.name.clone(),
                }),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let measured_init = (model.states.iter())
            .map(|state| {
                (state.init.as_ref())
                    .map(|init| Program::compile(init, system.layout()).map_err(internal))
                    .transpose()
            })
            .collect::<Result<Vec<_>, _>>()?;
        let correction_slots = (corrections.iter())
            .map(|&var| system.layout().slot(var))
            .collect();
        let names = (model.states.iter().chain(&model.hidden))
            .map(|state| state.name.clone())
            .collect();
        Ok(Simulator {
            integrator: Integrator::new(dim, tolerances, MAX_STEPS, Method::Auto),
            tolerances,
            init_derivatives,
            names,
            dynamics: model.dynamics,
            measured: model.states.len(),
            params: model.params.len(),
            measured_init,
            hidden_init,
            correction_slots,
            system,
            scratch: Vec::new(),
        })
    }

    /// Integrates with `method` from now on.
    pub fn set_method(&mut self, method: Method) {
        let dim = self.system.dim();
        self.integrator = Integrator::new(dim, self.tolerances, MAX_STEPS, method);
    }

    /// Implicit steps taken since the simulator was made (or its method set).
    pub fn implicit_steps(&self) -> usize {
        self.integrator.stats().implicit
    }

    /// Compiles an expression of this model (e.g. a let's value) against its slots.
    pub fn compile(&self, expr: &crate::ir::Expr) -> Result<Program, FitError> {
        Program::compile(expr, self.system.layout()).map_err(|e| FitError::internal(e.to_string()))
    }

    /// Sets the params (constrained values, declaration order) from the first entries of
    /// `values` (what follows, the fitted starts, is not the simulator's).
    pub fn set_params(&mut self, values: &[f64]) {
        let range = self.system.layout().param_range();
        let count = self.params.min(values.len());
        self.system.slots_mut()[range.start..range.start + count].copy_from_slice(&values[..count]);
    }

    /// Number of params.
    pub fn params(&self) -> usize {
        self.params
    }

    /// Sets the corrections held over the next interval, one per slot (missing ones 0).
    pub fn set_corrections(&mut self, values: &[f64]) {
        for (index, &slot) in self.correction_slots.iter().enumerate() {
            self.system.slots_mut()[slot] = values.get(index).copied().unwrap_or(0.0);
        }
    }

    /// Clears every correction.
    pub fn clear_corrections(&mut self) {
        self.set_corrections(&[]);
    }

    /// Number of hidden states.
    pub fn hidden_count(&self) -> usize {
        self.hidden_init.len()
    }

    /// The state a free run of `record` starts from at its first row: a measured state from
    /// `overrides` where given, else from its cell, else from its declared initial value
    /// (else 0, which [`super::split::Split`] never leaves); a hidden state from `overrides`
    /// (after the measured ones) where given, else from its declared initial value; both
    /// under the current params.
    pub fn start_state(&mut self, record: &Record, overrides: &[Option<f64>]) -> Vec<f64> {
        let mut state = Vec::with_capacity(self.measured + self.hidden_init.len());
        for k in 0..self.measured {
            let cell = record.states[k].first().copied().flatten();
            let value = match (
                overrides.get(k).copied().flatten(),
                cell,
                &self.measured_init[k],
            ) {
                (Some(value), _, _) | (None, Some(value), _) => value,
                (None, None, Some(init)) => init.eval(self.system.slots_mut(), &mut self.scratch),
                (None, None, None) => 0.0,
            };
            state.push(value);
        }
        for (h, init) in self.hidden_init.iter().enumerate() {
            let value = match overrides.get(self.measured + h).copied().flatten() {
                Some(value) => value,
                None => init.eval(self.system.slots_mut(), &mut self.scratch),
            };
            state.push(value);
        }
        state
    }

    /// Evaluates `program` (compiled against this model's layout) at `state` with the
    /// inputs of `row`.
    pub fn evaluate(
        &mut self,
        program: &Program,
        record: &Record,
        row: usize,
        state: &[f64],
    ) -> f64 {
        self.load(record, row, state);
        program.eval(self.system.slots_mut(), &mut self.scratch)
    }

    /// Loads the inputs of `row` and `state` into the slots.
    pub(super) fn load(&mut self, record: &Record, row: usize, state: &[f64]) {
        let layout = self.system.layout();
        let (inputs, states) = (layout.input_range(), layout.state_range());
        let slots = self.system.slots_mut();
        for (slot, value) in slots[inputs].iter_mut().zip(inputs_at(record, row)) {
            *slot = value;
        }
        slots[states].copy_from_slice(state);
    }

    /// Advances `state` over the interval from `row` to `row + 1`, as a run of its own
    /// (a whole step budget, the method choice from the start: a one-interval run is
    /// rarely long enough to repay the implicit method).
    pub fn step(
        &mut self,
        record: &Record,
        row: usize,
        state: &mut [f64],
    ) -> Result<(), IntegrationError> {
        self.integrator.restart();
        self.advance(record, (row, row + 1), state, &mut |_, _| {})
    }

    /// Advances `state` from `rows.0` to `rows.1`, inputs held at their `rows.0` values,
    /// calling `record_row(row, state)` at every row after the first.
    fn advance(
        &mut self,
        record: &Record,
        (first, last): (usize, usize),
        state: &mut [f64],
        record_row: &mut dyn FnMut(usize, &[f64]),
    ) -> Result<(), IntegrationError> {
        self.load(record, first, state);
        match self.dynamics {
            Dynamics::Continuous => {
                let times = &record.times[first + 1..=last];
                let span = (record.times[first], record.times[last]);
                self.integrator
                    .integrate(&mut self.system, span, state, times, |k, y| {
                        record_row(first + 1 + k, y)
                    })
                    .map_err(|error| error.named(&self.names))
            }
            Dynamics::Discrete => {
                let mut next = vec![0.0; state.len()];
                for row in first..last {
                    self.system.rhs(record.times[row], state, &mut next);
                    if next.iter().any(|v| !v.is_finite()) {
                        return Err(IntegrationError::non_finite(record.times[row + 1]));
                    }
                    state.copy_from_slice(&next);
                    record_row(row + 1, state);
                }
                Ok(())
            }
        }
    }

    /// The free run from row 0 to row `end - 1` of `record` (starts as in
    /// [`Simulator::start_state`]), integrating between input switches in one go.
    pub fn free_run(
        &mut self,
        record: &Record,
        overrides: &[Option<f64>],
        end: usize,
    ) -> Result<Run, IntegrationError> {
        self.integrator.restart();
        let mut state = self.start_state(record, overrides);
        let dim = state.len();
        let mut values = Vec::with_capacity(end * dim);
        values.extend_from_slice(&state);
        let mut first = 0;
        while first + 1 < end {
            let mut last = first + 1;
            while last + 1 < end && same_inputs(record, first, last) {
                last += 1;
            }
            let mut push = |_: usize, y: &[f64]| values.extend_from_slice(y);
            self.integrator.renew_budget();
            self.advance(record, (first, last), &mut state, &mut push)?;
            first = last;
        }
        Ok(Run { dim, values })
    }

    /// One-step predictions along rows `0..end - 1`: from row `i`'s measured cells (and,
    /// for a state not measured there and the hidden states, the value carried along this
    /// way from the free run's start), the state at row `i + 1`. Returns the states each
    /// step starts from and the predictions.
    pub fn one_step(
        &mut self,
        record: &Record,
        overrides: &[Option<f64>],
        end: usize,
    ) -> Result<(Run, Run), IntegrationError> {
        self.integrator.restart();
        let mut state = self.start_state(record, overrides);
        let dim = state.len();
        let (mut starts, mut predictions) = (Vec::new(), Vec::new());
        for row in 0..end.saturating_sub(1) {
            for (k, column) in record.states.iter().enumerate() {
                if let Some(value) = column[row] {
                    state[k] = value;
                }
            }
            starts.extend_from_slice(&state);
            self.step(record, row, &mut state)?;
            predictions.extend_from_slice(&state);
        }
        let run = |values| Run { dim, values };
        Ok((run(starts), run(predictions)))
    }
}

/// The input values held over the interval that starts at `row`.
pub fn inputs_at(record: &Record, row: usize) -> impl Iterator<Item = f64> + '_ {
    record.inputs.iter().map(move |column| column[row])
}

/// Whether the inputs of rows `a` and `b` are the same.
pub(super) fn same_inputs(record: &Record, a: usize, b: usize) -> bool {
    record.inputs.iter().all(|column| column[a] == column[b])
}

/// Tolerances of every run: tight enough that integration error stays far below any
/// measurement noise and finite differences through the simulator stay smooth.
pub fn tolerances() -> Tolerances {
    Tolerances {
        rtol: 1e-8,
        atol: 1e-12,
    }
}
