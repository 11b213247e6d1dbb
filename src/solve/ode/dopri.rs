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

use super::error::{IntegrationError, Stuck};
use super::sensitivity::Explicit;
use super::stiffness::Monitor;
use super::system::{all_finite, rms, OdeSystem, Stats, Tolerances};

// Butcher tableau of Dormand and Prince (1980).
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
// Difference between the 5th- and 4th-order weights.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
// Dense output of order 4 (Hairer's CONTD5).
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// Stages 2 to 6: their time fraction and their weights on the earlier stages.
pub(super) const TABLEAU: [(f64, &[(usize, f64)]); 5] = [
    (C2, &[(0, A21)]),
    (C3, &[(0, A31), (1, A32)]),
    (C4, &[(0, A41), (1, A42), (2, A43)]),
    (C5, &[(0, A51), (1, A52), (2, A53), (3, A54)]),
    (1.0, &[(0, A61), (1, A62), (2, A63), (3, A64), (4, A65)]),
];
/// The 5th-order solution's weights (the 7th stage is evaluated there: FSAL).
pub(super) const SOLUTION: [(usize, f64); 5] = [(0, A71), (2, A73), (3, A74), (4, A75), (5, A76)];

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
    pub(super) stages: [Vec<f64>; 7],
    pub(super) stage_state: Vec<f64>,
    pub(super) next: Vec<f64>,
    sample: Vec<f64>,
    pub(super) jacobian: Vec<f64>,
    stats: Stats,
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
        }
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
        let mut pending = samples.iter().enumerate().peekable();
        while let Some((k, _)) = pending.next_if(|&(_, &s)| s <= t0) {
            record(k, y, sensitivities(&options));
        }
        if t1 <= t0 {
            return Ok(Reached::End);
        }
        self.evaluate(system, t0, y, 0);
        if !all_finite(&self.stages[0]) {
            return Err(IntegrationError::non_finite(t0));
        }
        if let Some(sensitivity) = options.sensitivity.as_deref_mut() {
            sensitivity.first_stage(system, t0, y, &mut self.stats);
        }
        let mut stepper = Stepper {
            t: t0,
            h: self.initial_step(system, t0, y, t1 - t0),
            t_end: t1,
            previous_error: 1e-4,
            last_rejected: false,
            last_non_finite: false,
            attempts: 0,
            monitor: Monitor::new(options.monitor_stiffness.unwrap_or(usize::MAX)),
        };
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
                let step = (step_end, stepper.h, t1);
                let stiff = options.monitor_stiffness.is_some()
                    && self.stiffness(system, &mut stepper.monitor, step);
                while let Some((k, _)) = pending.next_if(|&(_, &s)| s <= step_end) {
                    let sample = samples[k];
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
                    record(k, &self.sample, s);
                }
                y.copy_from_slice(&self.next);
                self.stages.swap(0, 6);
                if let Some(sensitivity) = options.sensitivity.as_deref_mut() {
                    sensitivity.accept();
                }
                stepper.accept(error, step_end);
                self.stats.accepted += 1;
                if stiff && stepper.t < t1 {
                    let recorded = pending.peek().map_or(samples.len(), |&(k, _)| k);
                    return Ok(Reached::Stiff {
                        t: stepper.t,
                        recorded,
                        step: stepper.h,
                    });
                }
            } else {
                stepper.reject(error);
                self.stats.rejected += 1;
            }
        }
        for (k, _) in pending {
            record(k, y, sensitivities(&options));
        }
        Ok(Reached::End)
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
                let local = h
                    * (E1 * k[0][i]
                        + E3 * k[2][i]
                        + E4 * k[3][i]
                        + E5 * k[4][i]
                        + E6 * k[5][i]
                        + E7 * k[6][i]);
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

/// The continuous extension at fraction `theta` of a step of size `h` from `y` to `next`
/// with stages `k`, entry by entry (states or their sensitivities alike).
pub(super) fn dense(
    theta: f64,
    h: f64,
    y: &[f64],
    next: &[f64],
    k: &[Vec<f64>; 7],
    out: &mut [f64],
) {
    let theta1 = 1.0 - theta;
    for i in 0..y.len() {
        let difference = next[i] - y[i];
        let slope_gap = h * k[0][i] - difference;
        let curvature = difference - h * k[6][i] - slope_gap;
        let correction = h
            * (D1 * k[0][i]
                + D3 * k[2][i]
                + D4 * k[3][i]
                + D5 * k[4][i]
                + D6 * k[5][i]
                + D7 * k[6][i]);
        out[i] = y[i]
            + theta
                * (difference + theta1 * (slope_gap + theta * (curvature + theta1 * correction)));
    }
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

/// Sets `out = y + h * sum_j weight_j * stages[j]`, entry by entry.
#[inline]
pub(super) fn combine(
    out: &mut [f64],
    y: &[f64],
    h: f64,
    stages: &[Vec<f64>; 7],
    weights: &[(usize, f64)],
) {
    for (i, value) in out.iter_mut().enumerate() {
        let increment: f64 = weights.iter().map(|&(j, w)| w * stages[j][i]).sum();
        *value = y[i] + h * increment;
    }
}
