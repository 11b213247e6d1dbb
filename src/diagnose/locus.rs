//! Where the gap lies: a free correction at each `let` (`NAME += c`), at each *group* of
//! lets that share an input and a form (one correction each, fitted jointly; see
//! [`super::graph`]) and at each balance (`der X += c`), synthesised as closure outputs
//! patched in by an effect (the model's own source plus two declarations), fitted by
//! [`super::correction`] and scored by the held-out free run it leaves — a bound on what
//! any mechanism acting there can do.
//!
//! Each locus is tried with *present* features (everything the model knows at `t`) and with
//! *history* features (a fading memory up to the span chosen from the data, see
//! [`super::memory`]). All are fitted one step ahead; every present correction, and the
//! history corrections of the [`REFINED`] best loci, are refined on the training free runs
//! and scored.
//!
//! **Ranking.** Loci are ranked by the held-out gap they leave. A locus is *tied* with the
//! best when its gap is within [`TIE_FACTOR`] of the best's and either the block bootstrap
//! of the held-out errors cannot tell them apart ([`super::ranking`]) or it sits upstream
//! of the best (feeds it in the dependency graph: the cause of what the best corrects) and
//! explains as much: the excess gap it leaves exceeds the best's by less than [`NEAR_TIE`]
//! of the excess gap before (both close nearly all of it); among tied loci the most
//! specific and most upstream comes first (a let before a group before a balance; among
//! lets, the one furthest upstream), so a balance comes first only when no rate explains as
//! much.
//!
//! **Memory.** At the first locus, closing the gap needs history when the present alone
//! leaves more than [`PRESENT_RESIDUAL`] of the excess gap (the gap before, above the noise
//! floor) and history at most 1 / [`HISTORY_MARGIN`] of what the present leaves.

use super::context::{Context, Progress};
use super::correction::{self, Corrected, LocusValue, Pass, Solution};
use super::error::DiagnoseError;
use super::evaluate::Errors;
use super::features::FeatureMap;
use super::graph::Graph;
use super::ranking::compare;
use super::refine::{refine, score, Refinement};
use super::report::{Locus, LocusKind};
use crate::ir::{self, Constraint, Var};
use crate::numeric::{mean_std, root_mean_square};
use crate::solve::fit::fitter::thetas;
use crate::solve::fit::simulate::{tolerances, Simulator};
use rayon::prelude::*;
use std::time::Instant;

/// History must leave this many times less excess gap than the present alone.
pub const HISTORY_MARGIN: f64 = 2.0;
/// History is only needed when the present alone leaves more than this fraction of the
/// excess gap (the gap before, above the noise floor).
pub const PRESENT_RESIDUAL: f64 = 0.05;
/// Loci whose history correction is refined on the free run.
pub const REFINED: usize = 3;
/// A locus is tied with the best only if its bound is within this factor of the best's.
pub const TIE_FACTOR: f64 = 3.0;
/// A locus explains as much as the best when the excess gap it leaves exceeds the best's by
/// less than this share of the excess gap before.
pub const NEAR_TIE: f64 = 0.05;
/// Name of the synthesised closure.
const CLOSURE: &str = "__diagnose_closure";
/// Prefix of its outputs.
const OUTPUT: &str = "__diagnose_c";
/// Name of the synthesised effect.
const EFFECT: &str = "__diagnose_effect";

/// A place a correction can be added to.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// What the report calls it.
    pub name: String,
    /// Let, group or balance.
    pub kind: LocusKind,
    /// The corrected lets, or the balance's state.
    pub members: Vec<String>,
    /// How far upstream it sits.
    pub depth: usize,
}

impl Target {
    fn patches(&self) -> Vec<String> {
        (self.members.iter().enumerate())
            .map(|(slot, member)| match self.kind {
                LocusKind::Balance => format!("der {member} += {OUTPUT}{slot}"),
                _ => format!("{member} += {OUTPUT}{slot}"),
            })
            .collect()
    }
}

