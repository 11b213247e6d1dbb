//! What every chart draws around its data: the SVG document, the title, the grid with its
//! tick labels, the border of the plot area, the axis titles, and the legend right of the
//! plot (never over the data). Text that would not fit its room is squeezed into it.

use std::fmt::Write;

use super::axis::{tick_label, Axis};
use super::markup::escape;
use super::style::{Style, BAND_OPACITY};

/// Room left of the plot area (tick labels and the turned y-axis title), in pixels.
pub(super) const MARGIN_LEFT: f64 = 70.0;
/// Room right of the plot area (or of the legend).
pub(super) const MARGIN_RIGHT: f64 = 20.0;
/// Room above the plot area (the title).
pub(super) const MARGIN_TOP: f64 = 34.0;
/// Room below the plot area (tick labels and the x-axis title).
pub(super) const MARGIN_BOTTOM: f64 = 46.0;
/// Space between the plot and its legend, in pixels.
pub(super) const LEGEND_GAP: f64 = 12.0;
/// Estimated width of a character of 11-pixel sans-serif text (generous, so that text
/// sized by it fits).
pub(super) const CHAR_WIDTH: f64 = 6.5;
/// Most characters on one line of a legend entry (longer names wrap at spaces).
const LEGEND_CHARS: usize = 28;
/// Width of a legend entry's sample and the space after it.
const SAMPLE_WIDTH: f64 = 26.0;
/// Height of one line of legend text, and the space between entries.
const LEGEND_LINE: f64 = 13.0;
const LEGEND_SPACING: f64 = 4.0;

/// Estimated width of `text` at `char_width` pixels a character.
pub(super) fn text_width(text: &str, char_width: f64) -> f64 {
    text.chars().count() as f64 * char_width
}

/// The start of an SVG document of `width` x `height` pixels on a white background.
pub(super) fn open(svg: &mut String, width: f64, height: f64) -> std::fmt::Result {
    writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">"#
    )?;
    writeln!(
        svg,
        r#"<rect width="{width}" height="{height}" fill="white"/>"#
    )
}

/// A `<text>` element with `attributes` at `(x, y)`, squeezed to `room` pixels where its
/// estimated width (at `char_width`) is larger.
pub(super) fn text(
    svg: &mut String,
    (x, y): (f64, f64),
    attributes: &str,
    (content, char_width): (&str, f64),
    room: f64,
) -> std::fmt::Result {
    let squeeze = if text_width(content, char_width) > room && room > 0.0 {
        format!(r#" textLength="{room:.0}" lengthAdjust="spacingAndGlyphs""#)
    } else {
        String::new()
    };
    writeln!(
        svg,
        r#"<text x="{x:.1}" y="{y:.1}"{attributes}{squeeze}>{}</text>"#,
        escape(content)
    )
}

/// The frame of a chart: the title, the axes (`x.start..x.end`, `y.end..y.start` is the
/// plot area), which of them get ticks, and the axis titles.
pub(super) struct Frame<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub x: (&'a Axis, bool),
    pub y: (&'a Axis, bool),
}

impl Frame<'_> {
    /// Draws the frame on a figure `width` x `height`.
    pub fn write(&self, svg: &mut String, width: f64, height: f64) -> std::fmt::Result {
        let ((x, x_ticks), (y, y_ticks)) = (self.x, self.y);
        let (left, right, top, bottom) = (x.start, x.end, y.end, y.start);
        let title = (self.title, 7.8);
        text(
            svg,
            (width / 2.0, 18.0),
            r#" text-anchor="middle" font-size="13" font-weight="bold""#,
            title,
            width - 20.0,
        )?;
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
        for tick in y.ticks().into_iter().filter(|_| y_ticks) {
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
        let x_title = (self.x_label, CHAR_WIDTH);
        let middle = r#" text-anchor="middle""#;
        text(
            svg,
            ((left + right) / 2.0, height - 8.0),
            middle,
            x_title,
            width - 20.0,
        )?;
        let centre = (top + bottom) / 2.0;
        let turned = format!(r#" text-anchor="middle" transform="rotate(-90 14 {centre:.1})""#);
        let y_title = (self.y_label, CHAR_WIDTH);
        text(svg, (14.0, centre), &turned, y_title, bottom - top)
    }
}

/// One legend entry: its name, and its sample drawn as the thing it keys is drawn.
pub(super) struct Entry<'a> {
    pub name: &'a str,
    pub color: &'a str,
    pub style: Style,
    /// Marker radius (markers only).
    pub radius: f64,
    /// A band's entry: its sample is a shaded box, not the series' line or marker.
    pub shaded: bool,
}

/// `name` broken at spaces into lines of at most [`LEGEND_CHARS`] characters (a longer
/// word keeps a line of its own).
fn wrap(name: &str) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    for word in name.split(' ') {
        match lines.last_mut() {
            Some(line) if line.chars().count() + 1 + word.chars().count() <= LEGEND_CHARS => {
                line.push(' ');
                line.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    lines
}

/// Width of a legend of `names` (sample, then the longest wrapped line), plus the gap
/// before it; zero without names.
pub(super) fn legend_width<'a>(names: impl Iterator<Item = &'a str>) -> f64 {
    let longest = (names.flat_map(wrap))
        .map(|line| line.chars().count())
        .max();
    longest.map_or(0.0, |chars| {
        (SAMPLE_WIDTH + CHAR_WIDTH * chars.min(LEGEND_CHARS) as f64).max(60.0) + LEGEND_GAP
    })
}

/// The legend from `x` (right of the plot) to `right`: each entry's sample drawn as its
/// series is (a dashed line dashed, markers as a dot), then its name, wrapped.
pub(super) fn write_legend(
    svg: &mut String,
    entries: &[Entry],
    (x, right): (f64, f64),
) -> std::fmt::Result {
    let mut y = MARGIN_TOP + 10.0;
    // A series without a name is drawn but not keyed (the faint replicates beside one that
    // is).
    for entry in entries.iter().filter(|e| !e.name.is_empty()) {
        let color = entry.color;
        let dash = entry.style.dash();
        if entry.shaded {
            writeln!(
                svg,
                r#"<rect x="{x}" y="{}" width="20" height="10" fill="{color}" fill-opacity="{}"/>"#,
                y - 9.0,
                BAND_OPACITY
            )?;
        } else if entry.style != Style::Markers {
            writeln!(
                svg,
                r#"<line x1="{x}" y1="{0}" x2="{1}" y2="{0}" stroke="{color}" stroke-width="2"{dash}/>"#,
                y - 4.0,
                x + 20.0,
            )?;
        }
        if !entry.shaded && matches!(entry.style, Style::Markers | Style::LineMarkers) {
            writeln!(
                svg,
                r#"<circle cx="{}" cy="{}" r="{}" fill="{color}"/>"#,
                x + 10.0,
                y - 4.0,
                entry.radius.max(2.5)
            )?;
        }
        for line in wrap(entry.name) {
            let room = right - x - SAMPLE_WIDTH;
            text(svg, (x + SAMPLE_WIDTH, y), "", (&line, CHAR_WIDTH), room)?;
            y += LEGEND_LINE;
        }
        y += LEGEND_SPACING;
    }
    Ok(())
}
