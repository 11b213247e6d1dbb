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
//! and the initial values along a free run ([`super::sensitivity`]). Every run here goes
//! through the one free run ([`crate::solve::ode::free_run`]): its segments are the runs of
//! rows with the same inputs (one row each for a one-step prediction).

use super::FitError;
use crate::eval::{JacobianProgram, Program};
use crate::ir::{Dynamics, Model, Var};
use crate::record::Record;
use crate::solve::ode::{
    free_run, Adaptive, IntegrationError, Integrator, Map, Method, ModelSystem, Observer,
    OdeSystem, Renewal, Segment, Stepper, Tolerances,
};
use std::ops::ControlFlow;

/// Most integration steps between two input switches (or over one interval of a one-step
/// prediction) before a run is declared failed (wild params): a failing run costs no more.
const MAX_STEPS: usize = 20_000;

/// States along a record, row-major: `values[row * dim + k]` is state `k` (measured, then
/// hidden) at that row; with the measured outputs (observables) of the model at each row
/// where the simulator observes them ([`Simulator::observe`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// States per row.
    pub dim: usize,
    /// The values.
    pub values: Vec<f64>,
    /// Measured states per row (the columns before the observables, [`Run::column`]).
    pub measured: usize,
    /// Observables per row.
    pub observables: usize,
    /// The observables, `observed[row * observables + j]`
    /// ([`crate::record::Normalisation::observables`] order; empty where nothing is
    /// observed).
    pub observed: Vec<f64>,
}

impl Run {
    /// A run of states alone (no observable).
    pub fn of_states(dim: usize, values: Vec<f64>) -> Run {
        Run {
            dim,
            values,
            measured: dim,
            observables: 0,
            observed: Vec::new(),
        }
    }

    /// Column `k` at `row` in [`crate::record::Record::columns`] order: a measured state,
    /// then an observable.
    pub fn column(&self, row: usize, k: usize) -> f64 {
        match k.checked_sub(self.measured) {
            None => self.values[row * self.dim + k],
            Some(j) => self.observed[row * self.observables + j],
        }
    }

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
    /// The observables' values and derivatives, where observed.
    pub(super) observation: Option<Observation>,
}

