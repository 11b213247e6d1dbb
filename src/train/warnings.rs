//! What a training run warns of before its first epoch, on stderr and in `run.json`'s
//! `warnings`: a balance too stiff for RK4 ([`StiffnessWarning`]), and one-step pairs with a
//! measured target that do not train ([`DroppedPairs`]; issue 24: nothing is dropped
//! silently).

use std::fmt;

use crate::ir;
use crate::record::Track;

use super::analysis::StiffnessWarning;
use super::split::Training;
use crate::engine::pairs::has_target;

/// A warning of a training run. In `run.json` each is the object of its kind (untagged, so
/// that runs saved before dropped pairs were reported read back).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum Warning {
    /// A balance too stiff for RK4 at the chosen step.
    Stiffness(StiffnessWarning),
    /// Steps with a measured target that do not train.
    DroppedPairs(DroppedPairs),
}

impl fmt::Display for Warning {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Warning::Stiffness(warning) => warning.fmt(formatter),
            Warning::DroppedPairs(dropped) => dropped.fmt(formatter),
        }
    }
}

/// The steps of the training part that have a measured cell at their end but do not train,
/// because the start of some measured state is not known from data there.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DroppedPairs {
    /// Steps of the training part with a measured cell at their end (a target).
    pub with_target: usize,
    /// Of those, the steps that do not train.
    pub dropped: usize,
    /// Per measured state that holds steps back: how many, and why.
    pub causes: Vec<DropCause>,
}

/// One measured state whose start is not known from data at some steps.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DropCause {
    /// The state.
    pub state: String,
    /// The steps at whose start it is not known from data.
    pub steps: usize,
    /// Its gap limit: two of its measurements farther apart than this are not joined by
    /// their interpolant (the shortest embedding delay that reads it, else the longest
    /// step).
    #[serde(with = "crate::json")]
    pub gap_limit: f64,
}

impl fmt::Display for DroppedPairs {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        let causes: Vec<String> = (self.causes.iter())
            .map(|c| {
                format!(
                    "`{}` at {} (its measurements there more than {} apart)",
                    c.state,
                    c.steps,
                    super::analysis::compact(c.gap_limit)
                )
            })
            .collect();
        write!(
            formatter,
            "{} of {} steps with a measured target do not train: the start state is not known \
             from data there: {}; measure those states more often, or give the closures that \
             read them a longer embedding delay (without an embedding: a longer --dt)",
            self.dropped,
            self.with_target,
            causes.join(", ")
        )
    }
}

/// The steps of `trainings` that have a target but do not train (those whose start is not
/// known from data for some state the track measures), or `None` when every one trains.
/// `gap_limits[i]` is state `i`'s gap limit.
pub fn dropped_pairs(
    model: &ir::Model,
    tracks: &[Track],
    trainings: &[Training],
    gap_limits: &[f64],
) -> Option<DroppedPairs> {
    let mut with_target = 0;
    let mut dropped = 0;
    let mut per_state = vec![0usize; model.states.len()];
    for (track, training) in tracks.iter().zip(trainings) {
        let observed: Vec<usize> = (0..model.states.len())
            .filter(|&i| track.measured[i].iter().any(|&m| m))
            .collect();
        for knot in training.knots.clone().filter(|&k| has_target(track, k)) {
            with_target += 1;
            let unknown: Vec<usize> = (observed.iter().copied())
                .filter(|&i| !track.known[i][knot])
                .collect();
            dropped += usize::from(!unknown.is_empty());
            for i in unknown {
                per_state[i] += 1;
            }
        }
    }
    let causes = (model.states.iter().zip(&per_state).enumerate())
        .filter(|(_, (_, &steps))| steps > 0)
        .map(|(i, (state, &steps))| DropCause {
            state: state.name.clone(),
            steps,
            gap_limit: gap_limits.get(i).copied().unwrap_or(f64::NAN),
        })
        .collect();
    (dropped > 0).then_some(DroppedPairs {
        with_target,
        dropped,
        causes,
    })
}
