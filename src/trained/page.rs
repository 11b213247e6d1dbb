//! The run report (`RUN/report.html`): what a person checks after training — the loss
//! curve, each state measured against its one-step prediction and its free run with the
//! training/validation split marked, the learned closure outputs over time, the params with
//! their standard errors, and per experiment and state MATLAB's fit percentage beside the
//! paper's normalised MSE.

use std::fmt::Write;

use super::predict::{predict_in_range, Mode, PredictionTable};
use crate::ir;
use crate::plot::{escape, figure, page, thin, tick_label, Chart, Series, Style, PALETTE};
use crate::record::measure::{cell_error, StateErrors};
use crate::record::Record;
use crate::train::{History, TrainReport, Trained};
use crate::train::{ParamEstimate, PhysicalRange};

/// Figure width in pixels.
const WIDTH: f64 = 640.0;
/// Figure height in pixels.
const HEIGHT: f64 = 330.0;
/// Experiments drawn per role (the tables cover every experiment).
const DRAWN: usize = 3;
/// Colour of measured cells.
const DATA: &str = crate::plot::DATA_COLOR;
/// Colour of one-step predictions.
const OFFLINE: &str = "#1f77b4";
/// Colour of free runs.
const ONLINE: &str = "#d62728";
/// Colour of the training/validation boundary.
const SPLIT: &str = crate::plot::SPLIT_COLOR;

/// One experiment with its role and both predictions.
struct Shown<'a> {
    record: &'a Record,
    role: &'static str,
    offline: Option<PredictionTable>,
    online: Option<PredictionTable>,
}

/// The report page of a trained run: `train` and `validation` are the experiments it
/// trained and validated on, `history` where their free runs start, `horizons` each
/// epoch's rollout length (1: one-step; empty: unknown).
pub fn run_page(
    model: &ir::Model,
    trained: &Trained,
    (train, validation): (&[Record], &[Record]),
    (history, horizons): (History, &[usize]),
    title: &str,
) -> String {
    let shown = shown_experiments(model, trained, (train, validation), history);
    let report = &trained.report;
    let sections = vec![
        training_section(report, horizons, title),
        fit_section(model, trained, &shown),
        params_section(report),
        states_section(model, trained, &shown, title),
        closures_section(model, &shown, title),
    ];
    page(
        &format!("{title}: training report"),
        &format!(
            "<p>Model <code>{}</code>. Every figure is drawn from the saved run: rerun \
             <code>gbc predict</code> for the tables behind them.</p>",
            escape(&model.name)
        ),
        &sections,
    )
}

/// Every experiment, training ones first, with its role and both predictions along it.
fn shown_experiments<'a>(
    model: &ir::Model,
    trained: &Trained,
    (train, validation): (&'a [Record], &'a [Record]),
    history: History,
) -> Vec<Shown<'a>> {
    // The run's own physical range: a free run the training's validation called diverged
    // is drawn and scored as diverged here too.
    let range = PhysicalRange::new(
        &trained.setup.normalisation,
        trained.report.recipe.range_factor,
    );
    let predicted = |record, mode| {
        predict_in_range(
            model,
            &trained.network,
            &trained.setup,
            record,
            (mode, history, range.as_ref()),
        )
        .ok()
    };
    (train.iter().map(|r| (r, "training")))
        .chain(validation.iter().map(|r| (r, "validation")))
        .map(|(record, role)| Shown {
            record,
            role,
            offline: predicted(record, Mode::Offline),
            online: predicted(record, Mode::Online),
        })
        .collect()
}

