//! Which effects explain the gap: chosen on the training side, scored on the held-out side.
//!
//! The candidates are sets of effects: every effect alone (the ranking,
//! [`super::effects::rank_effects`]), and, unless one effect alone already leaves no
//! significant gap, every pair among the best [`PAIRS_AMONG`], each fitted with all its
//! params, warm-started from its members' single fits. Effects that only act together (a
//! source of a species and its sink) are found this way; greedy forward selection stops at
//! the first step, where neither alone helps. Unless a pair then leaves no significant
//! gap, the triples among the best [`TRIPLES_AMONG`] that contain a pair earning both its
//! effects are fitted too (heredity: a triple is credited only over every pair inside it,
//! and a third effect is looked for on top of two that act, not among effects no pair of
//! which acts together).
//!
//! The choice uses the training fits only: Schwarz's criterion (BIC) on the training cells,
//! and how much of the training gap above the noise floor a set removes. Free-run errors
//! are correlated in time, so BIC alone overstates the evidence of thousands of cells: a
//! set is preferred to one of its subsets only when the subset leaves a significant
//! training gap, BIC falls by [`EVIDENCE`] *and* the set removes at least [`MARGINAL`] of
//! what the subset leaves above the floor (each effect of a set must earn its place).
//! A candidate that refits a held constant pays a prior penalty
//! ([`super::candidates::REFIT_PRIOR`] per constant) on top of its BIC: the modeller's
//! declared values are knowledge, and a refitted design setting fits many gaps that a
//! missing effect causes. The set with the lowest penalised BIC, trimmed that way, is
//! credited when:
//!
//! 1. the model's training gap is significant (above [`super::SIGNIFICANCE`] times the
//!    noise floor);
//! 2. the set removes at least [`super::CREDIT`] of the training gap above the floor;
//! 3. its penalised BIC falls by at least [`EVIDENCE`] ("strong" evidence on Kass and
//!    Raftery's scale);
//! 4. no other set that is not its subset or superset (and earns each of its effects)
//!    comes within [`TIE`] of its BIC: else the verdict is "undecided between" them, with
//!    the evidence for each.
//!
//! The held-out data only score the choice: the credited set's held-out gap, its shrink
//! and the block-bootstrap spread of its decrease ([`super::ranking`]) are reported, and a
//! credited set that does worse on the held-out data than the model is flagged.

use super::candidates::{lower, prior_penalty};
use super::context::{Context, Progress, CREDIT, SIGNIFICANCE};
use super::effects::{block_sums, fit_and_score, fit_and_score_with, Ranking, Scored};
use super::error::DiagnoseError;
use super::ranking::compare;
use super::render::num;
use super::report::{Selection, SelectionStep};
use rayon::prelude::*;
use std::collections::BTreeMap;

/// BIC must fall by this much for an effect (or set) to be credited, and a set must beat
/// each of its subsets by this much to be preferred to it.
pub const EVIDENCE: f64 = 6.0;
/// Two sets within this BIC of each other cannot be told apart.
pub const TIE: f64 = 2.0;
/// A set beats its subset only when it removes at least this share of what the subset
/// leaves above the noise floor.
pub const MARGINAL: f64 = 0.25;
/// The fits that decide a verdict are searched again with this many times the restarts.
pub const CONFIRM_RESTARTS: usize = 2;
/// Triples are tried among at most this many candidates (the best by BIC alone).
pub const TRIPLES_AMONG: usize = 5;
/// Pairs are tried among at most this many candidates (the best by BIC alone).
pub const PAIRS_AMONG: usize = 8;

/// The gap and noise level a selection works against.
#[derive(Debug, Clone, Copy)]
pub struct Levels {
    /// The model's held-out gap without effects.
    pub gap_before: f64,
    /// The noise floor.
    pub noise_floor: f64,
    /// What a correct model's held-out gap would be: the noise floor plus the spread its
    /// fitted params and noisy starts add ([`crate::solve::fit::predictive`]).
    pub held_out_floor: f64,
}

/// One fitted set of effects.
struct Candidate {
    effects: Vec<String>,
    fit: Scored,
}

