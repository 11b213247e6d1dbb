//! The report of an ensemble run (`RUN/report.html`): the band rule and its calibration,
//! the coverage of the held-out experiments, the median's and the members' errors, the
//! members, and each measured state of the held-out (and the first training) experiments
//! with its measured cells, the members' median and the calibrated band.

use std::fmt::Write;

use super::calibrate::{cells, CellCount};
use super::info::EnsembleInfo;
use super::members::Trained;
use super::resample::Resample;
use super::run::Run;
use crate::ir;
use crate::plot::{escape, figure, page, thin, tick_label, Chart, Series, Style};
use crate::record::Record;

/// Figure width in pixels.
const WIDTH: f64 = 640.0;
/// Figure height in pixels.
const HEIGHT: f64 = 330.0;
/// Training experiments drawn (every held-out one is).
const DRAWN: usize = 3;
/// Most measured cells drawn as dots per figure.
const MARKERS: usize = 300;
/// Colour of the median and its band.
const MEDIAN: &str = "#d62728";

/// The report page of a trained ensemble at band `level`; `train` and `validation` are the
/// experiments of the members' runs, in the order of their runs.
pub fn ensemble_page(
    model: &ir::Model,
    trained: &Trained,
    (train, validation): (&[Record], &[Record]),
    level: f64,
    title: &str,
) -> String {
    let info = &trained.info;
    let used = info.used().count();
    let intro = format!(
        "<p>Model <code>{}</code>: {used} members of {} ({}, seeds {} to {}). Every figure is \
         drawn from the saved members: <code>gbc predict</code> writes the tables behind \
         them.</p>",
        escape(&model.name),
        info.members.len(),
        match info.resample {
            Resample::Experiments => "each on a bootstrap of whole training experiments",
            Resample::None => "every member on every training experiment",
        },
        info.seed,
        info.seed + info.members.len().saturating_sub(1) as u64,
    );
    let mut sections = vec![
        band_section(info, level),
        coverage_section(info),
        members_section(info),
    ];
    let validation_start = train.len();
    let shown = (validation.iter().enumerate())
        .map(|(v, r)| (r, validation_start + v, "held out"))
        .chain((train.iter().enumerate().take(DRAWN)).map(|(e, r)| (r, e, "training")));
    let mut figures = format!(
        "<h2>Measured, median and the {} % band</h2>\n<p>Dots: measured cells. Line: the \
         members' median free run from the experiment's start. Shaded: the calibrated band of \
         a new measurement. On a training experiment most members trained on it: its band is \
         no test.</p>\n",
        tick_label(100.0 * level)
    );
    for (record, index, role) in shown {
        figures.push_str(&experiment_figures(
            model,
            trained,
            (record, index, role),
            level,
            title,
        ));
    }
    sections.push(figures);
    page(&format!("{title}: ensemble report"), &intro, &sections)
}

/// The band rule, each state's noise and its calibration.
fn band_section(info: &EnsembleInfo, level: f64) -> String {
    let calibration = &info.calibration;
    let mut html = format!(
        "<h2>Band</h2>\n<p>{}. Calibrated on {}.</p>\n",
        escape(&capitalised(&info.band.rule)),
        escape(&calibration.source)
    );
    if let Some(reason) = &calibration.reason {
        let _ = writeln!(
            html,
            "<p><strong>Not calibrated:</strong> {} — no band is claimed.</p>",
            escape(reason)
        );
    }
    html.push_str(
        "<table><tr><th>state</th><th>noise</th><th>out-of-bag cells</th><th>scores from</th>\
         <th>factor</th></tr>\n",
    );
    for (state, (noise, scores)) in (info.band.noise.iter().zip(&calibration.states)).enumerate() {
        let factor = calibration.factor(state, level);
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&noise.state),
            escape(&noise.describe()),
            scores.cells,
            if scores.pooled {
                "every state"
            } else {
                "its own"
            },
            factor.map_or("– (not calibrated)".into(), tick_label)
        );
    }
    html.push_str("</table>\n");
    html
}

/// The coverage of the held-out experiments and the errors.
fn coverage_section(info: &EnsembleInfo) -> String {
    let Some(coverage) = &info.coverage else {
        return "<h2>Coverage</h2>\n<p>No held-out measured cell to count.</p>\n".into();
    };
    let mut html = format!(
        "<h2>Coverage of the held-out experiments</h2>\n<p>Measured cells of {} after the free \
         run's start inside the {} % band (a cell no member reached counts outside).</p>\n\
         <table><tr><th>state</th><th>cells</th><th>inside</th><th>share</th></tr>\n",
        escape(&coverage.experiments.join(", ")),
        tick_label(100.0 * coverage.level)
    );
    for count in coverage.states.iter().chain([&coverage.overall]) {
        html.push_str(&count_row(count));
    }
    let base = &coverage.uncalibrated;
    let _ = writeln!(
        html,
        "</table>\n<p>Not calibrated (the members' spread with the noise at {} %): {} of {} \
         cells inside ({}).</p>",
        tick_label(100.0 * info.band.base_level),
        base.inside,
        base.cells,
        percent(base.share())
    );
    if let Some(errors) = &info.errors {
        let members: Vec<String> = errors.members.iter().map(|e| tick_label(*e)).collect();
        let _ = writeln!(
            html,
            "<p>Held-out error ({}): median {}; members {}.</p>",
            escape(&errors.measure),
            tick_label(errors.median),
            members.join(", ")
        );
    }
    html
}

