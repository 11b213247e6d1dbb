//! The parts of the report that summarise the fitted model's runs: per-state errors and the
//! noise floor, the memory verdict, windows and regimes, series for plots, starts and the
//! split.

use super::context::{Context, SIGNIFICANCE};
use super::effects::{Ranking, Scored};
use super::evaluate::{offline_errors, regimes, windows, Variable};
use super::locus::{Located, HISTORY_MARGIN, PRESENT_RESIDUAL};
use super::render::num;
use super::report::*;
use super::selection::Levels;
use crate::record::measure;
use crate::solve::fit::simulate::Simulator;
use crate::solve::fit::split::{measured_rows, Holdout, Start};
use crate::solve::fit::{noise, predictive};

/// Per measured state, its noise: estimated from the data ([`noise::noise_floors`]), at
/// most the training residual of the model's fit and of the best effect's (by BIC).
pub fn noise_estimates(
    context: &Context,
    before: &Scored,
    ranking: &Ranking,
) -> Vec<noise::NoiseEstimate> {
    let mut estimates = noise::noise_floors(&context.split);
    let best = (ranking.fits.iter()).min_by(|a, b| a.summary.bic.total_cmp(&b.summary.bic));
    for fit in std::iter::once(before).chain(best) {
        noise::cap_by_fit(&mut estimates, &fit.training_squares, fit.fitted.x.len());
    }
    estimates
}

/// What a correct model's held-out runs add to the noise floor: the spread of the model's
/// fit `before` (its params' covariance and the noise of the measured starts, each state's
/// as `states` give it) at the scored cells ([`predictive::held_out_spread`]). Params the
/// fit held or could not identify stay at their values: a direction the training data
/// leave free has no spread to draw from (its linearised variance is unbounded), and a
/// param driven there is a symptom of a misfit, not of a correct model's noise.
pub fn held_out_spread(
    context: &Context,
    base: &Simulator,
    before: &Scored,
    states: &[StateGap],
) -> Option<f64> {
    let split = &context.split;
    let unknowns = context.unknowns(context.model, base);
    let x = &before.fitted.x;
    let held = |name: &String| {
        (before.summary.estimates.iter())
            .find(|e| &e.name == name)
            .is_some_and(|e| e.held || !e.identified)
    };
    let fixed: Vec<bool> = unknowns.names.iter().map(held).collect();
    let noise: Vec<f64> = states.iter().map(|s| s.noise).collect();
    let seed = context.seed(7000);
    predictive::held_out_spread((split, base), (&unknowns, x, &fixed), (&noise, seed))
}

/// The names of the measured columns: the measured states, then the observables (the
/// model outputs the data measure, [`crate::record::Record::columns`]).
pub fn column_names(context: &Context) -> Vec<String> {
    let model = context.model;
    let observables = context.split.normalisation.observables.iter();
    (model.states.iter().map(|s| s.name.clone()))
        .chain(observables.map(|&o| model.outputs[o].name.clone()))
        .collect()
}

/// Per measured column (state, then observable): its share of the held-out error, online
/// and offline errors, noise.
pub fn state_gaps(
    context: &Context,
    base: &Simulator,
    before: &Scored,
    noise: &[noise::NoiseEstimate],
) -> Vec<StateGap> {
    let model = context.model;
    let split = &context.split;
    let names = column_names(context);
    let online = before.errors.per_state(names.len());
    let mut simulator = base.clone();
    simulator.set_params(&before.fitted.x);
    let fitted = &before.fitted.x[model.params.len()..];
    let offline = offline_errors(&mut simulator, split, fitted);
    let cells: Vec<usize> = (0..names.len())
        .map(|k| {
            (split.scored())
                .map(|(_, record, rows)| record.column(k)[rows].iter().flatten().count())
                .sum()
        })
        .collect();
    let squares: Vec<f64> = (0..names.len())
        .map(|k| online[k].map_or(0.0, |e| e * cells[k] as f64))
        .collect();
    let total: f64 = squares.iter().sum();
    (names.into_iter().enumerate())
        .map(|(k, name)| StateGap {
            name,
            share: if total > 0.0 && total.is_finite() {
                squares[k] / total
            } else {
                0.0
            },
            online: online[k],
            offline: offline[k],
            noise: noise[k].variance,
            noise_estimate: if measured_anywhere(split, k) {
                noise[k].describe()
            } else {
                "not measured (no cell in any experiment)".into()
            },
            cells: cells[k],
        })
        .collect()
}

/// Whether column `k` (a measured state or an observable) has a cell in some experiment: a
/// state the data never give (read only through outputs, or not at all) has no noise to
/// estimate.
fn measured_anywhere(split: &crate::solve::fit::split::Split, k: usize) -> bool {
    (split.records.iter()).any(|record| record.column(k).iter().any(Option::is_some))
}

/// The error of the held-out free runs: the mean over states of each one's NMSE
/// ([`measure`], the measure `gbc train` and `gbc predict` report). Infinite when a free run
/// diverged.
pub fn mean_over_states(states: &[StateGap]) -> f64 {
    measure::mean_over_states(states.iter().filter_map(|s| s.online))
}

