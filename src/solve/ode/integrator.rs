//! The one integrator every simulation, fit and free run uses: explicit Dormand–Prince
//! while the system is not stiff, Radau IIA where it is, chosen automatically as LSODA
//! does — the explicit method's stiffness monitor hands a stretch to the implicit method,
//! and the implicit method hands it back once the explicit method would be stable at the
//! step it takes. A step budget per run turns a runaway integration into an error that
//! names the fastest balance; forward sensitivities go through whichever method steps.

use super::dopri::{Dopri5, Options, Reached, Record};
use super::error::IntegrationError;
use super::radau::Radau;
use super::sensitivity::{Explicit, Implicit};
use super::stiffness::STIFF_WORK;
use super::system::{OdeSystem, Stats, Tolerances};

/// Which method integrates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Dormand–Prince while the system is not stiff, Radau IIA where it is (the default).
    #[default]
    Auto,
    /// Dormand–Prince only.
    Explicit,
    /// Radau IIA only.
    Implicit,
}

/// Implicit steps between checks whether the explicit method would do.
const CALM_CHECK: usize = 10;
/// The explicit method takes over where `h * |J|` is below this (well inside its
/// stability region, whose real extent is about 3.3).
const CALM_PRODUCT: f64 = 1.0;
/// The implicit method keeps a stretch only where its work per unit of time (right-hand
/// sides, Jacobians and factorisations, [`cost`]) is below the explicit method's at the
/// hand-over divided by this, or still falls (by [`GROWING`] between checks).
const WORTH: f64 = 1.5;
/// A fall of the implicit method's cost per unit of time between two checks that counts as
/// still improving.
const GROWING: f64 = 2.0;
/// After a lost trial, the explicit method waits this many times longer before the next.
const BACKOFF: usize = 4;

/// The implicit method's steps since it last took over, judged every [`CALM_CHECK`] steps
/// (across stretches) by their cost per unit of time against the explicit method's.
#[derive(Debug, Clone, Copy, Default)]
struct Trial {
    steps: usize,
    /// Time advanced in the current window of [`CALM_CHECK`] steps.
    time: f64,
    /// The implicit method's work counters at the window's start.
    start: Stats,
    /// The cost per unit of time of the window before (infinite: none yet).
    previous: f64,
}

/// The cost of work, in evaluations of the right-hand side: a Jacobian (the balances and
/// their derivatives) about three, a factorisation (small dense systems) about two.
fn cost(stats: &Stats) -> f64 {
    stats.evaluations as f64 + 3.0 * stats.jacobians as f64 + 2.0 * stats.factorisations as f64
}

/// A reusable integrator with automatic method choice (owns its work arrays).
#[derive(Debug, Clone)]
pub struct Integrator {
    method: Method,
    budget: usize,
    attempts: usize,
    stiff: bool,
    /// Accepted explicit steps in a stretch before it may be declared stiff (`None`: never):
    /// [`STIFF_WORK`], four times more after each trial the implicit method lost.
    monitor: Option<usize>,
    /// The implicit method's steps since it took over.
    trial: Trial,
    /// The explicit method's step where it last handed over.
    explicit_step: f64,
    implicit_step: Option<f64>,
    explicit: Dopri5,
    implicit: Radau,
    explicit_sensitivity: Option<Explicit>,
    implicit_sensitivity: Option<Implicit>,
    sample: Vec<f64>,
    scratch: Vec<f64>,
    switches: usize,
}

impl Integrator {
    /// An integrator for systems of `dim` equations that attempts at most `budget` steps
    /// per run (from one [`Integrator::restart`] to the next).
    pub fn new(dim: usize, tolerances: Tolerances, budget: usize, method: Method) -> Self {
        Integrator {
            method,
            budget,
            attempts: 0,
            stiff: method == Method::Implicit,
            monitor: (method == Method::Auto).then_some(STIFF_WORK),
            trial: Trial::default(),
            explicit_step: 0.0,
            implicit_step: None,
            explicit: Dopri5::new(dim, tolerances, budget),
            implicit: Radau::new(dim, tolerances),
            explicit_sensitivity: None,
            implicit_sensitivity: None,
            sample: vec![0.0; dim],
            scratch: vec![0.0; dim * dim],
            switches: 0,
        }
    }

    /// Starts a new run: the step budget is whole again and the method choice starts over
    /// (explicit, unless only the implicit method runs).
    pub fn restart(&mut self) {
        self.explicit.forget_step();
        self.attempts = 0;
        self.stiff = self.method == Method::Implicit;
        self.monitor = (self.method == Method::Auto).then_some(STIFF_WORK);
        self.implicit_step = None;
    }

    /// Makes the step budget whole again, keeping the method choice (a new stretch of the
    /// same run, e.g. the next one-step prediction along a record).
    pub fn renew_budget(&mut self) {
        self.attempts = 0;
    }

    /// Work done since the integrator was made, both methods together.
    pub fn stats(&self) -> Stats {
        let mut stats = self.explicit.stats();
        stats.add(&self.implicit.stats());
        stats.switches = self.switches;
        stats
    }

