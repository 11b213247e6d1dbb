//! The paper's figures as SVG, from a study's results and the weights of its
//! representative runs:
//!
//! | file | paper | what |
//! |---|---|---|
//! | `data_<state>.svg`, `data_inputs.svg` | 2a, 3a | the record: measured states and inputs, the start of validation marked ([`super::data_figure`]) |
//! | `mse_offline.svg`, `mse_online.svg` | 2b, 3b | validation MSE against training points (log-log), median line and min–max band over replicates |
//! | `trajectory_<state>.svg` | 2c, 3c | free runs over the validation window against the data |
//! | `closure_<output>.svg` | 2c (lower), 3d | learned closure outputs (one step from the true history) against the truth's rates |
//! | `params.svg` | 3e | trained params (median over replicates) against the truth's values |
//! | `generalisation_<record>_<state>.svg` | 2d | free runs under a record never trained on |

use std::path::{Path, PathBuf};

use super::black_box::is_black_box;
use super::data_figure::data_figures;
use super::figure::{axis_titles, color, Figure, TrainedModel, HEIGHT, WIDTH};
use super::held_out::held_out_figures;
use super::prepare::{LoadedModel, Prepared};
use super::reference::{first_predicted_row, free_run, true_params, truth_along, TruthRun};
use super::results::{runs_of, summarise, RunResult, Spread};
use crate::data::Dataset;
use crate::engine::graph::{Network, Setup};
use crate::plot::{
    clip, thin, widened_range, BarChart, Chart, Series, Style, DATA_COLOR, MAX_POINTS,
};
use crate::train::History;
use crate::trained::artifacts;
use crate::trained::predict::{predict, Mode, PredictionTable};

/// Errors above this are drawn at it in the MSE figures (an MSE of 1 is the error of
/// predicting the mean; 100 is a free run ten standard deviations off).
pub const MSE_CEILING: f64 = 100.0;
/// Largest deviation (in standard deviations) of the truth from the data before the
/// closure figures carry a warning.
pub const TRUTH_TOLERANCE: f64 = 0.05;

/// Where a run's weights are, if anywhere.
pub type WeightsLookup<'a> = &'a dyn Fn(&str) -> Option<PathBuf>;

/// Draws every figure the results allow; `notes` say what was left out and why.
pub fn draw(
    prepared: &Prepared,
    results: &[RunResult],
    weights: WeightsLookup,
) -> (Vec<Figure>, Vec<String>) {
    let mut figures = data_figures(prepared);
    figures.push(mse_figure(prepared, results, Metric::Offline));
    figures.push(mse_figure(prepared, results, Metric::Online));
    let mut notes = Vec::new();
    let size = prepared.study.figure_size();
    let mut trained = Vec::new();
    for (index, loaded) in prepared.models.iter().enumerate() {
        match restore_representative(loaded, results, size, weights) {
            Ok((network, setup, id)) => trained.push((index, network, setup, id)),
            Err(note) => notes.push(note),
        }
    }
    if prepared.study.on_data_set() {
        figures.extend(held_out_figures(prepared, &trained, size));
        notes.push(
            "the closure figures need one uniform record along which the truth runs: left out \
             on a data set"
                .into(),
        );
    } else {
        figures.extend(trajectory_figures(prepared, &trained, size, &mut notes));
        figures.extend(closure_figures(prepared, &trained, size, &mut notes));
    }
    figures.extend(params_figure(prepared, results, size));
    for data in &prepared.generalisation {
        figures.extend(generalisation_figures(
            prepared, &trained, data, size, &mut notes,
        ));
    }
    (figures, notes)
}

/// Writes figures as `dir/<name>.svg`.
pub fn write_figures(dir: &Path, figures: &[Figure]) -> Result<(), crate::io::IoError> {
    for figure in figures {
        let path = dir.join(format!("{}.svg", figure.name));
        crate::io::write_atomic(&path, figure.svg.as_bytes())?;
    }
    Ok(())
}

/// Offline or online error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Metric {
    /// One step from the true history.
    Offline,
    /// Free run.
    Online,
}

