//! Plain SVG figures for every report (`gbc experiment`, `gbc demo`, `gbc train`, `gbc
//! diagnose --html`), drawn in one place so they look alike: line and marker series with
//! optional shaded bands and vertical marks on linear or log axes ([`Chart`]), grouped
//! vertical bars ([`BarChart`]), labelled horizontal bars ([`Bars`]), and the HTML page
//! around them ([`page`], [`figure`]).
//!
//! The look: axis titles carry units ([`titled`]); legends sit right of the plot, never
//! over the data, each sample drawn as its series is (dashed lines keyed dashed); text
//! that would not fit its room is squeezed into it rather than cut. The output is
//! deterministic text with no fonts or external files; embed the SVG inline in HTML.
//!
//! An in-house renderer rather than the `plotters` crate: the figures need few primitives
//! (lines, circles, rectangles, text), the SVG stays small and diffable, and layout rules
//! such as the legend's place are ours to keep.

mod axis;
mod bar;
mod frame;
mod line;
mod markup;
mod page;
mod points;
mod style;
#[cfg(test)]
mod tests;

pub use axis::tick_label;
#[cfg(test)]
pub use axis::{linear_ticks, log_ticks};
pub use bar::{Bar, BarChart, Bars};
pub use line::{Chart, Series};
pub use markup::escape;
pub use page::{figure, page};
pub use points::{clip, thin, titled, widened_range, MAX_POINTS};
pub use style::{Style, DATA_COLOR, PALETTE, SPLIT_COLOR};
