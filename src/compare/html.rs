//! The comparison report (`gbc compare --html FILE`): the verdict, the table of errors per
//! held-out experiment and, per held-out experiment and state, the measured cells with the
//! fitted mechanism's free run, the grey box's free runs (the median seed's bold, the
//! others faint) and the naive forecast, side by side.

use std::fmt::Write;

use super::comparison::{Comparison, Curve, ExperimentScore, HeldOutRun, MemberRun, SplitResult};
use super::score::{number, times, Score};
use crate::plot::{clip, escape, figure, page as html_page, widened_range, Chart, Series, Style};
use crate::record::Record;

/// Figure width in pixels.
const WIDTH: f64 = 640.0;
/// Figure height in pixels.
const HEIGHT: f64 = 320.0;
/// Colour of the fitted mechanism.
const MECHANISM: &str = "#1f77b4";
/// Colour of the grey box's median seed.
const GREY_BOX: &str = "#d62728";
/// Colour of the grey box's other seeds.
const OTHER_SEEDS: &str = "#f2b8b8";
/// Colour of the naive forecast.
const NAIVE: &str = "#2ca02c";

/// The report page; `records` holds the held-out experiments' measured cells (bound to
/// the grey box, as compared).
pub fn page(comparison: &Comparison, records: &[Record], title: &str) -> String {
    let mut sections = vec![summary(comparison)];
    for split in &comparison.splits {
        sections.push(split_section(comparison, split, records));
    }
    let intro =
        format!(
        "<p>Grey box <code>{}</code> against its mechanism <code>{}</code> (every closure output \
         at its prior, or zero; params fitted by free runs to every measured training cell, as \
         <code>gbc diagnose</code> fits them) and the naive forecast (the training experiments' \
         mean at the same time since their start). Each is run free from the held-out \
         experiment's first row and scored on its measured cells after it: the error is the mean \
         over states of each state's NMSE (<code>docs/error-measure.md</code>). The grey box is \
         trained once per seed ({}) with <code>gbc train</code>'s defaults (a sparse record's budget, \
         the stop that cross-validation over the training experiments chooses: epochs trained \
         per seed {}).</p>",
        escape(&comparison.grey_box),
        escape(&comparison.mechanism),
        comparison.seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", "),
        escape(&epochs_trained(comparison)),
    );
    html_page(&format!("{title}: comparison"), &intro, &sections)
}

/// The grey box's epochs trained, per split and seed: "B4: seed 1 280, seed 2 300".
fn epochs_trained(comparison: &Comparison) -> String {
    let splits: Vec<String> = (comparison.splits.iter())
        .map(|split| format!("{}: {}", split.held_out.join(", "), split.epochs_trained()))
        .collect();
    splits.join("; ")
}

/// The verdict over every held-out experiment and its table.
fn summary(comparison: &Comparison) -> String {
    let scores: Vec<&ExperimentScore> = (comparison.splits.iter())
        .flat_map(|s| s.scores.iter())
        .collect();
    let mut html = String::from("<h2>Verdict</h2>\n");
    let overall = &comparison.overall;
    let _ = writeln!(html, "<p><b>{}</b></p>", escape(&overall.verdict.sentence));
    if scores.len() > 1 {
        html.push_str(
            "<p>Over every held-out experiment: each run's errors averaged over them, then \
             reduced as for one experiment.</p>\n",
        );
    }
    let mut rows: Vec<&ExperimentScore> = scores;
    if rows.len() > 1 {
        rows.push(overall);
    }
    html.push_str(&score_table(&rows));
    html
}

/// A table of scores: per experiment the three errors, the grey box's range and diverged
/// runs, and the ratios.
fn score_table(scores: &[&ExperimentScore]) -> String {
    let mut html = String::from(
        "<table><tr><th>held out</th><th>mechanism</th><th>grey box (median)</th>\
         <th>grey box min–max</th><th>naive</th><th>mechanism / grey box</th>\
         <th>naive / grey box</th><th>diverged</th><th>standing</th></tr>\n",
    );
    for score in scores {
        let grey = &score.grey_box;
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}–{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{} of {}</td><td>{:?}</td></tr>",
            escape(&score.experiment),
            number(score.mechanism.error),
            number(grey.error),
            number(grey.range.0),
            number(grey.range.1),
            number(score.naive.error),
            times(score.verdict.ratio_to_mechanism),
            times(score.verdict.ratio_to_naive),
            grey.diverged.len(),
            grey.runs,
            score.verdict.standing,
        );
    }
    html.push_str("</table>\n");
    html
}

/// Per-state errors of the three models on one experiment (and of the untrained grey box,
/// whose distance from the mechanism is the verdict's numerical resolution).
fn state_table(score: &ExperimentScore, states: &[String]) -> String {
    let mut html = String::from("<table><tr><th>NMSE</th>");
    for state in states {
        let _ = write!(html, "<th>{}</th>", escape(state));
    }
    html.push_str("<th>error</th></tr>\n");
    let row = |html: &mut String, label: &str, score: &Score| {
        let _ = write!(html, "<tr><td>{label}</td>");
        for state in states {
            let value = (score.per_state.iter()).find(|(n, _)| n == state);
            let _ = write!(
                html,
                "<td>{}</td>",
                value.map_or("—".into(), |v| number(v.1))
            );
        }
        let _ = writeln!(html, "<td>{}</td></tr>", number(score.error));
    };
    row(&mut html, "mechanism", &score.mechanism);
    if let Some(untrained) = &score.untrained {
        row(&mut html, "grey box untrained", untrained);
    }
    row(&mut html, "grey box (median)", &score.grey_box);
    row(&mut html, "naive", &score.naive);
    html.push_str("</table>\n");
    html
}

