//! Simulations (`gbc simulate`): a model without closures integrated under input
//! programmes, sampled on a grid, with measurement noise, a range it stays in, fitted
//! params and initial values; or, with a trained run, a what-if run of the trained model
//! ([`whatif`]). [`simulate`] turns a [`SimulateSpec`] into a [`Simulation`], a table that
//! writes itself as CSV or JSON.
//!
//! Columns: `t`, the inputs, the measured states, the hidden states (with `hidden`), then
//! the outputs; a what-if run writes `t`, the inputs, the states (measured, then hidden),
//! every closure output and every model output. Noise ([`noise`]): `0.01` perturbs the
//! measured states relatively, `y * (1 + 0.01 N(0, 1))`, `declared` by the model's `noise`
//! declarations, `X=4%+0.01` one quantity by the combined model; drawn row by row from a
//! ChaCha8 generator seeded with `seed`; hidden states and outputs without noise stay
//! exact. `init` replaces a state's declared initial value; `params` sets the params to
//! those `gbc train` or `gbc diagnose` fitted ([`params`]); the model's effects
//! ([`Model::from_file_with_effects`]) are applied before lowering.

mod error;
mod noise;
mod params;
mod range;
mod whatif;

use std::path::{Path, PathBuf};

pub use error::SimulateError;

use super::{ApiError, Model};
use crate::ir;
use crate::signal::Signal;
use crate::solve::ode::{Method, SimOptions, Tolerances, Trajectory};

/// Everything a simulation is asked for, with the defaults of `gbc simulate` (its flags'
/// names are the fields' names).
#[derive(Debug, Clone)]
pub struct SimulateSpec {
    /// Time of the last sample.
    pub t_end: f64,
    /// Sampling step (needed without `weights`; with them, default: the run's step).
    pub dt: Option<f64>,
    /// Time of the first sample (default 0; with a history, its last row).
    pub t_start: Option<f64>,
    /// A trained run directory: free-run the trained model (a what-if run).
    pub weights: Option<PathBuf>,
    /// With the weights of an ensemble run: the level of the prediction band.
    pub band: f64,
    /// With `weights`: measured data before the start (one experiment).
    pub history: Option<PathBuf>,
    /// `NAME=HEADER` mappings of the history's columns.
    pub columns: Vec<(String, String)>,
    /// Initial values by state name (measured or hidden).
    pub init: Vec<(String, f64)>,
    /// A params file of `gbc train` (run.json or `--json`) or `gbc diagnose --json`.
    pub params: Option<PathBuf>,
    /// One input programme per input, `NAME=PROGRAM` (e.g. `u=steps(hold=5..40)`).
    pub inputs: Vec<String>,
    /// Settle this long at the first input values before recording.
    pub warmup: f64,
    /// Measurement noise specs (none: an exact record).
    pub noise: Vec<ir::NoiseSpec>,
    /// Seed of the noise.
    pub seed: u64,
    /// Bounds of measured states, `(NAME, LO, HI)`: the run stops before the first sample
    /// outside them.
    pub ranges: Vec<(String, f64, f64)>,
    /// Also keep the hidden states (a what-if run always does).
    pub hidden: bool,
    /// The integrator's tolerances.
    pub tolerances: Tolerances,
    /// Most integration steps in the whole run.
    pub max_steps: usize,
    /// Integration method.
    pub integrator: Method,
    /// Members of an ensemble run running at once (default: the number of cores).
    pub jobs: Option<usize>,
}

impl Default for SimulateSpec {
    fn default() -> Self {
        SimulateSpec {
            t_end: 0.0,
            dt: None,
            t_start: None,
            weights: None,
            band: crate::ensemble::DEFAULT_LEVEL,
            history: None,
            columns: Vec::new(),
            init: Vec::new(),
            params: None,
            inputs: Vec::new(),
            warmup: 0.0,
            noise: Vec::new(),
            seed: 0,
            ranges: Vec::new(),
            hidden: false,
            tolerances: Tolerances::default(),
            max_steps: crate::solve::ode::DEFAULT_MAX_STEPS,
            integrator: Method::Auto,
            jobs: None,
        }
    }
}

/// What a simulation tells its caller while it runs.
#[derive(Debug, Clone, PartialEq)]
pub enum SimulateEvent {
    /// Something the user should know that changes nothing (a param kept its guess, the
    /// model differs from the trained one in text).
    Note(String),
    /// The run stopped early (it left its range), or part of an ensemble did.
    Warning(String),
    /// The integration starts (before the warm-up).
    Started,
    /// Samples recorded of the total.
    Samples {
        /// Samples done.
        done: usize,
        /// Samples in all.
        total: usize,
    },
    /// The integration ended.
    Finished,
    /// The members of an ensemble start their what-if runs.
    Members {
        /// Members that run.
        members: usize,
        /// At once.
        jobs: usize,
    },
}

