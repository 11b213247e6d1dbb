//! Step control of free runs: each step of a `der` model's free run is cut into as many
//! equal sub-steps as its stiffness needs there, so that a balance that turns stiff (a
//! substrate running out under a feed) is integrated stably and accurately whatever
//! `--substeps` the network was trained with.
//!
//! The control is step doubling: the step from a knot is taken in `m` and in `2m` sub-steps
//! (each one RK4 step of `h / m`, its stages reading the delay embedding at their own
//! fractions of the step); where the two differ by more than [`TOLERANCE`] of the state's
//! scale, `m` doubles, up to [`MOST_SUBSTEPS`] sub-steps of the step in all. A network
//! trained with `K` sub-steps per step is called once per sub-step as a one-sub-step copy
//! of itself ([`crate::engine::graph::Network::with_substeps`]), and the control starts at
//! `m = K`: its trained step, the same arithmetic (and [`MOST_SUBSTEPS`] bounds the
//! sub-steps of a step, not multiples of `K`: a member trained with 1024 sub-steps took
//! up to 1024 x 4096 per knot before, and its free runs ran for hours). The result of the `m` that sufficed
//! is kept, so where the step the model was trained with is stable and accurate the run is
//! exactly the trained model's (and its ONNX export's) step; the next knot starts from that
//! `m`; it never falls back to fewer within a run (below). The tolerance guards
//! stability, not the last digit: an unstable explicit step shows as two results far
//! apart, so this finds the stable step without estimating the Jacobian. A step that needs
//! more than [`MOST_SUBSTEPS`] keeps the finest result and lets the physical range judge
//! it.
//!
//! A state declared `nonnegative` cannot be driven below zero by a learned term (the
//! compiler proves it), so a step that takes it from (about) zero or above to below zero
//! is a discretisation error, not the model: such a step is refined like one whose `m`
//! and `2m` results disagree, until the state stays above `-TOLERANCE` of its floor
//! (`1e-6` of its scale). Nothing is clamped: a crossing the finest step still shows (the
//! model's own, unchecked terms drive the state down) is kept and judged by the physical
//! range. Training steps are never refined or clamped.

use crate::engine::graph::{BackendError, Batch, Network, Prediction};
use crate::ir;
use crate::record::Track;
use crate::solve::ode::Segment;

use crate::engine::pairs::embedding_row;

/// Largest relative difference between the `m`- and `2m`-sub-step results of a step that
/// is accepted, per state, on the scale `|x| + floor`.
pub const TOLERANCE: f64 = 1e-3;
/// Most sub-steps of one step.
pub const MOST_SUBSTEPS: usize = 4096;

/// How a free run steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stepping {
    /// One network step per knot: what training windows do.
    Fixed,
    /// As many sub-steps per knot as the step needs (this module).
    Controlled,
}

/// The step control's state along one run.
#[derive(Debug, Clone, PartialEq)]
pub struct Stepper {
    /// Sub-steps to try first at the next knot.
    substeps: usize,
    /// Per state, the absolute part of its scale.
    floors: Vec<f64>,
    /// Per state (measured, then hidden), whether it is declared `nonnegative`.
    nonnegative: Vec<bool>,
    /// The most sub-steps any step needed.
    pub most: usize,
}

impl Stepper {
    /// A controller for states whose typical sizes are `scales` (zero where unknown).
    pub fn new(scales: &[f64]) -> Self {
        Stepper {
            substeps: 1,
            floors: scales.iter().map(|s| 1e-3 * s.abs().max(1e-9)).collect(),
            nonnegative: Vec::new(),
            most: 1,
        }
    }

    /// The same controller trying `substeps` first (a network trained with `K` sub-steps
    /// per step starts at `K`: its trained step).
    pub fn starting_at(mut self, substeps: usize) -> Self {
        self.substeps = substeps.max(1);
        self.most = self.substeps;
        self
    }

    /// The controller for `model`'s states: a step that takes a `nonnegative` one below
    /// zero is refined (module documentation).
    pub fn for_model(model: &ir::Model, scales: &[f64]) -> Self {
        let states = model.states.iter().chain(&model.hidden);
        Stepper {
            nonnegative: states.map(|s| s.nonnegative).collect(),
            ..Stepper::new(scales)
        }
    }