    /// Integrates `system` from `(t0, y)` to `t1 >= t0`, leaving `y(t1)` in `y`;
    /// `record(k, y)` is called once for each of the increasing `samples` in `[t0, t1]`.
    pub fn integrate<S: OdeSystem>(
        &mut self,
        system: &mut S,
        span: (f64, f64),
        y: &mut [f64],
        samples: &[f64],
        mut record: impl FnMut(usize, &[f64]),
    ) -> Result<(), IntegrationError> {
        self.run(system, span, y, None, samples, &mut |k, y, _| record(k, y))
    }

    /// [`Integrator::integrate`] carrying the sensitivities `s = dy/dp` (`dim x p`,
    /// row-major, `p` = [`OdeSystem::sensitivity_params`]) along: `record(k, y, s)`.
    pub fn integrate_with_sensitivities<S: OdeSystem>(
        &mut self,
        system: &mut S,
        span: (f64, f64),
        y: &mut [f64],
        s: &mut [f64],
        samples: &[f64],
        mut record: impl FnMut(usize, &[f64], &[f64]),
    ) -> Result<(), IntegrationError> {
        let (n, p) = (y.len(), system.sensitivity_params());
        if self
            .explicit_sensitivity
            .as_ref()
            .map(|e| e.current().len())
            != Some(n * p)
        {
            self.explicit_sensitivity = Some(Explicit::new(n, p));
            self.implicit_sensitivity = Some(Implicit::new(n, p));
        }
        self.run(system, span, y, Some(s), samples, &mut record)
    }

