//! From a model and its input signals to a sampled [`Trajectory`].

use super::{Integrator, OdeSystem, SimError, SimOptions, Stats, Trajectory};
use crate::eval::{CompileError, CompiledRhs, JacobianProgram, Layout, Program, ProgramSet};
use crate::ir::{Dynamics, Model};
use crate::signal::Signal;
use std::ops::Range;

/// Most samples one simulation may record.
const MAX_SAMPLES: usize = 100_000_000;

/// A model's balances as an [`OdeSystem`] (or, for a `next` model, as its map): the states
/// are the measured then hidden states, and the other slots (inputs, params) are held at
/// whatever they were last set to. Its Jacobian is the exact derivative of the balances
/// ([`JacobianProgram`]); forward sensitivities are taken with respect to the slots given
/// to [`ModelSystem::differentiate_by`].
#[derive(Debug, Clone)]
pub struct ModelSystem {
    layout: Layout,
    rhs: CompiledRhs,
    jacobian: JacobianProgram,
    sensitivity: Option<JacobianProgram>,
    extra: usize,
    slots: Vec<f64>,
    scratch: Vec<f64>,
    values: Vec<f64>,
    combined: Vec<f64>,
    states: Range<usize>,
}

impl ModelSystem {
    /// Compiles the balances of `model` and their Jacobian; params start at their initial
    /// values, inputs at 0.
    pub fn new(model: &Model) -> Result<Self, CompileError> {
        let layout = Layout::new(model);
        let rhs = CompiledRhs::new(model, &layout)?;
        let states: Vec<usize> = layout.state_range().collect();
        let jacobian = JacobianProgram::balances(model, &layout, &states)?;
        Ok(ModelSystem {
            slots: layout.initial_slots(),
            states: layout.state_range(),
            values: vec![0.0; states.len()],
            layout,
            rhs,
            jacobian,
            sensitivity: None,
            extra: 0,
            scratch: Vec::new(),
            combined: Vec::new(),
        })
    }

    /// Takes forward sensitivities with respect to the quantities in `slots` (params,
    /// closure outputs held as corrections, ...) from now on, followed by `extra` columns
    /// that the balances do not depend on (initial values: their sensitivities only start
    /// non-zero).
    pub fn differentiate_by(
        &mut self,
        model: &Model,
        slots: &[usize],
        extra: usize,
    ) -> Result<(), CompileError> {
        let wrt: Vec<usize> = self.states.clone().chain(slots.iter().copied()).collect();
        self.sensitivity = Some(JacobianProgram::balances(model, &self.layout, &wrt)?);
        self.extra = extra;
        Ok(())
    }

    /// The slot layout of the model.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// Sets the number of columns after the differentiated slots that the balances do not
    /// depend on (see [`ModelSystem::differentiate_by`]).
    pub fn set_extra_columns(&mut self, extra: usize) {
        self.extra = extra;
    }

    /// All slots, e.g. to set params before integrating.
    pub fn slots_mut(&mut self) -> &mut [f64] {
        &mut self.slots
    }

    /// Holds every input at the value its signal has at time `t` (one signal per input).
    pub fn hold_inputs(&mut self, signals: &[Signal], t: f64) {
        for (slot, signal) in self.slots[self.layout.input_range()]
            .iter_mut()
            .zip(signals)
        {
            *slot = signal.value_at(t);
        }
    }
}

