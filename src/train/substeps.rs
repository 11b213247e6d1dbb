//! The sub-steps training takes by itself: as many as the step control of the network's
//! own free runs over the training knots needed ([`super::stepping`]).

use super::evaluate::{simulate, Feed};
use super::split::Training;
use super::stepping::Stepping;
use crate::engine::graph::Network;
use crate::ir;
use crate::record::Track;

/// Most sub-steps training takes by itself (beyond, the stiffness warning asks the user).
pub const MOST_TRAINING_SUBSTEPS: usize = 1024;

/// The sub-steps training needs: the most any step of `network`'s free runs over the
/// training knots of `tracks` needed under step control, at least `asked`, at most
/// [`MOST_TRAINING_SUBSTEPS`] (the runs start from the data; a run that fails counts as
/// needing the most).
pub fn training_substeps(
    (network, model): (&Network, &ir::Model),
    (tracks, trainings): (&[Track], &[Training]),
    (fractions, hidden): (&[f64], &[f64]),
    asked: usize,
) -> usize {
    if model.dynamics == ir::Dynamics::Discrete {
        return asked;
    }
    let mut needed = asked.max(1);
    for (track, training) in tracks.iter().zip(trainings) {
        let knots = training.knots.clone();
        if knots.is_empty() || track.len() < 2 {
            continue;
        }
        let last = knots
            .end
            .min(track.len() - 1)
            .saturating_sub(1)
            .max(knots.start);
        let how = (Feed::Own, None, Stepping::Controlled);
        let run = simulate(
            network,
            model,
            track,
            fractions,
            (knots.start, last),
            hidden,
            how,
        );
        needed = needed.max(run.map_or(MOST_TRAINING_SUBSTEPS, |run| run.substeps));
    }
    needed.min(MOST_TRAINING_SUBSTEPS)
}
