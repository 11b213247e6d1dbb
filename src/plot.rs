//! Plain SVG charts for reports (`gbc experiment`, `gbc demo`, `gbc diagnose --html`): line
//! and marker series with optional shaded bands on linear or log axes, and grouped bars.
//! Deterministic text output, no fonts or external files; embed the SVG inline in HTML.

use std::fmt::Write;

/// Colours cycled through by series without an explicit colour.
pub const PALETTE: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
];

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Style {
    /// A polyline through the points.
    Line,
    /// A dashed polyline.
    Dashed,
    /// A circle at each point.
    Markers,
    /// A polyline with a circle at each point.
    LineMarkers,
}

/// One named series of points, optionally with a band (`lower`, `upper` per point).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// A shaded band around the series (same length as `points`), e.g. replicate spread.
    pub band: Option<Vec<(f64, f64)>>,
    /// How it is drawn.
    pub style: Style,
    /// Colour, or `None` for the palette.
    pub color: Option<String>,
}

impl Series {
    /// A series drawn as a line.
    pub fn line(name: &str, points: Vec<(f64, f64)>) -> Self {
        Series {
            name: name.to_string(),
            points,
            band: None,
            style: Style::Line,
            color: None,
        }
    }
    /// The same series drawn in another style.
    pub fn styled(mut self, style: Style) -> Self {
        self.style = style;
        self
    }
    /// The same series with a band.
    pub fn with_band(mut self, band: Vec<(f64, f64)>) -> Self {
        self.band = Some(band);
        self
    }
    /// The same series in a given colour.
    pub fn colored(mut self, color: &str) -> Self {
        self.color = Some(color.to_string());
        self
    }
}

/// An x–y chart.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Log-scale x axis (non-positive values are dropped).
    pub x_log: bool,
    /// Log-scale y axis (non-positive values are dropped).
    pub y_log: bool,
    /// The series.
    pub series: Vec<Series>,
}

const MARGIN_LEFT: f64 = 70.0;
const MARGIN_RIGHT: f64 = 20.0;
const MARGIN_TOP: f64 = 34.0;
const MARGIN_BOTTOM: f64 = 46.0;

/// Escapes text for SVG/HTML.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A number formatted compactly for tick labels.
pub fn tick_label(value: f64) -> String {
    if value == 0.0 {
        return "0".to_string();
    }
    let magnitude = value.abs();
    if !(1e-3..1e5).contains(&magnitude) {
        return format!("{value:.0e}");
    }
    let text = format!("{value:.4}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    text.to_string()
}

/// "Nice" tick positions covering `[lo, hi]` on a linear axis (steps of 1, 2 or 5 x 10^k).
pub fn linear_ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let power = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * power)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * power);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// Decade ticks covering `[lo, hi]` (both > 0) on a log axis.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let first = lo.log10().ceil() as i32;
    let last = hi.log10().floor() as i32;
    let mut ticks: Vec<f64> = (first..=last).map(|k| 10f64.powi(k)).collect();
    if ticks.len() < 2 {
        ticks = linear_ticks(lo, hi, 4)
            .into_iter()
            .filter(|t| *t > 0.0)
            .collect();
    }
    ticks
}

/// An axis mapping data values to pixels.
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    start: f64,
    end: f64,
}

impl Axis {
    fn new(values: impl Iterator<Item = f64>, log: bool, start: f64, end: f64) -> Self {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if !lo.is_finite() {
            (lo, hi) = if log { (1.0, 10.0) } else { (0.0, 1.0) };
        }
        if hi <= lo {
            let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
            (lo, hi) = if log {
                (lo / 2.0, hi * 2.0)
            } else {
                (lo - pad, hi + pad)
            };
        } else if !log {
            let pad = (hi - lo) * 0.04;
            (lo, hi) = (lo - pad, hi + pad);
        }
        Axis {
            lo,
            hi,
            log,
            start,
            end,
        }
    }
    fn transform(&self, v: f64) -> f64 {
        if self.log {
            v.log10()
        } else {
            v
        }
    }
    fn pixel(&self, v: f64) -> f64 {
        let (a, b) = (self.transform(self.lo), self.transform(self.hi));
        self.start + (self.transform(v) - a) / (b - a) * (self.end - self.start)
    }
    fn ticks(&self) -> Vec<f64> {
        if self.log {
            log_ticks(self.lo, self.hi)
        } else {
            linear_ticks(self.lo, self.hi, 5)
        }
    }
    fn valid(&self, v: f64) -> bool {
        v.is_finite() && (!self.log || v > 0.0)
    }
}

