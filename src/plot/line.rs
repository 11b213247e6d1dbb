//! x–y charts: named series of points drawn as lines, dashed lines, markers or both, with
//! optional shaded bands, vertical marks (a split, an event) and linear or log axes.

use std::fmt::Write;

use super::axis::Axis;
use super::frame::{
    legend_width, open, write_legend, Entry, Frame, LEGEND_GAP, MARGIN_BOTTOM, MARGIN_LEFT,
    MARGIN_RIGHT, MARGIN_TOP,
};
use super::style::{Style, BAND_OPACITY, MARKER_RADIUS, PALETTE};

/// One named series of points, optionally with a band (`lower`, `upper` per point).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// The points, in drawing order.
    pub points: Vec<(f64, f64)>,
    /// A shaded band around the series (same length as `points`), e.g. replicate spread.
    pub band: Option<Vec<(f64, f64)>>,
    /// The band's legend text (empty: the band is not keyed).
    pub band_name: String,
    /// How it is drawn.
    pub style: Style,
    /// Colour, or `None` for the palette.
    pub color: Option<String>,
    /// Radius of its markers in pixels (small for dense data).
    pub radius: f64,
}

impl Series {
    /// A series drawn as a line.
    pub fn line(name: &str, points: Vec<(f64, f64)>) -> Self {
        Series {
            name: name.to_string(),
            points,
            band: None,
            band_name: String::new(),
            style: Style::Line,
            color: None,
            radius: MARKER_RADIUS,
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
    /// The same series with a band keyed in the legend as `name` (a shaded sample after
    /// the series' own entry).
    pub fn with_named_band(mut self, band: Vec<(f64, f64)>, name: &str) -> Self {
        self.band = Some(band);
        self.band_name = name.to_string();
        self
    }
    /// The same series in a given colour.
    pub fn colored(mut self, color: &str) -> Self {
        self.color = Some(color.to_string());
        self
    }
    /// The same series with markers of another radius.
    pub fn sized(mut self, radius: f64) -> Self {
        self.radius = radius;
        self
    }
}

/// A vertical line across the whole plot at one x value (where validation starts, an
/// event), keyed in the legend like a series; it does not widen the y axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Mark {
    /// Legend text.
    pub name: String,
    /// Where it stands.
    pub x: f64,
    /// [`Style::Line`] or [`Style::Dashed`].
    pub style: Style,
    /// Its colour.
    pub color: String,
}

/// An x–y chart.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// Label of the x axis (with its unit).
    pub x_label: String,
    /// Label of the y axis (with its unit).
    pub y_label: String,
    /// Log-scale x axis (non-positive values are dropped).
    pub x_log: bool,
    /// Log-scale y axis (non-positive values are dropped).
    pub y_log: bool,
    /// Values the y axis covers besides the data (e.g. zero).
    pub y_include: Vec<f64>,
    /// The series.
    pub series: Vec<Series>,
    /// Vertical marks, drawn over the series.
    pub marks: Vec<Mark>,
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
    /// Adds a vertical mark at `x`.
    pub fn with_mark(mut self, name: &str, x: f64, style: Style, color: &str) -> Self {
        self.marks.push(Mark {
            name: name.to_string(),
            x,
            style,
            color: color.to_string(),
        });
        self
    }
    /// Uses a log scale on the x and/or y axis.
    pub fn log_axes(mut self, x_log: bool, y_log: bool) -> Self {
        self.x_log = x_log;
        self.y_log = y_log;
        self
    }
    /// Makes the y axis reach `value` whatever the data (e.g. zero under an error).
    pub fn including_y(mut self, value: f64) -> Self {
        self.y_include.push(value);
        self
    }

    /// The colour of the series at `index`: its own, else the palette's.
    fn color(&self, index: usize) -> &str {
        self.series[index]
            .color
            .as_deref()
            .unwrap_or(PALETTE[index % PALETTE.len()])
    }

