//! The report as a self-contained HTML page with inline SVG figures, and the same figures as
//! separate SVG files ([`figures`]): data against the free runs before and after the
//! credited effects (per scored experiment and measured state), the error over time on the
//! held-out part, the gap before and after (logarithmic bars), the held-out gap each free
//! correction leaves with and without history, and the sets of effects. This file says
//! which figures, which series and what text; [`crate::plot`] draws them.

use super::render::{num, percent};
use super::report::{ExperimentSeries, LocusKind, Report};
use crate::plot::{
    clip, escape, figure, thin, titled, widened_range, Bar, Bars, Chart, Series, Style, MAX_POINTS,
};

/// Figure size in pixels (bar charts take the height their rows need).
const WIDTH: f64 = 640.0;
const HEIGHT: f64 = 300.0;
/// Radius of the data's dots (dense, noisy data: a grey band, not a row of blobs).
const DOT: f64 = 1.5;
/// Scored experiments drawn (the others are listed).
const MAX_EXPERIMENTS: usize = 3;
/// Colours: data, fitted model, with the effects, free correction with history, free
/// correction of present values only, a step not credited, the held-out split.
const DATA: &str = "#888";
const BEFORE: &str = "#c0392b";
const AFTER: &str = "#2471a3";
const HISTORY: &str = "#7d3c98";
const PRESENT: &str = "#e59866";
const REJECTED: &str = "#bbb";
const SPLIT: &str = "#444";
/// The value axis of every bar chart: the gap is a normalised MSE, without unit.
const GAP_AXIS: &str = "held-out gap (normalised MSE, log scale)";

/// Renders the report as an HTML page.
pub fn page(report: &Report) -> String {
    let mut gap = format!(
        "<h2>Gap before and after</h2>\n{}",
        figure(
            &bars(report),
            "The held-out gap (the free run's normalised MSE over the held-out part) before any \
             effect, after the credited effects (or the best effect, when none is credited), \
             with the best free correction, the noise floor and what a correct model would \
             show (the floor plus the spread of its fitted params and noisy starts; the gap \
             is significant above twice that); percentages are changes from \
             before."
        )
    );
    if !report.selection.steps.is_empty() {
        gap.push_str(&figure(
            &selection_chart(report),
            "The sets of effects fitted on the training data, best training BIC first (a set \
             that refits a held constant pays a prior penalty on top; the first twelve): the \
             held-out gap of each scores the choice, it does not make it.",
        ));
    }
    let mut sections = Vec::new();
    if let Some(partial) = &report.partial {
        sections.push(format!(
            "<p><strong>Partial report:</strong> {}</p>\n",
            escape(partial)
        ));
    }
    sections.push(gap);
    if !report.locus.is_empty() {
        sections.push(format!(
            "<h2>Free corrections: held-out gap left at each place</h2>\n{}",
            figure(
                &loci_chart(report),
                "Per place (the first eight), the held-out gap a free correction leaves there: \
                 from present values only, and with history. The gap before and the noise \
                 floor give the scale."
            )
        ));
    }
    for series in report.series.iter().take(MAX_EXPERIMENTS) {
        sections.push(experiment_section(series));
    }
    if report.series.len() > MAX_EXPERIMENTS {
        let rest: Vec<&str> = (report.series[MAX_EXPERIMENTS..].iter())
            .map(|s| s.name.as_str())
            .collect();
        sections.push(format!(
            "<p>Also scored (not drawn): {}.</p>\n",
            escape(&rest.join(", "))
        ));
    }
    sections.push(format!(
        "<h2>Report</h2>\n<pre>{}</pre>\n",
        escape(&super::render::text(report))
    ));
    crate::plot::page(
        &format!("gbc diagnose: {}", report.model),
        "<p>Where the model's free run misses the data, which candidate effect closes the gap, \
         and by how much. The gap is the normalised MSE of the free run over the held-out part \
         of the data; the text report at the end has every number.</p>\n",
        &sections,
    )
}

