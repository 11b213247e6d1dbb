//! The Dormand–Prince 5(4) integrator with PI step-size control, FSAL and 4th-order dense
//! output, after Hairer, Nørsett and Wanner, *Solving Ordinary Differential Equations I*,
//! section II.5 and II.6 (their code DOPRI5), with its stiffness detection (section IV.2,
//! "automatic stiffness detection"): `h |lambda|` estimated from the last two stages.
//!
//! One call of [`Dopri5::integrate`] covers one smooth stretch `[t0, t1]` of the right-hand
//! side: it starts afresh (new first stage, new initial step), ends exactly at `t1`, and
//! reports the solution at requested times inside the stretch through the continuous
//! extension, so sampling never shortens a step. [`super::Integrator`] runs it with the
//! stiffness monitor on (it then hands the stretch over to Radau IIA) and, for forward
//! sensitivities, differentiates every stage ([`super::sensitivity::Explicit`]).

use super::dopri_tableau::{combine, dense, local_error, Stages, SOLUTION, TABLEAU};
use super::error::{IntegrationError, Stuck};
use super::sensitivity::Explicit;
use super::stiffness::{Accepted, Monitor};
use super::system::{all_finite, rms, OdeSystem, Stats, Tolerances};

// PI controller (Hairer's defaults for DOPRI5).
const SAFETY: f64 = 0.9;
const BETA: f64 = 0.04;
const EXPONENT: f64 = 0.2 - BETA * 0.75;
const MAX_GROWTH: f64 = 10.0;
const MAX_SHRINK: f64 = 5.0;
/// Step reduction after a step that produced non-finite values.
const NON_FINITE_SHRINK: f64 = 0.1;
/// What a stretch records: `record(k, y, s)` for sample `k` (sensitivities empty
/// without).
pub(super) type Record<'a> = dyn FnMut(usize, &[f64], &[f64]) + 'a;

/// How a stretch ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reached {
    /// The end of the stretch.
    End,
    /// The method hands over at `t` (the state and sensitivities are there, and the first
    /// `recorded` samples are recorded): the explicit method found the stretch stiff, or
    /// the implicit method found it calm or not worth its cost.
    Stiff {
        /// Time reached.
        t: f64,
        /// Samples recorded.
        recorded: usize,
        /// The step size the method was taking.
        step: f64,
    },
}

/// What to do besides stepping.
pub(super) struct Options<'s> {
    /// Stop when the stretch is found stiff, after at least this many accepted steps
    /// (`None`: never).
    pub monitor_stiffness: Option<usize>,
    /// Forward sensitivities to carry along.
    pub sensitivity: Option<&'s mut Explicit>,
}

/// A reusable Dormand–Prince 5(4) integrator (owns its work arrays).
#[derive(Debug, Clone)]
pub struct Dopri5 {
    tolerances: Tolerances,
    max_steps: usize,
    stages: Stages,
    stage_state: Vec<f64>,
    next: Vec<f64>,
    sample: Vec<f64>,
    /// Work space of the stiffness monitor's exact Jacobian.
    jacobian: Vec<f64>,
    stats: Stats,
    /// The step the last stretch proposed before it was cut to reach the stretch's end:
    /// the next stretch of the same run starts with it ([`Dopri5::forget_step`] at a new run).
    carried: Option<f64>,
}

/// The state of one integration while stepping.
struct Stepper {
    t: f64,
    h: f64,
    t_end: f64,
    previous_error: f64,
    last_rejected: bool,
    last_non_finite: bool,
    attempts: usize,
    monitor: Monitor,
    /// The step proposed before the last one was cut to the stretch's end.
    proposed: f64,
}

impl Dopri5 {
    /// An integrator for systems of `dim` equations; at most `max_steps` steps are
    /// attempted per call of [`Dopri5::integrate`].
    pub fn new(dim: usize, tolerances: Tolerances, max_steps: usize) -> Self {
        let work = || vec![0.0; dim];
        Dopri5 {
            tolerances,
            max_steps,
            stages: std::array::from_fn(|_| work()),
            stage_state: work(),
            next: work(),
            sample: work(),
            jacobian: Vec::new(),
            stats: Stats::default(),
            carried: None,
        }
    }

    /// Forgets the step carried from the last stretch: the next starts with Hairer's
    /// heuristic (a new run, whose numbers must not depend on the runs before it).
    pub(super) fn forget_step(&mut self) {
        self.carried = None;
    }

    /// Work done since the integrator was made.
    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Sets the most steps attempted per stretch.
    pub(super) fn set_max_steps(&mut self, max_steps: usize) {
        self.max_steps = max_steps;
    }