/// Validation MSE against training points, median and min–max band per model.
pub fn mse_figure(prepared: &Prepared, results: &[RunResult], metric: Metric) -> Figure {
    let rows = summarise(&prepared.study, results);
    let (word, paper) = match metric {
        Metric::Offline => ("offline", "one step from the true history"),
        Metric::Online => ("online", "free run over the validation window"),
    };
    let mut chart = Chart::new(
        &format!("{}: {word} validation MSE", prepared.study.name),
        "training points",
        "MSE (z-scored states)",
    )
    .log_axes(true, true);
    for (index, model) in prepared.study.models.iter().enumerate() {
        let cells: Vec<(usize, Spread)> = (rows.iter())
            .filter(|r| r.model == model.label)
            .filter_map(|r| {
                let spread = match metric {
                    Metric::Offline => r.offline,
                    Metric::Online => r.online,
                };
                spread.map(|s| (r.size, s))
            })
            .collect();
        let cap = |value: f64| value.min(MSE_CEILING);
        let points = cells
            .iter()
            .map(|(n, s)| (*n as f64, cap(s.median)))
            .collect();
        let band = cells
            .iter()
            .map(|(_, s)| (cap(s.min), cap(s.max)))
            .collect();
        let series = Series::line(&model.label, points)
            .styled(Style::LineMarkers)
            .with_band(band)
            .colored(color(index));
        chart = chart.with(series);
    }
    Figure {
        name: format!("mse_{word}"),
        caption: format!(
            "Validation MSE ({paper}) against training points: median over replicates, band \
             from min to max (paper Fig. 2b/3b). Values above {MSE_CEILING} (free runs that \
             blew up, or diverged) are drawn at {MSE_CEILING}."
        ),
        svg: chart.to_svg(WIDTH, HEIGHT),
    }
}

/// The ok run at `size` with the median online error (the lower middle for an even count).
pub fn representative<'a>(
    results: &'a [RunResult],
    label: &str,
    size: usize,
) -> Option<&'a RunResult> {
    let mut runs: Vec<&RunResult> = runs_of(results, label, size)
        .into_iter()
        .filter(|r| r.is_ok())
        .collect();
    runs.sort_by(|a, b| {
        let (x, y) = (
            a.online().unwrap_or(f64::INFINITY),
            b.online().unwrap_or(f64::INFINITY),
        );
        x.total_cmp(&y).then(a.replicate.cmp(&b.replicate))
    });
    runs.get(runs.len().saturating_sub(1) / 2).copied()
}

fn restore_representative(
    loaded: &LoadedModel,
    results: &[RunResult],
    size: usize,
    weights: WeightsLookup,
) -> Result<(Network, Setup, String), String> {
    let run = representative(results, &loaded.label, size).ok_or_else(|| {
        format!(
            "no finished run of `{}` at {size} points to plot",
            loaded.label
        )
    })?;
    let dir = weights(&run.id).ok_or_else(|| {
        format!(
            "the weights of run `{}` are missing: its trajectories are left out",
            run.id
        )
    })?;
    let (network, setup, _) = artifacts::restore(&loaded.model, &loaded.source, &dir)
        .map_err(|error| format!("cannot restore run `{}`: {error}", run.id))?;
    Ok((network, setup, run.id.clone()))
}

/// Predictions of every restored model along `data`, with the notes of those that failed.
fn predictions<'a>(
    prepared: &Prepared,
    trained: impl IntoIterator<Item = &'a TrainedModel>,
    data: &Dataset,
    mode: Mode,
    notes: &mut Vec<String>,
) -> Vec<(&'a TrainedModel, PredictionTable)> {
    let mut tables = Vec::new();
    for entry in trained {
        let (index, network, setup, id) = entry;
        let model = &prepared.models[*index].model;
        let table = match mode {
            Mode::Online | Mode::OnlineTrainedStep => free_run(model, network, setup, data),
            Mode::Offline => crate::train::record_of(model, data).and_then(|record| {
                predict(model, network, setup, &record, (mode, History::Measured))
            }),
        };
        match table {
            Ok(table) => tables.push((entry, table)),
            Err(error) => notes.push(format!("cannot predict with run `{id}`: {error}")),
        }
    }
    tables
}

/// A column of a prediction table by name.
fn column<'t>(table: &'t PredictionTable, name: &str) -> Option<&'t [f64]> {
    (table.header.iter().position(|h| h == name)).map(|i| table.columns[i].as_slice())
}