    /// Renders the chart as an SVG document of `width` x `height` pixels.
    pub fn to_svg(&self, width: f64, height: f64) -> String {
        let ys = self.series.iter().flat_map(|s| {
            let band = s.band.iter().flatten().flat_map(|(a, b)| [*a, *b]);
            s.points.iter().map(|p| p.1).chain(band)
        });
        let xs = (self.series.iter())
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .chain(self.marks.iter().map(|m| m.x));
        let names = (self.series.iter())
            .flat_map(|s| [s.name.as_str(), s.band_name.as_str()])
            .chain(self.marks.iter().map(|m| m.name.as_str()));
        // The legend sits right of the plot, never over the data.
        let right = width - MARGIN_RIGHT - legend_width(names);
        let x = Axis::new(xs, self.x_log, MARGIN_LEFT, right);
        let ys = ys.chain(self.y_include.iter().copied());
        let y = Axis::new(ys, self.y_log, height - MARGIN_BOTTOM, MARGIN_TOP);
        let mut svg = String::new();
        let _ = open(&mut svg, width, height);
        let frame = Frame {
            title: &self.title,
            x_label: &self.x_label,
            y_label: &self.y_label,
            x: (&x, true),
            y: (&y, true),
        };
        let _ = frame.write(&mut svg, width, height);
        for (index, series) in self.series.iter().enumerate() {
            let _ = write_series(&mut svg, series, self.color(index), &x, &y);
        }
        for mark in self.marks.iter().filter(|m| x.valid(m.x)) {
            let px = x.pixel(mark.x);
            let _ = writeln!(
                svg,
                r#"<line x1="{px:.1}" y1="{}" x2="{px:.1}" y2="{}" stroke="{}" stroke-width="1.5"{}/>"#,
                y.end,
                y.start,
                mark.color,
                mark.style.dash()
            );
        }
        let series = (self.series.iter().enumerate()).flat_map(|(index, series)| {
            let entry = |name, shaded| Entry {
                name,
                color: self.color(index),
                style: series.style,
                radius: series.radius,
                shaded,
            };
            [entry(&series.name, false), entry(&series.band_name, true)]
        });
        let marks = self.marks.iter().map(|mark| Entry {
            name: &mark.name,
            color: &mark.color,
            style: mark.style,
            radius: MARKER_RADIUS,
            shaded: false,
        });
        let entries: Vec<Entry> = series.chain(marks).collect();
        let _ = write_legend(&mut svg, &entries, (right + LEGEND_GAP, width - 4.0));
        svg.push_str("</svg>\n");
        svg
    }
}

fn write_series(
    svg: &mut String,
    series: &Series,
    color: &str,
    x: &Axis,
    y: &Axis,
) -> std::fmt::Result {
    if let Some(band) = &series.band {
        // (x, lower, upper) of each point whose band can be drawn.
        let edges: Vec<(f64, f64, f64)> = (series.points.iter().zip(band))
            .map(|((px, _), (lo, hi))| (*px, *lo, *hi))
            .filter(|(px, lo, hi)| x.valid(*px) && y.valid(*lo) && y.valid(*hi))
            .collect();
        let upper = (edges.iter()).map(|(px, _, hi)| pixel_pair(x, y, *px, *hi));
        let lower = (edges.iter().rev()).map(|(px, lo, _)| pixel_pair(x, y, *px, *lo));
        writeln!(
            svg,
            r#"<polygon points="{}" fill="{color}" fill-opacity="{BAND_OPACITY}" stroke="none"/>"#,
            upper.chain(lower).collect::<Vec<_>>().join(" ")
        )?;
    }
    let pixels: Vec<(f64, f64)> = (series.points.iter())
        .filter(|(px, py)| x.valid(*px) && y.valid(*py))
        .map(|(px, py)| (x.pixel(*px), y.pixel(*py)))
        .collect();
    let lined = matches!(
        series.style,
        Style::Line | Style::Dashed | Style::LineMarkers
    );
    if lined && pixels.len() > 1 {
        let path: Vec<String> = (pixels.iter())
            .map(|(a, b)| format!("{a:.1},{b:.1}"))
            .collect();
        writeln!(
            svg,
            r#"<polyline points="{}" fill="none" stroke="{color}" stroke-width="1.5"{}/>"#,
            path.join(" "),
            series.style.dash()
        )?;
    }
    if matches!(series.style, Style::Markers | Style::LineMarkers) {
        let radius = series.radius;
        for (a, b) in pixels {
            writeln!(
                svg,
                r#"<circle cx="{a:.1}" cy="{b:.1}" r="{radius}" fill="{color}"/>"#
            )?;
        }
    }
    Ok(())
}

/// `x,y` of a data point in pixels.
fn pixel_pair(x: &Axis, y: &Axis, vx: f64, vy: f64) -> String {
    format!("{:.1},{:.1}", x.pixel(vx), y.pixel(vy))
}