impl OdeSystem for ModelSystem {
    fn dim(&self) -> usize {
        self.rhs.dim()
    }

    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) {
        self.slots[self.states.clone()].copy_from_slice(y);
        self.rhs.eval(&self.slots, &mut self.scratch, dydt);
    }

    fn jacobian(&mut self, _t: f64, y: &[f64], jacobian: &mut [f64]) {
        self.slots[self.states.clone()].copy_from_slice(y);
        let (slots, scratch, values) = (&self.slots, &mut self.scratch, &mut self.values);
        self.jacobian.eval(slots, scratch, values, jacobian);
    }

    fn sensitivity_params(&self) -> usize {
        (self.sensitivity.as_ref()).map_or(0, |program| {
            program.columns() - self.states.len() + self.extra
        })
    }

    fn sensitivity_derivative(&mut self, _t: f64, y: &[f64], s: &[f64], out: &mut [f64]) {
        let width = self.sensitivity_params();
        match &self.sensitivity {
            Some(program) => {
                self.slots[self.states.clone()].copy_from_slice(y);
                program.eval_product(&self.slots, &mut self.scratch, s, width, out);
            }
            None => out.fill(0.0),
        }
    }

    fn sensitivity_jacobians(&mut self, t: f64, y: &[f64], states: &mut [f64], params: &mut [f64]) {
        let Some(program) = &self.sensitivity else {
            return self.jacobian(t, y, states);
        };
        self.slots[self.states.clone()].copy_from_slice(y);
        let (n, columns) = (self.states.len(), program.columns());
        self.combined.resize(n * columns, 0.0);
        program.eval(
            &self.slots,
            &mut self.scratch,
            &mut self.values,
            &mut self.combined,
        );
        let (slots, p) = (columns - n, columns - n + self.extra);
        for i in 0..n {
            let row = &self.combined[i * columns..(i + 1) * columns];
            states[i * n..(i + 1) * n].copy_from_slice(&row[..n]);
            params[i * p..i * p + slots].copy_from_slice(&row[n..]);
            params[i * p + slots..(i + 1) * p].fill(0.0);
        }
    }
}

/// Simulates a model without closures driven by `inputs` (one signal per model input, in
/// declaration order). Params take their initial values.
pub fn simulate(
    model: &Model,
    inputs: &[Signal],
    options: &SimOptions,
) -> Result<Trajectory, SimError> {
    simulate_with_progress(model, inputs, options, &mut |_, _| {})
}

/// [`simulate`], calling `progress(done, total)` after each recorded sample, with the
/// number of samples recorded so far and in all (for progress bars).
pub fn simulate_with_progress(
    model: &Model,
    inputs: &[Signal],
    options: &SimOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Trajectory, SimError> {
    check_model(model, inputs)?;
    let times = sample_times(options)?;
    let mut system = ModelSystem::new(model)?;
    let mut state = initial_state(model, system.layout(), &options.initial)?;
    let mut columns = vec![Vec::with_capacity(times.len()); state.len()];
    let mut record = |k: usize, values: &[f64]| {
        for (column, value) in columns.iter_mut().zip(values) {
            column.push(*value);
        }
        progress(k + 1, times.len());
    };
    let run = Run {
        inputs,
        options,
        times: &times,
    };
    let stats = match model.dynamics {
        Dynamics::Continuous => run.continuous(&mut system, &mut state, &mut record),
        Dynamics::Discrete => run.discrete(&mut system, &mut state, &mut record),
    }
    .map_err(|error| match error {
        SimError::Integration(error) => {
            let names: Vec<String> = (model.states.iter().chain(&model.hidden))
                .map(|state| state.name.clone())
                .collect();
            SimError::Integration(error.named(&names))
        }
        other => other,
    })?;
    let hidden = columns.split_off(model.states.len());
    let algebraic = evaluate_algebraic(model, system.layout(), inputs, &times, &columns, &hidden)?;
    Ok(Trajectory {
        times,
        inputs: algebraic.inputs,
        states: columns,
        hidden,
        outputs: algebraic.outputs,
        lets: algebraic.lets,
        stats,
    })
}

/// One simulation's fixed arguments.
struct Run<'a> {
    inputs: &'a [Signal],
    options: &'a SimOptions,
    times: &'a [f64],
}

