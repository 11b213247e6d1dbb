//! From runs to scores: each held-out experiment of a split scored, and every held-out
//! experiment of every split together ([`super::score`] reduces one model's runs and
//! gives the verdict).

use super::comparison::{ExperimentScore, MemberRun, SplitResult};
use super::score::{Score, Verdict};
use crate::train::ErrorSet;

/// The scores of each held-out experiment of a split.
pub fn split_scores<'s>(split: &'s SplitResult, states: &[String]) -> Vec<ExperimentScore> {
    (split.held_out.iter().enumerate())
        .map(|(index, name)| {
            let on = |run: &'s MemberRun| error_on(run, index);
            let grey: Vec<(String, Option<&ErrorSet>)> = (split.grey_box.iter())
                .map(|run| (format!("seed {}", run.seed), on(run)))
                .collect();
            let mechanism = vec![("mechanism".to_string(), on(&split.mechanism))];
            let untrained: Vec<(String, Option<&ErrorSet>)> = (split.untrained.iter())
                .map(|run| ("untrained".to_string(), on(run)))
                .collect();
            let resolves = split.untrained_is_mechanism();
            let naive = vec![(
                "naive".to_string(),
                split.naive.get(index).and_then(|h| h.error.as_ref()),
            )];
            scored(
                name,
                (&grey, (&mechanism, &untrained, resolves), &naive),
                states,
            )
        })
        .collect()
}

/// The scores over every held-out experiment of every split: each run's errors averaged
/// over the experiments (a seed's over every split), then reduced as per experiment.
pub fn overall(splits: &[SplitResult], seeds: &[u64], states: &[String]) -> ExperimentScore {
    let grey: Vec<(String, Option<ErrorSet>)> = (seeds.iter())
        .map(|&seed| {
            let runs: Option<Vec<&MemberRun>> = (splits.iter())
                .map(|split| split.grey_box.iter().find(|r| r.seed == seed))
                .collect();
            (
                format!("seed {seed}"),
                runs.and_then(|r| averaged(&r, states)),
            )
        })
        .collect();
    let mechanisms: Vec<&MemberRun> = splits.iter().map(|s| &s.mechanism).collect();
    let mechanism = vec![("mechanism".to_string(), averaged(&mechanisms, states))];
    let untrained_runs: Option<Vec<&MemberRun>> =
        splits.iter().map(|s| s.untrained.as_ref()).collect();
    let untrained: Vec<(String, Option<ErrorSet>)> = (untrained_runs.iter())
        .map(|runs| ("untrained".to_string(), averaged(runs, states)))
        .collect();
    let naive_sets: Vec<Option<&ErrorSet>> = (splits.iter())
        .flat_map(|s| s.naive.iter().map(|h| h.error.as_ref()))
        .collect();
    let naive = vec![("naive".to_string(), mean_set(&naive_sets, states))];
    let (grey, mechanism, naive) = (borrowed(&grey), borrowed(&mechanism), borrowed(&naive));
    let untrained = borrowed(&untrained);
    let resolves = splits.iter().all(SplitResult::untrained_is_mechanism);
    scored(
        "overall",
        (&grey, (&mechanism, &untrained, resolves), &naive),
        states,
    )
}

/// A run's error on held-out experiment `index`.
fn error_on(run: &MemberRun, index: usize) -> Option<&ErrorSet> {
    run.held_out.get(index).and_then(|h| h.error.as_ref())
}

/// The mean error set of `runs` over all their held-out experiments.
fn averaged(runs: &[&MemberRun], states: &[String]) -> Option<ErrorSet> {
    let sets: Vec<Option<&ErrorSet>> = (runs.iter())
        .flat_map(|run| run.held_out.iter().map(|h| h.error.as_ref()))
        .collect();
    if runs.iter().any(|r| r.failed.is_some()) {
        return None;
    }
    mean_set(&sets, states)
}

/// Labelled sets by reference.
fn borrowed(runs: &[(String, Option<ErrorSet>)]) -> Vec<(String, Option<&ErrorSet>)> {
    runs.iter().map(|(l, s)| (l.clone(), s.as_ref())).collect()
}

type Runs<'a> = [(String, Option<&'a ErrorSet>)];

/// The scores of one experiment (or of all); `untrained` may be empty, and measures the
/// resolution where it `resolves` (its params are the mechanism's).
fn scored(
    experiment: &str,
    (grey, (mechanism, untrained, resolves), naive): (&Runs, (&Runs, &Runs, bool), &Runs),
    states: &[String],
) -> ExperimentScore {
    let grey_box = Score::of(grey, states);
    let mechanism = Score::of(mechanism, states);
    let untrained = (!untrained.is_empty())
        .then(|| Score::of(untrained, states))
        .filter(|score| score.runs > 0);
    let naive = Score::of(naive, states);
    let resolution = untrained.as_ref().filter(|_| resolves);
    let verdict = Verdict::of(&grey_box, (&mechanism, resolution), &naive);
    ExperimentScore {
        experiment: experiment.to_string(),
        mechanism,
        untrained,
        grey_box,
        naive,
        verdict,
    }
}

/// The mean of error sets over experiments (per state over those that score it); `None`
/// when any experiment has none.
fn mean_set(sets: &[Option<&ErrorSet>], states: &[String]) -> Option<ErrorSet> {
    let sets: Vec<&ErrorSet> = sets.iter().copied().collect::<Option<_>>()?;
    let mean = |values: &[f64]| values.iter().sum::<f64>() / values.len() as f64;
    let overall: Vec<f64> = sets.iter().map(|s| s.overall).collect();
    let per_state = (states.iter())
        .filter_map(|name| {
            let values: Vec<f64> = (sets.iter())
                .filter_map(|s| s.per_state.iter().find(|(n, _)| n == name))
                .map(|(_, v)| *v)
                .collect();
            (!values.is_empty()).then(|| (name.clone(), mean(&values)))
        })
        .collect();
    Some(ErrorSet {
        per_state,
        overall: (!overall.is_empty()).then(|| mean(&overall))?,
        rows: sets.iter().map(|s| s.rows).sum(),
        cells: sets.iter().map(|s| s.cells).sum(),
        divergence: sets.iter().find_map(|s| s.divergence.clone()),
    })
}
