//! Where the gap lies: a free correction at each `let` (`NAME += c`) and at each balance
//! (`der X += c`) in turn, synthesised as a closure output patched in by an effect (the
//! model's own source plus two declarations), fitted by [`super::correction`] and scored
//! by the held-out free run it leaves — a bound on what any mechanism acting there can do.
//!
//! Each locus is tried with *present* features (everything the model knows at `t`, see
//! [`super::features`]) and with *history* features (plus a delay embedding of the
//! measured record, at a short and a long delay unless one is given). All are fitted one
//! step ahead; every present correction, and the history corrections of the [`REFINED`]
//! best loci, are then refined on the training free run (params, gain, constant and
//! proportional terms) and scored. At the best locus, history is needed when the present
//! alone leaves more than [`PRESENT_RESIDUAL`] of the excess gap (the gap before, above the
//! noise floor) and history at most 1 / [`HISTORY_MARGIN`] of what the present leaves;
//! with much data, history features also win a little by their mere number. A locus is *tied* with the best when its bound is within
//! [`TIE_FACTOR`] of the best's and a paired test of their per-row held-out errors over
//! time blocks cannot tell them apart.

use super::correction::{self, Corrected, LocusValue, Pass, Solution};
use super::evaluate::{indistinguishable, row_errors};
use super::features::{FeatureMap, Lags};
use super::report::{Locus, LocusKind};
use super::simulate::{tolerances, Simulator};
use super::{Context, DiagnoseError, Progress};
use crate::ir::{self, Model, Var};
use crate::numeric::{mean_std, root_mean_square};
use rayon::prelude::*;

/// History must leave this many times less excess gap than the present alone.
pub const HISTORY_MARGIN: f64 = 2.0;
/// History is only needed when the present alone leaves more than this fraction of the
/// excess gap (the gap before, above the noise floor).
pub const PRESENT_RESIDUAL: f64 = 0.05;
/// Loci refined on the free run.
pub const REFINED: usize = 3;
/// Blocks of the paired test between loci (few and long: free-run errors are correlated
/// in time).
const TIE_BLOCKS: usize = 8;
/// A locus is tied with the best only if its bound is within this factor of the best's.
pub const TIE_FACTOR: f64 = 3.0;
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

/// A fitted correction along the training rows, for the symbolic hint.
#[derive(Debug, Clone, PartialEq)]
pub struct Along {
    /// Correction values per row.
    pub values: Vec<f64>,
    /// Variable names: inputs, measured, hidden, then the corrected let (if a let).
    pub names: Vec<String>,
    /// Per row: the variables' values in that order.
    pub variables: Vec<Vec<f64>>,
    /// Whether the last variable is the corrected let.
    pub let_last: bool,
}

/// The loci, best first, the memory verdict, and the best correction along the data.
#[derive(Debug, Clone)]
pub struct Located {
    /// Report entries, best first.
    pub loci: Vec<Locus>,
    /// Whether the best locus needs history.
    pub history_dependent: bool,
    /// The best locus's present-only correction along the training rows.
    pub along: Option<Along>,
}

/// One correction tried at one locus.
#[derive(Debug, Clone)]
struct Variant {
    map: FeatureMap,
    solution: Solution,
    gap: f64,
    errors: Vec<f64>,
}

/// Everything tried at one target.
#[derive(Debug, Clone)]
struct Trial {
    target: Target,
    corrected: Corrected,
    pass: Pass,
    present: Option<Variant>,
    history: Option<Variant>,
}

impl Trial {
    fn best(&self) -> Option<&Variant> {
        [&self.present, &self.history]
            .into_iter()
            .flatten()
            .min_by(|a, b| a.gap.total_cmp(&b.gap))
    }

    fn bound(&self) -> f64 {
        self.best().map_or(f64::INFINITY, |v| v.gap)
    }
}