impl Run<'_> {
    /// Integrates from input switch to input switch, sampling from the dense output.
    fn continuous(
        &self,
        system: &mut ModelSystem,
        state: &mut [f64],
        record: &mut dyn FnMut(usize, &[f64]),
    ) -> Result<Stats, SimError> {
        let options = self.options;
        let mut integrator = Integrator::new(
            system.dim(),
            options.tolerances,
            options.max_steps,
            options.method,
        );
        let (first, last) = (self.times[0], self.times[self.times.len() - 1]);
        if options.warmup > 0.0 {
            system.hold_inputs(self.inputs, first);
            integrator.integrate(
                system,
                (first - options.warmup, first),
                state,
                &[],
                |_, _| {},
            )?;
        }
        let bounds = segment_bounds(self.inputs, first, last);
        let mut next_sample = 0;
        for window in bounds.windows(2) {
            let (start, end) = (window[0], window[1]);
            let samples = &self.times[next_sample..];
            let count = samples.partition_point(|&t| t <= end);
            system.hold_inputs(self.inputs, start);
            let offset = next_sample;
            integrator.integrate(system, (start, end), state, &samples[..count], |k, y| {
                record(offset + k, y)
            })?;
            next_sample += count;
        }
        Ok(integrator.stats())
    }

    /// Iterates the map `x <- f(x, u)` once per sampling step.
    fn discrete(
        &self,
        system: &mut ModelSystem,
        state: &mut [f64],
        record: &mut dyn FnMut(usize, &[f64]),
    ) -> Result<Stats, SimError> {
        let options = self.options;
        let mut next = vec![0.0; state.len()];
        let first = self.times[0];
        system.hold_inputs(self.inputs, first);
        let warmup_steps = (options.warmup / options.dt).round() as usize;
        for step in 0..warmup_steps {
            let t = first - (warmup_steps - step) as f64 * options.dt;
            map_once(system, (t, options.dt), state, &mut next)?;
        }
        for (k, &t) in self.times.iter().enumerate() {
            record(k, state);
            if k + 1 < self.times.len() {
                system.hold_inputs(self.inputs, t);
                map_once(system, (t, options.dt), state, &mut next)?;
            }
        }
        Ok(Stats::default())
    }
}

/// One application of a discrete model's map from time `t` to `t + dt`, refusing
/// non-finite results (reported at `t + dt`).
fn map_once(
    system: &mut ModelSystem,
    (t, dt): (f64, f64),
    state: &mut [f64],
    next: &mut [f64],
) -> Result<(), SimError> {
    system.rhs(t, state, next);
    if next.iter().any(|v| !v.is_finite()) {
        return Err(super::IntegrationError::non_finite(t + dt).into());
    }
    state.copy_from_slice(next);
    Ok(())
}

fn check_model(model: &Model, inputs: &[Signal]) -> Result<(), SimError> {
    if !model.closures.is_empty() {
        let names: Vec<&str> = model.closures.iter().map(|c| c.name.as_str()).collect();
        return Err(SimError::HasClosures {
            model: model.name.clone(),
            closures: names.join(", "),
        });
    }
    if inputs.len() != model.inputs.len() {
        return Err(SimError::InputCount {
            expected: model.inputs.len(),
            found: inputs.len(),
        });
    }
    for (input, signal) in model.inputs.iter().zip(inputs) {
        if signal.values.is_empty() || signal.values.iter().any(|v| !v.is_finite()) {
            return Err(SimError::Options(format!(
                "input `{}` has no value or a non-finite one",
                input.name
            )));
        }
    }
    Ok(())
}

/// `t_start, t_start + dt, ...` up to `t_end` (inclusive within rounding).
fn sample_times(options: &SimOptions) -> Result<Vec<f64>, SimError> {
    let SimOptions {
        t_start,
        t_end,
        dt,
        warmup,
        tolerances,
        ..
    } = *options;
    let invalid = |message: String| Err(SimError::Options(message));
    if ![t_start, t_end, dt, warmup].iter().all(|v| v.is_finite()) {
        return invalid("expected finite times, step and warm-up".into());
    }
    if dt <= 0.0 {
        return invalid(format!("expected a positive sampling step, found {dt:?}"));
    }
    if t_end < t_start {
        return invalid(format!(
            "expected t_end >= t_start = {t_start}, found {t_end}"
        ));
    }
    if warmup < 0.0 {
        return invalid(format!("expected a non-negative warm-up, found {warmup:?}"));
    }
    if !(tolerances.rtol > 0.0 && tolerances.atol > 0.0) {
        return invalid(format!(
            "expected positive tolerances, found rtol {:?} and atol {:?}",
            tolerances.rtol, tolerances.atol
        ));
    }
    let steps = ((t_end - t_start) / dt + 1e-9).floor();
    if steps >= MAX_SAMPLES as f64 {
        return invalid(format!(
            "expected at most {MAX_SAMPLES} samples, found {steps}"
        ));
    }
    Ok((0..=steps as usize)
        .map(|k| t_start + k as f64 * dt)
        .collect())
}

