//! The report as a self-contained HTML page with inline SVG plots: data against the free
//! runs before and after the best effect, the error over time on the held-out part, and
//! bars of the gap before and after (logarithmic scale).

use super::render::{num, percent};
use super::report::{Report, Series};
use std::fmt::Write;

/// Plot size in pixels.
const WIDTH: f64 = 760.0;
const HEIGHT: f64 = 190.0;
/// Margins: left (axis labels), right, top, bottom.
const MARGIN: (f64, f64, f64, f64) = (70.0, 10.0, 10.0, 24.0);
/// Most points drawn per line.
const MAX_POINTS: usize = 1500;

/// Renders the report as an HTML page.
pub fn page(report: &Report) -> String {
    let mut out = String::new();
    let title = format!("gbc diagnose: {}", report.model);
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{}</title>\n\
         <style>body{{font-family:sans-serif;max-width:800px;margin:1em auto;color:#222}}\
         pre{{background:#f6f6f6;padding:0.8em;overflow-x:auto;font-size:12px}}\
         svg{{display:block;margin:0.3em 0 1em 0}}.legend span{{margin-right:1.2em}}</style>\n</head>\n<body>\n\
         <h1>{}</h1>\n",
        escape(&title),
        escape(&title)
    );
    let _ = writeln!(out, "<h2>Gap before and after</h2>\n{}", bars(report));
    let series = &report.series;
    if !series.times.is_empty() {
        let _ = writeln!(
            out,
            "<h2>Data and free runs</h2>\n<p class=\"legend\"><span style=\"color:#999\">&#9679; data</span>\
             <span style=\"color:#c0392b\">&#9473; fitted model</span><span style=\"color:#2471a3\">&#9473; with {}</span>\
             <span>&#9482; start of the held-out part</span></p>",
            escape(report.effects.first().map_or("-", |e| e.name.as_str()))
        );
        for k in 0..series.names.len() {
            let _ = writeln!(
                out,
                "<h3>{}</h3>\n{}",
                escape(&series.names[k]),
                state_plot(series, k)
            );
        }
        let _ = writeln!(
            out,
            "<h2>Error of the fitted model over time (held-out part)</h2>\n{}",
            error_plot(report)
        );
    }
    let _ = writeln!(
        out,
        "<h2>Report</h2>\n<pre>{}</pre>\n</body>\n</html>",
        escape(&super::render::text(report))
    );
    out
}

/// `&`, `<`, `>` and `"` escaped.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Maps data coordinates onto the plot area.
struct Frame {
    x: (f64, f64),
    y: (f64, f64),
}

impl Frame {
    fn new(xs: &[f64], ys: &[&[f64]]) -> Frame {
        let range = |values: &mut dyn Iterator<Item = f64>| {
            values
                .filter(|v| v.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                })
        };
        let x = range(&mut xs.iter().copied());
        let mut y = range(&mut ys.iter().flat_map(|c| c.iter().copied()));
        if y.1.is_nan() || y.0.is_nan() || y.1 <= y.0 {
            y = (y.0 - 1.0, y.0 + 1.0);
        }
        if !y.0.is_finite() {
            y = (0.0, 1.0);
        }
        Frame { x, y }
    }

    fn px(&self, x: f64) -> f64 {
        let span = (self.x.1 - self.x.0).max(f64::MIN_POSITIVE);
        MARGIN.0 + (x - self.x.0) / span * (WIDTH - MARGIN.0 - MARGIN.1)
    }

    fn py(&self, y: f64) -> f64 {
        let clamped = y.clamp(self.y.0, self.y.1);
        HEIGHT
            - MARGIN.3
            - (clamped - self.y.0) / (self.y.1 - self.y.0) * (HEIGHT - MARGIN.2 - MARGIN.3)
    }

    fn axes(&self, out: &mut String) {
        let (left, bottom) = (MARGIN.0, HEIGHT - MARGIN.3);
        let _ = write!(
            out,
            "<line x1=\"{left}\" y1=\"{}\" x2=\"{left}\" y2=\"{bottom}\" stroke=\"#444\"/>\
             <line x1=\"{left}\" y1=\"{bottom}\" x2=\"{}\" y2=\"{bottom}\" stroke=\"#444\"/>",
            MARGIN.2,
            WIDTH - MARGIN.1
        );
        for (value, anchor) in [(self.y.0, bottom), (self.y.1, MARGIN.2 + 8.0)] {
            let _ = write!(
                out,
                "<text x=\"{}\" y=\"{anchor}\" font-size=\"10\" text-anchor=\"end\">{}</text>",
                left - 4.0,
                num(value)
            );
        }
        for (value, anchor) in [(self.x.0, "start"), (self.x.1, "end")] {
            let _ = write!(
                out,
                "<text x=\"{}\" y=\"{}\" font-size=\"10\" text-anchor=\"{anchor}\">t = {}</text>",
                self.px(value),
                HEIGHT - 6.0,
                num(value)
            );
        }
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
            "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.2\" points=\"{}\"/>",
            points.join(" ")
        );
    }

    fn dots(&self, out: &mut String, xs: &[f64], ys: &[f64]) {
        let stride = (xs.len() / MAX_POINTS).max(1);
        for i in (0..xs.len().min(ys.len())).step_by(stride) {
            let _ = write!(
                out,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"1.1\" fill=\"#999\"/>",
                self.px(xs[i]),
                self.py(ys[i])
            );
        }
    }
}

fn svg_open(out: &mut String) {
    let _ = write!(out, "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH}\" height=\"{HEIGHT}\" viewBox=\"0 0 {WIDTH} {HEIGHT}\">");
}

fn state_plot(series: &Series, k: usize) -> String {
    let mut out = String::new();
    svg_open(&mut out);
    let mut columns: Vec<&[f64]> = vec![&series.data[k]];
    columns.extend(series.before.get(k).map(Vec::as_slice));
    let frame = Frame::new(&series.times, &columns);
    frame.axes(&mut out);
    frame.dots(&mut out, &series.times, &series.data[k]);
    if let Some(before) = series.before.get(k) {
        frame.polyline(&mut out, &series.times, before, "#c0392b");
    }
    if let Some(after) = series.after.as_ref().and_then(|a| a.get(k)) {
        frame.polyline(&mut out, &series.times, after, "#2471a3");
    }
    if let Some(&split) = series.times.get(series.first_scored) {
        let x = frame.px(split);
        let _ = write!(out, "<line x1=\"{x}\" y1=\"{}\" x2=\"{x}\" y2=\"{}\" stroke=\"#444\" stroke-dasharray=\"4 3\"/>", MARGIN.2, HEIGHT - MARGIN.3);
    }
    out.push_str("</svg>");
    out
}

fn error_plot(report: &Report) -> String {
    let series = &report.series;
    let times = &series.times[series.first_scored..];
    let mut out = String::new();
    svg_open(&mut out);
    let frame = Frame::new(times, &[&series.errors]);
    for window in report.windows.iter().take(3) {
        let (x0, x1) = (frame.px(window.t_start), frame.px(window.t_end));
        let _ = write!(
            out,
            "<rect x=\"{x0:.1}\" y=\"{}\" width=\"{:.1}\" height=\"{}\" fill=\"#f9e79f\"/>",
            MARGIN.2,
            (x1 - x0).max(1.0),
            HEIGHT - MARGIN.2 - MARGIN.3
        );
    }
    frame.axes(&mut out);
    frame.polyline(&mut out, times, &series.errors, "#c0392b");
    out.push_str("</svg>");
    out
}

/// Horizontal bars of the gaps on a logarithmic scale.
fn bars(report: &Report) -> String {
    let mut rows: Vec<(String, f64)> = vec![("before".into(), report.gap_before)];
    if let Some(best) = report.effects.first() {
        rows.push((format!("after {}", best.name), best.gap_after));
    }
    if let Some(combined) = &report.combined {
        rows.push((
            format!("after {}", combined.names.join(" + ")),
            combined.gap_after,
        ));
    }
    if let Some(locus) = report.locus.first() {
        rows.push((
            format!("free correction at {}", locus.name),
            locus.bound_after,
        ));
    }
    rows.push(("noise floor".into(), report.noise_floor));
    let finite: Vec<f64> = rows
        .iter()
        .map(|r| r.1)
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let lo = finite
        .iter()
        .fold(f64::INFINITY, |m, v| m.min(*v))
        .log10()
        .floor()
        - 0.5;
    let hi = finite
        .iter()
        .fold(f64::NEG_INFINITY, |m, v| m.max(*v))
        .log10()
        .ceil();
    let (label_width, bar_height) = (260.0, 22.0);
    let height = rows.len() as f64 * bar_height + 10.0;
    let mut out =
        format!("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH}\" height=\"{height}\">");
    for (index, (label, gap)) in rows.iter().enumerate() {
        let y = 5.0 + index as f64 * bar_height;
        let fraction = if gap.is_finite() && *gap > 0.0 && hi > lo {
            ((gap.log10() - lo) / (hi - lo)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        let length = fraction * (WIDTH - label_width - 90.0);
        let shrink = 1.0 - gap / report.gap_before;
        let _ = write!(
            out,
            "<text x=\"{}\" y=\"{}\" font-size=\"12\" text-anchor=\"end\">{}</text>\
             <rect x=\"{label_width}\" y=\"{y}\" width=\"{length:.1}\" height=\"{}\" fill=\"{}\"/>\
             <text x=\"{}\" y=\"{}\" font-size=\"11\">{} ({})</text>",
            label_width - 6.0,
            y + 15.0,
            escape(label),
            bar_height - 6.0,
            if index == 0 { "#c0392b" } else { "#2471a3" },
            label_width + length + 4.0,
            y + 14.0,
            num(*gap),
            if index == 0 {
                "log scale".to_string()
            } else {
                percent(-shrink)
            }
        );
    }
    out.push_str("</svg>");
    out
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
        let frame = Frame::new(&[0.0, 10.0], &[&[1.0, 3.0]]);
        assert_eq!(frame.px(0.0), MARGIN.0);
        assert_eq!(frame.px(10.0), WIDTH - MARGIN.1);
        assert_eq!(frame.py(1.0), HEIGHT - MARGIN.3);
        assert_eq!(frame.py(3.0), MARGIN.2);
        // A constant series gets a unit band around it instead of a zero-height range.
        let flat = Frame::new(&[0.0, 1.0], &[&[2.0, 2.0]]);
        assert_eq!(flat.y, (1.0, 3.0));
    }
}