impl Chart {
    /// A chart with a title and axis labels and no series yet.
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Chart {
            title: title.to_string(),
            x_label: x_label.to_string(),
            y_label: y_label.to_string(),
            ..Chart::default()
        }
    }
    /// Adds a series.
    pub fn with(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }
    /// Uses a log scale on the x and/or y axis.
    pub fn log_axes(mut self, x_log: bool, y_log: bool) -> Self {
        self.x_log = x_log;
        self.y_log = y_log;
        self
    }

    /// Renders the chart as an SVG document of `width` x `height` pixels.
    pub fn to_svg(&self, width: f64, height: f64) -> String {
        let all = || {
            self.series.iter().flat_map(|s| {
                let band = s.band.iter().flatten().flat_map(|(a, b)| [*a, *b]);
                s.points.iter().map(|p| p.1).chain(band).collect::<Vec<_>>()
            })
        };
        let xs = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.0));
        // The legend sits right of the plot, never over the data.
        let right = width - MARGIN_RIGHT - legend_width(self.series.iter().map(|s| &s.name));
        let x = Axis::new(xs, self.x_log, MARGIN_LEFT, right);
        let y = Axis::new(all(), self.y_log, height - MARGIN_BOTTOM, MARGIN_TOP);
        let mut svg = String::new();
        let _ = self.write_frame(&mut svg, (&x, true), &y, width, height);
        for (index, series) in self.series.iter().enumerate() {
            let color = series
                .color
                .clone()
                .unwrap_or_else(|| PALETTE[index % PALETTE.len()].to_string());
            let _ = write_series(&mut svg, series, &color, &x, &y);
        }
        let entries: Vec<(&str, String, Style)> = (self.series.iter().enumerate())
            .map(|(index, series)| {
                let color = (series.color.clone())
                    .unwrap_or_else(|| PALETTE[index % PALETTE.len()].to_string());
                (series.name.as_str(), color, series.style)
            })
            .collect();
        let _ = write_legend(&mut svg, &entries, right + LEGEND_GAP);
        svg.push_str("</svg>\n");
        svg
    }

    fn write_frame(
        &self,
        svg: &mut String,
        (x, x_ticks): (&Axis, bool),
        y: &Axis,
        w: f64,
        h: f64,
    ) -> std::fmt::Result {
        writeln!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="11">"#
        )?;
        writeln!(svg, r#"<rect width="{w}" height="{h}" fill="white"/>"#)?;
        writeln!(
            svg,
            r#"<text x="{}" y="18" text-anchor="middle" font-size="13" font-weight="bold">{}</text>"#,
            w / 2.0,
            escape(&self.title)
        )?;
        let (left, right, top, bottom) = (x.start, x.end, y.end, y.start);
        for tick in x.ticks().into_iter().filter(|_| x_ticks) {
            let px = x.pixel(tick);
            writeln!(
                svg,
                r##"<line x1="{px:.1}" y1="{top}" x2="{px:.1}" y2="{bottom}" stroke="#e5e5e5"/>"##
            )?;
            writeln!(
                svg,
                r#"<text x="{px:.1}" y="{}" text-anchor="middle">{}</text>"#,
                bottom + 14.0,
                tick_label(tick)
            )?;
        }
        for tick in y.ticks() {
            let py = y.pixel(tick);
            writeln!(
                svg,
                r##"<line x1="{left}" y1="{py:.1}" x2="{right}" y2="{py:.1}" stroke="#e5e5e5"/>"##
            )?;
            writeln!(
                svg,
                r#"<text x="{}" y="{:.1}" text-anchor="end">{}</text>"#,
                left - 4.0,
                py + 4.0,
                tick_label(tick)
            )?;
        }
        writeln!(
            svg,
            r##"<rect x="{left}" y="{top}" width="{}" height="{}" fill="none" stroke="#333"/>"##,
            right - left,
            bottom - top
        )?;
        writeln!(
            svg,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            (left + right) / 2.0,
            h - 8.0,
            escape(&self.x_label)
        )?;
        writeln!(
            svg,
            r#"<text x="14" y="{0}" text-anchor="middle" transform="rotate(-90 14 {0})">{1}</text>"#,
            (top + bottom) / 2.0,
            escape(&self.y_label)
        )
    }
}