/// The training section: pairs, epochs and recipe, how errors are measured, and the loss
/// curve (or why there is none).
fn training_section(report: &TrainReport, horizons: &[usize], title: &str) -> String {
    let losses = if report.losses.is_empty() {
        match &report.mechanism_fit {
            Some(fit) => format!(
                "<p>No epoch ran: the params were fitted by free runs to every measured \
                 training cell, as <code>gbc diagnose</code> fits them ({} starts, training \
                 gap {}).</p>",
                fit.starts,
                tick_label(fit.gap_train)
            ),
            None => "<p>No epoch ran.</p>".to_string(),
        }
    } else {
        figure(
            &loss_chart(report.losses.as_slice(), horizons, title),
            if horizons.iter().any(|&h| h > 1) {
                "Mean training loss per epoch. Rollout epochs score free runs over windows \
                 that grow along the curriculum, so their loss is not comparable with the \
                 one-step epochs' and rises as the windows lengthen."
            } else {
                "Mean training loss per epoch."
            },
        )
    };
    format!(
        "<h2>Training</h2>\n<p>{} pairs, {} epochs ({} recipe), learning rate {}, grid step up to \
         {}. Errors are over measured cells only; NMSE is the paper's (squared error over the \
         training data's variance), fit is MATLAB's <code>100 (1 - |y - ŷ| / |y - mean y|)</code> \
         (100 %: exact; 0 %: no better than the mean).</p>\n{losses}",
        report.train_pairs,
        report.losses.len(),
        report.recipe.objective.name(),
        tick_label(report.learning_rate),
        tick_label(report.dt),
    )
}

/// The mean training loss per epoch (log scale), one series per phase: one-step epochs and
/// rollout epochs have losses of different kinds.
fn loss_chart(losses: &[f64], horizons: &[usize], title: &str) -> String {
    let point = |(epoch, loss): (usize, &f64)| ((epoch + 1) as f64, *loss);
    let rollout = |epoch: usize| horizons.get(epoch).is_some_and(|h| *h > 1);
    let one_step: Vec<(f64, f64)> = (losses.iter().enumerate())
        .filter(|(epoch, _)| !rollout(*epoch))
        .map(point)
        .collect();
    let multi_step: Vec<(f64, f64)> = (losses.iter().enumerate())
        .filter(|(epoch, _)| rollout(*epoch))
        .map(point)
        .collect();
    let mut chart = Chart::new(
        &format!("{title}: training loss"),
        "epoch",
        "mean loss (z-scored)",
    )
    .log_axes(false, true);
    if !one_step.is_empty() {
        chart = chart.with(Series::line("one-step epochs", one_step).colored(OFFLINE));
    }
    if !multi_step.is_empty() {
        let series = Series::line("rollout epochs", multi_step).styled(Style::Dashed);
        chart = chart.with(series.colored(ONLINE));
    }
    chart.to_svg(WIDTH, HEIGHT)
}

/// Per experiment and state: fit % and NMSE of the one-step prediction and the free run.
fn fit_section(model: &ir::Model, trained: &Trained, shown: &[Shown]) -> String {
    let mut html = String::from(
        "<h2>Fit per state</h2>\n<table><tr><th>experiment</th><th>role</th><th>state</th>\
         <th>cells</th><th>one-step fit %</th><th>free-run fit %</th><th>one-step NMSE</th>\
         <th>free-run NMSE</th></tr>\n",
    );
    let std = &trained.setup.normalisation.state_std;
    let parts = shown.iter().flat_map(|entry| {
        let split = (trained.report.validated_from.iter())
            .find(|(name, _)| name == &entry.record.name)
            .map(|(_, time)| *time);
        match split {
            Some(time) => vec![
                (entry, "training", f64::NEG_INFINITY..time),
                (entry, "validated part", time..f64::INFINITY),
            ],
            None => vec![(entry, entry.role, f64::NEG_INFINITY..f64::INFINITY)],
        }
    });
    for (entry, role, times) in parts {
        for (index, state) in model.states.iter().enumerate() {
            let within = |table: &PredictionTable| {
                let mut pairs = paired(entry.record, table, index);
                pairs.retain(|(time, ..)| times.contains(time));
                pairs
                    .into_iter()
                    .map(|(_, y, p)| (y, p))
                    .collect::<Vec<_>>()
            };
            let offline = entry.offline.as_ref().map(within);
            let online = entry.online.as_ref().map(within);
            let cells = online.as_ref().or(offline.as_ref()).map_or(0, Vec::len);
            if cells == 0 {
                continue;
            }
            let scale = std.get(index).copied().unwrap_or(1.0);
            // A run that stopped before a cell it is scored on diverged there: that cell is
            // not dropped (which would score the rest as if the run had been fine).
            let cell = |pairs: &Option<Vec<(f64, f64)>>, what: fn(&[(f64, f64)], f64) -> f64| {
                pairs
                    .as_deref()
                    .map_or("–".to_string(), |p| scored(p, what, scale))
            };
            let _ = writeln!(
                html,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td>{cells}</td><td>{}</td><td>{}</td>\
                 <td>{}</td><td>{}</td></tr>",
                escape(&entry.record.name),
                role,
                escape(&state.name),
                cell(&offline, |p, _| fit_percent(p)),
                cell(&online, |p, _| fit_percent(p)),
                cell(&offline, nmse),
                cell(&online, nmse),
            );
        }
    }
    html.push_str("</table>\n");
    html
}

