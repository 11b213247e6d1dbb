//! Bar charts: grouped vertical bars (one group per category, one bar per named value
//! set, keyed in a legend) and labelled horizontal bars (one row each, a label left of the
//! bar and a text after its end) on a linear or log value axis.

use std::fmt::Write;

use super::axis::Axis;
use super::frame::{
    legend_width, open, text, text_width, write_legend, Entry, Frame, CHAR_WIDTH, LEGEND_GAP,
    MARGIN_BOTTOM, MARGIN_LEFT, MARGIN_RIGHT, MARGIN_TOP,
};
use super::style::{Style, MARKER_RADIUS, PALETTE};

/// Grouped bars: one group per category, one bar per named value set.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BarChart {
    /// Title.
    pub title: String,
    /// Label of the value axis (with its unit).
    pub y_label: String,
    /// Category names along the x axis.
    pub categories: Vec<String>,
    /// `(name, one value per category)`.
    pub groups: Vec<(String, Vec<f64>)>,
}

impl BarChart {
    /// Renders the bars as SVG (values below zero are drawn from zero downwards).
    pub fn to_svg(&self, width: f64, height: f64) -> String {
        let values = (self.groups.iter())
            .flat_map(|(_, v)| v.iter().copied())
            .chain([0.0]);
        let y = Axis::new(values, false, height - MARGIN_BOTTOM - 20.0, MARGIN_TOP);
        let names = self.groups.iter().map(|(n, _)| n.as_str());
        let right = width - MARGIN_RIGHT - legend_width(names);
        let x = Axis::new([0.0, 1.0].into_iter(), false, MARGIN_LEFT, right);
        let mut svg = String::new();
        let _ = open(&mut svg, width, height);
        // The x axis only places the bars: no numeric ticks under the category names.
        let frame = Frame {
            title: &self.title,
            x_label: "",
            y_label: &self.y_label,
            x: (&x, false),
            y: (&y, true),
        };
        let _ = frame.write(&mut svg, width, height);
        let slot = (right - MARGIN_LEFT) / self.categories.len().max(1) as f64;
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
            let at = (left + slot * 0.4, height - MARGIN_BOTTOM - 4.0);
            let middle = r#" text-anchor="middle""#;
            let _ = text(&mut svg, at, middle, (category, CHAR_WIDTH), slot);
        }
        let entries: Vec<Entry> = (self.groups.iter().enumerate())
            .map(|(g, (name, _))| Entry {
                name,
                color: PALETTE[g % PALETTE.len()],
                style: Style::Line,
                radius: MARKER_RADIUS,
                shaded: false,
            })
            .collect();
        let _ = write_legend(&mut svg, &entries, (right + LEGEND_GAP, width - 4.0));
        svg.push_str("</svg>\n");
        svg
    }
}

/// One horizontal bar.
#[derive(Debug, Clone, PartialEq)]
pub struct Bar {
    /// Text left of the bar.
    pub label: String,
    /// Its length on the value axis; a value the axis cannot show (not finite, or not
    /// positive on a log axis) gets no bar, only its text.
    pub value: f64,
    /// Its colour.
    pub color: String,
    /// Text after the bar's end (the value, a note).
    pub text: String,
}

impl Bar {
    /// A bar of `value` labelled `label` in `color`, with `text` after it.
    pub fn new(label: &str, value: f64, color: &str, text: &str) -> Self {
        Bar {
            label: label.to_string(),
            value,
            color: color.to_string(),
            text: text.to_string(),
        }
    }
}

/// The largest share of the plot's width the texts after the bars may take.
const TEXT_SHARE: f64 = 0.6;

/// Horizontal bars, one row each, from the left end of the value axis (log) or from zero
/// (linear); the figure's height follows from the number of rows.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Bars {
    /// Title.
    pub title: String,
    /// Label of the value axis (with its unit).
    pub value_label: String,
    /// Log-scale value axis.
    pub log: bool,
    /// The rows, top to bottom.
    pub rows: Vec<Bar>,
}