/// The model outputs a fit compares with data columns, compiled with their derivatives by
/// the states and the params (the chain rule onto a run's sensitivities).
#[derive(Debug, Clone)]
pub(super) struct Observation {
    /// Values and derivatives by the state slots, then the param slots.
    pub(super) program: JacobianProgram,
    /// Number of observables.
    pub(super) count: usize,
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
            observation: None,
        })
    }

    /// Computes model outputs `outputs` (indices, in the order of the data's observable
    /// columns) at every row of every run from now on ([`Run::column`]).
    pub fn observe(&mut self, model: &Model, outputs: &[usize]) -> Result<(), FitError> {
        if outputs.is_empty() {
            self.observation = None;
            return Ok(());
        }
        let layout = self.system.layout();
        let wrt: Vec<usize> = (layout.state_range()).chain(layout.param_range()).collect();
        let exprs = outputs.iter().map(|&o| &model.outputs[o].expr);
        let program = JacobianProgram::compile(exprs, layout, &wrt)
            .map_err(|e| FitError::internal(e.to_string()))?;
        self.observation = Some(Observation {
            program,
            count: outputs.len(),
        });
        Ok(())
    }

    /// Fills the observables of `run` (its row `r` at record row `first + r`) from its
    /// states, the record's inputs and the current params; nothing where nothing is
    /// observed.
    pub fn observe_run(&mut self, record: &Record, run: &mut Run, first: usize) {
        let Some(count) = self.observation.as_ref().map(|o| o.count) else {
            return;
        };
        run.observed.clear();
        run.measured = self.measured;
        run.observables = count;
        for row in 0..run.rows() {
            let values = self.observe_state(record, first + row, run.row(row));
            run.observed.extend_from_slice(&values);
        }
    }

    /// The observables at `state` with the inputs of `row` and the current params (and
    /// corrections); empty where nothing is observed.
    pub fn observe_state(&mut self, record: &Record, row: usize, state: &[f64]) -> Vec<f64> {
        let Some(observation) = self.observation.take() else {
            return Vec::new();
        };
        let (count, columns) = (observation.count, observation.program.columns());
        let (mut values, mut jacobian) = (vec![0.0; count], vec![0.0; count * columns]);
        self.load(record, row, state);
        let slots = self.system.slots_mut();
        (observation.program).eval(slots, &mut self.scratch, &mut values, &mut jacobian);
        self.observation = Some(observation);
        values
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

    /// Number of measured states (the model's `state`s; the hidden ones follow them).
    pub(super) fn measured_count(&self) -> usize {
        self.measured
    }

    /// Whether state `k`'s declared initial value reads a param.
    pub(super) fn init_reads_params(&self, k: usize) -> bool {
        self.init_derivatives.structure().any(|(row, _)| row == k)
    }

    /// Number of hidden states.
    pub fn hidden_count(&self) -> usize {
        self.hidden_init.len()
    }

    /// The state a free run of `record` starts from at its first row: a measured state from
    /// `overrides` where given, else from its cell, else from its declared initial value
    /// (else 0, which [`super::split::Split`] never leaves); a hidden state from `overrides`
    /// (after the measured ones) where given, else from its declared initial value; both
    /// under the current params. A measured state with none of these but a declaration
    /// that reads no param, which a first-row observable reads, starts where that
    /// observable puts it ([`super::observed`]).
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
        self.solve_observed_starts(record, overrides, &mut state);
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
        let segment = rows(record, (row, row + 1));
        let how = (Renewal::Restart, None);
        self.run(
            record,
            [segment],
            state,
            how,
            &mut |_: &[f64], _: &[f64]| {},
        )
        .map_err(|error| error.named(&self.names))
    }

    /// Runs `state` over `segments` of `record` with this model's stepper (the integrator
    /// renewed at each as `renewal` says, carrying the sensitivities `s` along where
    /// given), `observer` having its say ([`crate::solve::ode::free_run`]).
    pub(super) fn run<'s, O>(
        &mut self,
        record: &Record,
        segments: impl IntoIterator<Item = Segment<'s>>,
        state: &mut [f64],
        (renewal, s): (Renewal, Option<&mut [f64]>),
        observer: &mut O,
    ) -> Result<(), IntegrationError>
    where
        O: for<'a> Observer<Adaptive<'a>> + for<'a> Observer<Map<'a>>,
    {
        let inputs = &record.inputs;
        match self.dynamics {
            Dynamics::Continuous => {
                let stepper =
                    Adaptive::new(&mut self.integrator, &mut self.system, inputs, renewal);
                let mut stepper = match s {
                    Some(s) => stepper.with_sensitivities(s),
                    None => stepper,
                };
                free_run(&mut stepper, segments, state, observer)
            }
            Dynamics::Discrete => {
                let stepper = Map::new(&mut self.system, inputs);
                let mut stepper = match s {
                    Some(s) => stepper.with_sensitivities(s),
                    None => stepper,
                };
                free_run(&mut stepper, segments, state, observer)
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
        let mut push = |y: &[f64], _: &[f64]| values.extend_from_slice(y);
        let segments = input_runs(record, end);
        self.run(
            record,
            segments,
            &mut state,
            (Renewal::Budget, None),
            &mut push,
        )
        .map_err(|error| error.named(&self.names))?;
        let mut run = Run::of_states(dim, values);
        self.observe_run(record, &mut run, 0);
        Ok(run)
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
        if end > 1 {
            reset_to_cells(record, 0, &mut state);
        }
        let mut steps = OneStep {
            record,
            starts: Vec::new(),
            predictions: Vec::new(),
        };
        let segments = (0..end.saturating_sub(1)).map(|row| rows(record, (row, row + 1)));
        let how = (Renewal::Restart, None);
        self.run(record, segments, &mut state, how, &mut steps)
            .map_err(|error| error.named(&self.names))?;
        let (mut starts, mut predictions) = (
            Run::of_states(dim, steps.starts),
            Run::of_states(dim, steps.predictions),
        );
        self.observe_run(record, &mut starts, 0);
        self.observe_run(record, &mut predictions, 1);
        Ok((starts, predictions))
    }
}

/// One-step predictions along a record: each step starts from the measured cells of its
/// row ([`Simulator::one_step`]).
struct OneStep<'r> {
    record: &'r Record,
    starts: Vec<f64>,
    predictions: Vec<f64>,
}

