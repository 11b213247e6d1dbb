//! From a model and its input signals to a sampled [`Trajectory`].

use super::error::IntegrationError;
use super::integrator::Integrator;
use super::model::ModelSystem;
use super::run::{free_run, Segment};
use super::steppers::{Adaptive, Map, Renewal};
use super::system::{OdeSystem, Stats};
use super::{SimError, SimOptions, Trajectory};
use crate::eval::{CompileError, Layout, Program, ProgramSet};
use crate::ir::{Dynamics, Model};
use crate::signal::Signal;

/// Most samples one simulation may record.
const MAX_SAMPLES: usize = 100_000_000;

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
    let held: Vec<Vec<f64>> = inputs.iter().map(|signal| signal.sample(&times)).collect();
    let mut columns = vec![Vec::with_capacity(times.len()); state.len()];
    let mut recorded = 0;
    let mut record = |values: &[f64], _: &[f64]| {
        for (column, value) in columns.iter_mut().zip(values) {
            column.push(*value);
        }
        recorded += 1;
        progress(recorded, times.len());
    };
    let run = Run {
        inputs,
        options,
        times: &times,
        held: &held,
    };
    let stats = match model.dynamics {
        Dynamics::Continuous => run.continuous(&mut system, &mut state, &mut record),
        Dynamics::Discrete => run.discrete(&mut system, &mut state, &mut record),
    }
    .map_err(|error| {
        let names: Vec<String> = (model.states.iter().chain(&model.hidden))
            .map(|state| state.name.clone())
            .collect();
        SimError::Integration(error.named(&names))
    })?;
    let hidden = columns.split_off(model.states.len());
    let algebraic = evaluate_algebraic(model, system.layout(), held, &times, &columns, &hidden)?;
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
    /// The inputs held at every sample time, one column per input.
    held: &'a [Vec<f64>],
}

impl Run<'_> {
    /// Integrates from input switch to input switch (after the warm-up, if any, with the
    /// inputs held at their first values), sampling from the dense output.
    fn continuous(
        &self,
        system: &mut ModelSystem,
        state: &mut [f64],
        record: &mut impl FnMut(&[f64], &[f64]),
    ) -> Result<Stats, IntegrationError> {
        let options = self.options;
        let mut integrator = Integrator::new(
            system.dim(),
            options.tolerances,
            options.max_steps,
            options.method,
        );
        let (first, last) = (self.times[0], self.times[self.times.len() - 1]);
        let bounds = segment_bounds(self.inputs, first, last);
        // The inputs held over each segment: their values at its start.
        let held: Vec<Vec<f64>> = (self.inputs.iter())
            .map(|signal| signal.sample(&bounds))
            .collect();
        let warmup = (options.warmup > 0.0).then_some(Segment {
            index: 0,
            span: (first - options.warmup, first),
            samples: &[],
        });
        let mut next_sample = 0;
        let segments = bounds.windows(2).enumerate().map(|(index, window)| {
            let samples = &self.times[next_sample..];
            let count = samples.partition_point(|&t| t <= window[1]);
            next_sample += count;
            Segment {
                index,
                span: (window[0], window[1]),
                samples: &samples[..count],
            }
        });
        let mut stepper = Adaptive::new(&mut integrator, system, &held, Renewal::Never);
        free_run(
            &mut stepper,
            warmup.into_iter().chain(segments),
            state,
            record,
        )?;
        Ok(integrator.stats())
    }

    /// Iterates the map `x <- f(x, u)` once per sampling step (after the warm-up's steps,
    /// if any, with the inputs held at their first values).
    fn discrete(
        &self,
        system: &mut ModelSystem,
        state: &mut [f64],
        record: &mut impl FnMut(&[f64], &[f64]),
    ) -> Result<Stats, IntegrationError> {
        let (times, dt) = (self.times, self.options.dt);
        let first = times[0];
        let warmup_steps = (self.options.warmup / dt).round() as usize;
        let warmup = (0..warmup_steps).map(|step| {
            let t = first - (warmup_steps - step) as f64 * dt;
            Segment {
                index: 0,
                span: (t, t + dt),
                samples: &[],
            }
        });
        // Step `k` lands at `times[k] + dt`, sampled as `times[k + 1]`.
        let steps = (0..times.len() - 1).map(|k| Segment {
            index: k,
            span: (times[k], times[k] + dt),
            samples: &times[k + 1..k + 2],
        });
        let mut stepper = Map::new(system, self.held);
        free_run(&mut stepper, warmup, state, &mut |_: &[f64], _: &[f64]| {})?;
        record(state, &[]);
        free_run(&mut stepper, steps, state, record)?;
        Ok(Stats::default())
    }
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

/// Evaluates the outputs and lets at every sample, with `inputs` held there (one column
/// per input).
fn evaluate_algebraic(
    model: &Model,
    layout: &Layout,
    inputs: Vec<Vec<f64>>,
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
    let state_slots = layout.state_range();
    for k in 0..times.len() {
        let input_slots = &mut slots[layout.input_range()];
        for (slot, column) in input_slots.iter_mut().zip(&inputs) {
            *slot = column[k];
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