/// One split: per held-out experiment its verdict, its state table and its figures.
fn split_section(comparison: &Comparison, split: &SplitResult, records: &[Record]) -> String {
    let mut html = format!(
        "<h2>Held out {} (trained on {})</h2>\n",
        escape(&split.held_out.join(", ")),
        escape(&split.training.join(", "))
    );
    for failed in split.grey_box.iter().filter(|r| r.failed.is_some()) {
        let _ = writeln!(
            html,
            "<p class=\"notes\">seed {} did not train: {}</p>",
            failed.seed,
            escape(failed.failed.as_deref().unwrap_or_default())
        );
    }
    for (index, score) in split.scores.iter().enumerate() {
        let _ = writeln!(
            html,
            "<h3>{}</h3>\n<p>{}</p>",
            escape(&score.experiment),
            escape(&score.verdict.sentence)
        );
        for diverged in &score.grey_box.diverged {
            let _ = writeln!(html, "<p class=\"notes\">{}</p>", escape(diverged));
        }
        html.push_str(&state_table(score, &comparison.states));
        html.push_str(
            "<p>Measured cells (black); free runs from the first row: the fitted mechanism \
             (blue, dashed, drawn over the others), the grey box (red: the median seed bold, \
             the other seeds faint); the naive forecast (green, dashed). A run that leaves \
             the drawing's range is clipped to it and says so.</p>\n",
        );
        let record = records.iter().find(|r| r.name == score.experiment);
        for state in 0..comparison.states.len() {
            let chart = state_chart(comparison, split, (index, state), record);
            html.push_str(&figure(&chart.to_svg(WIDTH, HEIGHT), ""));
        }
    }
    html
}

/// The chart of state `state` on held-out experiment `index` of `split`.
fn state_chart<'a>(
    comparison: &Comparison,
    split: &'a SplitResult,
    (index, state): (usize, usize),
    record: Option<&Record>,
) -> Chart {
    let name = &comparison.states[state];
    let labels = &comparison.labels;
    let experiment = &split.held_out[index];
    let mut chart = Chart::new(
        &format!("{experiment}: {name}"),
        labels.first().map_or("time", String::as_str),
        labels.get(state + 1).map_or(name.as_str(), String::as_str),
    );
    let cells: Vec<(f64, f64)> = record.map_or_else(Vec::new, |r| {
        (r.times.iter().zip(&r.states[state]))
            .filter_map(|(t, c)| c.map(|v| (*t, v)))
            .collect()
    });
    let values: Vec<f64> = cells.iter().map(|c| c.1).collect();
    let range = widened_range(&values);
    let mut add = |label: &str, curve: Option<&Curve>, color: &str, style: Style| {
        let Some(curve) = curve else { return };
        let Some(column) = curve.states.get(state) else {
            return;
        };
        let points = curve.times.iter().copied().zip(column.iter().copied());
        let (clipped, points) = clip(label, points, range);
        let label = if label.is_empty() {
            String::new()
        } else {
            clipped
        };
        chart
            .series
            .push(Series::line(&label, points).colored(color).styled(style));
    };
    let median = median_seed(split, index);
    let mut faint_named = false;
    for (seed, run) in split.grey_box.iter().enumerate() {
        let Some(held) = run.held_out.get(index) else {
            continue;
        };
        if Some(seed) != median {
            let label = if faint_named {
                ""
            } else {
                "grey box, other seeds"
            };
            faint_named = true;
            add(label, curve_of(held), OTHER_SEEDS, Style::Line);
        }
    }
    let on = |run: &'a MemberRun| run.held_out.get(index).and_then(curve_of);
    if let Some(run) = median.and_then(|m| split.grey_box.get(m)) {
        let label = format!("grey box, seed {} (median)", run.seed);
        add(&label, on(run), GREY_BOX, Style::Line);
    }
    let naive = split.naive.get(index).and_then(curve_of);
    add("naive forecast", naive, NAIVE, Style::Dashed);
    // Over the grey box, which holds the mechanism's params: where they agree both show.
    let mechanism = on(&split.mechanism);
    add("fitted mechanism", mechanism, MECHANISM, Style::Dashed);
    let measured = Series::line("measured", cells)
        .styled(Style::Markers)
        .colored(crate::plot::DATA_COLOR);
    chart.with(measured)
}

/// A run's curve.
fn curve_of(run: &HeldOutRun) -> Option<&Curve> {
    run.curve.as_ref()
}

/// The index of the seed whose error on held-out experiment `index` is the median (the
/// lower middle of an even count); `None` without a scored run.
fn median_seed(split: &SplitResult, index: usize) -> Option<usize> {
    let mut scored: Vec<(f64, usize)> = (split.grey_box.iter().enumerate())
        .filter_map(|(seed, run)| {
            let error = run.held_out.get(index)?.error.as_ref()?.overall;
            (!error.is_nan()).then_some((error, seed))
        })
        .collect();
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    scored.get(scored.len().checked_sub(1)? / 2).map(|s| s.1)
}