impl<S: Stepper> Observer<S> for OneStep<'_> {
    fn before(&mut self, _: &Segment<'_>, state: &[f64]) -> Result<(), S::Error> {
        self.starts.extend_from_slice(state);
        Ok(())
    }

    fn sample(&mut self, _: &[f64], _: &[f64]) {}

    fn after(
        &mut self,
        segment: &Segment<'_>,
        state: &mut [f64],
        _: &mut S,
    ) -> Result<ControlFlow<()>, S::Error> {
        self.predictions.extend_from_slice(state);
        reset_to_cells(self.record, segment.index + 1, state);
        Ok(ControlFlow::Continue(()))
    }
}

/// Sets every measured state that `row` of `record` has a cell for to that cell.
fn reset_to_cells(record: &Record, row: usize, state: &mut [f64]) {
    for (k, column) in record.states.iter().enumerate() {
        if let Some(value) = column[row] {
            state[k] = value;
        }
    }
}

/// Rows `first..=last` of `record` as a segment: the inputs of `first` held, every later
/// row sampled.
fn rows(record: &Record, (first, last): (usize, usize)) -> Segment<'_> {
    Segment {
        index: first,
        span: (record.times[first], record.times[last]),
        samples: &record.times[first + 1..=last],
    }
}

/// The segments of a free run over rows `0..end` of `record`: from row 0, each from its
/// first row to the first later row whose inputs differ (or row `end - 1`).
pub(super) fn input_runs(record: &Record, end: usize) -> impl Iterator<Item = Segment<'_>> {
    let mut first = 0;
    std::iter::from_fn(move || {
        if first + 1 >= end {
            return None;
        }
        let mut last = first + 1;
        while last + 1 < end && same_inputs(record, first, last) {
            last += 1;
        }
        let segment = rows(record, (first, last));
        first = last;
        Some(segment)
    })
}

/// The input values held over the interval that starts at `row`.
pub fn inputs_at(record: &Record, row: usize) -> impl Iterator<Item = f64> + '_ {
    record.inputs.iter().map(move |column| column[row])
}

/// Whether the inputs of rows `a` and `b` are the same.
fn same_inputs(record: &Record, a: usize, b: usize) -> bool {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A first-order lag driven by an input that changes at every row (a logged volume, a
    /// pump's rate): each row is its own stretch. The run matches the closed form of every
    /// stretch to the tolerance; the stretches after the first start with the step the one
    /// before was taking, so a slow state costs one step per row (Hairer's cautious start
    /// at each would take two or more); and a second run of the same record takes the same
    /// steps and gives the same numbers (nothing is carried from one run to the next).
    #[test]
    fn an_input_changing_at_every_row_costs_a_step_per_row_and_matches_the_closed_form() {
        let source = "model lag\ninput u\nstate X = 1\nparam tau = 20 positive\n\
                      der X = (u - X) / tau\n";
        let model = crate::driver::compile("lag", source, &[]).unwrap().model;
        let rows = 200;
        let times: Vec<f64> = (0..rows).map(|k| 0.1 * k as f64).collect();
        let input: Vec<f64> = (0..rows).map(|k| 1.0 + 0.5 * (k * 7 % 5) as f64).collect();
        let states = vec![vec![0.0; rows]];
        let mut record = Record::complete("a", times, vec![input.clone()], states);
        record.states[0] = vec![None; rows];
        let mut simulator = Simulator::new(&model, &[], tolerances()).unwrap();
        simulator.set_params(&[20.0]);
        let run = simulator.free_run(&record, &[], rows).unwrap();
        let steps = simulator.integrator.stats().accepted;
        let mut exact = 1.0;
        for row in 1..rows {
            let held = input[row - 1];
            exact = held + (exact - held) * (-0.1_f64 / 20.0).exp();
            let error = (run.row(row)[0] - exact).abs();
            assert!(error < 1e-8 * exact.abs(), "row {row}: {error:e}");
        }
        assert!(steps <= rows + 10, "{steps} steps for {} rows", rows - 1);
        let again = simulator.free_run(&record, &[], rows).unwrap();
        assert_eq!(simulator.integrator.stats().accepted, 2 * steps);
        assert_eq!(again, run);
    }
}
