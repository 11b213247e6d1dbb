//! The held-out figures of a study on a data set: each held-out experiment's measured cells
//! against the free run of every model's representative run, one figure per experiment and
//! state.

use super::figure::{axis_titles, color, Figure, TrainedModel, HEIGHT, WIDTH};
use super::prepare::Prepared;
use crate::plot::{clip, thin, widened_range, Chart, Series, Style, DATA_COLOR, MAX_POINTS};
use crate::record::Record;
use crate::train::History;
use crate::trained::predict::{predict, Mode};

/// Free runs of each held-out experiment (from its first row) by the representative run of
/// every model, against the measured cells: one figure per experiment and state.
pub fn held_out_figures(prepared: &Prepared, trained: &[TrainedModel], size: usize) -> Vec<Figure> {
    let mut figures = Vec::new();
    let Some(first) = prepared.models.iter().find_map(|m| m.set.as_ref()) else {
        return figures;
    };
    for (held, record) in first.held.iter().enumerate() {
        let states = &prepared.models[0].model.states;
        for (index, state) in states.iter().enumerate() {
            let cells: Vec<(f64, f64)> = (record.times.iter().zip(&record.states[index]))
                .filter_map(|(t, cell)| cell.map(|v| (*t, v)))
                .collect();
            if cells.is_empty() {
                continue;
            }
            let experiment = HeldOut {
                held,
                record,
                state: &state.name,
            };
            let chart = held_out_chart(prepared, trained, &experiment, cells, size);
            figures.push(Figure {
                name: format!("heldout_{}_{}", file_safe(&record.name), state.name),
                caption: format!(
                    "Free run of {} over the held-out experiment {}, from its first row and \
                     driven by its inputs alone, by the median replicate of each model trained \
                     on {size} points, against its measured cells.",
                    state.name, record.name
                ),
                svg: chart.to_svg(WIDTH, HEIGHT),
            });
        }
    }
    figures
}

/// One state of one held-out experiment: what a held-out figure shows.
struct HeldOut<'a> {
    /// The experiment's place among the held-out ones (the same in every model's split).
    held: usize,
    /// The experiment, as the study's first model binds it.
    record: &'a Record,
    /// The state's name.
    state: &'a str,
}

/// The measured `cells` of a held-out state against every model's free run of it.
fn held_out_chart(
    prepared: &Prepared,
    trained: &[TrainedModel],
    experiment: &HeldOut,
    cells: Vec<(f64, f64)>,
    size: usize,
) -> Chart {
    let values: Vec<f64> = cells.iter().map(|(_, v)| *v).collect();
    let range = widened_range(&values);
    let title = format!(
        "{}: free run of held-out {} ({size} training points): {}",
        prepared.study.name, experiment.record.name, experiment.state
    );
    let (time, axis) = axis_titles(prepared, experiment.state);
    let mut chart = Chart::new(&title, &time, &axis).with(
        Series::line("data", cells)
            .styled(Style::Markers)
            .colored(DATA_COLOR),
    );
    for run in trained {
        if let Some(series) = held_out_run(prepared, run, experiment, range) {
            chart = chart.with(series);
        }
    }
    chart
}

/// A model's free run of a held-out state from the experiment's first row, clipped to
/// `range`; `None` where the model has no such experiment, cannot predict it or lacks the
/// state.
fn held_out_run(
    prepared: &Prepared,
    (model, network, setup, _): &TrainedModel,
    experiment: &HeldOut,
    range: (f64, f64),
) -> Option<Series> {
    let loaded = &prepared.models[*model];
    let own = loaded.set.as_ref()?.held.get(experiment.held)?;
    let table = predict(
        &loaded.model,
        network,
        setup,
        own,
        (Mode::Online, History::Held),
    )
    .ok()?;
    let column = table.header.iter().position(|h| h == experiment.state)?;
    let points = (table.columns[0].iter().copied()).zip(table.columns[column].iter().copied());
    let (label, points) = clip(&loaded.label, points, range);
    Some(
        Series::line(&label, thin(points, MAX_POINTS))
            .styled(Style::Dashed)
            .colored(color(*model)),
    )
}

/// `name` with every character but letters, digits, `-` and `_` replaced by `_`.
fn file_safe(name: &str) -> String {
    (name.chars())
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}
