//! Initial states of experiments (records spec, section 3): where a free run of an
//! experiment starts.
//!
//! A measured state takes its cell at the experiment's first row; without one, its declared
//! initial value (`state X = 0.1`); without that, a per-experiment value *fitted* with the
//! trained model. Before training the fitted value starts at the state's first measured
//! value in the experiment (its earliest cell, held back to the start); after training it
//! is refined by Levenberg–Marquardt on the experiment's free-run error over its training
//! part, the network and params frozen ([`super::evaluate`]), and reported with the params.
//! Hidden states take their declared initial values.

use super::stepping::Stepping;
use crate::ir;
use crate::record::Record;

use super::TrainError;

/// Where an experiment's initial value of a measured state comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Origin {
    /// Its cell at the first row.
    Measured,
    /// The model's declared initial value.
    Declared,
    /// Fitted per experiment.
    Fitted,
}

/// The initial values of one experiment's measured states.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InitialState {
    /// The experiment.
    pub experiment: String,
    /// Per measured state: `(name, value, origin)`.
    pub states: Vec<(String, f64, Origin)>,
}

impl InitialState {
    /// The values, in model order.
    pub fn values(&self) -> Vec<f64> {
        self.states.iter().map(|(_, v, _)| *v).collect()
    }

    /// Indices of the states whose value is fitted.
    pub fn fitted(&self) -> Vec<usize> {
        (self.states.iter().enumerate())
            .filter(|(_, (_, _, origin))| *origin == Origin::Fitted)
            .map(|(index, _)| index)
            .collect()
    }
}

/// The initial values of `record`'s measured states before training.
pub fn initial_state(model: &ir::Model, record: &Record) -> Result<InitialState, TrainError> {
    let states = (model.states.iter().zip(&record.states))
        .map(|(state, cells)| {
            if let Some(value) = cells.first().copied().flatten() {
                return Ok((state.name.clone(), value, Origin::Measured));
            }
            if let Some(init) = &state.init {
                let value = constant_value(model, init);
                return Ok((state.name.clone(), value, Origin::Declared));
            }
            let first = cells.iter().flatten().next().copied().ok_or_else(|| {
                TrainError::NoInitialValue {
                    state: state.name.clone(),
                    experiment: record.name.clone(),
                }
            })?;
            Ok((state.name.clone(), first, Origin::Fitted))
        })
        .collect::<Result<Vec<_>, TrainError>>()?;
    Ok(InitialState {
        experiment: record.name.clone(),
        states,
    })
}

/// Value of a constant expression of consts and params (params at their initial values).
pub fn constant_value(model: &ir::Model, expr: &ir::Expr) -> f64 {
    crate::eval::interpret(expr, &|var| match var {
        ir::Var::Const(i) => model.consts.get(i).map_or(f64::NAN, |c| c.value),
        ir::Var::Param(i) => model.params.get(i).map_or(f64::NAN, |p| p.init),
        _ => f64::NAN,
    })
}

/// Refines the fitted initial values of every track of `course` with the trained network:
/// for each track whose `initial` entry (matched by experiment name) has fitted states,
/// Levenberg–Marquardt moves those values to minimise the z-scored one-step errors of the
/// run from the first knot (measured states reset to the data where known, the fitted ones
/// free) up to each fitted state's first measured cell. Updates the tracks and `initial`.
pub(super) fn fit_initial_states(
    network: &crate::engine::graph::Network,
    model: &ir::Model,
    (course, fractions): (&mut super::validation::Course, &[f64]),
    normalisation: &crate::engine::graph::Normalisation,
    (initial, hidden_init): (&mut [InitialState], &[f64]),
) -> Result<(), TrainError> {
    use super::evaluate::{simulate, Feed};
    for track in course.tracks.iter_mut() {
        let Some(entry) = initial.iter_mut().find(|i| i.experiment == track.name) else {
            continue;
        };
        let fitted = entry.fitted();
        if fitted.is_empty() || track.len() < 2 {
            continue;
        }
        let last = (fitted.iter())
            .filter_map(|&i| track.measured[i].iter().position(|&m| m))
            .max()
            .unwrap_or(0)
            .clamp(1, track.len() - 1);
        let start: Vec<f64> = fitted.iter().map(|&i| track.states[i][0]).collect();
        let base = track.clone();
        let residuals = |x: &[f64]| -> Option<Vec<f64>> {
            let mut trial = base.clone();
            for (&state, &value) in fitted.iter().zip(x) {
                trial.states[state][0] = value;
            }
            let run = simulate(
                network,
                model,
                &trial,
                fractions,
                (0, last - 1),
                hidden_init,
                (Feed::Data, None, Stepping::Fixed),
            )
            .ok()?;
            let mut errors = Vec::new();
            for (offset, next) in run.next_states.iter().enumerate() {
                let knot = offset + 1;
                for (state, std) in normalisation.state_std.iter().enumerate() {
                    if trial.measured[state][knot] {
                        errors.push((next[state] - trial.states[state][knot]) / std);
                    }
                }
            }
            errors.iter().all(|e| e.is_finite()).then_some(errors)
        };
        let outcome = fit(&residuals, start);
        for (&state, &value) in fitted.iter().zip(&outcome) {
            track.states[state][0] = value;
            entry.states[state].1 = value;
        }
    }
    Ok(())
}

/// Levenberg–Marquardt with forward differences from `start` (the start again when no
/// step improves).
fn fit(residuals: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync), start: Vec<f64>) -> Vec<f64> {
    use crate::numeric::lm::{Damping, Function, Jacobian};
    let problem = Function {
        residuals,
        jacobian: Jacobian::ForwardDifferences { step: 1e-6 },
        damping: Damping {
            min_diagonal: 1e-300,
            jitter: 1e-300,
            relative_jitter: 1e-9,
        },
    };
    let settings = crate::numeric::Settings {
        max_trials: 40,
        ..crate::numeric::Settings::DEFAULT
    };
    problem.minimise(start, &settings).x
}
