//! Where the gap lies: a free correction at each `let` (`NAME += c`) and at each balance
//! (`der X += c`) in turn, synthesised as a closure output patched in by an effect (the
//! model's own source plus two declarations), fitted by [`super::correction`] and scored
//! by the held-out free run it leaves — a bound on what any mechanism acting there can do.
//!
//! Each locus is tried with *present* features (everything the model knows at `t`, see
//! [`super::features`]) and with *history* features (plus a delay embedding of the
//! measured record, at a short and a long delay unless one is given). At the best locus,
//! history is needed when it leaves clearly less excess gap (above the noise floor) than
//! the present alone: by a factor [`HISTORY_MARGIN`].

use super::correction::{self, Corrected, LocusValue, Pass, Solution};
use super::features::{FeatureMap, Lags};
use super::record::mean_std;
use super::report::{Locus, LocusKind};
use super::simulate::{tolerances, Simulator};
use super::{Context, DiagnoseError};
use crate::ir::{self, Model, Var};
use rayon::prelude::*;

/// History must leave this many times less excess gap than the present alone.
pub const HISTORY_MARGIN: f64 = 2.0;
/// Name of the synthesised closure.
const CLOSURE: &str = "__diagnose_closure";
/// Name of its output.
const OUTPUT: &str = "__diagnose_c";
/// Name of the synthesised effect.
const EFFECT: &str = "__diagnose_effect";

/// A quantity a correction can be added to.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// The let's or the state's name.
    pub name: String,
    /// Let or balance.
    pub kind: LocusKind,
}

impl Target {
    fn patch(&self) -> String {
        match self.kind {
            LocusKind::Balance => format!("der {} += {OUTPUT}", self.name),
            _ => format!("{} += {OUTPUT}", self.name),
        }
    }
}

/// Every let, then every balance (measured, then hidden states).
pub fn targets(model: &Model) -> Vec<Target> {
    let lets = model.lets.iter().map(|l| Target {
        name: l.name.clone(),
        kind: LocusKind::Let,
    });
    let balances = model.states.iter().chain(&model.hidden).map(|s| Target {
        name: s.name.clone(),
        kind: LocusKind::Balance,
    });
    lets.chain(balances).collect()
}

/// The embeddings tried as history, in rows: the user's, or a short and a long delay.
pub fn history_lags(delay: Option<usize>, dim: usize) -> Vec<Lags> {
    match delay {
        Some(delay) => vec![Lags { delay, dim }],
        None => vec![Lags { delay: 2, dim }, Lags { delay: 12, dim }],
    }
}

/// The outcome at one locus.
#[derive(Debug, Clone)]
pub struct Tried {
    /// The report entry.
    pub locus: Locus,
    /// The best correction's values along the training rows, with the variables they were
    /// computed from (for the symbolic hint).
    pub along: Option<Along>,
}

/// A fitted correction along the training rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Along {
    /// Correction values per row.
    pub values: Vec<f64>,
    /// Variable names: inputs, measured, hidden, then the corrected quantity.
    pub names: Vec<String>,
    /// Per row: the variables' values in that order.
    pub variables: Vec<Vec<f64>>,
}