    /// The step from `knot` of `track` (its history in `history`) starting at `state`:
    /// the prediction at the knot (closure and model outputs) and the state at the next
    /// knot.
    pub fn step(
        &mut self,
        (network, model): (&Network, &ir::Model),
        (track, history): (&Track, &Track),
        (knot, state): (usize, &[f64]),
        fractions: &[f64],
    ) -> Result<(Prediction, Vec<f64>), BackendError> {
        let step = Step {
            network,
            model,
            track,
            history,
            knot,
            fractions,
        };
        let first = network.predict(&step.batch(state, 0, 1))?;
        if model.dynamics == ir::Dynamics::Discrete {
            let next = first.next_states.clone();
            return Ok((first, next));
        }
        let mut m = self.substeps;
        let mut coarse = step.advance(state, m, &first)?;
        loop {
            let fine = step.advance(state, 2 * m, &first)?;
            let error = self
                .error(&coarse.next_states, &fine.next_states)
                .max(self.crossing(state, &coarse.next_states));
            if error <= 1.0 || 2 * m >= MOST_SUBSTEPS {
                let kept = if error <= 1.0 { coarse } else { fine };
                // Never fewer later: a step that agrees at `m` and `2m` may still have
                // jumped, at both, past a singularity of the rates (Monod's `S = -K`) onto a
                // smooth spurious branch; a stiff stretch stays stiff (seen on a fed-batch).
                self.substeps = m;
                self.most = self.most.max(m);
                let mut prediction = first;
                prediction.next_states.clone_from(&kept.next_states);
                prediction.observed = kept.observed;
                return Ok((prediction, kept.next_states));
            }
            m *= 2;
            coarse = fine;
        }
    }

    /// How far a step from `start` to `end` takes a `nonnegative` state below zero, on
    /// its floor, over [`TOLERANCE`]: above 1 for a crossing to refine; 0 for none, and for
    /// a state that starts below that (it is judged by the physical range instead).
    fn crossing(&self, start: &[f64], end: &[f64]) -> f64 {
        (self.nonnegative.iter().enumerate())
            .filter(|(_, declared)| **declared)
            .map(|(i, _)| {
                let allowed = TOLERANCE * self.floors.get(i).copied().unwrap_or(1e-12);
                let from = start.get(i).copied().unwrap_or(0.0);
                let to = end.get(i).copied().unwrap_or(f64::NAN);
                if from < -allowed || to.is_nan() || to >= 0.0 {
                    0.0
                } else {
                    -to / allowed
                }
            })
            .fold(0.0, f64::max)
    }

    /// The largest difference of `a` and `b` on the states' scales, over [`TOLERANCE`];
    /// infinite where either is not finite.
    fn error(&self, a: &[f64], b: &[f64]) -> f64 {
        (a.iter().zip(b).enumerate())
            .map(|(i, (x, y))| {
                let floor = self.floors.get(i).copied().unwrap_or(1e-9);
                let scale = x.abs().max(y.abs()) + floor;
                let difference = (x - y).abs() / scale / TOLERANCE;
                if difference.is_nan() {
                    f64::INFINITY
                } else {
                    difference
                }
            })
            .fold(0.0, f64::max)
    }
}

/// A trained network's step from knot to knot of a track: the stepper of a grey box's free
/// runs ([`crate::solve::ode::free_run`], `super::evaluate::simulate`). A segment is one
/// knot (its index), stepped once by the whole network ([`Stepping::Fixed`]) or under step
/// control ([`Stepping::Controlled`]); the delay embedding reads the run's own history.
pub struct NetworkStep<'a> {
    network: &'a Network,
    model: &'a ir::Model,
    track: &'a Track,
    fractions: &'a [f64],
    stepping: Stepping,
    /// What step control steps a network trained with `K > 1` sub-steps by: a
    /// one-sub-step copy of it and its stage fractions ([`split_network`]).
    single: Option<(Network, Vec<f64>)>,
    control: Stepper,
    /// The track as the run has seen it: where it fed itself, its own measured states.
    history: Track,
    /// The prediction made at the last knot stepped from, until taken.
    prediction: Option<Prediction>,
}

impl<'a> NetworkStep<'a> {
    /// Steps `network` along `track` as `stepping` says, its stage fractions `fractions`,
    /// the states' typical sizes `scales` (step control's floors).
    pub fn new(
        (network, model): (&'a Network, &'a ir::Model),
        track: &'a Track,
        fractions: &'a [f64],
        scales: &[f64],
        stepping: Stepping,
    ) -> Self {
        let split = split_network(network, model, stepping);
        let first = split.as_ref().map_or(1, |(_, _, trained)| *trained);
        NetworkStep {
            network,
            model,
            track,
            fractions,
            stepping,
            single: split.map(|(single, fractions, _)| (single, fractions)),
            control: Stepper::for_model(model, scales).starting_at(first),
            history: track.clone(),
            prediction: None,
        }
    }

    /// The most sub-steps one step needed (1 at the trained step).
    pub fn most(&self) -> usize {
        self.control.most
    }