/// A score of `(measured, predicted)` cells as the table shows it: "diverged" where a
/// prediction is not finite (a free run that stopped before that cell), else the score.
fn scored(pairs: &[(f64, f64)], score: fn(&[(f64, f64)], f64) -> f64, scale: f64) -> String {
    if pairs.iter().any(|(_, predicted)| !predicted.is_finite()) {
        "diverged".to_string()
    } else {
        tick_label(score(pairs, scale))
    }
}

/// `(time, measured, predicted)` at the measured cells of state `index`; a cell the
/// prediction did not reach finitely (a free run that diverged before it) keeps its
/// non-finite prediction, so that the scores call the run diverged.
fn paired(record: &Record, table: &PredictionTable, index: usize) -> Vec<(f64, f64, f64)> {
    let Some(column) = table.columns.get(index + 1) else {
        return Vec::new();
    };
    let mut pairs = Vec::new();
    for (time, predicted) in table.columns[0].iter().zip(column) {
        let Ok(row) = record.times.binary_search_by(|t| t.total_cmp(time)) else {
            continue;
        };
        if let Some(measured) = record.states[index][row] {
            pairs.push((*time, measured, *predicted));
        }
    }
    pairs
}

/// MATLAB's fit: `100 (1 - |y - ŷ| / |y - mean y|)` (Euclidean norms).
pub fn fit_percent(pairs: &[(f64, f64)]) -> f64 {
    let mean = pairs.iter().map(|p| p.0).sum::<f64>() / pairs.len().max(1) as f64;
    let error: f64 = pairs
        .iter()
        .map(|(y, p)| (y - p).powi(2))
        .sum::<f64>()
        .sqrt();
    let spread: f64 = pairs
        .iter()
        .map(|(y, _)| (y - mean).powi(2))
        .sum::<f64>()
        .sqrt();
    if spread > 0.0 {
        100.0 * (1.0 - error / spread)
    } else {
        f64::NAN
    }
}

/// The paper's normalised MSE of one state ([`crate::record::measure`]): the mean cell error
/// with `scale` the training std.
pub fn nmse(pairs: &[(f64, f64)], scale: f64) -> f64 {
    let mut errors = StateErrors::new(1);
    for &(measured, predicted) in pairs {
        errors.add(0, cell_error(predicted, measured, scale));
    }
    errors.nmse()[0].unwrap_or(0.0)
}

/// Params with standard errors and identifiability.
fn params_section(report: &TrainReport) -> String {
    if report.params.is_empty() {
        return String::new();
    }
    let mut html = String::from(
        "<h2>Params</h2>\n<table><tr><th>param</th><th>value</th><th>standard error</th>\
         <th>relative</th><th>identified</th></tr>\n",
    );
    for (name, value) in &report.params {
        let estimate = report.estimates.iter().find(|e| &e.name == name);
        let (se, relative, flag) = param_cells(estimate);
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{se}</td><td>{relative}</td><td>{flag}</td></tr>",
            escape(name),
            tick_label(*value)
        );
    }
    html.push_str("</table>\n");
    html
}

