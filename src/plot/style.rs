//! How series look in every report: their drawing style, the shared colours, the shading
//! of bands and the size of markers.

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

impl Style {
    /// The SVG attribute that dashes a line drawn in this style (empty for the others).
    pub(super) fn dash(self) -> &'static str {
        if self == Style::Dashed {
            r#" stroke-dasharray="5,3""#
        } else {
            ""
        }
    }
}

/// Opacity of a band's shading (and of its legend sample).
pub(super) const BAND_OPACITY: f64 = 0.18;

/// Radius of markers unless a series says otherwise, in pixels.
pub const MARKER_RADIUS: f64 = 3.0;

/// Colour of measured data and of the truth in every report.
pub const DATA_COLOR: &str = "#000000";
/// Colour of the line where training ends and validation starts, in every report.
pub const SPLIT_COLOR: &str = "#888888";

/// Colours cycled through by series without an explicit colour.
pub const PALETTE: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
];