    /// Integrates `system` from `(t0, y)` to `t1 >= t0`, leaving `y(t1)` in `y`.
    ///
    /// `samples` are increasing times in `[t0, t1]`; `record(k, y)` is called once for each
    /// `samples[k]`, in order, with the solution there (from the dense output, or the exact
    /// step end when a sample coincides with one).
    #[cfg(test)]
    pub fn integrate<S: OdeSystem>(
        &mut self,
        system: &mut S,
        span: (f64, f64),
        y: &mut [f64],
        samples: &[f64],
        mut record: impl FnMut(usize, &[f64]),
    ) -> Result<(), IntegrationError> {
        let options = Options {
            monitor_stiffness: None,
            sensitivity: None,
        };
        self.advance(
            system,
            span,
            y,
            samples,
            &mut |k, y, _| record(k, y),
            options,
        )
        .map(|_| ())
    }

    /// [`Dopri5::integrate`] with sensitivities and the stiffness monitor as `options`
    /// says; `record(k, y, s)` also gets the sensitivities (empty without).
    pub(super) fn advance<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (t0, t1): (f64, f64),
        y: &mut [f64],
        samples: &[f64],
        record: &mut Record,
        mut options: Options,
    ) -> Result<Reached, IntegrationError> {
        let mut samples = Samples {
            times: samples,
            recorded: 0,
            record,
        };
        samples.record_until(t0, y, sensitivities(&options));
        if t1 <= t0 {
            return Ok(Reached::End);
        }
        let mut stepper = self.start(system, (t0, t1), y, &mut options)?;
        while stepper.t < t1 {
            let last = self.check_step(system, &mut stepper, y)?;
            self.step(
                system,
                stepper.t,
                stepper.h,
                y,
                options.sensitivity.as_deref_mut(),
            );
            let error = self.error_norm(stepper.h, y);
            if error <= 1.0 {
                let step_end = if last { t1 } else { stepper.t + stepper.h };
                let stiff = options.monitor_stiffness.is_some()
                    && self.is_stiff(system, &mut stepper, step_end);
                self.record_inside(&stepper, step_end, y, &mut samples, &mut options);
                self.accept(&mut stepper, (error, step_end), y, &mut options);
                if stiff && stepper.t < t1 {
                    return Ok(Reached::Stiff {
                        t: stepper.t,
                        recorded: samples.recorded,
                        step: stepper.h,
                    });
                }
            } else {
                stepper.reject(error);
                self.stats.rejected += 1;
            }
        }
        samples.record_rest(y, sensitivities(&options));
        self.carried = Some(stepper.proposed);
        Ok(Reached::End)
    }

    /// Starts a stretch `(t0, t1)` at `y`: the first stage (and its sensitivities), the
    /// initial step and the stiffness monitor.
    fn start<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (t0, t1): (f64, f64),
        y: &[f64],
        options: &mut Options,
    ) -> Result<Stepper, IntegrationError> {
        self.evaluate(system, t0, y, 0);
        if !all_finite(&self.stages[0]) {
            return Err(IntegrationError::non_finite(t0));
        }
        if let Some(sensitivity) = options.sensitivity.as_deref_mut() {
            sensitivity.first_stage(system, t0, y, &mut self.stats);
        }
        // A stretch that goes on from the one before (the next input segment of one run)
        // starts with the step that one was taking: an input switch every few minutes of a
        // day-long record would otherwise pay the heuristic's cautious start at each.
        let h = match self.carried.take() {
            Some(h) if h.is_finite() && h > 0.0 => h.min(t1 - t0),
            _ => self.initial_step(system, t0, y, t1 - t0),
        };
        Ok(Stepper {
            t: t0,
            h,
            proposed: h,
            t_end: t1,
            previous_error: 1e-4,
            last_rejected: false,
            last_non_finite: false,
            attempts: 0,
            monitor: Monitor::new(options.monitor_stiffness.unwrap_or(usize::MAX)),
        })
    }

    /// Whether the stiffness monitor finds the stretch stiff after the step just
    /// accepted, ending at `step_end`.
    fn is_stiff<S: OdeSystem>(
        &mut self,
        system: &mut S,
        stepper: &mut Stepper,
        step_end: f64,
    ) -> bool {
        let step = Accepted {
            stages: (&self.stages[5], &self.stages[6]),
            states: (&self.stage_state, &self.next),
            span: (step_end, stepper.h, stepper.t_end),
        };
        stepper.monitor.is_stiff(system, step, &mut self.jacobian)
    }

    /// Records the samples inside the step just accepted, ending at `step_end`, from the
    /// dense output (and the sensitivities' where carried).
    fn record_inside(
        &mut self,
        stepper: &Stepper,
        step_end: f64,
        y: &[f64],
        samples: &mut Samples,
        options: &mut Options,
    ) {
        while let Some(k) = samples.next_until(step_end) {
            let sample = samples.times[k];
            self.interpolate(stepper.t, stepper.h, step_end, sample, y);
            let s = match options.sensitivity.as_deref_mut() {
                Some(sensitivity) => {
                    sensitivity.interpolate(
                        self.theta(stepper.t, stepper.h, step_end, sample),
                        stepper.h,
                    );
                    sensitivity.sample()
                }
                None => &[],
            };
            (samples.record)(k, &self.sample, s);
        }
    }

    /// Moves to the end of the step just accepted (its error `error`, ending at
    /// `step_end`) and proposes the next step.
    fn accept(
        &mut self,
        stepper: &mut Stepper,
        (error, step_end): (f64, f64),
        y: &mut [f64],
        options: &mut Options,
    ) {
        y.copy_from_slice(&self.next);
        self.stages.swap(0, 6);
        if let Some(sensitivity) = options.sensitivity.as_deref_mut() {
            sensitivity.accept();
        }
        stepper.accept(error, step_end);
        self.stats.accepted += 1;
    }

    /// Clamps the step to the end of the stretch and checks the step budget; returns
    /// whether this step ends the stretch.
    fn check_step<S: OdeSystem>(
        &self,
        system: &mut S,
        stepper: &mut Stepper,
        y: &[f64],
    ) -> Result<bool, IntegrationError> {
        stepper.attempts += 1;
        if stepper.attempts > self.max_steps {
            return Err(IntegrationError::TooManySteps {
                t: stepper.t,
                steps: self.max_steps,
                stuck: stuck(system, stepper, y),
            });
        }
        let remaining = stepper.t_end - stepper.t;
        stepper.proposed = stepper.h;
        if stepper.t + 1.01 * stepper.h >= stepper.t_end {
            stepper.h = remaining;
            return Ok(true);
        }
        // The rounding level of the time itself (not of the stretch's length: a stretch of
        // 4e10 may start with steps of 1e-9 at t = 0).
        let smallest = 16.0 * f64::EPSILON * stepper.t.abs().max(f64::MIN_POSITIVE);
        if stepper.h <= smallest {
            return Err(if stepper.last_non_finite {
                IntegrationError::non_finite(stepper.t)
            } else {
                IntegrationError::StepSizeUnderflow {
                    t: stepper.t,
                    step: stepper.h,
                    stuck: stuck(system, stepper, y),
                }
            });
        }
        Ok(false)
    }

    fn evaluate<S: OdeSystem>(&mut self, system: &mut S, t: f64, y: &[f64], stage: usize) {
        system.rhs(t, y, &mut self.stages[stage]);
        self.stats.evaluations += 1;
    }

    /// One Dormand–Prince step from `(t, y)`: stages 2..7 (stage 1 is already there), the
    /// 5th-order solution in `next`, and the stages' sensitivities where asked.
    fn step<S: OdeSystem>(
        &mut self,
        system: &mut S,
        t: f64,
        h: f64,
        y: &[f64],
        mut sensitivity: Option<&mut Explicit>,
    ) {
        for (stage, (c, weights)) in TABLEAU.into_iter().enumerate() {
            combine(&mut self.stage_state, y, h, &self.stages, weights);
            system.rhs(t + c * h, &self.stage_state, &mut self.stages[stage + 1]);
            if let Some(sensitivity) = sensitivity.as_deref_mut() {
                let at = (t + c * h, h);
                sensitivity.stage(
                    system,
                    at,
                    &self.stage_state,
                    stage + 1,
                    weights,
                    &mut self.stats,
                );
            }
        }
        combine(&mut self.next, y, h, &self.stages, &SOLUTION);
        system.rhs(t + h, &self.next, &mut self.stages[6]);
        self.stats.evaluations += 6;
        if let Some(sensitivity) = sensitivity {
            sensitivity.stage(
                system,
                (t + h, h),
                &self.next,
                6,
                &SOLUTION,
                &mut self.stats,
            );
        }
    }

    /// Root-mean-square of the embedded error estimate relative to the tolerance.
    fn error_norm(&self, h: f64, y: &[f64]) -> f64 {
        let Tolerances { rtol, atol } = self.tolerances;
        let k = &self.stages;
        let sum: f64 = (0..y.len())
            .map(|i| {
                let local = local_error(h, k, i);
                let scale = atol + rtol * y[i].abs().max(self.next[i].abs());
                (local / scale).powi(2)
            })
            .sum();
        if y.is_empty() {
            return 0.0;
        }
        let norm = (sum / y.len() as f64).sqrt();
        if all_finite(&self.next) {
            norm
        } else {
            f64::NAN
        }
    }

    /// The fraction of the step `(t, t + h]` at `sample` (1 at or past the step's end).
    fn theta(&self, t: f64, h: f64, step_end: f64, sample: f64) -> f64 {
        if sample >= step_end {
            1.0
        } else {
            (sample - t) / h
        }
    }

    /// Writes the solution at `sample` in `(t, t + h]` into `self.sample`.
    fn interpolate(&mut self, t: f64, h: f64, step_end: f64, sample: f64, y: &[f64]) {
        if sample >= step_end {
            self.sample.copy_from_slice(&self.next);
            return;
        }
        let theta = (sample - t) / h;
        dense(theta, h, y, &self.next, &self.stages, &mut self.sample);
    }

    /// Hairer's starting step heuristic (HINIT), bounded by `max_step`.
    fn initial_step<S: OdeSystem>(
        &mut self,
        system: &mut S,
        t: f64,
        y: &[f64],
        max_step: f64,
    ) -> f64 {
        let Tolerances { rtol, atol } = self.tolerances;
        let scale = |i: usize| atol + rtol * y[i].abs();
        let slope = rms((0..y.len()).map(|i| self.stages[0][i] / scale(i)));
        let size = rms((0..y.len()).map(|i| y[i] / scale(i)));
        let mut h = if slope <= 1e-10 || size <= 1e-10 {
            1e-6
        } else {
            0.01 * size / slope
        };
        h = h.min(max_step);
        for ((stage, &value), &slope) in self.stage_state.iter_mut().zip(y).zip(&self.stages[0]) {
            *stage = value + h * slope;
        }
        system.rhs(t + h, &self.stage_state, &mut self.stages[1]);
        self.stats.evaluations += 1;
        let curvature =
            rms((0..y.len()).map(|i| (self.stages[1][i] - self.stages[0][i]) / scale(i))) / h;
        let bound = curvature.abs().max(slope);
        let guess = if !bound.is_finite() {
            h * 1e-3
        } else if bound <= 1e-15 {
            (h * 1e-3).max(1e-6)
        } else {
            (0.01 / bound).powf(0.2)
        };
        (100.0 * h).min(guess).min(max_step)
    }
}