/// A param's standard error, relative error and flag as the params table shows them.
fn param_cells(estimate: Option<&ParamEstimate>) -> (String, String, &'static str) {
    match estimate {
        Some(e) if e.held => ("–".into(), "–".into(), "no (held at its declared value)"),
        Some(ParamEstimate {
            std_error: Some(se),
            relative_error: Some(relative),
            identified,
            ..
        }) if se.is_finite() => (
            tick_label(*se),
            format!("{:.1} %", 100.0 * relative),
            if *identified { "yes" } else { "poorly" },
        ),
        Some(_) => ("∞".into(), "–".into(), "no (the data leave it free)"),
        None => ("–".into(), "–".into(), "not estimated"),
    }
}

/// Measured cells against the one-step prediction and the free run, per state, for the
/// first experiments of each role; the validated part of a training experiment is marked.
fn states_section(model: &ir::Model, trained: &Trained, shown: &[Shown], title: &str) -> String {
    let mut html = String::from(
        "<h2>Measured and predicted</h2>\n<p>Dots: measured cells. Solid: one step from the \
         measured history. Dashed: free run from the experiment's start, driven by its inputs \
         alone. A grey vertical line marks where a training experiment's validated part \
         starts; a dashed red one where a free run diverged (left the run's physical \
         range, said below the figure).</p>\n",
    );
    for entry in drawn(shown) {
        let split = (trained.report.validated_from.iter())
            .find(|(name, _)| name == &entry.record.name)
            .map(|(_, time)| *time);
        for (index, state) in model.states.iter().enumerate() {
            let cells: Vec<(f64, f64)> = (entry.record.times.iter())
                .zip(&entry.record.states[index])
                .filter_map(|(t, cell)| cell.map(|v| (*t, v)))
                .collect();
            if cells.is_empty() {
                continue;
            }
            let (lo, hi) = span(cells.iter().map(|c| c.1));
            let mut chart = Chart::new(
                &format!(
                    "{title}: {} ({}) — {}",
                    entry.record.name, entry.role, state.name
                ),
                &model.time_label(),
                &model.axis_label(&state.name),
            )
            .with(
                Series::line("measured", thin(cells, MARKERS))
                    .styled(Style::Markers)
                    .colored(DATA),
            );
            for (table, name, color, style) in [
                (&entry.offline, "one step", OFFLINE, Style::Line),
                (&entry.online, "free run", ONLINE, Style::Dashed),
            ] {
                if let Some(points) = table
                    .as_ref()
                    .map(|t| column_points(t, index + 1, (lo, hi)))
                {
                    chart = chart.with(Series::line(name, points).styled(style).colored(color));
                }
            }
            if let Some(time) = split {
                chart = chart.with_mark("validated from", time, Style::Line, SPLIT);
            }
            let diverged = entry.online.as_ref().and_then(|t| t.divergence.as_ref());
            if let Some(divergence) = diverged {
                chart =
                    chart.with_mark("free run diverged", divergence.time, Style::Dashed, ONLINE);
            }
            let caption = diverged.map_or(String::new(), |d| d.to_string());
            html.push_str(&figure(&chart.to_svg(WIDTH, HEIGHT), &caption));
        }
    }
    html
}

/// The learned closure outputs along each drawn experiment's free run.
fn closures_section(model: &ir::Model, shown: &[Shown], title: &str) -> String {
    let outputs: Vec<&str> = (model.closures.iter())
        .flat_map(|c| c.outputs.iter().map(|o| o.name.as_str()))
        .collect();
    if outputs.is_empty() {
        return String::new();
    }
    let mut html = String::from(
        "<h2>Learned closures</h2>\n<p>Each closure output along the free run of each drawn \
         experiment.</p>\n",
    );
    for output in outputs {
        let mut chart = Chart::new(
            &format!("{title}: closure output {output}"),
            &model.time_label(),
            &model.axis_label(output),
        );
        for (index, entry) in drawn(shown).enumerate() {
            let Some(table) = &entry.online else {
                continue;
            };
            let Some(column) = table.header.iter().position(|h| h == output) else {
                continue;
            };
            let points = column_points(table, column, (f64::NEG_INFINITY, f64::INFINITY));
            let name = format!("{} ({})", entry.record.name, entry.role);
            let series = Series::line(&name, points).colored(PALETTE[index % PALETTE.len()]);
            chart = chart.with(series);
        }
        html.push_str(&figure(&chart.to_svg(WIDTH, HEIGHT), ""));
    }
    html
}