/// Space between the plot and its legend, in pixels.
const LEGEND_GAP: f64 = 12.0;

/// Width of a legend of `names` (sample line, gap, text at about 6.5 pixels a character),
/// plus the gap before it; zero without names.
fn legend_width<'a>(names: impl Iterator<Item = &'a String>) -> f64 {
    let longest = names.map(|n| n.chars().count()).max();
    longest.map_or(0.0, |chars| {
        (26.0 + 6.5 * chars as f64).clamp(60.0, 220.0) + LEGEND_GAP
    })
}

/// The legend at `x` (right of the plot): each entry's sample drawn as its series is (a
/// dashed line dashed, markers as a dot), then its name.
fn write_legend(svg: &mut String, entries: &[(&str, String, Style)], x: f64) -> std::fmt::Result {
    let mut y = MARGIN_TOP + 10.0;
    for (name, color, style) in entries {
        let dash = if *style == Style::Dashed {
            r#" stroke-dasharray="5,3""#
        } else {
            ""
        };
        if *style != Style::Markers {
            writeln!(
                svg,
                r#"<line x1="{x}" y1="{0}" x2="{1}" y2="{0}" stroke="{color}" stroke-width="2"{dash}/>"#,
                y - 4.0,
                x + 20.0,
            )?;
        }
        if matches!(style, Style::Markers | Style::LineMarkers) {
            writeln!(
                svg,
                r#"<circle cx="{}" cy="{}" r="3" fill="{color}"/>"#,
                x + 10.0,
                y - 4.0
            )?;
        }
        writeln!(
            svg,
            r#"<text x="{}" y="{y}">{}</text>"#,
            x + 26.0,
            escape(name)
        )?;
        y += 15.0;
    }
    Ok(())
}

fn write_series(
    svg: &mut String,
    series: &Series,
    color: &str,
    x: &Axis,
    y: &Axis,
) -> std::fmt::Result {
    if let Some(band) = &series.band {
        let upper: Vec<String> = series
            .points
            .iter()
            .zip(band)
            .filter(|((px, _), (lo, hi))| x.valid(*px) && y.valid(*lo) && y.valid(*hi))
            .map(|((px, _), (_, hi))| format!("{:.1},{:.1}", x.pixel(*px), y.pixel(*hi)))
            .collect();
        let lower: Vec<String> = series
            .points
            .iter()
            .zip(band)
            .rev()
            .filter(|((px, _), (lo, hi))| x.valid(*px) && y.valid(*lo) && y.valid(*hi))
            .map(|((px, _), (lo, _))| format!("{:.1},{:.1}", x.pixel(*px), y.pixel(*lo)))
            .collect();
        writeln!(
            svg,
            r#"<polygon points="{} {}" fill="{color}" fill-opacity="0.18" stroke="none"/>"#,
            upper.join(" "),
            lower.join(" ")
        )?;
    }
    let pixels: Vec<(f64, f64)> = series
        .points
        .iter()
        .filter(|(px, py)| x.valid(*px) && y.valid(*py))
        .map(|(px, py)| (x.pixel(*px), y.pixel(*py)))
        .collect();
    if matches!(
        series.style,
        Style::Line | Style::Dashed | Style::LineMarkers
    ) && pixels.len() > 1
    {
        let path: Vec<String> = pixels
            .iter()
            .map(|(a, b)| format!("{a:.1},{b:.1}"))
            .collect();
        let dash = if series.style == Style::Dashed {
            r#" stroke-dasharray="5,3""#
        } else {
            ""
        };
        writeln!(
            svg,
            r#"<polyline points="{}" fill="none" stroke="{color}" stroke-width="1.5"{dash}/>"#,
            path.join(" ")
        )?;
    }
    if matches!(series.style, Style::Markers | Style::LineMarkers) {
        for (a, b) in pixels {
            writeln!(
                svg,
                r#"<circle cx="{a:.1}" cy="{b:.1}" r="3" fill="{color}"/>"#
            )?;
        }
    }
    Ok(())
}

