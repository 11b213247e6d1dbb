//! Fitting models on the training parts and scoring them on the held-out parts: the model
//! alone, each candidate effect alone (ranked, with a block-bootstrap confidence), and
//! forward selection of several effects ([`super::selection`]).

use super::evaluate::{scored_errors, Errors};
use super::fit::{fit, Fitted, Objective, Starts};
use super::ranking::{compare, Comparison, RESAMPLES};
use super::report::{Confidence, EffectScore, FitSummary};
use super::simulate::{tolerances, Run, Simulator};
use super::uncertainty::summarise;
use super::{Context, DiagnoseError, Progress};
use crate::ir::{self, Model};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::time::Instant;

/// A model fitted on the training parts and run over the scored parts.
#[derive(Debug, Clone)]
pub struct Scored {
    /// The fitted params (then fitted starts) and their training gap.
    pub fitted: Fitted,
    /// The fitted unknowns by name (params, `STATE@EXPERIMENT` starts).
    pub named: BTreeMap<String, f64>,
    /// Uncertainty, criteria and cost of the fit.
    pub summary: FitSummary,
    /// Errors at the scored cells.
    pub errors: Errors,
    /// Held-out gap.
    pub gap: f64,
    /// Free runs of the scored records (`None` where one failed).
    pub runs: Vec<Option<Run>>,
    /// Per measured state, the sum of its squared normalised training residuals and their
    /// count (empty if the fit's free runs failed): an upper bound of its noise.
    pub training_squares: Vec<(f64, usize)>,
}

/// A fit pinned along a free direction is kept when its training gap is within this share
/// of the free fit's.
pub const PIN_TOLERANCE: f64 = 1e-6;

/// Components of a free direction within this share of the largest are equally large.
const PIN_TIE: f64 = 0.9;

/// The unknown to pin when a fit leaves a direction free: among the direction's largest
/// components (within [`PIN_TIE`] of the largest; an exact scaling symmetry gives several
/// of equal size) the first declared, if it is not identified.
fn pin(summary: &FitSummary, names: &[String]) -> Option<usize> {
    let largest = summary.free_direction.first()?.1.abs();
    let index = (summary.free_direction.iter())
        .filter(|(_, v)| v.abs() >= PIN_TIE * largest)
        .filter_map(|(name, _)| names.iter().position(|n| n == name))
        .min()?;
    let estimate = summary.estimates.iter().find(|e| e.name == names[index])?;
    (!estimate.identified).then_some(index)
}

/// Fits `model` from the unknowns `start` (by name: params and `STATE@EXPERIMENT` starts;
/// others from their defaults), and scores it on the held-out parts.
pub fn fit_and_score(
    context: &Context,
    model: &Model,
    start: &BTreeMap<String, f64>,
    seed: u64,
) -> Result<Scored, DiagnoseError> {
    let starts = Starts::new(context.options.restarts);
    fit_and_score_with(context, model, (start, starts), seed)
}

/// [`fit_and_score`] with its own budget of starts (the fits that decide a verdict get
/// more).
pub fn fit_and_score_with(
    context: &Context,
    model: &Model,
    (start, starts): (&BTreeMap<String, f64>, Starts),
    seed: u64,
) -> Result<Scored, DiagnoseError> {
    let started = Instant::now();
    let simulator = Simulator::new(model, &[], tolerances())?;
    let unknowns = context.unknowns(model, &simulator);
    let x = unknowns.values(start);
    let constraints = &unknowns.constraints;
    let objective = Objective {
        simulator: &simulator,
        split: &context.split,
    };
    let free = vec![false; x.len()];
    let mut fitted = fit(&objective, constraints, &x, (starts, &free), seed);
    let names = unknowns.names.as_slice();
    let mut summary = summarise(&objective, constraints, &fitted.x, (names, &free));
    if let Some(pinned) = pin(&summary, names) {
        // The data leave a direction free: hold its largest component at its declared
        // value, so that fits are compared at one point of the ridge, not at arbitrary
        // ones; kept if the gap stays within [`PIN_TOLERANCE`] (the direction was free).
        let mut fixed = free;
        fixed[pinned] = true;
        let mut held = fitted.x.clone();
        held[pinned] = unknowns.defaults[pinned];
        let refit = fit(
            &objective,
            constraints,
            &held,
            (Starts::new(0), &fixed),
            seed,
        );
        if refit.gap <= fitted.gap * (1.0 + PIN_TOLERANCE) {
            let starts = fitted.starts + refit.starts;
            summary = summarise(&objective, constraints, &refit.x, (names, &fixed));
            fitted = Fitted { starts, ..refit };
        }
    }
    let (errors, runs) = held_out(context, &simulator, &fitted.x);
    let training_squares = (objective.residuals(&fitted.x))
        .map(|r| super::noise::by_state(&context.split, &r))
        .unwrap_or_default();
    summary.starts = fitted.starts;
    summary.seconds = started.elapsed().as_secs_f64();
    Ok(Scored {
        gap: errors.gap(),
        named: (unknowns.names.iter().cloned())
            .zip(fitted.x.iter().copied())
            .collect(),
        fitted,
        summary,
        errors,
        runs,
        training_squares,
    })
}