/// The first [`DRAWN`] experiments of each role.
fn drawn<'s, 'a>(shown: &'s [Shown<'a>]) -> impl Iterator<Item = &'s Shown<'a>> {
    let training = shown.iter().filter(|s| s.role == "training").take(DRAWN);
    let validation = shown.iter().filter(|s| s.role == "validation").take(DRAWN);
    training.chain(validation)
}

/// Finite values of column `column` against time, clamped to `(lo, hi)` widened by half
/// their span (so that a runaway free run does not flatten the data).
fn column_points(table: &PredictionTable, column: usize, (lo, hi): (f64, f64)) -> Vec<(f64, f64)> {
    let pad = if hi > lo {
        0.5 * (hi - lo)
    } else {
        f64::INFINITY
    };
    (table.columns[0].iter().zip(&table.columns[column]))
        .filter(|(_, v)| v.is_finite())
        .map(|(t, v)| (*t, v.clamp(lo - pad, hi + pad)))
        .collect()
}

/// Most measured cells drawn as dots per figure (dots denser than that hide the lines).
const MARKERS: usize = 300;

/// The smallest and largest of `values`.
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_is_100_for_an_exact_prediction_and_0_for_the_mean() {
        let exact = [(1.0, 1.0), (2.0, 2.0), (4.0, 4.0)];
        assert_eq!(fit_percent(&exact), 100.0);
        let mean = 7.0 / 3.0;
        let flat = [(1.0, mean), (2.0, mean), (4.0, mean)];
        assert!(fit_percent(&flat).abs() < 1e-12);
        // Half the error of the mean everywhere: 50 %.
        let half = [
            (1.0, (1.0 + mean) / 2.0),
            (2.0, (2.0 + mean) / 2.0),
            (4.0, (4.0 + mean) / 2.0),
        ];
        assert!((fit_percent(&half) - 50.0).abs() < 1e-12);
        assert!(fit_percent(&[(3.0, 1.0), (3.0, 2.0)]).is_nan());
    }

    /// Issue 43: a held param shows no standard error and is not called identified.
    #[test]
    fn a_held_param_has_no_standard_error_in_the_params_table() {
        let held = ParamEstimate::held_at("K".into(), 2.0);
        let cells = param_cells(Some(&held));
        assert_eq!(
            cells,
            ("–".into(), "–".into(), "no (held at its declared value)")
        );
        let fitted = ParamEstimate::fitted("k".into(), 0.5, 0.005);
        let (se, relative, flag) = param_cells(Some(&fitted));
        assert_eq!((relative.as_str(), flag), ("1.0 %", "yes"), "{se}");
    }

    #[test]
    fn a_diverged_cell_scores_the_run_diverged_not_zero() {
        let fine = [(1.0, 1.5), (2.0, 2.0)];
        assert_eq!(scored(&fine, nmse, 1.0), tick_label(nmse(&fine, 1.0)));
        // Every finite cell exact, the last one past the divergence: before the page kept
        // only finite cells, this run scored NMSE 0 and fit 100 %.
        let stopped = [(1.0, 1.0), (2.0, 2.0), (3.0, f64::NAN)];
        assert_eq!(scored(&stopped, nmse, 1.0), "diverged");
        assert_eq!(scored(&stopped, |p, _| fit_percent(p), 1.0), "diverged");
    }

    #[test]
    fn nmse_divides_by_the_training_variance() {
        let pairs = [(1.0, 3.0), (2.0, 2.0)];
        assert!((nmse(&pairs, 2.0) - 0.5).abs() < 1e-15);
    }
}