/// A state of the data against every model's free run, one chart per measured state.
fn state_charts(
    prepared: &Prepared,
    tables: &[(&TrainedModel, PredictionTable)],
    data: &Dataset,
    title: &str,
) -> Vec<(String, String)> {
    let mut states: Vec<&str> = Vec::new();
    for (entry, _) in tables {
        for state in &prepared.models[entry.0].model.states {
            if !states.contains(&state.name.as_str()) {
                states.push(&state.name);
            }
        }
    }
    let mut charts = Vec::new();
    for state in states {
        let Some(actual) = data.column(state) else {
            continue;
        };
        let first = tables
            .iter()
            .map(|(_, t)| first_predicted_row(data, t))
            .min()
            .unwrap_or(0);
        let truth: Vec<(f64, f64)> = (data.times[first..].iter().copied())
            .zip(actual[first..].iter().copied())
            .collect();
        let range = widened_range(&actual[first..]);
        let (time, axis) = axis_titles(prepared, state);
        let mut chart = Chart::new(&format!("{title}: {state}"), &time, &axis)
            .with(Series::line("data", thin(truth, MAX_POINTS)).colored(DATA_COLOR));
        for ((index, ..), table) in tables {
            let Some(values) = column(table, state) else {
                continue;
            };
            let points = table.columns[0].iter().copied().zip(values.iter().copied());
            let (label, points) = clip(&prepared.models[*index].label, points, range);
            chart = chart.with(
                Series::line(&label, points)
                    .styled(Style::Dashed)
                    .colored(color(*index)),
            );
        }
        charts.push((state.to_string(), chart.to_svg(WIDTH, HEIGHT)));
    }
    charts
}

fn trajectory_figures(
    prepared: &Prepared,
    trained: &[TrainedModel],
    size: usize,
    notes: &mut Vec<String>,
) -> Vec<Figure> {
    let Some(first) = prepared.models.first() else {
        return Vec::new();
    };
    let data = &first.validation;
    let tables = predictions(prepared, trained, data, Mode::Online, notes);
    let title = format!(
        "{}: free run on validation data ({size} training points)",
        prepared.study.name
    );
    (state_charts(prepared, &tables, data, &title).into_iter())
        .map(|(state, svg)| Figure {
            name: format!("trajectory_{state}"),
            caption: format!(
                "Free runs of {state} over the validation window, driven by the inputs alone, of \
                 the median replicate of each model trained on {size} points, against the data \
                 (paper Fig. 2c/3c)."
            ),
            svg,
        })
        .collect()
}

fn closure_figures(
    prepared: &Prepared,
    trained: &[TrainedModel],
    size: usize,
    notes: &mut Vec<String>,
) -> Vec<Figure> {
    let Some(run) = truth_run(prepared, notes) else {
        return Vec::new();
    };
    let grey: Vec<&TrainedModel> = (trained.iter())
        .filter(|(index, ..)| !prepared.models[*index].model.closures.is_empty())
        .filter(|(index, ..)| !is_black_box(&prepared.models[*index].model))
        .collect();
    let mut tables = Vec::new();
    for entry in &grey {
        let data = &prepared.models[entry.0].validation;
        tables.extend(predictions(prepared, [*entry], data, Mode::Offline, notes));
    }
    let mut outputs: Vec<&str> = Vec::new();
    for (entry, _) in &tables {
        let closures = &prepared.models[entry.0].model.closures;
        for output in closures.iter().flat_map(|c| &c.outputs) {
            if !outputs.contains(&output.name.as_str()) && run.closure_truth(&output.name).is_some()
            {
                outputs.push(&output.name);
            }
        }
    }
    (outputs.into_iter())
        .map(|output| closure_figure(prepared, &tables, &run, output, size))
        .collect()
}

/// The truth model along the validation record, with a note when it cannot be had or
/// does not reproduce the data.
fn truth_run(prepared: &Prepared, notes: &mut Vec<String>) -> Option<TruthRun> {
    let Some(truth) = &prepared.truth else {
        notes.push("no truth model: the closure figures are left out".into());
        return None;
    };
    let checked_from = prepared.models.iter().map(|m| m.offset).min().unwrap_or(0);
    let Ok(run) = truth_along(truth, &prepared.validation_source, checked_from) else {
        notes.push("the truth model cannot be simulated along the data".into());
        return None;
    };
    if run.deviation > TRUTH_TOLERANCE {
        notes.push(format!(
            "the truth model deviates from the data by up to {:.3} standard deviations over \
             the validation window: its rates may not be the data's",
            run.deviation
        ));
    }
    Some(run)
}

/// One closure output of every grey-box model against the truth's rate.
fn closure_figure(
    prepared: &Prepared,
    tables: &[(&TrainedModel, PredictionTable)],
    run: &TruthRun,
    output: &str,
    size: usize,
) -> Figure {
    let title = format!(
        "{}: closure output {output} ({size} training points)",
        prepared.study.name
    );
    let (time, axis) = axis_titles(prepared, output);
    let mut chart = Chart::new(&title, &time, &axis);
    let mut truth_added = false;
    for ((index, ..), table) in tables {
        let Some(values) = column(table, output) else {
            continue;
        };
        let loaded = &prepared.models[*index];
        let times = &table.columns[0];
        if let (false, Some(true_values)) = (truth_added, run.closure_truth(output)) {
            let start = loaded.offset + first_predicted_row(&loaded.validation, table);
            let truth = true_values[start.min(true_values.len())..].iter().copied();
            let points = times.iter().copied().zip(truth).collect();
            chart = chart.with(Series::line("truth", thin(points, MAX_POINTS)).colored(DATA_COLOR));
            truth_added = true;
        }
        let points = times.iter().copied().zip(values.iter().copied()).collect();
        let series = Series::line(&loaded.label, thin(points, MAX_POINTS)).styled(Style::Dashed);
        chart = chart.with(series.colored(color(*index)));
    }
    Figure {
        name: format!("closure_{output}"),
        caption: format!(
            "The learned {output} along the validation window (one step from the true history) \
             of the median replicate trained on {size} points, against the truth model's rate \
             (paper Fig. 2c lower panel, 3d)."
        ),
        svg: chart.to_svg(WIDTH, HEIGHT),
    }
}

