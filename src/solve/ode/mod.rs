//! Simulation of models without closures (spec section 4: "a model without closures and
//! with only consts is a simulator").
//!
//! Continuous models (`der`) are integrated by the adaptive, error-controlled
//! [`Integrator`]: explicit Dormand–Prince ([`Dopri5`]) while the balances are not stiff,
//! Radau IIA ([`Radau`]) where they are, switched automatically; restarted at every input
//! switch (inputs are piecewise constant), with samples taken from the dense output; with
//! forward sensitivities on request ([`sensitivity`]) and a step budget whose error names
//! the fastest balance ([`IntegrationError`], [`Stuck`]). Discrete models (`next`) iterate
//! their map once per sampling step. [`simulate`] is the entry point; [`OdeSystem`],
//! [`Integrator`], [`Dopri5`] and [`Radau`] are reusable on their own.
//!
//! Every free run — [`simulate`], a mechanistic model's run along a record
//! (`crate::solve::fit`), a trained grey box's run along a track (`crate::train`) — goes
//! through the one [`free_run`] ([`run`]): segments over which the inputs hold, a
//! [`Stepper`] that advances the state over each ([`Adaptive`], [`Map`], the network's
//! step), and the caller's say before and after each ([`Observer`]).
//!
//! [`tableau`] holds the fixed-step explicit Runge–Kutta schemes as Butcher tableaux: the
//! [`tableau::RK4`] that training's engines and the ONNX export step with, its stage times
//! and its stability limit.

mod dopri;
mod dopri_tableau;
mod driver;
mod error;
mod integrator;
mod model;
mod radau;
mod radau_tableau;
pub mod run;
pub mod sensitivity;
mod steppers;
mod stiffness;
mod system;
pub mod tableau;
#[cfg(test)]
mod tests;

#[cfg(test)]
pub use dopri::Dopri5;
pub use driver::{simulate, simulate_with_progress};
pub use error::IntegrationError;
pub use integrator::{Integrator, Method};
pub use model::ModelSystem;
pub use run::{free_run, Observer, Segment, Stepper};
pub use steppers::{Adaptive, Map, Renewal};
pub use system::{OdeSystem, Stats, Tolerances};

use crate::eval::CompileError;

/// The default step budget of a simulation: a million steps, about a second of work on a
/// small model, far more than any model needs once stiff stretches run implicit.
pub const DEFAULT_MAX_STEPS: usize = 1_000_000;

/// What to simulate and how accurately.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Time of the first sample.
    pub t_start: f64,
    /// Time of the last sample (rounded down to the sampling grid).
    pub t_end: f64,
    /// Sampling step; also the step of a discrete (`next`) model.
    pub dt: f64,
    /// Time to run before `t_start` with every input held at its value at `t_start`, so
    /// that recording starts from a settled state (0: no warm-up).
    pub warmup: f64,
    /// Integration tolerances.
    pub tolerances: Tolerances,
    /// Most integration steps attempted in the whole simulation before giving up.
    pub max_steps: usize,
    /// Which integration method runs ([`Method::Auto`]: explicit unless stiff).
    pub method: Method,
    /// Explicit initial values, measured states first then hidden (the balance order):
    /// `Some(v)` replaces the declared initial value of that state; entries past the end
    /// of the vector, and `None`s, keep the declared values.
    pub initial: Vec<Option<f64>>,
}

impl SimOptions {
    /// Samples `0, dt, 2 dt, ...` up to `t_end`, default tolerances and step budget,
    /// automatic method choice, no warm-up, declared initial values.
    pub fn new(t_end: f64, dt: f64) -> Self {
        SimOptions {
            t_start: 0.0,
            t_end,
            dt,
            warmup: 0.0,
            tolerances: Tolerances::default(),
            max_steps: DEFAULT_MAX_STEPS,
            method: Method::Auto,
            initial: Vec::new(),
        }
    }
}

/// A simulated record: column `k` of every table belongs to `times[k]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Sample times.
    pub times: Vec<f64>,
    /// Input values held at each sample, one column per model input.
    pub inputs: Vec<Vec<f64>>,
    /// Measured states, one column per `model.states` entry.
    pub states: Vec<Vec<f64>>,
    /// Hidden states, one column per `model.hidden` entry.
    pub hidden: Vec<Vec<f64>>,
    /// Outputs, one column per `model.outputs` entry.
    pub outputs: Vec<Vec<f64>>,
    /// Lets, one column per `model.lets` entry.
    pub lets: Vec<Vec<f64>>,
    /// Integration work (all zero for a discrete model).
    pub stats: Stats,
}

impl Trajectory {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Keeps the first `rows` samples.
    pub fn truncate(&mut self, rows: usize) {
        self.times.truncate(rows);
        let tables = [
            &mut self.inputs,
            &mut self.states,
            &mut self.hidden,
            &mut self.outputs,
            &mut self.lets,
        ];
        for table in tables {
            table.iter_mut().for_each(|column| column.truncate(rows));
        }
    }
}

/// Why a model could not be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error, miette::Diagnostic)]
pub enum SimError {
    /// The model has closures: it needs training, not simulation.
    #[error("cannot simulate model `{model}`: it has closures ({closures})")]
    #[diagnostic(
        code(gbm::E0701),
        help(
            "closures are learned from data with `gbc train`; run the trained model with \
             `gbc simulate MODEL --weights RUN_DIR`, or replace each closure by a rate law"
        )
    )]
    HasClosures {
        /// Model name.
        model: String,
        /// Closure names, comma separated.
        closures: String,
    },
    /// The number of input signals differs from the model's inputs.
    #[error("expected {expected} input signals, found {found}")]
    #[diagnostic(
        code(gbm::E0702),
        help("give one signal per model input, in declaration order")
    )]
    InputCount {
        /// Model inputs.
        expected: usize,
        /// Signals given.
        found: usize,
    },
    /// A state has neither a declared nor an explicit initial value.
    #[error("state `{state}` has no initial value")]
    #[diagnostic(
        code(gbm::E0703),
        help("declare one in the model (e.g. `state {state} = 1.0`) or pass it explicitly")
    )]
    MissingInitial {
        /// State name.
        state: String,
    },
    /// An initial value is infinite or NaN.
    #[error("initial value of state `{state}` is not finite, found {value}")]
    #[diagnostic(
        code(gbm::E0704),
        help("check the initial value expression and the values it uses")
    )]
    NonFiniteInitial {
        /// State name.
        state: String,
        /// Its value.
        value: f64,
    },
    /// Bad times, step or tolerances.
    #[error("invalid simulation options: {0}")]
    #[diagnostic(
        code(gbm::E0708),
        help("use finite times with t_end >= t_start, dt > 0, warmup >= 0, rtol > 0 and atol > 0")
    )]
    Options(String),
    /// The integration failed.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Integration(#[from] IntegrationError),
    /// A bug: the model's expressions do not fit its own layout.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Compile(#[from] crate::error::Bug),
}

impl From<CompileError> for SimError {
    fn from(error: CompileError) -> Self {
        SimError::Compile(crate::error::Bug::new("the simulator", error.to_string()))
    }
}