/// A simulated record: a header and one column per header name, `t` first.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulation {
    /// Column names.
    pub header: Vec<String>,
    /// Columns, one value per sample.
    pub columns: Vec<Vec<f64>>,
    /// How numbers are written: a plain simulation's in full (`1.0`, times rounded to 12
    /// digits), a what-if run's as the data writer does (`1`).
    exact: bool,
}

/// Simulates `model` as `spec` asks: a what-if run of the trained model with
/// `spec.weights`, else a plain integration of the model (which must have no closures).
/// `on_event` hears notes, warnings and progress.
pub fn simulate(
    model: &Model,
    spec: &SimulateSpec,
    on_event: &mut dyn FnMut(SimulateEvent),
) -> Result<Simulation, ApiError> {
    if let Some(weights) = &spec.weights {
        return whatif::run(model, weights, spec, on_event);
    }
    let mut ir = model.ir().clone();
    if let Some(path) = &spec.params {
        let notes = params::apply(&mut ir, path, &model.effects).map_err(ApiError::user)?;
        notes
            .into_iter()
            .for_each(|note| on_event(SimulateEvent::Note(note)));
    }
    let noise = noise::record_noise(&ir, &spec.noise)?;
    let range = range::simulation_range(&ir, &spec.ranges).map_err(ApiError::user)?;
    let t_start = spec.t_start.unwrap_or(0.0);
    let dt = spec.dt.ok_or_else(missing_dt)?;
    let signals = input_signals(&ir, &spec.inputs, (t_start, spec.t_end, dt))?;
    let options = SimOptions {
        t_start,
        warmup: spec.warmup,
        tolerances: spec.tolerances,
        initial: initial_values(&ir, &spec.init)?,
        max_steps: spec.max_steps,
        method: spec.integrator,
        ..SimOptions::new(spec.t_end, dt)
    };
    on_event(SimulateEvent::Started);
    let mut progress = |done, total| on_event(SimulateEvent::Samples { done, total });
    let simulated =
        crate::solve::ode::simulate_with_progress(&ir, &signals, &options, &mut progress);
    on_event(SimulateEvent::Finished);
    let mut trajectory = simulated.map_err(ApiError::user)?;
    if let Some(divergence) = range::stop_outside(&ir, &mut trajectory, &range) {
        on_event(SimulateEvent::Warning(format!(
            "{divergence}; the run stops before it"
        )));
    }
    noise::add_noise(&mut trajectory, &noise, spec.seed);
    Ok(Simulation::of_trajectory(&ir, trajectory, spec.hidden))
}

/// `dt` is needed without weights.
fn missing_dt() -> ApiError {
    ApiError::user(crate::solve::ode::SimError::Options(
        "expected --dt (the sampling step), found none".into(),
    ))
}

/// The initial values by name in the model's state order (measured, then hidden).
fn initial_values(model: &ir::Model, init: &[(String, f64)]) -> Result<Vec<Option<f64>>, ApiError> {
    let names: Vec<&str> = (model.states.iter().chain(&model.hidden))
        .map(|s| s.name.as_str())
        .collect();
    let mut values = vec![None; names.len()];
    for (name, value) in init {
        let index = names.iter().position(|n| n == name).ok_or_else(|| {
            ApiError::user(SimulateError::UnknownInitState {
                name: name.clone(),
                states: crate::suggest::did_you_mean(name, &names, "states"),
            })
        })?;
        values[index] = Some(*value);
    }
    Ok(values)
}

/// One signal per model input, from the input programmes (`NAME=PROGRAM`), sampled on the
/// grid `t_start + k dt` up to `t_end`; every defect reported at once.
fn input_signals(
    model: &ir::Model,
    texts: &[String],
    (t_start, t_end, dt): (f64, f64, f64),
) -> Result<Vec<Signal>, ApiError> {
    let mut programs = vec![None; model.inputs.len()];
    let mut reports = Vec::new();
    // Inputs whose program was given but is defective: reported once, not also as missing.
    let mut defective: Vec<&str> = Vec::new();
    for text in texts {
        let parsed = crate::signal::parse_input_argument(text).and_then(|argument| {
            let input = argument.resolve(&model.inputs)?;
            Ok((input.name.clone(), argument.program))
        });
        match parsed {
            Ok((name, program)) => {
                let index = model.inputs.iter().position(|i| i.name == name);
                if let Some(Some(_)) = index.map(|index| programs[index].replace(program)) {
                    reports.push(report(SimulateError::DuplicateInput { name }));
                }
            }
            Err(error) => {
                defective.extend(text.split_once('=').map(|(name, _)| name.trim()));
                reports.push(report(error));
            }
        }
    }
    let mut signals = Vec::with_capacity(model.inputs.len());
    for (input, program) in model.inputs.iter().zip(&programs) {
        let Some(program) = program else {
            if !defective.contains(&input.name.as_str()) {
                let name = input.name.clone();
                reports.push(report(SimulateError::MissingInput { name }));
            }
            continue;
        };
        match program.generate(input, t_start, t_end, dt) {
            Ok(signal) => signals.push(signal),
            Err(error) => reports.push(report(error)),
        }
    }
    if reports.is_empty() {
        Ok(signals)
    } else {
        Err(ApiError::from(reports))
    }
}

