//! The report as a self-contained HTML page with inline SVG figures, and the same figures as
//! separate SVG files ([`figures`]): data against the free runs before and after the
//! credited effects (per scored experiment and measured state), the error over time on the
//! held-out part, the gap before and after (logarithmic bars), the held-out gap each free
//! correction leaves with and without history, and the forward selection.

use super::render::{num, percent};
use super::report::{ExperimentSeries, LocusKind, Report};
use crate::plot::{linear_ticks, tick_label};
use std::fmt::Write;

/// Plot size in pixels.
const WIDTH: f64 = 760.0;
const HEIGHT: f64 = 210.0;
/// Margins: left (tick labels and the axis title), right, top, bottom (ticks and title).
const MARGIN: (f64, f64, f64, f64) = (82.0, 14.0, 12.0, 44.0);
/// Most points drawn per line.
const MAX_POINTS: usize = 1500;
/// Scored experiments drawn (the others are listed).
const MAX_EXPERIMENTS: usize = 3;
/// Colours: data, fitted model, with the effects.
const DATA: &str = "#888";
const BEFORE: &str = "#c0392b";
const AFTER: &str = "#2471a3";

/// Renders the report as an HTML page.
pub fn page(report: &Report) -> String {
    let mut out = String::new();
    let title = format!("gbc diagnose: {}", report.model);
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n\
         <style>body{{font-family:sans-serif;max-width:800px;margin:1em auto;color:#222}}\
         pre{{background:#f6f6f6;padding:0.8em;white-space:pre-wrap;font-size:11px}}\
         svg{{display:block;margin:0.3em 0 1em 0}}.legend span{{margin-right:1.2em}}</style>\n</head>\n<body>\n\
         <h1>{}</h1>\n",
        escape(&title),
        escape(&title)
    );
    let _ = writeln!(out, "<h2>Gap before and after</h2>\n{}", bars(report));
    if !report.locus.is_empty() {
        let _ = writeln!(
            out,
            "<h2>Free corrections: held-out gap left at each place</h2>\n{}",
            loci_chart(report)
        );
    }
    if !report.selection.steps.is_empty() {
        let _ = writeln!(
            out,
            "<h2>Forward selection</h2>\n{}",
            selection_chart(report)
        );
    }
    for series in report.series.iter().take(MAX_EXPERIMENTS) {
        experiment_section(&mut out, series);
    }
    if report.series.len() > MAX_EXPERIMENTS {
        let rest: Vec<&str> = (report.series[MAX_EXPERIMENTS..].iter())
            .map(|s| s.name.as_str())
            .collect();
        let _ = writeln!(
            out,
            "<p>Also scored (not drawn): {}.</p>",
            escape(&rest.join(", "))
        );
    }
    let _ = writeln!(
        out,
        "<h2>Report</h2>\n<pre>{}</pre>\n</body>\n</html>",
        escape(&super::render::text(report))
    );
    out
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

fn experiment_section(out: &mut String, series: &ExperimentSeries) {
    let after = if series.after.is_some() {
        format!(
            "<span style=\"color:{AFTER}\">&#9473; with {}</span>",
            escape(&series.after_name)
        )
    } else {
        String::new()
    };
    let split = if series.first_scored > 0 {
        "<span>&#9482; start of the held-out part</span>"
    } else {
        "<span>(the whole experiment is held out)</span>"
    };
    let _ = writeln!(
        out,
        "<h2>Experiment {}: data and free runs</h2>\n<p class=\"legend\"><span style=\"color:{DATA}\">&#9679; data</span>\
         <span style=\"color:{BEFORE}\">&#9473; fitted model</span>{after}{split}</p>",
        escape(&series.name)
    );
    for k in 0..series.names.len() {
        let _ = writeln!(out, "{}", state_plot(series, k));
    }
    let _ = writeln!(
        out,
        "<h3>Error of the fitted model over time (held-out part of {})</h3>\n{}",
        escape(&series.name),
        error_plot(series)
    );
}

/// `&`, `<`, `>` and `"` escaped.
pub fn escape(text: &str) -> String {
    crate::plot::escape(text)
}

/// A name with its unit, `X [g/L]`.
fn titled(name: &str, unit: Option<&str>) -> String {
    match unit {
        Some(unit) if !unit.is_empty() => format!("{name} [{unit}]"),
        _ => name.to_string(),
    }
}

/// Maps data coordinates onto the plot area and draws axes with ticks and titles.
struct Frame {
    x: (f64, f64),
    y: (f64, f64),
}

impl Frame {
    fn new(xs: &[f64], ys: &mut dyn Iterator<Item = f64>) -> Frame {
        let range = |values: &mut dyn Iterator<Item = f64>| {
            values
                .filter(|v| v.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                })
        };
        let mut x = range(&mut xs.iter().copied());
        if x.1.is_nan() || x.0.is_nan() || x.1 <= x.0 {
            x = (x.0.min(0.0), x.0.max(0.0) + 1.0);
        }
        let mut y = range(ys);
        if !y.0.is_finite() {
            y = (0.0, 1.0);
        } else if y.1 <= y.0 {
            let pad = if y.0 == 0.0 { 1.0 } else { 0.1 * y.0.abs() };
            y = (y.0 - pad, y.0 + pad);
        } else {
            let pad = 0.05 * (y.1 - y.0);
            y = (y.0 - pad, y.1 + pad);
        }
        Frame { x, y }
    }

    fn px(&self, x: f64) -> f64 {
        MARGIN.0 + (x - self.x.0) / (self.x.1 - self.x.0) * (WIDTH - MARGIN.0 - MARGIN.1)
    }

    fn py(&self, y: f64) -> f64 {
        let clamped = y.clamp(self.y.0, self.y.1);
        HEIGHT
            - MARGIN.3
            - (clamped - self.y.0) / (self.y.1 - self.y.0) * (HEIGHT - MARGIN.2 - MARGIN.3)
    }

    fn axes(&self, out: &mut String, x_title: &str, y_title: &str) {
        let (left, right, top, bottom) = (MARGIN.0, WIDTH - MARGIN.1, MARGIN.2, HEIGHT - MARGIN.3);
        for tick in linear_ticks(self.y.0, self.y.1, 4) {
            let y = self.py(tick);
            let _ = write!(
                out,
                "<line x1=\"{left}\" y1=\"{y:.1}\" x2=\"{right}\" y2=\"{y:.1}\" stroke=\"#eee\"/>\
                 <text x=\"{}\" y=\"{:.1}\" font-size=\"10\" text-anchor=\"end\">{}</text>",
                left - 4.0,
                y + 3.5,
                tick_label(tick)
            );
        }
        for tick in linear_ticks(self.x.0, self.x.1, 6) {
            let x = self.px(tick);
            let _ = write!(
                out,
                "<line x1=\"{x:.1}\" y1=\"{bottom}\" x2=\"{x:.1}\" y2=\"{}\" stroke=\"#444\"/>\
                 <text x=\"{x:.1}\" y=\"{}\" font-size=\"10\" text-anchor=\"middle\">{}</text>",
                bottom + 4.0,
                bottom + 15.0,
                tick_label(tick)
            );
        }
        let (width, height) = (right - left, bottom - top);
        let (centre_x, centre_y) = ((left + right) / 2.0, (top + bottom) / 2.0);
        let (x_title, y_title) = (escape(x_title), escape(y_title));
        let _ = write!(
            out,
            "<rect x=\"{left}\" y=\"{top}\" width=\"{width}\" height=\"{height}\" fill=\"none\" stroke=\"#444\"/>\
             <text x=\"{centre_x}\" y=\"{}\" font-size=\"11\" text-anchor=\"middle\">{x_title}</text>\
             <text x=\"14\" y=\"{centre_y}\" font-size=\"11\" text-anchor=\"middle\" \
             transform=\"rotate(-90 14 {centre_y})\">{y_title}</text>",
            HEIGHT - 6.0,
        );
    }

    fn polyline(&self, out: &mut String, xs: &[f64], ys: &[f64], colour: &str) {
        let stride = (xs.len() / MAX_POINTS).max(1);
        let points: Vec<String> = (0..xs.len().min(ys.len()))
            .step_by(stride)
            .filter(|&i| ys[i].is_finite())
            .map(|i| format!("{:.1},{:.1}", self.px(xs[i]), self.py(ys[i])))
            .collect();
        let _ = write!(
            out,
            "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.3\" points=\"{}\"/>",
            points.join(" ")
        );
    }

    fn dots(&self, out: &mut String, points: &[(f64, f64)]) {
        let stride = (points.len() / MAX_POINTS).max(1);
        for &(x, y) in points.iter().step_by(stride) {
            let _ = write!(
                out,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"1.4\" fill=\"{DATA}\"/>",
                self.px(x),
                self.py(y)
            );
        }
    }
}

fn svg_open(out: &mut String, height: f64) {
    let _ = write!(
        out,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH}\" height=\"{height}\" \
         viewBox=\"0 0 {WIDTH} {height}\" font-family=\"sans-serif\"><rect width=\"{WIDTH}\" height=\"{height}\" fill=\"white\"/>"
    );
}

fn time_title(series: &ExperimentSeries) -> String {
    format!(
        "{}, experiment {}",
        titled("t", series.time_unit.as_deref()),
        series.name
    )
}

fn state_plot(series: &ExperimentSeries, k: usize) -> String {
    let mut out = String::new();
    svg_open(&mut out, HEIGHT);
    let data: Vec<(f64, f64)> = (series.times.iter().zip(&series.data[k]))
        .filter_map(|(&t, cell)| cell.map(|v| (t, v)))
        .collect();
    let before = series.before.get(k);
    let after = series.after.as_ref().and_then(|a| a.get(k));
    let frame = Frame::new(
        &series.times,
        &mut (data.iter().map(|p| p.1))
            .chain(before.into_iter().flatten().copied())
            .chain(after.into_iter().flatten().copied()),
    );
    let y_title = titled(&series.names[k], series.units[k].as_deref());
    frame.axes(&mut out, &time_title(series), &y_title);
    frame.dots(&mut out, &data);
    if let Some(before) = before {
        frame.polyline(&mut out, &series.times, before, BEFORE);
    }
    if let Some(after) = after {
        frame.polyline(&mut out, &series.times, after, AFTER);
    }
    if series.first_scored > 0 {
        if let Some(&split) = series.times.get(series.first_scored) {
            let x = frame.px(split);
            let _ = write!(
                out,
                "<line x1=\"{x:.1}\" y1=\"{}\" x2=\"{x:.1}\" y2=\"{}\" stroke=\"#444\" stroke-dasharray=\"4 3\"/>",
                MARGIN.2,
                HEIGHT - MARGIN.3
            );
        }
    }
    out.push_str("</svg>");
    out
}

fn error_plot(series: &ExperimentSeries) -> String {
    let times = &series.times[series.first_scored..];
    let points: Vec<(f64, f64)> = (times.iter().zip(&series.errors))
        .filter_map(|(&t, e)| e.map(|e| (t, e)))
        .collect();
    let mut out = String::new();
    svg_open(&mut out, HEIGHT);
    let frame = Frame::new(times, &mut points.iter().map(|p| p.1).chain([0.0]));
    frame.axes(&mut out, &time_title(series), "squared error (normalised)");
    let (xs, ys): (Vec<f64>, Vec<f64>) = points.into_iter().unzip();
    frame.polyline(&mut out, &xs, &ys, BEFORE);
    out.push_str("</svg>");
    out
}

/// Horizontal bars on a logarithmic scale: `(label, value, colour, note)`.
fn log_bars(rows: &[(String, f64, &str, String)], axis: &str) -> String {
    let finite: Vec<f64> = (rows.iter().map(|r| r.1))
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let lo = finite
        .iter()
        .fold(f64::INFINITY, |m, v| m.min(*v))
        .log10()
        .floor()
        - 0.3;
    let hi = finite
        .iter()
        .fold(f64::NEG_INFINITY, |m, v| m.max(*v))
        .log10()
        .ceil();
    let (label_width, bar_height, note_width) = (250.0, 20.0, 150.0);
    let height = rows.len() as f64 * bar_height + 34.0;
    let mut out = String::new();
    svg_open(&mut out, height);
    let span = WIDTH - label_width - note_width;
    for (index, (label, value, colour, note)) in rows.iter().enumerate() {
        let y = 4.0 + index as f64 * bar_height;
        let fraction = if value.is_finite() && *value > 0.0 && hi > lo {
            ((value.log10() - lo) / (hi - lo)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let length = (fraction * span).max(1.0);
        let _ = write!(
            out,
            "<text x=\"{}\" y=\"{}\" font-size=\"11\" text-anchor=\"end\">{}</text>\
             <rect x=\"{label_width}\" y=\"{y}\" width=\"{length:.1}\" height=\"{}\" fill=\"{colour}\"/>\
             <text x=\"{}\" y=\"{}\" font-size=\"10\">{} {}</text>",
            label_width - 6.0,
            y + 13.0,
            escape(label),
            bar_height - 6.0,
            label_width + length + 4.0,
            y + 12.0,
            num(*value),
            escape(note)
        );
    }
    if lo.is_finite() && hi.is_finite() {
        let base = rows.len() as f64 * bar_height + 8.0;
        let mut decade = lo.ceil() as i32;
        while (decade as f64) <= hi {
            let x = label_width + (decade as f64 - lo) / (hi - lo) * span;
            let _ = write!(
                out,
                "<line x1=\"{x:.1}\" y1=\"{base}\" x2=\"{x:.1}\" y2=\"{}\" stroke=\"#444\"/>\
                 <text x=\"{x:.1}\" y=\"{}\" font-size=\"9\" text-anchor=\"middle\">1e{decade}</text>",
                base + 4.0,
                base + 14.0
            );
            decade += 1;
        }
        let _ = write!(
            out,
            "<text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"end\">{}</text>",
            label_width - 6.0,
            base + 14.0,
            escape(axis)
        );
    }
    out.push_str("</svg>");
    out
}

/// The gap before, after the credited effects (or the best one), at the best locus, and the
/// noise floor.
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
        rows.push((
            label,
            locus.bound_after,
            "#7d3c98",
            change(locus.bound_after),
        ));
    }
    rows.push((
        "noise floor".into(),
        report.noise_floor,
        DATA,
        change(report.noise_floor),
    ));
    log_bars(&rows, "held-out gap (log)")
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
        rows.push((
            format!("{} ({kind}), present", locus.name),
            locus.bound_present,
            "#e59866",
            present_note.to_string(),
        ));
        rows.push((
            format!("{} ({kind}), history", locus.name),
            locus.bound_history,
            "#7d3c98",
            history_note.to_string(),
        ));
    }
    rows.push((
        "noise floor".into(),
        report.noise_floor,
        DATA,
        String::new(),
    ));
    rows.push((
        "gap before".into(),
        report.gap_before,
        BEFORE,
        String::new(),
    ));
    log_bars(&rows, "held-out gap (log)")
}

/// The held-out gap after each step of the forward selection.
fn selection_chart(report: &Report) -> String {
    let mut rows = vec![(
        "no effect".to_string(),
        report.gap_before,
        BEFORE,
        String::new(),
    )];
    for step in &report.selection.steps {
        let verdict = if step.accepted {
            "credited"
        } else {
            "not credited"
        };
        rows.push((
            step.effects.join(" + "),
            step.gap_after,
            if step.accepted { AFTER } else { "#bbb" },
            format!("{verdict}, BIC {}", num(step.bic)),
        ));
    }
    rows.push((
        "noise floor".into(),
        report.noise_floor,
        DATA,
        String::new(),
    ));
    log_bars(&rows, "held-out gap (log)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_markup() {
        assert_eq!(escape("a<b & \"c\">"), "a&lt;b &amp; &quot;c&quot;&gt;");
    }

    #[test]
    fn frames_map_the_data_range_onto_the_plot_area() {
        let frame = Frame::new(&[0.0, 10.0], &mut [1.0, 3.0].into_iter());
        assert_eq!(frame.px(0.0), MARGIN.0);
        assert_eq!(frame.px(10.0), WIDTH - MARGIN.1);
        // The y range is padded by 5 % on each side.
        assert!((frame.y.0 - 0.9).abs() < 1e-12 && (frame.y.1 - 3.1).abs() < 1e-12);
        assert_eq!(frame.py(frame.y.0), HEIGHT - MARGIN.3);
        // A constant series gets a band around it instead of a zero-height range.
        let flat = Frame::new(&[0.0, 1.0], &mut [2.0, 2.0].into_iter());
        assert!((flat.y.0 - 1.8).abs() < 1e-12 && (flat.y.1 - 2.2).abs() < 1e-12);
    }

    #[test]
    fn axis_titles_carry_units() {
        assert_eq!(titled("X", Some("g/L")), "X [g/L]");
        assert_eq!(titled("u", None), "u");
    }

    /// Both axis titles are drawn inside the figure: the x title under the plot area, the
    /// y title (turned a quarter) beside its middle.
    #[test]
    fn axis_titles_lie_inside_the_figure() {
        let frame = Frame::new(&[0.0, 10.0], &mut [1.0, 3.0].into_iter());
        let mut out = String::new();
        frame.axes(&mut out, "t [h]", "X [g/L]");
        let y_of = |title: &str| -> f64 {
            let end = out.find(&format!(">{title}</text>")).unwrap();
            let start = out[..end].rfind("<text").unwrap();
            let tag = &out[start..end];
            let value = tag
                .split(" y=\"")
                .nth(1)
                .unwrap()
                .split('"')
                .next()
                .unwrap();
            value.parse().unwrap()
        };
        let x_title = y_of("t [h]");
        assert!(x_title > HEIGHT - MARGIN.3 && x_title < HEIGHT, "{x_title}");
        let y_title = y_of("X [g/L]");
        assert_eq!(y_title, (MARGIN.2 + HEIGHT - MARGIN.3) / 2.0);
        assert!(out.contains(&format!("rotate(-90 14 {y_title})")));
    }
}