/// Grouped bars: one group per category, one bar per named value set.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BarChart {
    /// Title.
    pub title: String,
    /// Label of the value axis.
    pub y_label: String,
    /// Category names along the x axis.
    pub categories: Vec<String>,
    /// `(name, one value per category)`.
    pub groups: Vec<(String, Vec<f64>)>,
}

impl BarChart {
    /// Renders the bars as SVG (values below zero are drawn from zero downwards).
    pub fn to_svg(&self, width: f64, height: f64) -> String {
        let values = self
            .groups
            .iter()
            .flat_map(|(_, v)| v.iter().copied())
            .chain([0.0]);
        let y = Axis::new(values, false, height - MARGIN_BOTTOM - 20.0, MARGIN_TOP);
        let right = width - MARGIN_RIGHT - legend_width(self.groups.iter().map(|(n, _)| n));
        let x = Axis::new([0.0, 1.0].into_iter(), false, MARGIN_LEFT, right);
        let chart = Chart::new(&self.title, "", &self.y_label);
        let mut svg = String::new();
        // The x axis only places the bars: no numeric ticks under the category names.
        let _ = chart.write_frame(
            &mut svg,
            (&Axis { log: false, ..x }, false),
            &y,
            width,
            height,
        );
        let plot_width = right - MARGIN_LEFT;
        let slot = plot_width / self.categories.len().max(1) as f64;
        let bar = slot * 0.8 / self.groups.len().max(1) as f64;
        let zero = y.pixel(0.0);
        for (c, category) in self.categories.iter().enumerate() {
            let left = MARGIN_LEFT + c as f64 * slot + slot * 0.1;
            for (g, (_, values)) in self.groups.iter().enumerate() {
                let value = values.get(c).copied().unwrap_or(f64::NAN);
                if !value.is_finite() {
                    continue;
                }
                let top = y.pixel(value);
                let _ = writeln!(
                    svg,
                    r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{}"/>"#,
                    left + g as f64 * bar,
                    top.min(zero),
                    bar * 0.95,
                    (zero - top).abs(),
                    PALETTE[g % PALETTE.len()]
                );
            }
            let _ = writeln!(
                svg,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
                left + slot * 0.4,
                height - MARGIN_BOTTOM - 4.0,
                escape(category)
            );
        }
        let entries: Vec<(&str, String, Style)> = (self.groups.iter().enumerate())
            .map(|(g, (name, _))| {
                (
                    name.as_str(),
                    PALETTE[g % PALETTE.len()].to_string(),
                    Style::Line,
                )
            })
            .collect();
        let _ = write_legend(&mut svg, &entries, right + LEGEND_GAP);
        svg.push_str("</svg>\n");
        svg
    }
}

