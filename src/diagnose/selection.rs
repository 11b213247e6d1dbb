//! Several causes at once: forward selection over the effects, with a stopping rule that
//! penalises params on held-out data.
//!
//! The first step is the ranking of the single effects ([`super::effects::rank_effects`]).
//! Each later step fits every remaining effect *added* to the credited set (warm-started
//! from the set's params and the effect's own single fit) and takes the best addition. A
//! step is credited only when all of these hold, otherwise the selection stops and says
//! which failed:
//!
//! 1. the gap before the step is significant (above [`super::SIGNIFICANCE`] times the noise
//!    floor), and the step removes at least [`super::CREDIT`] of it above the floor;
//! 2. the step's held-out gap is told apart from the gap before it *and* from every other
//!    candidate of the step (block bootstrap, [`super::ranking`]: lower in at least 95 % of
//!    the draws): its lead exceeds the ranking's uncertainty, so the held-out data pay for
//!    the params it adds;
//! 3. Schwarz's criterion (BIC) on the training cells falls: the fit gained more than
//!    `ln n` per added unknown.
//!
//! AIC and BIC are reported beside the held-out gap for every step, as PEtab-Select does.

use super::effects::{block_sums, fit_and_score, lower, Ranking, Scored};
use super::ranking::{compare, CONFIDENCE};
use super::render::num;
use super::report::{Selection, SelectionStep};
use super::{Context, DiagnoseError, Progress, CREDIT, SIGNIFICANCE};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// The gap and noise level a selection works against.
#[derive(Debug, Clone, Copy)]
pub struct Levels {
    /// The model's held-out gap without effects.
    pub gap_before: f64,
    /// The noise floor.
    pub noise_floor: f64,
}

