//! Tracks in use: the training or validation tracks with their hidden-state estimates and
//! the model's fill of unknown stretches, their pair table, and the paper's two validation
//! errors per scored experiment and pooled.

use super::stepping::Stepping;
use crate::engine::graph::{Network, Setup};
use crate::ir;
use crate::record::Track;

use super::evaluate::{
    offline_error, online_error, run_in, simulate, ErrorSum, Feed, PhysicalRange,
};
use super::split::Scoring;
use super::{ErrorSet, TrainError, TrainOptions, ValidationErrors};
use crate::engine::pairs::{stage_fractions, PairAt, PairTable};

/// Tracks with their hidden-state estimates and a table of pairs.
pub(crate) struct Course {
    /// The tracks (their reference filled by the model where unknown).
    pub tracks: Vec<Track>,
    /// `hidden[track][knot]`.
    pub hidden: Vec<Vec<Vec<f64>>>,
    /// The pairs of the table.
    pub table: PairTable,
    /// Per measured state, its loss weight.
    pub weights: Vec<f64>,
    /// The measured model outputs (the normalisation's observables).
    pub observables: Vec<usize>,
}

impl Course {
    /// Tracks with hidden states at their initial values (refresh before use) and the pair
    /// table of `pairs`, each target cell weighted by its column's weight.
    pub fn new(
        model: &ir::Model,
        tracks: Vec<Track>,
        (pairs, weights, observables): (&[PairAt], &[f64], &[usize]),
        fractions: &[f64],
    ) -> Course {
        let hidden = tracks.iter().map(|t| vec![Vec::new(); t.len()]).collect();
        let mut table = PairTable::build(model, &tracks, pairs, &[], fractions);
        table.scale_weights(weights);
        table.observe(&tracks, observables);
        Course {
            tracks,
            hidden,
            table,
            weights: weights.to_vec(),
            observables: observables.to_vec(),
        }
    }
}

/// Re-runs the hidden states and (with `fill`) the model's fill of unknown stretches
/// along every track of `course` with the current network (nothing to do for a model
/// without hidden states on fully known tracks). Before the first fill the unknown
/// stretches hold the data's provisional interpolant.
pub(crate) fn refresh(
    network: &Network,
    model: &ir::Model,
    course: &mut Course,
    (fractions, fill): (&[f64], bool),
    hidden_init: &[f64],
) -> Result<(), TrainError> {
    let mut changed = false;
    for (track, hidden) in course.tracks.iter_mut().zip(&mut course.hidden) {
        if model.hidden.is_empty() && (track.fully_known() || !fill) {
            continue;
        }
        let run = run_in(network, model, track, fractions, hidden_init)?;
        if fill {
            for (state, values) in run.states.iter().enumerate() {
                track.fill(state, values);
            }
        }
        if !model.hidden.is_empty() {
            *hidden = run.hidden;
            changed = true;
        }
    }
    if changed {
        course.table.set_hidden(&course.hidden);
    }
    Ok(())
}

/// Offline and online errors pooled over all scorings, and the errors of each.
pub(super) type Validated = (Option<ErrorSet>, Option<ErrorSet>, Vec<ValidationErrors>);

/// Offline and online errors pooled over `scorings`, and per scoring, with the current
/// network (hidden states and fill run in first).
pub(super) fn validate(
    network: &Network,
    model: &ir::Model,
    (course, scorings): (&mut Course, &[Scoring]),
    (setup, options, range): (&Setup, &TrainOptions, Option<&PhysicalRange>),
    hidden_init: &[f64],
) -> Result<Validated, TrainError> {
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    refresh(network, model, course, (&fractions, true), hidden_init)?;
    let norm = &setup.normalisation;
    let (mut offline_all, mut online_all) =
        (ErrorSum::new(model, norm), ErrorSum::new(model, norm));
    let mut each = Vec::new();
    for scoring in scorings {
        let pairs: Vec<PairAt> = scoring.pairs.iter().map(|&k| (scoring.track, k)).collect();
        let mut table = PairTable::build(model, &course.tracks, &pairs, &course.hidden, &fractions);
        table.scale_weights(&course.weights);
        table.observe(&course.tracks, &course.observables);
        let offline = offline_error(network, model, &table, norm)?;
        let track = &course.tracks[scoring.track];
        let start = scoring.run_start;
        let last = track.len() - 1;
        let end = match options.online_horizon {
            Some(horizon) => {
                let until = track.times[start] + horizon;
                let slack = 1e-9 * until.abs().max(1.0);
                let end = track.times.partition_point(|&t| t <= until + slack);
                end.saturating_sub(1).clamp(start, last)
            }
            None => last,
        };
        let hidden = (course.hidden[scoring.track].get(start))
            .filter(|h| !h.is_empty())
            .cloned()
            .unwrap_or_else(|| hidden_init.to_vec());
        let run = simulate(
            network,
            model,
            track,
            &fractions,
            (start, end.saturating_sub(1).max(start)),
            &hidden,
            (Feed::Own, range, Stepping::Controlled),
        )?;
        let online = online_error(model, track, &run, (norm, scoring.scored_from));
        offline_all.merge(&offline);
        online_all.merge(&online);
        each.push(ValidationErrors {
            name: scoring.name.clone(),
            pairs: pairs.len(),
            offline: offline.finish(),
            online: online.finish(),
        });
    }
    Ok((offline_all.finish(), online_all.finish(), each))
}