/// Tries every target in parallel; returns them best (smallest bound) first.
pub fn locate(
    context: &Context,
    params: &[f64],
    lags: &[Lags],
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<Tried>, DiagnoseError> {
    let found = targets(context.model)
        .par_iter()
        .map(|target| {
            let tried = try_target(context, target, params, lags);
            tick();
            tried
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut tried: Vec<Tried> = found.into_iter().flatten().collect();
    tried.sort_by(|a, b| a.locus.bound_after.total_cmp(&b.locus.bound_after));
    Ok(tried)
}

/// Whether the best locus needs history: the present leaves a significant excess that
/// history cuts by [`HISTORY_MARGIN`].
pub fn needs_history(best: &Locus, noise_floor: f64, significance: f64) -> bool {
    let excess = |gap: f64| (gap - noise_floor).max(0.0);
    best.bound_present > significance * noise_floor
        && excess(best.bound_present) > HISTORY_MARGIN * excess(best.bound_history)
}

/// The model with a correction at `target`; `None` when the target reaches no balance.
pub(super) fn synthesise(context: &Context, target: &Target, params: &[f64]) -> Result<Option<Corrected>, DiagnoseError> {
    let source = format!(
        "{}\n\nclosure {CLOSURE} {{\n  outputs {OUTPUT}\n}}\n\neffect {EFFECT} {{\n  {}\n}}\n",
        context.problem.source,
        target.patch()
    );
    let compiled = crate::driver::compile(context.problem.name, &source, &[EFFECT]).map_err(|reports| {
        let messages: Vec<String> = reports.iter().map(|r| r.to_string()).collect();
        DiagnoseError::Internal(format!("correction at `{}` does not compile: {}", target.name, messages.join("; ")))
    })?;
    let model = compiled.model;
    let Some(closure) = model.closures.iter().position(|c| c.name == CLOSURE) else {
        return Err(DiagnoseError::Internal("synthesised closure missing".into()));
    };
    if !model.balances.iter().any(|b| ir::uses_closure(&b.expr)) {
        return Ok(None);
    }
    let var = Var::ClosureOutput { closure, output: 0 };
    let mut simulator = Simulator::new(&model, Some(var), tolerances())?;
    simulator.set_params(params);
    let locus = match target.kind {
        LocusKind::Balance => {
            let index = (model.states.iter().chain(&model.hidden))
                .position(|s| s.name == target.name)
                .ok_or_else(|| DiagnoseError::Internal(format!("no state `{}`", target.name)))?;
            LocusValue::State(index)
        }
        _ => {
            let definition = (context.model.lets.iter())
                .find(|l| l.name == target.name)
                .ok_or_else(|| DiagnoseError::Internal(format!("no let `{}`", target.name)))?;
            LocusValue::Let(simulator.compile(&definition.expr)?)
        }
    };
    Ok(Some(Corrected {
        simulator,
        locus,
        balance: target.kind == LocusKind::Balance,
        constraints: model.params.iter().map(|p| p.constraint).collect(),
        joint: std::env::var("GBC_JOINT").is_ok(),
    }))
}

fn try_target(context: &Context, target: &Target, params: &[f64], lags: &[Lags]) -> Result<Option<Tried>, DiagnoseError> {
    let Some(mut corrected) = synthesise(context, target, params)? else {
        return Ok(None);
    };
    let (train, end) = (&context.split.train, context.split.train_rows.end);
    let unreachable = |kind| Tried {
        locus: Locus {
            name: target.name.clone(),
            kind,
            bound_after: f64::INFINITY,
            bound_present: f64::INFINITY,
            bound_history: f64::INFINITY,
        },
        along: None,
    };
    let theta = correction::theta_of(&corrected.constraints, params);
    let Ok(pass) = correction::one_step_pass(&mut corrected, &theta, train, end) else {
        return Ok(Some(unreachable(target.kind)));
    };
    let present_map = feature_map(context, &pass, None);
    let present = score(context, &mut corrected, &pass, &present_map);
    let mut best = present.clone();
    let mut history = (f64::INFINITY, None);
    for &lag in lags {
        let scored = score(context, &mut corrected, &pass, &feature_map(context, &pass, Some(lag)));
        if scored.0 < history.0 {
            history = scored;
        }
    }
    if history.0 < best.0 {
        best = history.clone();
    }
    let along = best.1.map(|(map, solution)| along(context, target, &pass, &map, &solution.weights));
    Ok(Some(Tried {
        locus: Locus {
            name: target.name.clone(),
            kind: target.kind,
            bound_after: best.0,
            bound_present: present.0,
            bound_history: history.0,
        },
        along,
    }))
}

type Scored = (f64, Option<(FeatureMap, Solution)>);

/// Fits a correction with features `map` (and the params) and returns its held-out gap
/// (infinite when the fit or the run fails) with the fitted map and solution.
pub(super) fn score(context: &Context, corrected: &mut Corrected, pass: &Pass, map: &FeatureMap) -> Scored {
    let train = &context.split.train;
    let Some(solution) = correction::fit(corrected, pass, map, train, &context.normalisation) else {
        return (f64::INFINITY, None);
    };
    let solution = correction::refine(
        corrected,
        map,
        &solution,
        train,
        context.split.train_rows.clone(),
        &context.normalisation,
    );
    let test = &context.split.test;
    let rows = context.split.test_rows.clone();
    let gap = match correction::corrected_run(corrected, map, &solution, test, rows.end) {
        Ok(run) => {
            let errors = super::evaluate::state_errors(&run, test, rows, &context.normalisation);
            eprintln!("DEBUG {:?} lags {:?}: {errors:?}", corrected.locus, map.lags.map(|l| l.delay));
            errors.iter().sum::<f64>() / errors.len().max(1) as f64
        }
        Err(_) => f64::INFINITY,
    };
    let gap = if gap.is_finite() { gap } else { f64::INFINITY };
    (gap, Some((map.clone(), solution)))
}

/// Feature scaling from the pass: present variables z-scored over the training rows.
pub(super) fn feature_map(context: &Context, pass: &Pass, lags: Option<Lags>) -> FeatureMap {
    let width = pass.present.first().map_or(0, Vec::len);
    let (center, scale) = (0..width)
        .map(|j| mean_std(&pass.present.iter().map(|p| p[j]).collect::<Vec<_>>()))
        .unzip();
    let locus_scale = correction::root_mean_square(&pass.locus);
    FeatureMap {
        center,
        scale,
        locus_scale: if locus_scale > 0.0 { locus_scale } else { 1.0 },
        embedded: context.model.inputs.len() + context.model.states.len(),
        lags,
    }
}

fn along(context: &Context, target: &Target, pass: &Pass, map: &FeatureMap, weights: &[f64]) -> Along {
    let model = context.model;
    let mut names: Vec<String> = (model.inputs.iter().map(|i| i.name.clone()))
        .chain(model.states.iter().chain(&model.hidden).map(|s| s.name.clone()))
        .collect();
    let balance = target.kind == LocusKind::Balance;
    if !balance {
        names.push(target.name.clone());
    }
    let variables = (0..pass.rows)
        .map(|row| {
            let mut values = pass.present[row].clone();
            if !balance {
                values.push(pass.locus[row]);
            }
            values
        })
        .collect();
    Along {
        values: correction::values_along(pass, map, &context.split.train, weights),
        names,
        variables,
    }
}