/// Runs forward selection from the single-effect ranking; returns the selection and the
/// fit of the credited set (`None` when nothing is credited).
pub fn select(
    context: &Context,
    base: &Scored,
    ranking: &Ranking,
    levels: Levels,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<(Selection, Option<Scored>), DiagnoseError> {
    let mut selection = Selection {
        gap_after: levels.gap_before,
        ..Selection::default()
    };
    let (Some(first), Some(first_fit)) = (ranking.scores.first(), ranking.fits.first()) else {
        return Ok((selection, None));
    };
    let alternatives: Vec<(String, f64)> = (ranking.scores[1..].iter())
        .map(|s| (s.name.clone(), s.gap_after))
        .collect();
    let others_tied: Vec<String> = (ranking.scores[1..].iter())
        .filter(|s| s.tied)
        .map(|s| s.name.clone())
        .collect();
    let step = judge(
        context,
        (base, first_fit),
        &first.name,
        &others_tied,
        levels,
    );
    let accepted = step.accepted;
    selection.stop = step.reason.clone();
    selection.steps.push(SelectionStep {
        effects: vec![first.name.clone()],
        alternatives,
        ..step
    });
    if !accepted {
        return Ok((selection, None));
    }
    let mut credited = vec![first.name.clone()];
    let mut current = first_fit.clone();
    let singles: BTreeMap<String, BTreeMap<String, f64>> = (ranking.scores.iter())
        .zip(&ranking.fits)
        .map(|(s, fit)| (s.name.clone(), fit.named.clone()))
        .collect();
    selection.stop = "every effect is credited".into();
    while credited.len() < ranking.scores.len() {
        let significant = current.gap > SIGNIFICANCE * levels.noise_floor;
        if !significant {
            selection.stop = format!(
                "the gap left ({}) is within {SIGNIFICANCE}x the noise floor ({})",
                num(current.gap),
                num(levels.noise_floor)
            );
            break;
        }
        let (step, fit) = next_step(context, &credited, &current, &singles, levels, progress)?;
        let accepted = step.accepted;
        let added = step.added.clone();
        if !accepted {
            selection.stop = format!("adding {added}: {}", step.reason);
        }
        selection.steps.push(step);
        if !accepted {
            break;
        }
        credited.push(added);
        current = fit;
    }
    selection.gap_after = current.gap;
    selection.credited = credited;
    Ok((selection, Some(current)))
}

/// Tries every remaining effect added to `credited`; the step of the best addition.
fn next_step(
    context: &Context,
    credited: &[String],
    current: &Scored,
    singles: &BTreeMap<String, BTreeMap<String, f64>>,
    levels: Levels,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<(SelectionStep, Scored), DiagnoseError> {
    let remaining: Vec<&String> = singles.keys().filter(|n| !credited.contains(n)).collect();
    let tried = remaining
        .par_iter()
        .enumerate()
        .map(|(index, name)| {
            let mut set = names(credited);
            set.push(name.as_str());
            let model = lower(context, &set)?;
            let mut start = singles[*name].clone();
            start.extend(current.named.clone());
            let seed = context.seed(2000 + 100 * credited.len() as u64 + index as u64);
            let scored = fit_and_score(context, &model, &start, seed)?;
            progress(Progress::Done {
                item: format!("{} + {name}", credited.join(" + ")),
                seconds: scored.summary.seconds,
            });
            Ok(((*name).clone(), scored))
        })
        .collect::<Result<Vec<_>, DiagnoseError>>()?;
    let mut order: Vec<usize> = (0..tried.len()).collect();
    order.sort_by(|&a, &b| tried[a].1.gap.total_cmp(&tried[b].1.gap));
    let best = order[0];
    let sums: Vec<_> = tried.iter().map(|(_, s)| block_sums(context, s)).collect();
    let comparison = compare(&sums, context.seed(3000 + credited.len() as u64));
    let others_tied: Vec<String> = (order[1..].iter())
        .filter(|&&i| comparison.tied_with_best(i))
        .map(|&i| tried[i].0.clone())
        .collect();
    let (name, fit) = &tried[best];
    let step = judge(context, (current, fit), name, &others_tied, levels);
    let mut effects = credited.to_vec();
    effects.push(name.clone());
    let alternatives = (order[1..].iter())
        .map(|&i| (tried[i].0.clone(), tried[i].1.gap))
        .collect();
    Ok((
        SelectionStep {
            effects,
            alternatives,
            ..step
        },
        fit.clone(),
    ))
}

/// Whether adding `name` (fit `after`) to the set fitted as `before` is credited, with the
/// step's numbers and the reason (see the module documentation).
fn judge(
    context: &Context,
    (before, after): (&Scored, &Scored),
    name: &str,
    others_tied: &[String],
    levels: Levels,
) -> SelectionStep {
    let pair = compare(
        &[block_sums(context, before), block_sums(context, after)],
        context.seed(4000),
    );
    let spread = pair.spread[0].max(pair.spread[1]);
    let excess = before.gap - levels.noise_floor;
    let removed = before.gap - after.gap;
    // Each test is false for a NaN, which is then refused.
    let significant = before.gap > SIGNIFICANCE * levels.noise_floor;
    let removes_enough = removed >= CREDIT * excess;
    let bic_falls = after.summary.bic < before.summary.bic;
    let reason = if !significant {
        format!(
            "the gap before it ({}) is within {SIGNIFICANCE}x the noise floor ({})",
            num(before.gap),
            num(levels.noise_floor)
        )
    } else if !removes_enough {
        format!(
            "it removes {} of the gap above the noise floor, less than {}",
            percent(removed / excess),
            percent(CREDIT)
        )
    } else if pair.best != Some(1) || pair.tied_with_best(0) {
        format!(
            "its decrease of the held-out gap ({} +- {}) does not hold in {} of the bootstrap draws",
            num(removed),
            num(spread),
            percent(CONFIDENCE)
        )
    } else if !others_tied.is_empty() {
        format!(
            "the held-out data cannot tell it from {}",
            others_tied.join(", ")
        )
    } else if !bic_falls {
        format!(
            "BIC does not fall ({} to {})",
            num(before.summary.bic),
            num(after.summary.bic)
        )
    } else {
        String::new()
    };
    let accepted = reason.is_empty();
    SelectionStep {
        added: name.to_string(),
        effects: Vec::new(),
        gap_after: after.gap,
        shrink: 1.0 - after.gap / levels.gap_before,
        aic: after.summary.aic,
        bic: after.summary.bic,
        unknowns: after.summary.unknowns,
        spread,
        alternatives: Vec::new(),
        accepted,
        reason: if accepted {
            format!(
                "removes {} of the gap above the noise floor, beyond its uncertainty; BIC falls by {}",
                percent(removed / excess),
                num(before.summary.bic - after.summary.bic)
            )
        } else {
            reason
        },
    }
}

fn names(set: &[String]) -> Vec<&str> {
    set.iter().map(String::as_str).collect()
}

fn percent(value: f64) -> String {
    super::render::percent(value)
}