    /// The prediction made at the last knot stepped from (its closure outputs and
    /// outputs), once.
    pub fn take_prediction(&mut self) -> Option<Prediction> {
        self.prediction.take()
    }

    /// Writes the run's own value of measured state `state` at `knot` into the history the
    /// delay embedding reads.
    pub fn remember(&mut self, state: usize, knot: usize, value: f64) {
        self.history.states[state][knot] = value;
    }
}

impl crate::solve::ode::Stepper for NetworkStep<'_> {
    type Error = BackendError;

    fn advance(
        &mut self,
        segment: &Segment<'_>,
        state: &mut [f64],
        _: &mut dyn FnMut(&[f64], &[f64]),
    ) -> Result<(), BackendError> {
        let (knot, place) = (segment.index, (self.track, &self.history));
        let prediction = match self.stepping {
            Stepping::Fixed => {
                let batch = fixed_batch(self.model, place, knot, state, self.fractions);
                self.network.predict(&batch)?
            }
            Stepping::Controlled => {
                let (stepped, fractions) = match &self.single {
                    Some((single, fractions)) => (single, &fractions[..]),
                    None => (self.network, self.fractions),
                };
                let pair = (stepped, self.model);
                (self.control.step(pair, place, (knot, state), fractions)?).0
            }
        };
        if prediction.next_states.len() != state.len() {
            return Err(BackendError::internal(
                "a step changed the number of states",
            ));
        }
        state.copy_from_slice(&prediction.next_states);
        self.prediction = Some(prediction);
        Ok(())
    }
}

/// What step control steps a network trained with `K > 1` sub-steps by: a one-sub-step
/// copy of it, its stage fractions, and `K` to start from (module documentation); `None`
/// where the network steps itself (fixed steps, `next` models, `K = 1`).
fn split_network(
    network: &Network,
    model: &ir::Model,
    stepping: Stepping,
) -> Option<(Network, Vec<f64>, usize)> {
    let trained = network.substeps();
    let split = stepping == Stepping::Controlled
        && model.dynamics == ir::Dynamics::Continuous
        && trained > 1;
    split.then(|| {
        let fractions = crate::engine::pairs::stage_fractions(model.dynamics, 1);
        (network.with_substeps(1), fractions, trained)
    })
}

/// The one-step batch of knot `knot` of `track` (its history `history`) from `state`.
fn fixed_batch(
    model: &ir::Model,
    (track, history): (&Track, &Track),
    knot: usize,
    state: &[f64],
    fractions: &[f64],
) -> Batch {
    Batch {
        rows: 1,
        states: state.to_vec(),
        inputs: track.inputs.iter().map(|u| u[knot]).collect(),
        embeddings: (model.closures.iter())
            .map(|c| {
                (fractions.iter())
                    .map(|&f| embedding_row(c, history, knot, f))
                    .collect()
            })
            .collect(),
        step_sizes: vec![track.steps[knot]],
        ..Batch::default()
    }
}

/// One knot's step, for [`Stepper::step`].
struct Step<'a> {
    network: &'a Network,
    model: &'a ir::Model,
    track: &'a Track,
    history: &'a Track,
    knot: usize,
    fractions: &'a [f64],
}

impl Step<'_> {
    /// The batch of sub-step `j` of `m` from `state`: the step `h / m`, the embedding at
    /// the sub-step's stage fractions of the whole step.
    fn batch(&self, state: &[f64], j: usize, m: usize) -> Batch {
        let (knot, m) = (self.knot, m as f64);
        Batch {
            rows: 1,
            states: state.to_vec(),
            inputs: self.track.inputs.iter().map(|u| u[knot]).collect(),
            embeddings: (self.model.closures.iter())
                .map(|c| {
                    (self.fractions.iter())
                        .map(|&f| embedding_row(c, self.history, knot, (j as f64 + f) / m))
                        .collect()
                })
                .collect(),
            step_sizes: vec![self.track.steps[knot] / m],
            ..Batch::default()
        }
    }

    /// The step in `m` sub-steps from `state` (`first`: the prediction of one sub-step of
    /// the whole step, reused when `m` is 1).
    fn advance(
        &self,
        state: &[f64],
        m: usize,
        first: &Prediction,
    ) -> Result<Prediction, BackendError> {
        if m == 1 {
            return Ok(first.clone());
        }
        let mut current = state.to_vec();
        let mut last = None;
        for j in 0..m {
            let prediction = self.network.predict(&self.batch(&current, j, m))?;
            current.clone_from(&prediction.next_states);
            if current.iter().any(|v| !v.is_finite()) {
                return Ok(prediction);
            }
            last = Some(prediction);
        }
        last.ok_or_else(|| BackendError::internal("a step of no sub-steps"))
    }
}