fn report(diagnostic: impl miette::Diagnostic + Send + Sync + 'static) -> miette::Report {
    miette::Report::new(diagnostic)
}

impl Simulation {
    /// The record of a plain simulation: `t` (rounded to 12 significant digits, without the
    /// noise of `t_start + k dt`), inputs, measured states, hidden states (if `hidden`),
    /// outputs.
    fn of_trajectory(model: &ir::Model, trajectory: Trajectory, hidden: bool) -> Simulation {
        let mut header = vec!["t".to_string()];
        let mut columns = vec![trajectory.times.iter().map(|&t| round_time(t)).collect()];
        let mut add = |names: Vec<&String>, values: Vec<Vec<f64>>| {
            header.extend(names.into_iter().cloned());
            columns.extend(values);
        };
        add(
            model.inputs.iter().map(|i| &i.name).collect(),
            trajectory.inputs,
        );
        add(
            model.states.iter().map(|s| &s.name).collect(),
            trajectory.states,
        );
        if hidden {
            add(
                model.hidden.iter().map(|s| &s.name).collect(),
                trajectory.hidden,
            );
        }
        add(
            model.outputs.iter().map(|o| &o.name).collect(),
            trajectory.outputs,
        );
        Simulation {
            header,
            columns,
            exact: true,
        }
    }

    /// A what-if run's table.
    fn of_table(header: Vec<String>, columns: Vec<Vec<f64>>) -> Simulation {
        Simulation {
            header,
            columns,
            exact: false,
        }
    }

    /// The samples recorded.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    /// Whether no sample was recorded.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Writes the table as CSV to `path` (atomically; a value that is not finite is refused,
    /// naming where, E0253).
    pub fn write_csv(&self, path: &Path) -> Result<(), ApiError> {
        if !self.exact {
            return crate::data::write_csv(path, &self.header, &self.columns)
                .map_err(ApiError::user);
        }
        let named: Vec<(&str, &[f64])> = (self.header.iter().zip(&self.columns))
            .map(|(name, values)| (name.as_str(), values.as_slice()))
            .collect();
        let found = crate::finite::in_table(&named);
        crate::finite::refuse(path, found, crate::data::NOT_FINITE_HELP).map_err(ApiError::user)?;
        crate::io::write_atomic(path, self.exact_csv(path)?.as_bytes()).map_err(ApiError::user)
    }

    /// The CSV text of a plain simulation: every number in full.
    fn exact_csv(&self, path: &Path) -> Result<String, ApiError> {
        let failed = |error: csv::Error| {
            ApiError::Internal(format!("cannot format `{}`: {error}", path.display()))
        };
        let mut writer = csv::Writer::from_writer(Vec::new());
        writer.write_record(&self.header).map_err(failed)?;
        for k in 0..self.len() {
            let row = self.columns.iter().map(|column| format!("{:?}", column[k]));
            writer.write_record(row).map_err(failed)?;
        }
        let bytes = (writer.into_inner()).map_err(|e| failed(e.into_error().into()))?;
        String::from_utf8(bytes).map_err(|e| ApiError::Internal(e.to_string()))
    }

    /// The table as JSON: `{"header": [...], "columns": [[...], ...]}` (a number that is not
    /// finite as `"inf"`, `"-inf"` or `"nan"`).
    pub fn json(&self) -> Result<String, ApiError> {
        #[derive(serde::Serialize)]
        struct Wire<'a> {
            header: &'a [String],
            #[serde(with = "crate::json")]
            columns: Vec<Vec<f64>>,
        }
        let wire = Wire {
            header: &self.header,
            columns: self.columns.clone(),
        };
        serde_json::to_string_pretty(&wire)
            .map_err(|error| ApiError::Internal(format!("cannot encode a simulation: {error}")))
    }
}

/// A sample time without the rounding noise of `t_start + k dt` (12 significant digits).
fn round_time(t: f64) -> f64 {
    format!("{t:.11e}").parse().unwrap_or(t)
}

#[cfg(test)]
mod tests;