/// Trained params (median over replicates at `size`) against the truth's consts.
fn params_figure(prepared: &Prepared, results: &[RunResult], size: usize) -> Option<Figure> {
    let mut names: Vec<String> = Vec::new();
    for loaded in &prepared.models {
        for param in &loaded.model.params {
            if !names.contains(&param.name) {
                names.push(param.name.clone());
            }
        }
    }
    if names.is_empty() {
        return None;
    }
    let mut groups = Vec::new();
    if let Some(truth) = &prepared.truth {
        let values: Vec<(String, f64)> = (prepared.models.iter())
            .flat_map(|m| true_params(truth, &m.model))
            .collect();
        let row = names.iter().map(|n| {
            values
                .iter()
                .find(|(v, _)| v == n)
                .map_or(f64::NAN, |v| v.1)
        });
        groups.push(("truth".to_string(), row.collect::<Vec<_>>()));
    }
    for loaded in prepared
        .models
        .iter()
        .filter(|m| !m.model.params.is_empty())
    {
        let runs = runs_of(results, &loaded.label, size);
        let row = (names.iter())
            .map(|name| {
                let values: Vec<f64> = (runs.iter().filter(|r| r.is_ok()))
                    .filter_map(|r| RunResult::measure(&r.params, name))
                    .collect();
                super::results::spread(&values).map_or(f64::NAN, |s| s.median)
            })
            .collect();
        groups.push((loaded.label.clone(), row));
    }
    let names = cut_off_scale(names, &mut groups);
    let chart = BarChart {
        title: format!(
            "{}: trained params ({size} training points, median)",
            prepared.study.name
        ),
        y_label: "value".into(),
        categories: names,
        groups,
    };
    Some(Figure {
        name: "params".into(),
        caption: format!(
            "Trained params, median over the replicates trained on {size} points, against the \
             truth model's values (paper Fig. 3e)."
        ),
        svg: chart.to_svg(WIDTH, HEIGHT),
    })
}

/// Bars more than [`PARAM_CEILING`] times the truth's largest value (a param the data leave
/// unidentified) are cut there, so the others stay readable; their category says the value.
fn cut_off_scale(mut names: Vec<String>, groups: &mut [(String, Vec<f64>)]) -> Vec<String> {
    let Some((_, truth)) = groups.iter().find(|(name, _)| name == "truth") else {
        return names;
    };
    let largest = truth
        .iter()
        .map(|v| v.abs())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    if largest <= 0.0 {
        return names;
    }
    let ceiling = PARAM_CEILING * largest;
    for (_, values) in groups.iter_mut() {
        for (index, value) in values.iter_mut().enumerate() {
            if value.abs() > ceiling {
                names[index] = format!(
                    "{} ({}, cut)",
                    names[index],
                    crate::plot::tick_label(*value)
                );
                *value = ceiling.copysign(*value);
            }
        }
    }
    names
}

/// How far above the truth's largest param a bar is drawn before it is cut.
pub const PARAM_CEILING: f64 = 3.0;

fn generalisation_figures(
    prepared: &Prepared,
    trained: &[TrainedModel],
    data: &Dataset,
    size: usize,
    notes: &mut Vec<String>,
) -> Vec<Figure> {
    let stem = (data.path.file_stem()).map_or("record".to_string(), |s| s.to_string_lossy().into());
    let tables = predictions(prepared, trained, data, Mode::Online, notes);
    let title = format!(
        "{}: free run on {stem} (never trained on)",
        prepared.study.name
    );
    (state_charts(prepared, &tables, data, &title).into_iter())
        .map(|(state, svg)| Figure {
            name: format!("generalisation_{stem}_{state}"),
            caption: format!(
                "Free runs of {state} under the inputs of {}, a record never used in training, \
                 of the median replicate of each model trained on {size} points, against the \
                 data (paper Fig. 2d).",
                data.path.display()
            ),
            svg,
        })
        .collect()
}