/// The errors at the scored cells of `simulator` with `x` (params, then fitted starts), and
/// its free runs of the scored records.
pub fn held_out(context: &Context, simulator: &Simulator, x: &[f64]) -> (Errors, Vec<Option<Run>>) {
    let mut simulator = simulator.clone();
    simulator.set_params(x);
    let fitted = &x[simulator.params().min(x.len())..];
    let split = &context.split;
    let runs: Vec<Option<Run>> = (split.scored())
        .map(|(index, record, rows)| {
            let overrides = split.overrides(index, fitted, simulator.hidden_count());
            simulator.free_run(record, &overrides, rows.end).ok()
        })
        .collect();
    (scored_errors(split, &runs), runs)
}

/// The named params of a model (the first `model.params.len()` entries of `x`).
pub fn named(model: &Model, x: &[f64]) -> BTreeMap<String, f64> {
    (model.params.iter().map(|p| p.name.clone()))
        .zip(x.iter().copied())
        .collect()
}

/// Every candidate effect applied alone and fitted, ranked by held-out gap.
#[derive(Default)]
pub struct Ranking {
    /// Scores, best first.
    pub scores: Vec<EffectScore>,
    /// The fits, in the same order.
    pub fits: Vec<Scored>,
    /// How sure the ranking is.
    pub confidence: Confidence,
}

/// Fits every effect of the model alone, from the model's fitted unknowns `base` (by name).
pub fn rank_effects(
    context: &Context,
    base: &BTreeMap<String, f64>,
    gap_before: f64,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Ranking, DiagnoseError> {
    let names: Vec<String> = (context.model.effects.iter())
        .map(|e| e.name.clone())
        .collect();
    let fits = names
        .par_iter()
        .enumerate()
        .map(|(index, name)| {
            let model = lower(context, &[name.as_str()])?;
            let scored = fit_and_score(context, &model, base, context.seed(index as u64 + 1))?;
            progress(Progress::Done {
                item: name.clone(),
                seconds: scored.summary.seconds,
            });
            Ok((model, scored))
        })
        .collect::<Result<Vec<_>, DiagnoseError>>()?;
    let sums: Vec<_> = (fits.iter())
        .map(|(_, scored)| context.blocks.sums(&scored.errors))
        .collect();
    let comparison = compare(&sums, context.seed(1000));
    let mut order: Vec<usize> = (0..fits.len()).collect();
    // Ranked by the training fit's criterion: the held-out gap scores, it does not choose.
    order.sort_by(|&a, &b| fits[a].1.summary.bic.total_cmp(&fits[b].1.summary.bic));
    let mut scores = Vec::with_capacity(fits.len());
    let mut ordered = Vec::with_capacity(fits.len());
    let mut fits: Vec<Option<(Model, Scored)>> = fits.into_iter().map(Some).collect();
    for &index in &order {
        let Some((model, scored)) = fits[index].take() else {
            continue;
        };
        scores.push(EffectScore {
            name: names[index].clone(),
            description: context.model.effects[index].description.clone(),
            gap_after: scored.gap,
            shrink: 1.0 - scored.gap / gap_before,
            params: named(&model, &scored.fitted.x),
            fit: scored.summary.clone(),
            adds_hidden: added_hidden(context.model, &model),
            probability_best: comparison.probability_best[index],
            spread: comparison.spread[index],
            tied: comparison.tied_with_best(index),
        });
        ordered.push(scored);
    }
    let confidence = confidence(
        &scores,
        &comparison,
        gap_before,
        context.blocks.blocks.len(),
    );
    Ok(Ranking {
        scores,
        fits: ordered,
        confidence,
    })
}

/// The ranking's confidence from the bootstrap comparison (scores sorted best first).
fn confidence(
    scores: &[EffectScore],
    comparison: &Comparison,
    gap_before: f64,
    blocks: usize,
) -> Confidence {
    let indistinguishable: Vec<String> = (scores.iter())
        .filter(|s| s.tied)
        .map(|s| s.name.clone())
        .collect();
    let (margin, margin_error) = match scores {
        [first, second, ..] => (
            (second.gap_after - first.gap_after) / gap_before,
            second.spread / gap_before,
        ),
        [only] => (1.0 - only.gap_after / gap_before, 0.0),
        [] => (0.0, 0.0),
    };
    Confidence {
        separated: scores.first().is_some_and(|s| s.gap_after.is_finite())
            && indistinguishable.len() == 1,
        margin,
        margin_error,
        probability_best: comparison
            .best
            .map_or(0.0, |b| comparison.probability_best[b]),
        indistinguishable,
        blocks,
        resamples: RESAMPLES,
    }
}

/// The hidden states `with` has that `model` has not.
pub fn added_hidden(model: &Model, with: &Model) -> Vec<String> {
    (with.hidden.iter())
        .filter(|h| !model.hidden.iter().any(|m| m.name == h.name))
        .map(|h| h.name.clone())
        .collect()
}

/// The block sums of a scored fit, for comparisons.
pub fn block_sums(context: &Context, scored: &Scored) -> Vec<(f64, usize)> {
    context.blocks.sums(&scored.errors)
}

/// The model with the named effects applied.
pub fn lower(context: &Context, effects: &[&str]) -> Result<Model, DiagnoseError> {
    ir::lower(context.problem()?.checked, effects).map_err(|error| DiagnoseError::Unsimulable {
        reason: format!("effect {}: {error}", effects.join(" + ")),
    })
}
