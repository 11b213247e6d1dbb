//! The one free run: every run of a model forward in time — a simulation from input
//! signals, a mechanistic model's run along a record (with or without its forward
//! sensitivities), a trained grey box's run from knot to knot — walks its [`Segment`]s
//! here, has its [`Stepper`] advance the state over each, and gives the caller its say
//! before and after each ([`Observer`]).
//!
//! A segment is a stretch over which the inputs hold: a stretch between two switches of
//! the input signals, a run of record rows with the same inputs, one knot of a track. The
//! steppers are the adaptive [`super::Integrator`] (explicit and implicit behind its
//! switch: [`super::Adaptive`]), a discrete model's map ([`super::Map`]) and, above this
//! crate's solving wing, a trained network's step (`crate::train::stepping`).

use std::ops::ControlFlow;

/// A stretch of a run over which the inputs hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment<'a> {
    /// Where the inputs held over the segment are read: an index into the run's input
    /// table (a record's row, a track's knot, an entry of a table of held signal values).
    pub index: usize,
    /// The times the segment starts and ends at.
    pub span: (f64, f64),
    /// The times the state is sampled at, increasing, within the span (none: a warm-up, or
    /// a grey box's knot, whose observer records it after the step).
    pub samples: &'a [f64],
}

/// What advances a state over a segment.
pub trait Stepper {
    /// Why a segment could not be advanced over.
    type Error;

    /// Advances `state` over `segment`, its inputs held, calling `sample(state,
    /// sensitivities)` at each of the segment's sample times, in order (the sensitivities
    /// are empty where the stepper carries none).
    fn advance(
        &mut self,
        segment: &Segment<'_>,
        state: &mut [f64],
        sample: &mut dyn FnMut(&[f64], &[f64]),
    ) -> Result<(), Self::Error>;
}

/// The caller's say in a run of stepper `S`: the samples, and a word before and after each
/// segment. A closure `FnMut(&[f64], &[f64])` is an observer that takes the samples only.
pub trait Observer<S: Stepper> {
    /// Before `segment`, which starts from `state`: the caller may end the run here with
    /// an error (a stop request, [`crate::stop`]) or note where the segment starts.
    fn before(&mut self, _segment: &Segment<'_>, _state: &[f64]) -> Result<(), S::Error> {
        Ok(())
    }

    /// The state at a sample time (in order) and its sensitivities (empty without).
    fn sample(&mut self, state: &[f64], sensitivities: &[f64]);

    /// After `segment`, which left `state`: the caller may change the state (reset a
    /// measured state to the data) and the stepper (the history it reads), and end the
    /// run early ([`ControlFlow::Break`]: a run that left its physical range).
    fn after(
        &mut self,
        _segment: &Segment<'_>,
        _state: &mut [f64],
        _stepper: &mut S,
    ) -> Result<ControlFlow<()>, S::Error> {
        Ok(ControlFlow::Continue(()))
    }
}

impl<S: Stepper, F: FnMut(&[f64], &[f64])> Observer<S> for F {
    fn sample(&mut self, state: &[f64], sensitivities: &[f64]) {
        self(state, sensitivities)
    }
}

/// Runs `state` forward over `segments` in turn with `stepper`, `observer` seeing every
/// sample and having its say before and after every segment; stops at the first error, or
/// after the segment the observer ends the run at.
pub fn free_run<'s, S: Stepper>(
    stepper: &mut S,
    segments: impl IntoIterator<Item = Segment<'s>>,
    state: &mut [f64],
    observer: &mut impl Observer<S>,
) -> Result<(), S::Error> {
    for segment in segments {
        observer.before(&segment, state)?;
        stepper.advance(&segment, state, &mut |y, s| observer.sample(y, s))?;
        if observer.after(&segment, state, stepper)?.is_break() {
            break;
        }
    }
    Ok(())
}