/// The sensitivities to hand a sample when the step's own are not at hand (empty without).
fn sensitivities<'a>(options: &'a Options) -> &'a [f64] {
    options
        .sensitivity
        .as_deref()
        .map_or(&[], Explicit::current)
}

/// Where an explicit integration was stuck.
fn stuck<S: OdeSystem>(system: &mut S, stepper: &Stepper, y: &[f64]) -> Stuck {
    let n = y.len();
    let mut jacobian = vec![0.0; n * n];
    system.jacobian(stepper.t, y, &mut jacobian);
    Stuck::from_jacobian(&jacobian, n, stepper.h, false)
}

impl Stepper {
    fn accept(&mut self, error: f64, step_end: f64) {
        let growth = error.powf(EXPONENT);
        let factor =
            (growth / self.previous_error.powf(BETA) / SAFETY).clamp(1.0 / MAX_GROWTH, MAX_SHRINK);
        let mut next = self.h / factor;
        if self.last_rejected {
            next = next.min(self.h);
        }
        self.previous_error = error.max(1e-4);
        self.t = step_end;
        self.h = next;
        self.last_rejected = false;
        self.last_non_finite = false;
    }

    fn reject(&mut self, error: f64) {
        if error.is_finite() {
            self.h /= (error.powf(EXPONENT) / SAFETY).min(MAX_SHRINK);
            self.last_non_finite = false;
        } else {
            self.h *= NON_FINITE_SHRINK;
            self.last_non_finite = true;
        }
        self.last_rejected = true;
    }
}

/// The samples a stretch records: their times, how many are recorded, and where to.
struct Samples<'a, 'r> {
    times: &'a [f64],
    recorded: usize,
    record: &'a mut Record<'r>,
}

impl Samples<'_, '_> {
    /// The next sample not after `bound`, counted as recorded.
    fn next_until(&mut self, bound: f64) -> Option<usize> {
        let k = self.recorded;
        (k < self.times.len() && self.times[k] <= bound).then(|| {
            self.recorded += 1;
            k
        })
    }

    /// Records every sample not after `bound` at `y` with sensitivities `s`.
    fn record_until(&mut self, bound: f64, y: &[f64], s: &[f64]) {
        while let Some(k) = self.next_until(bound) {
            (self.record)(k, y, s);
        }
    }

    /// Records every sample still to record at `y` with sensitivities `s`.
    fn record_rest(&mut self, y: &[f64], s: &[f64]) {
        for k in self.recorded..self.times.len() {
            (self.record)(k, y, s);
        }
        self.recorded = self.times.len();
    }
}