/// `first`, every input switch strictly between `first` and `last`, and `last`.
fn segment_bounds(inputs: &[Signal], first: f64, last: f64) -> Vec<f64> {
    let mut switches: Vec<f64> = inputs
        .iter()
        .flat_map(|signal| signal.breaks.iter().copied())
        .filter(|&b| b > first && b < last)
        .collect();
    switches.sort_by(f64::total_cmp);
    switches.dedup();
    let mut bounds = Vec::with_capacity(switches.len() + 2);
    bounds.push(first);
    bounds.extend(switches);
    bounds.push(last);
    bounds
}

/// Initial values: explicit ones where given, declared ones elsewhere.
fn initial_state(
    model: &Model,
    layout: &Layout,
    explicit: &[Option<f64>],
) -> Result<Vec<f64>, SimError> {
    let declared = model.states.iter().chain(&model.hidden);
    let count = model.states.len() + model.hidden.len();
    if explicit.len() > count {
        return Err(SimError::Options(format!(
            "expected at most {count} initial values, found {}",
            explicit.len()
        )));
    }
    let slots = layout.initial_slots();
    let mut scratch = Vec::new();
    declared
        .enumerate()
        .map(|(index, state)| {
            let value = match (explicit.get(index).copied().flatten(), &state.init) {
                (Some(value), _) => value,
                (None, Some(init)) => Program::compile(init, layout)?.eval(&slots, &mut scratch),
                (None, None) => {
                    return Err(SimError::MissingInitial {
                        state: state.name.clone(),
                    })
                }
            };
            if !value.is_finite() {
                return Err(SimError::NonFiniteInitial {
                    state: state.name.clone(),
                    value,
                });
            }
            Ok(value)
        })
        .collect()
}

/// Input, output and let columns of a trajectory.
struct Algebraic {
    inputs: Vec<Vec<f64>>,
    outputs: Vec<Vec<f64>>,
    lets: Vec<Vec<f64>>,
}

/// Evaluates the inputs, outputs and lets at every sample.
fn evaluate_algebraic(
    model: &Model,
    layout: &Layout,
    signals: &[Signal],
    times: &[f64],
    states: &[Vec<f64>],
    hidden: &[Vec<f64>],
) -> Result<Algebraic, CompileError> {
    let exprs = model.outputs.iter().chain(&model.lets).map(|d| &d.expr);
    let set = ProgramSet::compile(exprs, layout)?;
    let mut slots = layout.initial_slots();
    let mut scratch = Vec::new();
    let mut values = vec![0.0; set.len()];
    let mut columns = vec![Vec::with_capacity(times.len()); set.len()];
    let mut inputs = vec![Vec::with_capacity(times.len()); signals.len()];
    let state_slots = layout.state_range();
    for (k, &t) in times.iter().enumerate() {
        let input_slots = &mut slots[layout.input_range()];
        for ((slot, signal), column) in input_slots.iter_mut().zip(signals).zip(&mut inputs) {
            *slot = signal.value_at(t);
            column.push(*slot);
        }
        for (slot, column) in slots[state_slots.clone()]
            .iter_mut()
            .zip(states.iter().chain(hidden))
        {
            *slot = column[k];
        }
        set.eval_into(&slots, &mut scratch, &mut values);
        for (column, value) in columns.iter_mut().zip(&values) {
            column.push(*value);
        }
    }
    let lets = columns.split_off(model.outputs.len());
    Ok(Algebraic {
        inputs,
        outputs: columns,
        lets,
    })
}
