//! Fitting models to the training part and scoring them on the held-out part: the model
//! alone, each candidate effect, and the two best together.

use super::fit::{fit, Fitted, Objective};
use super::report::{Combined, Confidence, EffectScore};
use super::simulate::{tolerances, Run, Simulator};
use super::{Context, DiagnoseError};
use crate::ir::{self, Model};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::ops::Range;

/// A model fitted on some training rows and run over the held-out record.
#[derive(Debug, Clone)]
pub struct Scored {
    /// The fitted params and their training gap.
    pub fitted: Fitted,
    /// Held-out gap.
    pub gap: f64,
    /// Free run over the held-out record (from its row 0).
    pub run: Option<Run>,
}

/// Which training rows a fit uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// All training rows.
    Full,
    /// The first half of the training rows.
    FirstHalf,
    /// The second half of the training rows.
    SecondHalf,
}

impl Part {
    fn rows(self, train: Range<usize>) -> Range<usize> {
        let middle = train.start + train.len() / 2;
        match self {
            Part::Full => train,
            Part::FirstHalf => train.start..middle,
            Part::SecondHalf => middle..train.end,
        }
    }
}

/// Fits `model` on `part` of the training rows from the params `start` (by name; others
/// from their declared values) and scores it on the held-out rows.
pub fn fit_and_score(
    context: &Context,
    model: &Model,
    start: &BTreeMap<String, f64>,
    part: Part,
    seed: u64,
) -> Result<Scored, DiagnoseError> {
    let simulator = Simulator::new(model, None, tolerances())?;
    let initial: Vec<f64> = (model.params.iter())
        .map(|p| start.get(&p.name).copied().unwrap_or(p.init))
        .collect();
    let constraints: Vec<ir::Constraint> = model.params.iter().map(|p| p.constraint).collect();
    let objective = Objective {
        simulator: &simulator,
        record: &context.split.train,
        rows: part.rows(context.split.train_rows.clone()),
        normalisation: &context.normalisation,
    };
    let fitted = fit(
        &objective,
        &constraints,
        &initial,
        context.options.restarts,
        seed,
    );
    let (gap, run) = held_out(context, &simulator, &fitted.params);
    Ok(Scored { fitted, gap, run })
}

/// The held-out gap of `simulator` with `params`, and its free run (infinite gap and no run
/// if the run fails).
pub fn held_out(context: &Context, simulator: &Simulator, params: &[f64]) -> (f64, Option<Run>) {
    let mut simulator = simulator.clone();
    simulator.set_params(params);
    let test = &context.split.test;
    match simulator.free_run(test, context.split.test_rows.end) {
        Ok(run) => {
            let errors = super::evaluate::state_errors(
                &run,
                test,
                context.split.test_rows.clone(),
                &context.normalisation,
            );
            let gap = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
            (if gap.is_finite() { gap } else { f64::INFINITY }, Some(run))
        }
        Err(_) => (f64::INFINITY, None),
    }
}

/// The named params of a model.
pub fn named(model: &Model, values: &[f64]) -> BTreeMap<String, f64> {
    (model.params.iter().map(|p| p.name.clone()))
        .zip(values.iter().copied())
        .collect()
}

/// Every candidate effect fitted on the training part and on each half, ranked by held-out
/// gap; with the ranking confidence and the models (for plots and combinations).
pub struct Ranking {
    /// Scores, best first.
    pub scores: Vec<EffectScore>,
    /// Ranking stability.
    pub confidence: Confidence,
    /// Free run of the best effect on the held-out record.
    pub best_run: Option<Run>,
}

/// Fits every effect of the model (and each on both halves of the training part).
pub fn rank_effects(
    context: &Context,
    base_params: &BTreeMap<String, f64>,
    gap_before: f64,
    tick: &(dyn Fn() + Sync),
) -> Result<Ranking, DiagnoseError> {
    let names: Vec<String> = context
        .model
        .effects
        .iter()
        .map(|e| e.name.clone())
        .collect();
    let models = (names.iter())
        .map(|name| lower(context, &[name.as_str()]))
        .collect::<Result<Vec<_>, _>>()?;
    let parts = [Part::Full, Part::FirstHalf, Part::SecondHalf];
    let tasks: Vec<(usize, Part)> = (0..models.len())
        .flat_map(|m| parts.iter().map(move |&p| (m, p)))
        .collect();
    let results = tasks
        .par_iter()
        .enumerate()
        .map(|(index, &(m, part))| {
            let scored = fit_and_score(
                context,
                &models[m],
                base_params,
                part,
                context.seed(index as u64 + 1),
            );
            tick();
            scored
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut scores = Vec::new();
    let mut runs = Vec::new();
    for (m, chunk) in results.chunks(parts.len()).enumerate() {
        let full = &chunk[0];
        scores.push(EffectScore {
            name: names[m].clone(),
            description: context.model.effects[m].description.clone(),
            gap_after: full.gap,
            shrink: 1.0 - full.gap / gap_before,
            params: named(&models[m], &full.fitted.params),
            gap_after_halves: [chunk[1].gap, chunk[2].gap],
        });
        runs.push(full.run.clone());
    }
    let mut order: Vec<usize> = (0..scores.len()).collect();
    order.sort_by(|&a, &b| scores[a].gap_after.total_cmp(&scores[b].gap_after));
    let confidence = confidence(&scores, &order, gap_before);
    let best_run = order.first().and_then(|&b| runs[b].clone());
    let scores = order.into_iter().map(|i| scores[i].clone()).collect();
    Ok(Ranking {
        scores,
        confidence,
        best_run,
    })
}

fn confidence(scores: &[EffectScore], order: &[usize], gap_before: f64) -> Confidence {
    let best_of = |half: usize| {
        (scores.iter())
            .min_by(|a, b| a.gap_after_halves[half].total_cmp(&b.gap_after_halves[half]))
            .map(|s| s.name.clone())
    };
    let best_by_half = [best_of(0), best_of(1)];
    let best = order.first().map(|&b| scores[b].name.clone());
    let margin = match order {
        [first, second, ..] => (scores[*second].gap_after - scores[*first].gap_after) / gap_before,
        [_] => 1.0 - scores[order[0]].gap_after / gap_before,
        [] => 0.0,
    };
    Confidence {
        stable: best.is_some() && best_by_half.iter().all(|b| *b == best),
        margin,
        best_by_half,
    }
}

/// The two best effects applied together, fitted on the training part.
pub fn combine(
    context: &Context,
    scores: &[EffectScore],
    base_params: &BTreeMap<String, f64>,
    gap_before: f64,
) -> Result<Option<Combined>, DiagnoseError> {
    let [first, second, ..] = scores else {
        return Ok(None);
    };
    let names = [first.name.as_str(), second.name.as_str()];
    let model = lower(context, &names)?;
    let mut start = base_params.clone();
    start.extend(first.params.clone());
    start.extend(second.params.clone());
    let scored = fit_and_score(context, &model, &start, Part::Full, context.seed(0))?;
    Ok(Some(Combined {
        names: names.iter().map(|n| n.to_string()).collect(),
        gap_after: scored.gap,
        shrink: 1.0 - scored.gap / gap_before,
    }))
}

/// The model with the named effects applied.
pub fn lower(context: &Context, effects: &[&str]) -> Result<Model, DiagnoseError> {
    ir::lower(context.checked, effects).map_err(|error| DiagnoseError::Unsimulable {
        reason: format!("effect {}: {error}", effects.join(" + ")),
    })
}