/// The noise floor: the states' normalised noise variances weighted by their scored cells
/// (the gap a perfect model would show).
pub fn noise_floor(states: &[StateGap]) -> f64 {
    let cells: usize = states.iter().map(|s| s.cells).sum();
    let weighted: f64 = states.iter().map(|s| s.noise * s.cells as f64).sum();
    weighted / cells.max(1) as f64
}

/// The memory verdict: the free corrections' (history beats the present at the first locus
/// by the margin) or the credited effects' (they add hidden states and close the gap where
/// no present-only correction does), with the reasons in words.
pub fn memory(
    located: &Located,
    ranking: &Ranking,
    selection: &Selection,
    (levels, taus): (Levels, &[f64]),
) -> Memory {
    let span = taus.last().copied().unwrap_or(0.0);
    let mut memory = Memory {
        history_needed: false,
        probe: false,
        span,
        time_constants: taus.to_vec(),
        reason: String::new(),
    };
    let significant = levels.gap_before > SIGNIFICANCE * levels.held_out_floor;
    let Some(first) = located.loci.first().filter(|_| significant) else {
        memory.reason = if significant {
            "not probed: the free corrections were not tried".into()
        } else {
            "no significant gap".into()
        };
        return memory;
    };
    let excess = |gap: f64| (gap - levels.noise_floor).max(0.0);
    let probe = located.history_dependent;
    let best_present = (located.loci.iter())
        .min_by(|a, b| a.bound_present.total_cmp(&b.bound_present))
        .map(|l| (l.name.clone(), l.bound_present));
    let hidden: Vec<String> = (selection.credited.iter())
        .filter_map(|name| ranking.scores.iter().find(|s| &s.name == name))
        .flat_map(|s| s.adds_hidden.clone())
        .collect();
    let effect_memory = match (&best_present, hidden.is_empty()) {
        (Some((_, present)), false) => {
            excess(*present) > PRESENT_RESIDUAL * excess(levels.gap_before)
                && excess(*present) > HISTORY_MARGIN * excess(selection.gap_after)
        }
        _ => false,
    };
    let probe_text = format!(
        "at {} the free correction with history leaves {}, the present alone {}",
        first.name,
        num(first.bound_history),
        num(first.bound_present)
    );
    let credited = selection.credited.join(" + ");
    memory.reason = match (probe, effect_memory) {
        (true, true) => format!(
            "{probe_text}; the credited {credited} adds hidden states ({}) and leaves {}",
            hidden.join(", "),
            num(selection.gap_after)
        ),
        (true, false) if !selection.credited.is_empty() => format!(
            "{probe_text}, but the credited {credited} adds no hidden state: its params may be \
             standing in for a lag"
        ),
        (true, false) => probe_text,
        (false, true) => {
            let (name, present) = best_present.clone().unwrap_or_default();
            format!(
                "the credited {credited} adds hidden states ({}) and leaves {}, which no \
                 instantaneous correction reaches (the best present-only one, at {name}, \
                 leaves {}); {probe_text}",
                hidden.join(", "),
                num(selection.gap_after),
                num(present)
            )
        }
        (false, false) => format!("{probe_text}: an instantaneous term suffices"),
    };
    memory.probe = probe;
    memory.history_needed = probe || effect_memory;
    memory
}

/// The time windows of the held-out parts holding half the error (largest first) and the
/// regimes where it concentrates, for the fitted model's free runs.
pub fn where_and_when(context: &Context, before: &Scored) -> (Vec<Window>, Vec<Regime>) {
    let split = &context.split;
    let errors = &before.errors;
    if errors.diverged {
        return (Vec::new(), Vec::new());
    }
    let total: f64 = (errors.records.iter())
        .flat_map(|r| r.row_totals())
        .map(|(sum, _)| sum)
        .sum();
    let scored: Vec<_> = split.scored().collect();
    let duration = |(_, record, rows): &(usize, &crate::record::Record, std::ops::Range<usize>)| {
        record.times[rows.end - 1] - record.times[rows.start]
    };
    let all: f64 = scored.iter().map(duration).sum();
    let mut found = Vec::new();
    for (part, record_errors) in scored.iter().zip(&errors.records) {
        let share = if all > 0.0 { duration(part) / all } else { 1.0 };
        let count = ((context.options.windows as f64 * share).round() as usize).max(2);
        found.extend(windows(part.1, record_errors, count, total));
    }
    found.sort_by(|a, b| b.share.total_cmp(&a.share));
    let mut covered = 0.0;
    found.retain(|w| {
        let keep = covered < 0.5;
        covered += w.share;
        keep
    });
    (found, regimes(&variables(context, before)))
}