/// One row of a coverage table.
fn count_row(count: &CellCount) -> String {
    format!(
        "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
        escape(&count.state),
        count.cells,
        count.inside,
        percent(count.share())
    )
}

/// The members: seed, draws, status, error.
fn members_section(info: &EnsembleInfo) -> String {
    let mut html = String::from(
        "<h2>Members</h2>\n<table><tr><th>member</th><th>seed</th><th>trained on</th>\
         <th>out of bag</th><th>status</th><th>held-out error</th><th>seconds</th></tr>\n",
    );
    for member in &info.members {
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            member.index,
            member.seed,
            escape(&member.trained_on.join(" ")),
            escape(&member.out_of_bag.join(" ")),
            escape(&member.status.to_string()),
            member.validation_error.map_or("–".into(), tick_label),
            tick_label(member.seconds.round())
        );
    }
    html.push_str("</table>\n");
    html
}

/// One figure per measured state of `record` (run `index` of every member).
fn experiment_figures(
    model: &ir::Model,
    trained: &Trained,
    (record, index, role): (&Record, usize, &str),
    level: f64,
    title: &str,
) -> String {
    let info = &trained.info;
    let runs: Vec<&Run> = (trained.members.iter())
        .filter_map(|m| m.runs.get(index))
        .collect();
    let mut html = String::new();
    for (state, name) in model.states.iter().map(|s| &s.name).enumerate() {
        let measured: Vec<(f64, f64)> = (record.times.iter().zip(&record.states[state]))
            .filter_map(|(t, cell)| cell.map(|v| (*t, v)))
            .collect();
        if measured.is_empty() {
            continue;
        }
        let factor = info.calibration.factor(state, level);
        let (mut median, mut band) = (Vec::new(), Vec::new());
        for row in 0..record.len() {
            let predictions = runs.iter().map(|r| r.states[state][row]);
            if let Some(base) = info.band.noise[state].base_band(predictions) {
                median.push((record.times[row], base.median));
                band.push(factor.map_or((f64::NAN, f64::NAN), |f| base.stretched(f)));
            }
        }
        let mut series = Series::line("members' median", median).colored(MEDIAN);
        if factor.is_some() {
            series = series.with_named_band(band, &band_name(level));
        }
        let chart = Chart::new(
            &format!("{title}: {} ({role}) — {name}", record.name),
            &model.time_label(),
            &model.axis_label(name),
        )
        .with(series)
        .with(
            Series::line("measured", thin(measured, MARKERS))
                .styled(Style::Markers)
                .colored(crate::plot::DATA_COLOR),
        );
        let caption = caption(record, &runs, info, (state, level));
        html.push_str(&figure(&chart.to_svg(WIDTH, HEIGHT), &caption));
    }
    html
}

/// The share of the state's cells inside the band, in words.
fn caption(
    record: &Record,
    runs: &[&Run],
    info: &EnsembleInfo,
    (state, level): (usize, f64),
) -> String {
    let Some(factor) = info.calibration.factor(state, level) else {
        return "No calibrated band for this state.".into();
    };
    let all = cells(record, runs, &info.band.noise);
    let mine: Vec<_> = all.iter().filter(|c| c.state == state).collect();
    let inside = (mine.iter())
        .filter(|c| c.base.is_some_and(|b| b.covers(factor, c.measured)))
        .count();
    format!(
        "{inside} of {} measured cells after the start inside the band.",
        mine.len()
    )
}

/// The band's legend entry: `90 % band` at level 0.9.
pub fn band_name(level: f64) -> String {
    format!("{} % band", tick_label(100.0 * level))
}

/// A share as a percentage with one decimal (`–` for none).
fn percent(share: f64) -> String {
    if share.is_finite() {
        format!("{:.1} %", 100.0 * share)
    } else {
        "–".into()
    }
}

/// The text with its first letter in capitals.
fn capitalised(text: &str) -> String {
    let mut chars = text.chars();
    chars.next().map_or(String::new(), |first| {
        first.to_uppercase().collect::<String>() + chars.as_str()
    })
}