/// The figures of the report as standalone SVG documents, with file names.
pub fn figures(report: &Report) -> Vec<(String, String)> {
    let mut found = vec![("gap.svg".to_string(), bars(report))];
    if !report.locus.is_empty() {
        found.push(("loci.svg".to_string(), loci_chart(report)));
    }
    found.push(("selection.svg".to_string(), selection_chart(report)));
    for (index, series) in report.series.iter().enumerate().take(MAX_EXPERIMENTS) {
        for k in 0..series.names.len() {
            found.push((
                format!("run_{}_{}.svg", index + 1, series.names[k]),
                state_plot(series, k),
            ));
        }
        found.push((format!("error_{}.svg", index + 1), error_plot(series)));
    }
    found
}

fn experiment_section(series: &ExperimentSeries) -> String {
    let split = if series.first_scored > 0 {
        "the dashed line marks where the held-out part starts"
    } else {
        "the whole experiment is held out"
    };
    let mut html = format!(
        "<h2>Experiment {}: data and free runs</h2>\n<p>The measured data against the free runs \
         of the fitted model{}, from the experiment's first row and driven by its inputs \
         alone; {split}.</p>\n",
        escape(&series.name),
        if series.after.is_some() {
            format!(" and of the model with {}", escape(&series.after_name))
        } else {
            String::new()
        }
    );
    for k in 0..series.names.len() {
        html.push_str(&figure(&state_plot(series, k), ""));
    }
    let caption = format!(
        "Error of the fitted model over time on the held-out part of {}: per row, the \
         squared error of the z-scored states, summed over the measured states.",
        series.name
    );
    html.push_str(&figure(&error_plot(series), &caption));
    html
}

/// The time axis title, `time [s]`.
fn time_title(series: &ExperimentSeries) -> String {
    titled("time", series.time_unit.as_deref())
}

/// Measured state `k` of one experiment: the data, the fitted model's free run and the
/// free run with the effects (both kept near the data), and where the held-out part starts.
fn state_plot(series: &ExperimentSeries, k: usize) -> String {
    let data: Vec<(f64, f64)> = (series.times.iter().zip(&series.data[k]))
        .filter_map(|(&t, cell)| cell.map(|v| (t, v)))
        .collect();
    let range = widened_range(&data.iter().map(|p| p.1).collect::<Vec<_>>());
    let name = &series.names[k];
    let mut chart = Chart::new(
        &format!("experiment {}: {name}", series.name),
        &time_title(series),
        &titled(name, series.units[k].as_deref()),
    )
    .with(
        Series::line("data", thin(data, MAX_POINTS))
            .styled(Style::Markers)
            .sized(DOT)
            .colored(DATA),
    );
    let after_name = format!("with {}", series.after_name);
    let runs = [
        ("fitted model", series.before.get(k), BEFORE),
        (
            after_name.as_str(),
            (series.after.as_ref()).and_then(|a| a.get(k)),
            AFTER,
        ),
    ];
    for (label, run, colour) in runs {
        let Some(run) = run else { continue };
        let points = series.times.iter().copied().zip(run.iter().copied());
        let (label, points) = clip(label, points, range);
        chart = chart.with(Series::line(&label, points).colored(colour));
    }
    if series.first_scored > 0 {
        if let Some(&split) = series.times.get(series.first_scored) {
            chart = chart.with_mark("held-out part starts", split, Style::Dashed, SPLIT);
        }
    }
    chart.to_svg(WIDTH, HEIGHT)
}

/// The fitted model's error per scored row over the held-out part.
fn error_plot(series: &ExperimentSeries) -> String {
    let times = series.times.get(series.first_scored..).unwrap_or_default();
    let points: Vec<(f64, f64)> = (times.iter().zip(&series.errors))
        .filter_map(|(&t, e)| e.map(|e| (t, e)))
        .collect();
    Chart::new(
        &format!("experiment {}: error of the fitted model", series.name),
        &time_title(series),
        "squared z-scored error",
    )
    .including_y(0.0)
    .with(Series::line("fitted model", thin(points, MAX_POINTS)).colored(BEFORE))
    .to_svg(WIDTH, HEIGHT)
}

