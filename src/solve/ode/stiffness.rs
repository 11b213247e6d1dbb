//! The explicit method's stiffness monitor: whether a stretch has turned stiff, so that
//! [`super::Integrator`] hands it to the implicit method. It reads what an accepted
//! Dormand–Prince step leaves ([`Accepted`]), not the integrator itself. Two tests, either suffices once
//! the stretch has cost [`STIFF_WORK`] steps (more after an unprofitable trial): Hairer's (Hairer and Wanner II, section
//! IV.2), `h |lambda|` estimated from the last two stages at the edge of the stability
//! region; and the spectral radius of the exact Jacobian times the step.

use super::system::OdeSystem;

/// `h |lambda|` above this is at the edge of the stability region (about 3.3 on the
/// negative real axis; Hairer tests 3.25, the controller keeps our estimates just below).
const STIFF_PRODUCT: f64 = 3.0;
/// Accepted steps at the edge of stability that declare the stretch stiff ...
const STIFF_STEPS: usize = 15;
/// ... unless this many steps inside the region come first.
const NON_STIFF_STEPS: usize = 6;
/// Accepted steps between two estimates of the spectral radius from the exact Jacobian.
const RADIUS_CHECK: usize = 10;
/// `h rho(J)` above this at [`RADIUS_CHECKS`] estimates in a row declares the stretch stiff:
/// a step that large cannot resolve the fastest mode, so only stability limits it.
const RADIUS_PRODUCT: f64 = 1.0;
/// Consecutive spectral-radius estimates above [`RADIUS_PRODUCT`] that declare stiffness.
const RADIUS_CHECKS: usize = 3;
/// Power iterations per spectral-radius estimate.
const POWER_ITERATIONS: usize = 8;
/// Accepted steps in a stretch before it may be declared stiff: a short stretch costs
/// little explicit, and the explicit method's results are the reference for a system that
/// is only mildly stiff here and there.
pub(super) const STIFF_WORK: usize = 100;
/// Explicit steps of the stretch still to go, at the current step, below which it is not
/// handed over: the implicit method's start (Jacobian, factorisations, a first step that
/// must grow) costs tens of explicit steps.
const REMAINING_STEPS: f64 = 100.0;

/// The monitor's counters over one stretch.
#[derive(Debug, Clone, Copy)]
pub(super) struct Monitor {
    /// Accepted steps before the stretch may be declared stiff.
    pub work: usize,
    accepted: usize,
    stiff_steps: usize,
    non_stiff_steps: usize,
    radius_checks: usize,
}

impl Monitor {
    /// A monitor that waits `work` accepted steps before any verdict.
    pub fn new(work: usize) -> Self {
        Monitor {
            work,
            accepted: 0,
            stiff_steps: 0,
            non_stiff_steps: 0,
            radius_checks: 0,
        }
    }
}

/// What the monitor reads of an accepted explicit step.
pub(super) struct Accepted<'a> {
    /// The step's last two stages, `k6` and `k7` (the slope at its end).
    pub stages: (&'a [f64], &'a [f64]),
    /// The states they were taken at, `y6` and the step's end `y7`.
    pub states: (&'a [f64], &'a [f64]),
    /// The step's end, its size and the stretch's end.
    pub span: (f64, f64, f64),
}

impl Monitor {
    /// Whether the stretch has turned stiff, tested after each accepted step of size
    /// `h` (before the step's end is taken): Hairer's test, `h |lambda|` estimated
    /// as `h |k7 - k6| / |y7 - y6|` at the edge of the stability region for [`STIFF_STEPS`]
    /// steps (not interrupted by [`NON_STIFF_STEPS`] inside it), or every [`RADIUS_CHECK`]
    /// steps the spectral radius of the exact Jacobian times the step above
    /// [`RADIUS_PRODUCT`] [`RADIUS_CHECKS`] times in a row; never before `self.work`
    /// steps (at least [`STIFF_WORK`]), nor with fewer than [`REMAINING_STEPS`] explicit
    /// steps of the stretch left (finishing it costs less than a hand-over). `jacobian` is
    /// work space for the exact Jacobian.
    pub fn is_stiff<S: OdeSystem>(
        &mut self,
        system: &mut S,
        step: Accepted,
        jacobian: &mut Vec<f64>,
    ) -> bool {
        let (t_next, h, t_end) = step.span;
        self.accepted += 1;
        let hairer = self.hairer_test(&step, h);
        let remaining = (t_end - t_next) / h;
        if self.accepted < self.work || remaining < REMAINING_STEPS {
            return false;
        }
        if hairer {
            return true;
        }
        if self.accepted.is_multiple_of(RADIUS_CHECK) {
            let radius = spectral_radius(system, t_next, step.states.1, jacobian);
            if h * radius > RADIUS_PRODUCT {
                self.radius_checks += 1;
                if self.radius_checks >= RADIUS_CHECKS {
                    return true;
                }
            } else {
                self.radius_checks = 0;
            }
        }
        false
    }

    /// Hairer's test: whether [`STIFF_STEPS`] steps have been at the edge of stability.
    fn hairer_test(&mut self, step: &Accepted, h: f64) -> bool {
        let ((k6, k7), (y6, y7)) = (step.stages, step.states);
        let (numerator, denominator) = (0..y7.len()).fold((0.0, 0.0), |(n, d), i| {
            let slope = k7[i] - k6[i];
            let gap = y7[i] - y6[i];
            (n + slope * slope, d + gap * gap)
        });
        if denominator <= 0.0 {
            return false;
        }
        let product = h * (numerator / denominator).sqrt();
        if product > STIFF_PRODUCT {
            self.non_stiff_steps = 0;
            self.stiff_steps += 1;
            self.stiff_steps >= STIFF_STEPS
        } else {
            self.non_stiff_steps += 1;
            if self.non_stiff_steps >= NON_STIFF_STEPS {
                self.stiff_steps = 0;
            }
            false
        }
    }
}

/// The spectral radius of the Jacobian at `(t, y)` (the end of the step just taken), by
/// [`POWER_ITERATIONS`] power iterations from a vector of ones (its growth rate: exact
/// for a dominant real eigenvalue, the right size for a dominant complex pair);
/// `jacobian` is work space, resized to fit.
fn spectral_radius<S: OdeSystem>(
    system: &mut S,
    t: f64,
    y: &[f64],
    jacobian: &mut Vec<f64>,
) -> f64 {
    let n = y.len();
    if jacobian.len() != n * n {
        *jacobian = vec![0.0; n * n];
    }
    system.jacobian(t, y, jacobian);
    let mut vector = vec![1.0 / (n.max(1) as f64).sqrt(); n];
    let mut image = vec![0.0; n];
    let mut radius = 0.0;
    for _ in 0..POWER_ITERATIONS {
        for (i, value) in image.iter_mut().enumerate() {
            *value = (0..n).map(|j| jacobian[i * n + j] * vector[j]).sum();
        }
        let length = image.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(length > 0.0 && length.is_finite()) {
            return if length.is_nan() { 0.0 } else { length };
        }
        radius = length;
        for (v, w) in vector.iter_mut().zip(&image) {
            *v = w / length;
        }
    }
    radius
}