/// Height of one row of [`Bars`], and of its bar.
const ROW: f64 = 20.0;
const BAR: f64 = 14.0;

impl Bars {
    /// Height in pixels of the figure [`Bars::to_svg`] draws.
    pub fn height(&self) -> f64 {
        MARGIN_TOP + ROW * self.rows.len().max(1) as f64 + 8.0 + MARGIN_BOTTOM
    }

    /// Renders the bars as an SVG document `width` pixels wide.
    pub fn to_svg(&self, width: f64) -> String {
        let height = self.height();
        let longest = |texts: &mut dyn Iterator<Item = &String>| {
            texts.map(|t| text_width(t, CHAR_WIDTH)).fold(0.0, f64::max)
        };
        // Labels take what they need up to 45 % of the width (beyond it they are squeezed);
        // the texts after the bars get room right of the longest bar.
        let label_room = longest(&mut self.rows.iter().map(|r| &r.label)).min(0.45 * width);
        let left = 10.0 + label_room + 8.0;
        let area_right = width - MARGIN_RIGHT;
        let text_room = longest(&mut self.rows.iter().map(|r| &r.text)) + 8.0;
        let x = self.value_axis((left, area_right), text_room);
        let y = Axis::new(
            [0.0, 1.0].into_iter(),
            false,
            height - MARGIN_BOTTOM,
            MARGIN_TOP,
        );
        let mut svg = String::new();
        let _ = open(&mut svg, width, height);
        let frame = Frame {
            title: &self.title,
            x_label: &self.value_label,
            y_label: "",
            x: (&x, true),
            y: (&y, false),
        };
        let _ = frame.write(&mut svg, width, height);
        let origin = if x.log { x.start } else { x.pixel(0.0) };
        for (index, row) in self.rows.iter().enumerate() {
            let top = MARGIN_TOP + 4.0 + index as f64 * ROW;
            let baseline = top + BAR - 3.0;
            let end = if x.valid(row.value) {
                let end = x.pixel(row.value).clamp(x.start, x.end);
                let _ = writeln!(
                    svg,
                    r#"<rect x="{:.1}" y="{top:.1}" width="{:.1}" height="{BAR}" fill="{}"/>"#,
                    origin.min(end),
                    (end - origin).abs().max(1.0),
                    row.color
                );
                end.max(origin)
            } else {
                origin
            };
            let label = (row.label.as_str(), CHAR_WIDTH);
            let anchor = r#" text-anchor="end""#;
            let _ = text(&mut svg, (left - 6.0, baseline), anchor, label, label_room);
            let after = (row.text.as_str(), CHAR_WIDTH);
            let _ = text(
                &mut svg,
                (end + 4.0, baseline),
                "",
                after,
                area_right - end - 6.0,
            );
        }
        svg.push_str("</svg>\n");
        svg
    }

    /// The value axis from `start` to `end` pixels, its largest value `text_room` pixels
    /// short of `end` (the texts after the bars stay inside the plot); on a log axis the
    /// smallest value still gets a visible bar. The texts get at most [`TEXT_SHARE`] of the
    /// width: a long text would otherwise stretch the axis past any number.
    fn value_axis(&self, (start, end): (f64, f64), text_room: f64) -> Axis {
        let text_room = text_room.min(TEXT_SHARE * (end - start));
        let values = self.rows.iter().map(|r| r.value);
        let data = if self.log {
            let lowest = (values.clone())
                .filter(|v| v.is_finite() && *v > 0.0)
                .fold(f64::INFINITY, f64::min);
            Axis::new(values.chain([lowest / 2.0]), true, start, end - text_room)
        } else {
            Axis::new(values.chain([0.0]), false, start, end - text_room)
        };
        let room = (end - start - text_room).max(1.0);
        let stretch = (end - start) / room;
        let hi = if data.log {
            let (lo, hi) = (data.lo.log10(), data.hi.log10());
            10f64.powf(lo + (hi - lo) * stretch)
        } else {
            data.lo + (data.hi - data.lo) * stretch
        };
        Axis { hi, end, ..data }
    }
}