/// Log-scale bars of held-out gaps: `(label, gap, colour, note)`, the note after the value.
fn gap_bars(title: &str, rows: Vec<(String, f64, &str, String)>) -> String {
    let rows = (rows.into_iter())
        .map(|(label, gap, colour, note)| {
            let text = format!("{} {note}", num(gap));
            Bar::new(&label, gap, colour, text.trim_end())
        })
        .collect();
    let chart = Bars {
        title: title.to_string(),
        value_label: GAP_AXIS.to_string(),
        log: true,
        rows,
    };
    chart.to_svg(WIDTH)
}

/// The gap before, after the credited effects (or the best one), at the best locus, the
/// noise floor and what a correct model would show (the floor plus the held-out spread).
fn bars(report: &Report) -> String {
    let change = |gap: f64| percent(-(1.0 - gap / report.gap_before));
    let mut rows = vec![(
        "before".to_string(),
        report.gap_before,
        BEFORE,
        String::new(),
    )];
    let credited = &report.selection.credited;
    if !credited.is_empty() {
        let gap = report.selection.gap_after;
        rows.push((
            format!("after {}", credited.join(" + ")),
            gap,
            AFTER,
            change(gap),
        ));
    } else if let Some(best) = report.effects.first() {
        let label = format!("after {} (not credited)", best.name);
        rows.push((label, best.gap_after, AFTER, change(best.gap_after)));
    }
    if let Some(locus) = report.locus.first() {
        let label = format!("free correction at {}", locus.name);
        let gap = locus.bound_after;
        rows.push((label, gap, HISTORY, change(gap)));
    }
    let floor = report.noise_floor;
    rows.push(("noise floor".into(), floor, DATA, change(floor)));
    if let Some(spread) = report.held_out_spread {
        let label = "a correct model: the floor + its params' and starts' spread".to_string();
        rows.push((label, floor + spread, DATA, change(floor + spread)));
    }
    gap_bars("held-out gap before and after", rows)
}

/// Per locus (the first eight), the held-out gap of its present-only and history
/// corrections.
fn loci_chart(report: &Report) -> String {
    let mut rows = Vec::new();
    for (rank, locus) in report.locus.iter().take(8).enumerate() {
        let kind = match locus.kind {
            LocusKind::Balance => "balance",
            LocusKind::Group => "group",
            _ => "let",
        };
        // The note goes on the correction that gives the locus its bound.
        let note = match (rank, locus.tied) {
            (0, _) => "first",
            (_, true) => "tied with the first",
            _ => "",
        };
        let (present_note, history_note) = if locus.bound_history < locus.bound_present {
            ("", note)
        } else {
            (note, "")
        };
        let label = |what: &str| format!("{} ({kind}), {what}", locus.name);
        let present = (label("present"), locus.bound_present, PRESENT);
        rows.push((present.0, present.1, present.2, present_note.to_string()));
        let history = (label("history"), locus.bound_history, HISTORY);
        rows.push((history.0, history.1, history.2, history_note.to_string()));
    }
    let floor = report.noise_floor;
    rows.push(("noise floor".into(), floor, DATA, String::new()));
    let before = report.gap_before;
    rows.push(("gap before".into(), before, BEFORE, String::new()));
    gap_bars("free corrections: held-out gap left at each place", rows)
}

/// The held-out gap of each fitted set of effects (the first twelve by training BIC).
fn selection_chart(report: &Report) -> String {
    let before = report.gap_before;
    let mut rows = vec![("no effect".to_string(), before, BEFORE, String::new())];
    for step in report.selection.steps.iter().take(12) {
        let (verdict, colour) = if step.accepted {
            ("credited", AFTER)
        } else {
            ("not credited", REJECTED)
        };
        let penalty = super::candidates::prior_penalty(&step.effects);
        let note = if penalty > 0.0 {
            format!(
                "{verdict}, BIC {} + {} (refits)",
                num(step.bic),
                num(penalty)
            )
        } else {
            format!("{verdict}, BIC {}", num(step.bic))
        };
        rows.push((step.effects.join(" + "), step.gap_after, colour, note));
    }
    let floor = report.noise_floor;
    rows.push(("noise floor".into(), floor, DATA, String::new()));
    gap_bars("effect sets: held-out gap, chosen by training BIC", rows)
}