/// Tries every target, reporting progress in two stages.
pub fn locate(
    context: &Context,
    params: &[f64],
    lags: &[Lags],
    gaps: (f64, f64),
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Located, DiagnoseError> {
    let targets = targets(context.model);
    progress(Progress::Stage {
        name: "fitting corrections",
        total: targets.len(),
    });
    let found = targets
        .par_iter()
        .map(|target| {
            let trial = try_target(context, target, params, lags);
            progress(Progress::Item);
            trial
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut trials: Vec<Trial> = found.into_iter().flatten().collect();
    let top = trials.len().min(REFINED);
    progress(Progress::Stage {
        name: "refining corrections",
        total: trials.len() + top,
    });
    trials.par_iter_mut().for_each(|trial| {
        refine(context, trial, false);
        progress(Progress::Item);
    });
    trials.sort_by(|a, b| a.bound().total_cmp(&b.bound()));
    trials[..top].par_iter_mut().for_each(|trial| {
        refine(context, trial, true);
        progress(Progress::Item);
    });
    trials.sort_by(|a, b| a.bound().total_cmp(&b.bound()));
    Ok(summarise(context, &trials, gaps))
}

fn summarise(
    context: &Context,
    trials: &[Trial],
    (gap_before, noise_floor): (f64, f64),
) -> Located {
    let best = trials
        .first()
        .and_then(|t| t.best())
        .map(|v| (v.gap, v.errors.clone()));
    let loci: Vec<Locus> = trials
        .iter()
        .map(|trial| {
            let gap = |v: &Option<Variant>| v.as_ref().map_or(f64::INFINITY, |v| v.gap);
            let tied = match (&best, trial.best()) {
                (Some((gap, errors)), Some(variant)) => {
                    variant.gap <= TIE_FACTOR * gap
                        && indistinguishable(&variant.errors, errors, TIE_BLOCKS)
                }
                _ => false,
            };
            Locus {
                name: trial.target.name.clone(),
                kind: trial.target.kind,
                bound_after: trial.bound(),
                bound_present: gap(&trial.present),
                bound_history: gap(&trial.history),
                tied,
            }
        })
        .collect();
    let history_dependent = loci.first().is_some_and(|best| {
        let excess = |gap: f64| (gap - noise_floor).max(0.0);
        excess(best.bound_present) > PRESENT_RESIDUAL * excess(gap_before)
            && excess(best.bound_present) > HISTORY_MARGIN * excess(best.bound_history)
    });
    let along = trials.first().and_then(|trial| {
        let variant = trial.present.as_ref().filter(|v| v.gap.is_finite())?;
        Some(along(context, trial, variant))
    });
    Located {
        loci,
        history_dependent,
        along,
    }
}

/// The model with a correction at `target` (params set); `None` when the target reaches
/// no balance.
pub(super) fn synthesise(
    context: &Context,
    target: &Target,
    params: &[f64],
) -> Result<Option<Corrected>, DiagnoseError> {
    let source = format!(
        "{}\n\nclosure {CLOSURE} {{\n  outputs {OUTPUT}\n}}\n\neffect {EFFECT} {{\n  {}\n}}\n",
        context.problem.source,
        target.patch()
    );
    let compiled =
        crate::driver::compile(context.problem.name, &source, &[EFFECT]).map_err(|reports| {
            let messages: Vec<String> = reports.iter().map(|r| r.to_string()).collect();
            DiagnoseError::internal(format!(
                "correction at `{}` does not compile: {}",
                target.name,
                messages.join("; ")
            ))
        })?;
    let model = compiled.model;
    let Some(closure) = model.closures.iter().position(|c| c.name == CLOSURE) else {
        return Err(DiagnoseError::internal("synthesised closure missing"));
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
                .ok_or_else(|| DiagnoseError::internal(format!("no state `{}`", target.name)))?;
            LocusValue::State(index)
        }
        _ => {
            let definition = (context.model.lets.iter())
                .find(|l| l.name == target.name)
                .ok_or_else(|| DiagnoseError::internal(format!("no let `{}`", target.name)))?;
            LocusValue::Let(simulator.compile(&definition.expr)?)
        }
    };
    Ok(Some(Corrected {
        simulator,
        locus,
        balance: target.kind == LocusKind::Balance,
        constraints: model.params.iter().map(|p| p.constraint).collect(),
    }))
}

fn try_target(
    context: &Context,
    target: &Target,
    params: &[f64],
    lags: &[Lags],
) -> Result<Option<Trial>, DiagnoseError> {
    let Some(mut corrected) = synthesise(context, target, params)? else {
        return Ok(None);
    };
    let (train, end) = (&context.split.train, context.split.train_rows.end);
    let Ok(pass) = correction::one_step_pass(&mut corrected, train, end) else {
        return Ok(None);
    };
    let theta = correction::theta_of(&corrected.constraints, params);
    let mut variant = |lags| {
        let map = feature_map(context, &pass, lags);
        let solution = correction::fit(&pass, &map, train, &context.normalisation, &theta)?;
        Some(score(context, &mut corrected, map, solution))
    };
    let present = variant(None);
    let history = (lags.iter())
        .filter_map(|&lag| variant(Some(lag)))
        .min_by(|a, b| a.gap.total_cmp(&b.gap));
    Ok(Some(Trial {
        target: target.clone(),
        corrected,
        pass,
        present,
        history,
    }))
}

/// Refines a trial's present correction (with `history`, its history correction) on the
/// training free run, and scores it again.
fn refine(context: &Context, trial: &mut Trial, history: bool) {
    let split = &context.split;
    let fitting = (
        &split.train,
        split.train_rows.clone(),
        &context.normalisation,
    );
    let variants = if history {
        vec![&mut trial.history]
    } else {
        vec![&mut trial.present]
    };
    for variant in variants.into_iter().flatten() {
        let along = correction::values_along(
            &trial.pass,
            &variant.map,
            &split.train,
            &variant.solution.weights,
        );
        let typical = root_mean_square(&along);
        let refinement = correction::Refinement {
            directions: variant.map.directions(),
            reference: if typical > 0.0 {
                typical
            } else {
                1e-3 * variant.map.locus_scale
            },
        };
        let solution = correction::refine(
            &trial.corrected,
            &variant.map,
            &variant.solution,
            &refinement,
            fitting.clone(),
        );
        *variant = score(context, &mut trial.corrected, variant.map.clone(), solution);
    }
}

/// The held-out gap (infinite when the run fails) and per-row errors of a correction.
fn score(
    context: &Context,
    corrected: &mut Corrected,
    map: FeatureMap,
    solution: Solution,
) -> Variant {
    let test = &context.split.test;
    let rows = context.split.test_rows.clone();
    let (gap, errors) = match correction::corrected_run(corrected, &map, &solution, test, rows.end)
    {
        Ok(run) => {
            let errors = row_errors(&run, test, rows, &context.normalisation);
            let gap = errors.iter().sum::<f64>() / (errors.len() * test.states.len()).max(1) as f64;
            (if gap.is_finite() { gap } else { f64::INFINITY }, errors)
        }
        Err(_) => (f64::INFINITY, Vec::new()),
    };
    Variant {
        map,
        solution,
        gap,
        errors,
    }
}

/// Feature scaling from the pass: present variables z-scored over the training rows.
pub(super) fn feature_map(context: &Context, pass: &Pass, lags: Option<Lags>) -> FeatureMap {
    let width = pass.present.first().map_or(0, Vec::len);
    let (center, scale) = (0..width)
        .map(|j| mean_std(&pass.present.iter().map(|p| p[j]).collect::<Vec<_>>()))
        .unzip();
    let locus_scale = root_mean_square(&pass.locus);
    FeatureMap {
        center,
        scale,
        locus_scale: if locus_scale > 0.0 { locus_scale } else { 1.0 },
        embedded: context.model.inputs.len() + context.model.states.len(),
        lags,
    }
}

fn along(context: &Context, trial: &Trial, variant: &Variant) -> Along {
    let model = context.model;
    let pass = &trial.pass;
    let mut names: Vec<String> = (model.inputs.iter().map(|i| i.name.clone()))
        .chain(
            model
                .states
                .iter()
                .chain(&model.hidden)
                .map(|s| s.name.clone()),
        )
        .collect();
    let balance = trial.target.kind == LocusKind::Balance;
    if !balance {
        names.push(trial.target.name.clone());
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
        values: correction::values_along(
            pass,
            &variant.map,
            &context.split.train,
            &variant.solution.weights,
        ),
        names,
        variables,
        let_last: !balance,
    }
}
