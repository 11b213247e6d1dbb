//! Fitting models on the training parts and scoring them on the held-out parts: the model
//! alone, each candidate effect alone (ranked, with a block-bootstrap confidence), and
//! forward selection of several effects ([`super::selection`]).

use super::candidates::{candidates, lower};
use super::context::{Context, Progress};
use super::error::DiagnoseError;
use super::evaluate::{scored_errors, Errors};
use super::ranking::{compare, Comparison, RESAMPLES};
use super::report::{Confidence, EffectScore, FitSummary};
use crate::ir::Model;
use crate::solve::fit::fitter::{Fitted, Round, Starts};
use crate::solve::fit::model::{fit_model, ModelFit};
use crate::solve::fit::simulate::{Run, Simulator};
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

/// Fits `model` (named `fit` in the progress it reports) from the unknowns `start` (by
/// name: params and `STATE@EXPERIMENT` starts; others from their defaults), and scores it
/// on the held-out parts.
pub fn fit_and_score(
    context: &Context,
    (fit, model): (&str, &Model),
    start: &BTreeMap<String, f64>,
    seed: u64,
) -> Result<Scored, DiagnoseError> {
    let starts = Starts::new(context.options.restarts);
    fit_and_score_with(context, (fit, model), (start, starts), seed)
}

/// [`fit_and_score`] with its own budget of starts (the fits that decide a verdict get
/// more); every round of starts is reported as [`Progress::Round`].
pub fn fit_and_score_with(
    context: &Context,
    (name, model): (&str, &Model),
    (start, starts): (&BTreeMap<String, f64>, Starts),
    seed: u64,
) -> Result<Scored, DiagnoseError> {
    let started = Instant::now();
    let watch = |round: Round| {
        (context.progress)(Progress::Round {
            fit: name.to_string(),
            done: round.done,
            max: round.max,
            best: round.best,
            seconds: started.elapsed().as_secs_f64(),
        })
    };
    let starts = starts.watched(&watch);
    let fit = fit_model(&context.split, model, (start, starts), seed)?;
    let (errors, runs) = held_out(context, &fit.simulator, &fit.fitted.x);
    let named = fit.named();
    let ModelFit {
        fitted,
        mut summary,
        training_squares,
        ..
    } = fit;
    summary.seconds = started.elapsed().as_secs_f64();
    Ok(Scored {
        gap: errors.gap(),
        named,
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

/// Every candidate (effect or refitted constant) applied alone and fitted, ranked by BIC.
#[derive(Default)]
pub struct Ranking {
    /// Scores, best first.
    pub scores: Vec<EffectScore>,
    /// The fits, in the same order.
    pub fits: Vec<Scored>,
    /// How sure the ranking is.
    pub confidence: Confidence,
}

/// Fits every candidate of the model alone ([`candidates`]), from the model's fitted
/// unknowns `base` (by name).
pub fn rank_effects(
    context: &Context,
    base: &BTreeMap<String, f64>,
    gap_before: f64,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Ranking, DiagnoseError> {
    let candidates = candidates(context.model, context.options.refit_constants);
    let names: Vec<String> = candidates.iter().map(|c| c.name.clone()).collect();
    let fits = names
        .par_iter()
        .enumerate()
        .map(|(index, name)| {
            let model = lower(context, &[name.as_str()])?;
            let seed = context.seed(index as u64 + 1);
            let scored = fit_and_score(context, (name, &model), base, seed)?;
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
            description: candidates[index].description.clone(),
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