/// The inputs and measured states at the scored rows, each with the error of its rows.
fn variables(context: &Context, before: &Scored) -> Vec<Variable> {
    let model = context.model;
    let mut variables: Vec<Variable> = (model.inputs.iter().map(|i| i.name.clone()))
        .chain(column_names(context))
        .map(|name| (name, Vec::new(), Vec::new()))
        .collect();
    for ((_, record, rows), errors) in context.split.scored().zip(&before.errors.records) {
        let totals = errors.row_totals();
        for row in rows.clone() {
            let (error, cells) = totals[row - rows.start];
            if cells == 0 {
                continue;
            }
            for (i, column) in record.inputs.iter().enumerate() {
                variables[i].1.push(column[row]);
                variables[i].2.push(error);
            }
            for (k, cells) in record.columns().enumerate() {
                if let Some(value) = cells[row] {
                    let variable = &mut variables[model.inputs.len() + k];
                    variable.1.push(value);
                    variable.2.push(error);
                }
            }
        }
    }
    variables
}

/// The scored experiments' data and runs, for plots.
pub fn series(
    context: &Context,
    before: &Scored,
    after: Option<(&Scored, String)>,
) -> Vec<ExperimentSeries> {
    let model = context.model;
    let names = column_names(context);
    let columns = |run: &crate::solve::fit::simulate::Run, end: usize| -> Vec<Vec<f64>> {
        (0..names.len())
            .map(|k| (0..end).map(|row| run.column(row, k)).collect())
            .collect()
    };
    let unit = |name: &str| model.unit(name).map(|u| u.text.clone());
    (context.split.scored().enumerate())
        .map(|(slot, (_, record, rows))| {
            let errors = &before.errors.records[slot];
            ExperimentSeries {
                name: record.name.clone(),
                times: record.times[..rows.end].to_vec(),
                first_scored: rows.start,
                names: names.clone(),
                units: names.iter().map(|name| unit(name)).collect(),
                time_unit: model.time_unit.clone(),
                data: (record.columns())
                    .map(|cells| cells[..rows.end].to_vec())
                    .collect(),
                before: (before.runs[slot].as_ref())
                    .map(|run| columns(run, rows.end))
                    .unwrap_or_default(),
                after: after.as_ref().and_then(|(scored, _)| {
                    scored.runs[slot].as_ref().map(|run| columns(run, rows.end))
                }),
                after_name: after.as_ref().map_or(String::new(), |(_, n)| n.clone()),
                errors: (errors.row_totals().into_iter())
                    .map(|(sum, cells)| (cells > 0).then_some(sum))
                    .collect(),
            }
        })
        .collect()
}

/// The measured states' starts that no cell gives, with their values under the fitted
/// params `x`.
pub fn initial_states(context: &Context, base: &Simulator, x: &[f64]) -> Vec<InitialState> {
    let split = &context.split;
    let mut simulator = base.clone();
    simulator.set_params(x);
    let fitted = &x[context.model.params.len().min(x.len())..];
    let mut found = Vec::new();
    for (index, record) in split.records.iter().enumerate() {
        let overrides = split.overrides(index, fitted, simulator.hidden_count());
        let start = simulator.start_state(record, &overrides);
        let observed = simulator.observed_start_states(record, &overrides);
        for (k, &how) in split.starts[index].iter().enumerate() {
            if !matches!(how, Start::Cell | Start::CellFitted(_)) {
                found.push(InitialState {
                    experiment: record.name.clone(),
                    state: context.model.states[k].name.clone(),
                    value: start[k],
                    origin: match observed.contains(&k) {
                        true => "from the first row's observables".into(),
                        false => origin(how).into(),
                    },
                });
            }
        }
        let measured = context.model.states.len();
        for (h, state) in context.model.hidden.iter().enumerate() {
            if overrides[measured + h].is_some() {
                found.push(InitialState {
                    experiment: record.name.clone(),
                    state: state.name.clone(),
                    value: start[measured + h],
                    origin: "fitted".into(),
                });
            }
        }
    }
    found
}

/// Sizes of the split.
pub fn split_summary(context: &Context) -> SplitSummary {
    let split = &context.split;
    let (train_rows, test_rows) = split.measured_rows();
    SplitSummary {
        train_rows,
        test_rows,
        train_experiments: split.training().map(|(_, r, _)| r.name.clone()).collect(),
        scored: (split.scored())
            .map(|(_, record, rows)| ScoredPart {
                experiment: record.name.clone(),
                t_start: record.times[rows.start],
                t_end: record.times[rows.end - 1],
                rows: measured_rows(record, rows.clone()).count(),
            })
            .collect(),
        holdout: match split.holdout {
            Holdout::Tail(_) => "tail".into(),
            Holdout::Experiments => "experiments".into(),
        },
        share: match split.holdout {
            Holdout::Tail(share) => Some(share),
            Holdout::Experiments => None,
        },
        min_rows: context.options.min_rows,
    }
}

/// Where a measured state's run starts, in words.
fn origin(start: Start) -> &'static str {
    match start {
        Start::Cell => "measured",
        Start::Declared => "declared",
        Start::Fitted(_) => "fitted",
        Start::CellFitted(_) => "measured, fitted from its cell",
        Start::Fixed(_) => "first measured value",
    }
}
