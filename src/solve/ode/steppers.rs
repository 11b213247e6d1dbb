//! The steppers of a model's balances ([`ModelSystem`]) in the one free run
//! ([`super::run`]): the adaptive [`Integrator`] for a continuous (`der`) model, its map
//! for a discrete (`next`) one, both optionally carrying forward sensitivities along.

use super::error::IntegrationError;
use super::integrator::Integrator;
use super::model::ModelSystem;
use super::run::{Segment, Stepper};
use super::sensitivity::multiply_add;
use super::system::OdeSystem;

/// What the integrator's step budget and method choice do at the start of each segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Renewal {
    /// Nothing: one budget for the whole run (a simulation).
    Never,
    /// The budget is whole again, the method choice kept (a run along a record).
    Budget,
    /// The integrator restarts: budget and method choice (one-step predictions).
    Restart,
}

/// The adaptive integrator (Dormand–Prince, Radau IIA where stiff) as a stepper: over a
/// segment, the inputs held at the segment's entry of the input table, it integrates the
/// segment's span in one go, sampling from the dense output.
#[derive(Debug)]
pub struct Adaptive<'a> {
    integrator: &'a mut Integrator,
    system: &'a mut ModelSystem,
    inputs: &'a [Vec<f64>],
    renewal: Renewal,
    sensitivities: Option<&'a mut [f64]>,
}

impl<'a> Adaptive<'a> {
    /// Steps `system` with `integrator`, the inputs from `inputs` (one column per input),
    /// renewing the integrator as `renewal` says at each segment.
    pub fn new(
        integrator: &'a mut Integrator,
        system: &'a mut ModelSystem,
        inputs: &'a [Vec<f64>],
        renewal: Renewal,
    ) -> Self {
        Adaptive {
            integrator,
            system,
            inputs,
            renewal,
            sensitivities: None,
        }
    }

    /// The same stepper carrying the sensitivities `s` (`dim x p`, row-major,
    /// [`OdeSystem::sensitivity_params`]) along, updated in place.
    pub fn with_sensitivities(mut self, s: &'a mut [f64]) -> Self {
        self.sensitivities = Some(s);
        self
    }
}

impl Stepper for Adaptive<'_> {
    type Error = IntegrationError;

    fn advance(
        &mut self,
        segment: &Segment<'_>,
        state: &mut [f64],
        sample: &mut dyn FnMut(&[f64], &[f64]),
    ) -> Result<(), IntegrationError> {
        match self.renewal {
            Renewal::Never => {}
            Renewal::Budget => self.integrator.renew_budget(),
            Renewal::Restart => self.integrator.restart(),
        }
        self.system.hold(self.inputs, segment.index);
        let (span, samples) = (segment.span, segment.samples);
        match self.sensitivities.as_deref_mut() {
            Some(s) => self.integrator.integrate_with_sensitivities(
                self.system,
                span,
                state,
                s,
                samples,
                |_, y, s| sample(y, s),
            ),
            None => (self.integrator)
                .integrate(self.system, span, state, samples, |_, y| sample(y, &[])),
        }
    }
}

/// A discrete model's map as a stepper: over a segment, the inputs held at the segment's
/// entry of the input table, one application per sample, each landing at its sample time
/// but the last, which lands at the segment's end (a grid time may be its nominal value);
/// a segment without samples is one unsampled application to its end (a warm-up step).
/// A non-finite result is an error at the time the application lands at.
#[derive(Debug)]
pub struct Map<'a> {
    system: &'a mut ModelSystem,
    inputs: &'a [Vec<f64>],
    sensitivities: Option<&'a mut [f64]>,
    next: Vec<f64>,
    /// With sensitivities: the moved sensitivities, `df/dx` and `df/dp`.
    work: [Vec<f64>; 3],
}

impl<'a> Map<'a> {
    /// Iterates `system`'s map, the inputs from `inputs` (one column per input).
    pub fn new(system: &'a mut ModelSystem, inputs: &'a [Vec<f64>]) -> Self {
        Map {
            next: vec![0.0; system.dim()],
            system,
            inputs,
            sensitivities: None,
            work: Default::default(),
        }
    }

    /// The same stepper carrying the sensitivities `s` along by `S <- J S + f_p`, updated
    /// in place.
    pub fn with_sensitivities(mut self, s: &'a mut [f64]) -> Self {
        let n = self.next.len();
        let p = s.len() / n.max(1);
        self.work = [vec![0.0; n * p], vec![0.0; n * n], vec![0.0; n * p]];
        self.sensitivities = Some(s);
        self
    }

    /// One application from time `t`, landing at `to`.
    fn apply(&mut self, t: f64, to: f64, state: &mut [f64]) -> Result<(), IntegrationError> {
        self.system.rhs(t, state, &mut self.next);
        let Some(s) = self.sensitivities.as_deref_mut() else {
            if self.next.iter().any(|v| !v.is_finite()) {
                return Err(IntegrationError::non_finite(to));
            }
            state.copy_from_slice(&self.next);
            return Ok(());
        };
        let (n, p) = (state.len(), s.len() / state.len().max(1));
        let [moved, states, params] = &mut self.work;
        self.system.sensitivity_jacobians(t, state, states, params);
        multiply_add(states, s, params, n, p, moved);
        if self.next.iter().chain(moved.iter()).any(|v| !v.is_finite()) {
            return Err(IntegrationError::non_finite(to));
        }
        state.copy_from_slice(&self.next);
        s.copy_from_slice(moved);
        Ok(())
    }
}

impl Stepper for Map<'_> {
    type Error = IntegrationError;

    fn advance(
        &mut self,
        segment: &Segment<'_>,
        state: &mut [f64],
        sample: &mut dyn FnMut(&[f64], &[f64]),
    ) -> Result<(), IntegrationError> {
        self.system.hold(self.inputs, segment.index);
        let (samples, (mut t, end)) = (segment.samples, segment.span);
        let steps = samples.len().max(1);
        for k in 0..steps {
            let to = if k + 1 < steps { samples[k] } else { end };
            self.apply(t, to, state)?;
            if k < samples.len() {
                sample(state, self.sensitivities.as_deref().unwrap_or(&[]));
            }
            t = to;
        }
        Ok(())
    }
}