/// A whole HTML page: a title, an introduction (HTML) and sections (HTML), the one style
/// of every gbc report.
pub fn page(title: &str, intro: &str, sections: &[String]) -> String {
    let mut html = String::new();
    let _ = writeln!(
        html,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\n\
         <style>body{{font-family:sans-serif;max-width:1340px;margin:2em auto;padding:0 1em;color:#222}}\
         table{{border-collapse:collapse;margin:1em 0}}td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}\
         th{{background:#f3f3f3}}figure{{display:inline-block;margin:0.5em;vertical-align:top;width:640px}}\
         figcaption{{font-size:0.85em;color:#444}}.notes{{color:#8a4b00}}</style></head><body>",
        escape(title)
    );
    let _ = writeln!(html, "<h1>{}</h1>\n{intro}", escape(title));
    for section in sections {
        html.push_str(section);
    }
    html.push_str("</body></html>\n");
    html
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_ticks_are_round_and_cover_the_range() {
        assert_eq!(
            linear_ticks(0.0, 10.0, 5),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
        let ticks = linear_ticks(0.013, 0.047, 4);
        assert!(ticks.iter().all(|t| (0.013..=0.047).contains(t)));
        assert!((ticks[1] - ticks[0] - 0.01).abs() < 1e-12, "{ticks:?}");
    }

    #[test]
    fn log_ticks_are_decades() {
        assert_eq!(log_ticks(0.003, 20.0), vec![0.01, 0.1, 1.0, 10.0]);
    }

    #[test]
    fn points_map_inside_the_plot_area() {
        let chart =
            Chart::new("t", "x", "y").with(Series::line("a", vec![(0.0, 1.0), (10.0, 3.0)]));
        let svg = chart.to_svg(400.0, 300.0);
        let polyline = svg
            .lines()
            .find(|l| l.starts_with("<polyline"))
            .unwrap_or_default();
        let numbers: Vec<f64> = polyline
            .split(['"', ' ', ','])
            .filter_map(|s| s.parse().ok())
            .collect();
        assert_eq!(numbers.len(), 5, "{polyline}"); // 4 coordinates and the stroke width
        let (x0, y0, x1, y1) = (numbers[0], numbers[1], numbers[2], numbers[3]);
        assert!(x0 > MARGIN_LEFT && x1 < 400.0 - MARGIN_RIGHT && x0 < x1);
        assert!(y0 > y1, "larger values are drawn higher");
        assert!(y0 < 300.0 - MARGIN_BOTTOM && y1 > MARGIN_TOP);
    }

    #[test]
    fn log_axes_drop_non_positive_values_and_text_is_escaped() {
        let chart = Chart::new("a < b & c", "x", "y")
            .with(Series::line(
                "s",
                vec![(1.0, 0.0), (10.0, 1.0), (100.0, 10.0)],
            ))
            .log_axes(true, true);
        let svg = chart.to_svg(300.0, 200.0);
        assert!(svg.contains("a &lt; b &amp; c"));
        let polyline = svg
            .lines()
            .find(|l| l.starts_with("<polyline"))
            .unwrap_or_default();
        assert_eq!(
            polyline.matches(',').count(),
            2,
            "two valid points: {polyline}"
        );
    }

    #[test]
    fn bars_have_one_rect_per_finite_value() {
        let bars = BarChart {
            title: "gap".into(),
            y_label: "MSE".into(),
            categories: vec!["before".into(), "after".into()],
            groups: vec![("gap".into(), vec![1.0, 0.2])],
        };
        let svg = bars.to_svg(300.0, 200.0);
        assert_eq!(svg.matches("<rect x=").count(), 3, "frame + two bars");
        // Category names label the x axis; no numeric ticks sit under them.
        let x_labels: Vec<&str> = (svg.lines())
            .filter(|l| l.contains(r#"text-anchor="middle">"#) && !l.contains("font-size"))
            .filter(|l| !l.contains("></text>"))
            .collect();
        assert_eq!(x_labels.len(), 2, "{x_labels:?}");
        assert!(x_labels[0].contains(">before<") && x_labels[1].contains(">after<"));
    }
}