impl Candidate {
    /// What the selection ranks by: BIC plus the prior penalty of the constants the set
    /// refits ([`super::candidates::prior_penalty`]).
    fn criterion(&self) -> f64 {
        self.fit.summary.bic + prior_penalty(&self.effects)
    }
}

/// Chooses the credited effects (see the module documentation); returns the selection and
/// the fit of the credited set (`None` when nothing is credited).
pub fn select(
    context: &Context,
    base: &Scored,
    ranking: &Ranking,
    levels: Levels,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<(Selection, Option<Scored>), DiagnoseError> {
    let mut candidates: Vec<Candidate> = (ranking.scores.iter())
        .zip(&ranking.fits)
        .map(|(score, fit)| Candidate {
            effects: vec![score.name.clone()],
            fit: fit.clone(),
        })
        .collect();
    let settled = |candidates: &[Candidate]| {
        best(candidates).is_some_and(|set| {
            credible(base, set, levels) && !significant(set.fit.summary.gap_train, levels)
        })
    };
    for size in [2, 3] {
        if settled(&candidates) {
            break;
        }
        let earning = earning_pairs(&candidates, levels);
        let wanted = |names: &[&str]| size == 2 || contains_any(names, &earning);
        candidates.extend(combinations(context, ranking, (size, &wanted), progress)?);
    }
    candidates.sort_by(|a, b| a.criterion().total_cmp(&b.criterion()));
    let (selection, _) = decide(context, base, &candidates, levels);
    if confirm(context, &mut candidates, &selection, progress)? {
        candidates.sort_by(|a, b| a.criterion().total_cmp(&b.criterion()));
    }
    Ok(decide(context, base, &candidates, levels))
}

/// The fits that decide the verdict (the credited set, or the sets it is undecided between;
/// else the best by BIC) searched again with [`CONFIRM_RESTARTS`] times the restarts when
/// their best was reached by one start only or rivals stand within [`TIE`] of BIC; each
/// keeps the better fit. Returns whether any was searched again.
fn confirm(
    context: &Context,
    candidates: &mut [Candidate],
    selection: &Selection,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<bool, DiagnoseError> {
    if candidates.is_empty() {
        return Ok(false);
    }
    let deciding: Vec<usize> = if !selection.undecided.is_empty() {
        (0..candidates.len())
            .filter(|&i| {
                selection
                    .undecided
                    .contains(&candidates[i].effects.join(" + "))
            })
            .collect()
    } else {
        vec![0]
    };
    let needed = !selection.undecided.is_empty()
        || deciding
            .iter()
            .any(|&i| candidates[i].fit.fitted.agreeing < 2);
    if !needed || deciding.is_empty() {
        return Ok(false);
    }
    progress(Progress::Stage {
        name: "confirming the deciding fits",
        total: deciding.len(),
    });
    let restarts = CONFIRM_RESTARTS * context.options.restarts.max(1);
    let refits: Vec<(usize, Scored)> = deciding
        .par_iter()
        .map(|&i| {
            let candidate = &candidates[i];
            let names: Vec<&str> = candidate.effects.iter().map(String::as_str).collect();
            let model = lower(context, &names)?;
            let starts = crate::solve::fit::fitter::Starts::new(restarts);
            let seed = context.seed(6000 + i as u64);
            let label = names.join(" + ");
            let start = &candidate.fit.named;
            let fit = fit_and_score_with(context, (&label, &model), (start, starts), seed)?;
            progress(Progress::Done {
                item: label,
                seconds: fit.summary.seconds,
            });
            Ok((i, fit))
        })
        .collect::<Result<_, DiagnoseError>>()?;
    for (i, fit) in refits {
        let old = &candidates[i].fit;
        if fit.fitted.gap < old.fitted.gap * (1.0 - 1e-9) {
            candidates[i].fit = fit;
        } else if (fit.fitted.gap - old.fitted.gap).abs()
            <= crate::solve::fit::fitter::AGREE * old.fitted.gap
        {
            // The wider search (its first start the old best) counts who reached it again.
            let agreeing = old.fitted.agreeing.max(fit.fitted.agreeing);
            candidates[i].fit.fitted.agreeing = agreeing;
        }
    }
    Ok(true)
}

/// The candidate with the lowest BIC.
fn best(candidates: &[Candidate]) -> Option<&Candidate> {
    candidates
        .iter()
        .min_by(|a, b| a.criterion().total_cmp(&b.criterion()))
}

/// Whether a training gap is significant against the noise floor.
fn significant(gap_train: f64, levels: Levels) -> bool {
    gap_train > SIGNIFICANCE * levels.noise_floor
}

/// Whether `set` passes rules 1-3 against `base`.
fn credible(base: &Scored, set: &Candidate, levels: Levels) -> bool {
    reason_refused(base, set, levels).is_none()
}

/// Why `fit` is not credited over `base` by rules 1-3 (`None`: it is). Every test is false
/// for a NaN, which is then refused.
fn reason_refused(base: &Scored, set: &Candidate, levels: Levels) -> Option<String> {
    let (before, after) = (base.summary.gap_train, set.fit.summary.gap_train);
    let excess = before - levels.noise_floor;
    let removed = before - after;
    let falls = base.summary.bic - set.criterion();
    if !significant(before, levels) {
        Some(format!(
            "the training gap ({}) is within {SIGNIFICANCE}x the noise floor ({})",
            num(before),
            num(levels.noise_floor)
        ))
    } else if removed
        .partial_cmp(&(CREDIT * excess))
        .is_none_or(|o| o.is_lt())
    {
        Some(format!(
            "it removes {} of the training gap above the noise floor, less than {}",
            percent(removed / excess),
            percent(CREDIT)
        ))
    } else if falls.partial_cmp(&EVIDENCE).is_none_or(|o| o.is_lt()) {
        Some(format!(
            "BIC falls by {}{}, less than {EVIDENCE}",
            num(falls),
            penalty_words(&set.effects)
        ))
    } else {
        None
    }
}

/// Which sets of effects (by name) a round of combinations fits.
type Wanted<'a> = dyn Fn(&[&str]) -> bool + Sync + 'a;

/// The pairs among `candidates` that earn both their effects ([`earns_every_effect`]).
fn earning_pairs(candidates: &[Candidate], levels: Levels) -> Vec<Vec<String>> {
    (candidates.iter())
        .filter(|c| c.effects.len() == 2 && earns_every_effect(c, candidates, levels))
        .map(|c| c.effects.clone())
        .collect()
}

/// Whether `names` contains every effect of one of `sets`.
fn contains_any(names: &[&str], sets: &[Vec<String>]) -> bool {
    (sets.iter()).any(|set| set.iter().all(|e| names.contains(&e.as_str())))
}

/// Every set of `size` candidates among the best [`PAIRS_AMONG`] (pairs) or
/// [`TRIPLES_AMONG`] (triples) single candidates by BIC that `wanted` keeps, fitted side
/// by side.
fn combinations(
    context: &Context,
    ranking: &Ranking,
    (size, wanted): (usize, &Wanted),
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Vec<Candidate>, DiagnoseError> {
    let mut singles: Vec<usize> = (0..ranking.scores.len()).collect();
    let criterion = |i: usize| {
        ranking.fits[i].summary.bic + prior_penalty(std::slice::from_ref(&ranking.scores[i].name))
    };
    singles.sort_by(|&a, &b| criterion(a).total_cmp(&criterion(b)));
    singles.truncate(if size == 2 {
        PAIRS_AMONG
    } else {
        TRIPLES_AMONG
    });
    let names = |set: &[usize]| -> Vec<&str> {
        (set.iter())
            .map(|&i| ranking.scores[i].name.as_str())
            .collect()
    };
    let sets: Vec<Vec<usize>> = (subsets(&singles, size).into_iter())
        .filter(|set| wanted(&names(set)))
        .collect();
    if sets.is_empty() {
        return Ok(Vec::new());
    }
    progress(Progress::Stage {
        name: if size == 2 {
            "fitting pairs"
        } else {
            "fitting triples"
        },
        total: sets.len(),
    });
    sets.par_iter()
        .enumerate()
        .map(|(index, set)| {
            let names = names(set);
            let model = lower(context, &names)?;
            let mut start: BTreeMap<String, f64> = BTreeMap::new();
            for &i in set.iter().rev() {
                start.extend(ranking.fits[i].named.clone());
            }
            let seed = context.seed(1000 * size as u64 + index as u64);
            let label = names.join(" + ");
            let fit = fit_and_score(context, (&label, &model), &start, seed)?;
            progress(Progress::Done {
                item: label,
                seconds: fit.summary.seconds,
            });
            Ok(Candidate {
                effects: names.iter().map(|n| n.to_string()).collect(),
                fit,
            })
        })
        .collect()
}

/// The verdict over the fitted candidates (sorted by BIC).
fn decide(
    context: &Context,
    base: &Scored,
    candidates: &[Candidate],
    levels: Levels,
) -> (Selection, Option<Scored>) {
    let mut selection = Selection {
        gap_after: levels.gap_before,
        criterion: format!(
            "BIC of the training fit (credited when it falls by {EVIDENCE} or more)"
        ),
        ..Selection::default()
    };
    let Some(winner) = parsimonious(candidates, levels) else {
        selection.stop = "no candidate effects".into();
        return (selection, None);
    };
    let refused = reason_refused(base, winner, levels);
    let rivals: Vec<&Candidate> = (candidates.iter())
        .filter(|c| !nested(&c.effects, &winner.effects))
        .filter(|c| earns_every_effect(c, candidates, levels))
        .filter(|c| c.criterion() - winner.criterion() < TIE)
        .collect();
    let unconfirmed = winner.fit.fitted.agreeing < 2;
    selection.steps = candidates
        .iter()
        .map(|c| {
            step(
                context,
                base,
                c,
                levels,
                std::ptr::eq(c, winner) && refused.is_none() && rivals.is_empty(),
            )
        })
        .collect();
    selection.combinations = (candidates.iter())
        .filter(|c| c.effects.len() > 1)
        .map(|c| c.effects.join(" + "))
        .collect();
    let name = winner.effects.join(" + ");
    if let Some(reason) = refused {
        selection.stop = format!("{name} is the best by BIC, but {reason}");
        return (selection, None);
    }
    if !rivals.is_empty() {
        let mut names = vec![name];
        names.extend(rivals.iter().map(|c| c.effects.join(" + ")));
        selection.undecided = names.clone();
        selection.stop = format!(
            "undecided between {}: BIC within {TIE} of each other ({})",
            names.join(" and "),
            evidence(std::iter::once(winner).chain(rivals.iter().copied()))
        );
        return (selection, None);
    }
    selection.credited = winner.effects.clone();
    selection.refitted = (winner.effects.iter())
        .filter_map(|name| super::candidates::refitted(name).map(str::to_string))
        .collect();
    selection.gap_after = winner.fit.gap;
    selection.stop = held_out_note(base, &winner.fit, levels);
    if unconfirmed {
        selection
            .stop
            .push_str("; its best fit was reached by one start only");
    }
    (selection, Some(winner.fit.clone()))
}

/// The lowest-BIC candidate, trimmed: replaced by the best of its proper subsets it does
/// not [`beat`], until it beats them all.
fn parsimonious(candidates: &[Candidate], levels: Levels) -> Option<&Candidate> {
    let mut winner = candidates.first()?;
    while let Some(subset) = (candidates.iter())
        .filter(|c| c.effects.len() < winner.effects.len())
        .filter(|c| c.effects.iter().all(|e| winner.effects.contains(e)))
        .filter(|c| !beats(winner, c, levels))
        .min_by(|a, b| a.criterion().total_cmp(&b.criterion()))
    {
        winner = subset;
    }
    Some(winner)
}

/// Every subset of `items` with `size` members, in lexicographic order of positions.
fn subsets(items: &[usize], size: usize) -> Vec<Vec<usize>> {
    if size == 0 {
        return vec![Vec::new()];
    }
    let mut out = Vec::new();
    for (i, &first) in items.iter().enumerate() {
        for mut rest in subsets(&items[i + 1..], size - 1) {
            rest.insert(0, first);
            out.push(rest);
        }
    }
    out
}

/// Whether `set` beats every subset of it that was fitted (no effect in it is dead weight).
fn earns_every_effect(set: &Candidate, candidates: &[Candidate], levels: Levels) -> bool {
    (candidates.iter())
        .filter(|c| c.effects.len() < set.effects.len())
        .filter(|c| c.effects.iter().all(|e| set.effects.contains(e)))
        .all(|c| beats(set, c, levels))
}

/// Whether the set `larger` earns its place over its subset `smaller`: `smaller` leaves a
/// significant training gap (an effect added to a set that already explains the cells
/// down to the noise fits noise), the criterion falls by [`EVIDENCE`], and it removes
/// [`MARGINAL`] of what `smaller` leaves above the noise floor.
fn beats(larger: &Candidate, smaller: &Candidate, levels: Levels) -> bool {
    let (larger_gap, smaller_gap) = (larger.fit.summary.gap_train, smaller.fit.summary.gap_train);
    let left = smaller_gap - levels.noise_floor;
    let removed = smaller_gap - larger_gap;
    significant(smaller_gap, levels)
        && smaller.criterion() - larger.criterion() >= EVIDENCE
        && removed >= MARGINAL * left
}

/// The prior penalty a set pays, in words (empty when it refits no constant).
fn penalty_words(effects: &[String]) -> String {
    let penalty = prior_penalty(effects);
    if penalty > 0.0 {
        format!(
            " after the penalty of {} for refitted constants",
            num(penalty)
        )
    } else {
        String::new()
    }
}

/// Whether one of two sets contains the other.
fn nested(a: &[String], b: &[String]) -> bool {
    a.iter().all(|e| b.contains(e)) || b.iter().all(|e| a.contains(e))
}

/// Each candidate's BIC and held-out gap, in words.
fn evidence<'a>(candidates: impl Iterator<Item = &'a Candidate>) -> String {
    candidates
        .map(|c| {
            format!(
                "{}: BIC {}{}, held-out gap {}",
                c.effects.join(" + "),
                num(c.fit.summary.bic),
                match prior_penalty(&c.effects) {
                    p if p > 0.0 => format!(" (+{} for refitted constants)", num(p)),
                    _ => String::new(),
                },
                num(c.fit.gap)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The held-out score of the credited fit, in words.
fn held_out_note(base: &Scored, fit: &Scored, levels: Levels) -> String {
    let shrink = 1.0 - fit.gap / levels.gap_before;
    if fit.gap > base.gap {
        format!(
            "credited on the training data, but the held-out gap grows from {} to {}: the \
             held-out data do not confirm it",
            num(base.gap),
            num(fit.gap)
        )
    } else {
        format!(
            "the held-out gap shrinks by {} ({} to {})",
            percent(shrink),
            num(base.gap),
            num(fit.gap)
        )
    }
}

/// The report's line for one candidate set.
fn step(
    context: &Context,
    base: &Scored,
    candidate: &Candidate,
    levels: Levels,
    accepted: bool,
) -> SelectionStep {
    let fit = &candidate.fit;
    let pair = compare(
        &[block_sums(context, base), block_sums(context, fit)],
        context.seed(4000),
    );
    let reason = reason_refused(base, candidate, levels).unwrap_or_else(|| {
        format!(
            "removes {} of the training gap above the noise floor; BIC falls by {}{}",
            percent(
                (base.summary.gap_train - fit.summary.gap_train)
                    / (base.summary.gap_train - levels.noise_floor)
            ),
            num(base.summary.bic - candidate.criterion()),
            penalty_words(&candidate.effects)
        )
    });
    SelectionStep {
        added: candidate.effects.join(" + "),
        effects: candidate.effects.clone(),
        gap_train: fit.summary.gap_train,
        gap_after: fit.gap,
        shrink: 1.0 - fit.gap / levels.gap_before,
        aic: fit.summary.aic,
        bic: fit.summary.bic,
        delta_bic: fit.summary.bic - base.summary.bic,
        unknowns: fit.summary.unknowns,
        spread: pair.spread[0].max(pair.spread[1]),
        alternatives: Vec::new(),
        accepted,
        reason,
        fit: Some(fit.summary.clone()),
    }
}

fn percent(value: f64) -> String {
    super::render::percent(value)
}