/// Every let that reaches a balance, every group of them, then every balance (measured,
/// then hidden states).
pub fn targets(context: &Context) -> Result<Vec<Target>, DiagnoseError> {
    let graph = Graph::of(context.problem.checked);
    let model = context.model;
    let lets: Vec<String> = (model.lets.iter())
        .map(|l| l.name.clone())
        .filter(|name| graph.reaches_balance(name))
        .collect();
    let mut targets: Vec<Target> = (lets.iter())
        .map(|name| Target {
            name: name.clone(),
            kind: LocusKind::Let,
            members: vec![name.clone()],
            depth: graph.depth(name),
        })
        .collect();
    targets.extend(graph.groups(&lets).into_iter().map(|members| Target {
        name: members.join(" + "),
        kind: LocusKind::Group,
        depth: members.iter().map(|m| graph.depth(m)).min().unwrap_or(1),
        members,
    }));
    targets.extend(model.states.iter().chain(&model.hidden).map(|s| Target {
        name: s.name.clone(),
        kind: LocusKind::Balance,
        members: vec![s.name.clone()],
        depth: 0,
    }));
    Ok(targets)
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

/// The loci, best first, the memory verdict of the free corrections, and the best
/// correction along the data (empty when the loci are not searched).
#[derive(Debug, Clone, Default)]
pub struct Located {
    /// Report entries, best first.
    pub loci: Vec<Locus>,
    /// Whether, at the first locus, history beats the present by the margin.
    pub history_dependent: bool,
    /// The first locus's present-only correction along the training rows (single lets and
    /// balances only).
    pub along: Option<Along>,
}

/// One correction tried at one locus.
#[derive(Debug, Clone)]
struct Variant {
    map: FeatureMap,
    solution: Solution,
    gap: f64,
    errors: Errors,
}

/// Everything tried at one target.
#[derive(Debug, Clone)]
struct Trial {
    target: Target,
    corrected: Corrected,
    pass: Pass,
    present: Option<Variant>,
    history: Option<Variant>,
    seconds: f64,
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

    /// The report's entry for this trial (`tied`: with the best).
    fn locus(&self, tied: bool) -> Locus {
        let gap = |v: &Option<Variant>| v.as_ref().map_or(f64::INFINITY, |v| v.gap);
        Locus {
            name: self.target.name.clone(),
            kind: self.target.kind,
            members: self.target.members.clone(),
            bound_after: self.bound(),
            bound_present: gap(&self.present),
            bound_history: gap(&self.history),
            tied,
            depth: self.target.depth,
            seconds: self.seconds,
        }
    }
}

/// Tries every target with the fitted model `x` (params, then fitted starts) and the history
/// time constants `taus`.
pub fn locate(
    context: &Context,
    x: &[f64],
    taus: &[f64],
    gaps: (f64, f64),
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Located, DiagnoseError> {
    let targets = targets(context)?;
    progress(Progress::Stage {
        name: "fitting corrections",
        total: targets.len(),
    });
    let found = targets
        .par_iter()
        .map(|target| {
            let started = Instant::now();
            let mut trial = try_target(context, target, x, taus)?;
            if let Some(trial) = trial.as_mut() {
                refine_trial(context, trial, false);
                trial.seconds = started.elapsed().as_secs_f64();
            }
            progress(Progress::Done {
                item: target.name.clone(),
                seconds: started.elapsed().as_secs_f64(),
            });
            Ok(trial)
        })
        .collect::<Result<Vec<_>, DiagnoseError>>()?;
    let mut trials: Vec<Trial> = found.into_iter().flatten().collect();
    trials.sort_by(|a, b| a.bound().total_cmp(&b.bound()));
    let top = trials.len().min(REFINED);
    progress(Progress::Stage {
        name: "refining memory",
        total: top,
    });
    trials[..top].par_iter_mut().for_each(|trial| {
        let started = Instant::now();
        refine_trial(context, trial, true);
        trial.seconds += started.elapsed().as_secs_f64();
        progress(Progress::Done {
            item: trial.target.name.clone(),
            seconds: started.elapsed().as_secs_f64(),
        });
    });
    summarise(context, trials, gaps)
}

/// The loci in the report's order (the best and those tied with it first, most specific
/// and upstream first), the memory verdict at the first and its correction along the data.
fn summarise(
    context: &Context,
    mut trials: Vec<Trial>,
    gaps: (f64, f64),
) -> Result<Located, DiagnoseError> {
    trials.sort_by(|a, b| a.bound().total_cmp(&b.bound()));
    let tied = tied_with_best(context, &trials, gaps);
    let order = report_order(&trials, &tied);
    let loci: Vec<Locus> = (order.iter()).map(|&i| trials[i].locus(tied[i])).collect();
    let (gap_before, noise_floor) = gaps;
    let excess = |gap: f64| (gap - noise_floor).max(0.0);
    let history_dependent = loci.first().is_some_and(|best| {
        excess(best.bound_present) > PRESENT_RESIDUAL * excess(gap_before)
            && excess(best.bound_present) > HISTORY_MARGIN * excess(best.bound_history)
    });
    let along = order.first().and_then(|&i| {
        let trial = &trials[i];
        let variant = trial.present.as_ref().filter(|v| v.gap.is_finite())?;
        (trial.target.members.len() == 1).then(|| along(context, trial, variant))
    });
    Ok(Located {
        loci,
        history_dependent,
        along,
    })
}

/// Per trial (sorted by bound), whether it is the best or tied with it: within
/// [`TIE_FACTOR`] of the best bound and either not told apart from it by the block
/// bootstrap or upstream of it and leaving nearly as little of the gap ([`NEAR_TIE`]).
fn tied_with_best(
    context: &Context,
    trials: &[Trial],
    (gap_before, noise_floor): (f64, f64),
) -> Vec<bool> {
    let sums: Vec<_> = (trials.iter())
        .map(|t| match t.best() {
            Some(v) => context.blocks.sums(&v.errors),
            None => vec![(f64::INFINITY, 0); context.blocks.blocks.len()],
        })
        .collect();
    let comparison = compare(&sums, context.seed(5000));
    let best_bound = trials.first().map_or(f64::INFINITY, Trial::bound);
    let excess = |gap: f64| (gap - noise_floor).max(0.0);
    let graph = Graph::of(context.problem.checked);
    let upstream = |i: usize| {
        let best = &trials[0].target;
        (trials[i].target.members.iter())
            .any(|member| best.members.iter().any(|b| graph.feeds(member, b)))
    };
    let as_much = |i: usize| {
        upstream(i)
            && excess(trials[i].bound()) - excess(best_bound) < NEAR_TIE * excess(gap_before)
    };
    (0..trials.len())
        .map(|i| {
            i == 0
                || (trials[i].bound() <= TIE_FACTOR * best_bound
                    && (comparison.tied_with_best(i) || as_much(i)))
        })
        .collect()
}

/// The order of the trials in the report: the tied ones first, by kind and deepest first,
/// then every other by bound.
fn report_order(trials: &[Trial], tied: &[bool]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..trials.len()).collect();
    order.sort_by(|&a, &b| {
        let key = |i: usize| {
            (
                !tied[i],
                if tied[i] {
                    trials[i].target.kind
                } else {
                    LocusKind::Let
                },
            )
        };
        let depth = |i: usize| if tied[i] { trials[i].target.depth } else { 0 };
        key(a)
            .cmp(&key(b))
            .then(depth(b).cmp(&depth(a)))
            .then(trials[a].bound().total_cmp(&trials[b].bound()))
    });
    order
}

/// The model with corrections at `target`; `None` when no balance uses them.
pub(super) fn synthesise(
    context: &Context,
    target: &Target,
) -> Result<Option<Corrected>, DiagnoseError> {
    let outputs: Vec<String> = (0..target.members.len())
        .map(|j| format!("{OUTPUT}{j}"))
        .collect();
    let source = format!(
        "{}\n\nclosure {CLOSURE} {{\n  outputs {}\n}}\n\neffect {EFFECT} {{\n  {}\n}}\n",
        context.problem.source,
        outputs.join(", "),
        target.patches().join("\n  ")
    );
    let fails = |messages: Vec<String>| {
        DiagnoseError::internal(format!(
            "correction at `{}` does not compile: {}",
            target.name,
            messages.join("; ")
        ))
    };
    let checked = crate::driver::check(context.problem.name, &source)
        .map_err(|reports| fails(reports.iter().map(|r| r.to_string()).collect()))?;
    // A probe, fitted and thrown away: not held to the guard of `nonnegative` states.
    let model = ir::lower_unguarded(&checked, &[EFFECT])
        .map_err(|errors| fails(errors.iter().map(|e| e.to_string()).collect()))?;
    let Some(closure) = model.closures.iter().position(|c| c.name == CLOSURE) else {
        return Err(DiagnoseError::internal("synthesised closure missing"));
    };
    if !model.balances.iter().any(|b| ir::uses_closure(&b.expr)) {
        return Ok(None);
    }
    let vars: Vec<Var> = (0..outputs.len())
        .map(|output| Var::ClosureOutput { closure, output })
        .collect();
    let mut simulator = Simulator::new(&model, &vars, tolerances())?;
    simulator.set_method(context.corrections);
    simulator.observe(&model, &context.split.normalisation.observables)?;
    let mut loci = Vec::new();
    for member in &target.members {
        loci.push(match target.kind {
            LocusKind::Balance => {
                let index = (model.states.iter().chain(&model.hidden))
                    .position(|s| &s.name == member)
                    .ok_or_else(|| DiagnoseError::internal(format!("no state `{member}`")))?;
                LocusValue::State(index)
            }
            _ => {
                let definition = (context.model.lets.iter())
                    .find(|l| &l.name == member)
                    .ok_or_else(|| DiagnoseError::internal(format!("no let `{member}`")))?;
                LocusValue::Let(simulator.compile(&definition.expr)?)
            }
        });
    }
    let mut constraints: Vec<Constraint> = model.params.iter().map(|p| p.constraint).collect();
    let fitted = context.split.fitted_count(model.hidden.len());
    constraints.extend((0..fitted).map(|_| Constraint::Free));
    Ok(Some(Corrected {
        simulator,
        loci,
        balance: target.kind == LocusKind::Balance,
        constraints,
    }))
}

fn try_target(
    context: &Context,
    target: &Target,
    x: &[f64],
    taus: &[f64],
) -> Result<Option<Trial>, DiagnoseError> {
    let Some(mut corrected) = synthesise(context, target)? else {
        return Ok(None);
    };
    let Ok(pass) = correction::one_step_pass(&mut corrected, &context.split, x, taus) else {
        return Ok(None);
    };
    let theta = thetas(&corrected.constraints, x);
    let norm = &context.split.normalisation;
    let mut variant = |taus: Option<Vec<f64>>| {
        let map = feature_map(context, &pass, taus);
        let solution = correction::fit(&pass, &map, norm, &theta)?;
        Some(evaluate(context, &mut corrected, map, solution))
    };
    let present = variant(None);
    let history = (!taus.is_empty())
        .then(|| variant(Some(taus.to_vec())))
        .flatten();
    Ok(Some(Trial {
        target: target.clone(),
        corrected,
        pass,
        present,
        history,
        seconds: 0.0,
    }))
}

/// Refines a trial's present correction (with `history`, its history correction) on the
/// training free runs, and scores it again.
fn refine_trial(context: &Context, trial: &mut Trial, history: bool) {
    let variant = if history {
        &mut trial.history
    } else {
        &mut trial.present
    };
    let Some(variant) = variant.as_mut() else {
        return;
    };
    let slots = trial.corrected.loci.len();
    let width = variant.map.width();
    let reference: Vec<f64> = (0..slots)
        .map(|slot| {
            let along = correction::values_along(
                &trial.pass,
                &variant.map,
                &variant.solution.weights,
                slot,
            );
            let typical = root_mean_square(&along);
            if typical > 0.0 {
                typical
            } else {
                1e-3 * variant.map.locus_scale
            }
        })
        .collect();
    let refinement = Refinement {
        directions: variant.map.directions(),
        reference,
    };
    debug_assert_eq!(variant.solution.weights.len(), slots * width);
    let solution = refine(
        &trial.corrected,
        &variant.map,
        &variant.solution,
        &refinement,
        &context.split,
    );
    *variant = evaluate(context, &mut trial.corrected, variant.map.clone(), solution);
}

/// The held-out errors and gap of a correction.
fn evaluate(
    context: &Context,
    corrected: &mut Corrected,
    map: FeatureMap,
    solution: Solution,
) -> Variant {
    let errors = score(corrected, &map, &solution, &context.split);
    Variant {
        map,
        solution,
        gap: errors.gap(),
        errors,
    }
}

/// Feature scaling from the pass: present variables z-scored over the training rows, the
/// corrected quantities by their root mean square.
pub(super) fn feature_map(context: &Context, pass: &Pass, taus: Option<Vec<f64>>) -> FeatureMap {
    let rows: Vec<&Vec<f64>> = pass.records.iter().flat_map(|r| r.present.iter()).collect();
    let width = rows.first().map_or(0, |p| p.len());
    let (center, scale) = (0..width)
        .map(|j| mean_std(&rows.iter().map(|p| p[j]).collect::<Vec<_>>()))
        .unzip();
    let loci: Vec<f64> = (pass.records.iter())
        .flat_map(|r| r.locus.iter().flatten().copied())
        .collect();
    let locus_scale = root_mean_square(&loci);
    FeatureMap {
        center,
        scale,
        locus_scale: if locus_scale > 0.0 { locus_scale } else { 1.0 },
        embedded: context.model.inputs.len() + context.model.states.len(),
        taus,
    }
}

fn along(context: &Context, trial: &Trial, variant: &Variant) -> Along {
    let model = context.model;
    let mut names: Vec<String> = (model.inputs.iter().map(|i| i.name.clone()))
        .chain((model.states.iter().chain(&model.hidden)).map(|s| s.name.clone()))
        .collect();
    let balance = trial.target.kind == LocusKind::Balance;
    if !balance {
        names.push(trial.target.name.clone());
    }
    let variables = (trial.pass.records.iter())
        .flat_map(|record| (0..record.rows()).map(move |row| (record, row)))
        .map(|(record, row)| {
            let mut values = record.present[row].clone();
            if !balance {
                values.push(record.locus[row][0]);
            }
            values
        })
        .collect();
    Along {
        values: correction::values_along(&trial.pass, &variant.map, &variant.solution.weights, 0),
        names,
        variables,
        let_last: !balance,
    }
}