    fn run<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (t0, t1): (f64, f64),
        y: &mut [f64],
        mut s: Option<&mut [f64]>,
        samples: &[f64],
        record: &mut Record,
    ) -> Result<(), IntegrationError> {
        let (mut t, mut done) = (t0, 0);
        loop {
            let stretch = (t, t1);
            let result = if self.stiff {
                self.implicit_stretch(
                    system,
                    stretch,
                    y,
                    s.as_deref_mut(),
                    &samples[done..],
                    done,
                    record,
                )
            } else {
                self.explicit_stretch(
                    system,
                    stretch,
                    y,
                    s.as_deref_mut(),
                    &samples[done..],
                    done,
                    record,
                )
            };
            match result? {
                Reached::End => return Ok(()),
                Reached::Stiff {
                    t: at,
                    recorded,
                    step,
                } => {
                    (t, done) = (at, done + recorded);
                    if !self.stiff {
                        self.explicit_step = step;
                        self.implicit_step = Some(step);
                        self.trial = Trial {
                            start: self.implicit.stats(),
                            previous: f64::INFINITY,
                            ..Trial::default()
                        };
                    }
                    self.stiff = !self.stiff;
                    self.switches += 1;
                }
            }
        }
    }

    /// A stretch (or its start, up to where it turns stiff) with the explicit method.
    #[allow(clippy::too_many_arguments)]
    fn explicit_stretch<S: OdeSystem>(
        &mut self,
        system: &mut S,
        span: (f64, f64),
        y: &mut [f64],
        s: Option<&mut [f64]>,
        samples: &[f64],
        offset: usize,
        record: &mut Record,
    ) -> Result<Reached, IntegrationError> {
        let remaining = self.budget.saturating_sub(self.attempts);
        self.explicit.set_max_steps(remaining);
        let before = self.explicit.stats();
        let sensitivity = match (&s, self.explicit_sensitivity.as_mut()) {
            (Some(s), Some(sensitivity)) => {
                sensitivity.set(s);
                Some(sensitivity)
            }
            _ => None,
        };
        let options = Options {
            monitor_stiffness: self.monitor,
            sensitivity,
        };
        let mut shifted = |k: usize, y: &[f64], s: &[f64]| record(offset + k, y, s);
        let reached = self
            .explicit
            .advance(system, span, y, samples, &mut shifted, options);
        let after = self.explicit.stats();
        self.attempts += (after.accepted + after.rejected) - (before.accepted + before.rejected);
        let reached = reached.map_err(|error| self.whole_budget(error))?;
        if let (Some(s), Some(sensitivity)) = (s, &self.explicit_sensitivity) {
            s.copy_from_slice(sensitivity.current());
        }
        Ok(reached)
    }

    /// A stretch (or its start, up to where it turns calm) with the implicit method.
    #[allow(clippy::too_many_arguments)]
    fn implicit_stretch<S: OdeSystem>(
        &mut self,
        system: &mut S,
        (t0, t1): (f64, f64),
        y: &mut [f64],
        s: Option<&mut [f64]>,
        samples: &[f64],
        offset: usize,
        record: &mut Record,
    ) -> Result<Reached, IntegrationError> {
        // The explicit step is no guide once the implicit method has taken over.
        self.explicit.forget_step();
        if let (Some(s), Some(sensitivity)) = (&s, self.implicit_sensitivity.as_mut()) {
            sensitivity.set(s);
        }
        let with = s.is_some();
        let mut next = samples.partition_point(|&sample| sample <= t0);
        let start = self.implicit_current(with);
        for k in 0..next {
            record(offset + k, y, &start);
        }
        let mut reached = Reached::End;
        if t1 > t0 {
            self.implicit
                .start(system, (t0, t1), y, self.implicit_step)?;
            while self.implicit.time() < t1 {
                self.implicit_step(system, with)?;
                next += self.record_implicit(samples, next, offset, with, record);
                self.trial.steps += 1;
                self.trial.time += self.implicit.last_step();
                let check =
                    self.method == Method::Auto && self.trial.steps.is_multiple_of(CALM_CHECK);
                if check && self.implicit.time() < t1 && self.hand_back(system) {
                    let (t, step) = (self.implicit.time(), self.implicit.step_size());
                    reached = Reached::Stiff {
                        t,
                        recorded: next,
                        step,
                    };
                    break;
                }
            }
            self.implicit_step = Some(self.implicit.step_size());
            y.copy_from_slice(self.implicit.state());
        }
        if let (Some(s), Some(sensitivity)) = (s, &self.implicit_sensitivity) {
            s.copy_from_slice(sensitivity.current());
        }
        if reached == Reached::End {
            let end = self.implicit_current(with);
            for k in next..samples.len() {
                record(offset + k, y, &end);
            }
        }
        Ok(reached)
    }

    /// The implicit method's current sensitivities (empty without them).
    fn implicit_current(&self, with: bool) -> Vec<f64> {
        match (with, &self.implicit_sensitivity) {
            (true, Some(sensitivity)) => sensitivity.current().to_vec(),
            _ => Vec::new(),
        }
    }

    /// One implicit step (and the sensitivities over it).
    fn implicit_step<S: OdeSystem>(
        &mut self,
        system: &mut S,
        sensitivities: bool,
    ) -> Result<(), IntegrationError> {
        self.implicit
            .step(system, &mut self.attempts, self.budget)?;
        if sensitivities {
            if let Some(sensitivity) = self.implicit_sensitivity.as_mut() {
                self.implicit.step_sensitivities(system, sensitivity);
            }
        }
        Ok(())
    }

    /// Records the samples from `next` on that the last implicit step passed; returns how
    /// many.
    fn record_implicit(
        &mut self,
        samples: &[f64],
        next: usize,
        offset: usize,
        sensitivities: bool,
        record: &mut Record,
    ) -> usize {
        let now = self.implicit.time();
        let mut count = 0;
        for (k, &sample) in samples.iter().enumerate().skip(next) {
            if sample > now {
                break;
            }
            self.implicit.interpolate(sample, &mut self.sample);
            let s: &[f64] = match (sensitivities, self.implicit_sensitivity.as_mut()) {
                (true, Some(sensitivity)) => {
                    sensitivity.interpolate(sample);
                    sensitivity.sample()
                }
                _ => &[],
            };
            record(offset + k, &self.sample, s);
            count += 1;
        }
        count
    }

    /// Whether the explicit method should take the stretch back: the implicit method's
    /// work per unit of time over the last [`CALM_CHECK`] steps is not [`WORTH`] times below
    /// the explicit method's (six right-hand sides per explicit step) and no longer falls (a
    /// lost trial: the explicit method then waits [`BACKOFF`] times longer before the
    /// next), or the stretch has calmed down.
    fn hand_back<S: OdeSystem>(&mut self, system: &mut S) -> bool {
        let now = self.implicit.stats();
        let mut work = now;
        work.evaluations -= self.trial.start.evaluations;
        work.jacobians -= self.trial.start.jacobians;
        work.factorisations -= self.trial.start.factorisations;
        let implicit = cost(&work) / self.trial.time.max(f64::MIN_POSITIVE);
        let explicit = 6.0 / self.explicit_step.max(f64::MIN_POSITIVE);
        let improving = implicit * GROWING < self.trial.previous;
        (self.trial.previous, self.trial.start, self.trial.time) = (implicit, now, 0.0);
        if implicit * WORTH > explicit && !improving {
            self.monitor = self.monitor.map(|work| work.saturating_mul(BACKOFF));
            return true;
        }
        self.calm(system)
    }

    /// Whether the explicit method would be stable at the implicit method's step: `h` times
    /// the largest absolute row sum of a fresh Jacobian below [`CALM_PRODUCT`].
    fn calm<S: OdeSystem>(&mut self, system: &mut S) -> bool {
        let n = self.sample.len();
        system.jacobian(
            self.implicit.time(),
            self.implicit.state(),
            &mut self.scratch,
        );
        let largest = (0..n)
            .map(|i| {
                self.scratch[i * n..(i + 1) * n]
                    .iter()
                    .map(|v| v.abs())
                    .sum::<f64>()
            })
            .fold(0.0, f64::max);
        self.implicit.step_size() * largest < CALM_PRODUCT
    }

    /// An explicit method's budget error, counted against the whole run's budget.
    fn whole_budget(&self, error: IntegrationError) -> IntegrationError {
        match error {
            IntegrationError::TooManySteps { t, stuck, .. } => IntegrationError::TooManySteps {
                t,
                steps: self.budget,
                stuck,
            },
            other => other,
        }
    }
}
