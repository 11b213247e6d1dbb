//! What every figure of a study shares: the [`Figure`] itself, its size, each model's
//! colour and the axis titles with units, and the restored representative runs the
//! trajectory figures draw.

use super::prepare::Prepared;
use crate::engine::graph::{Network, Setup};
use crate::plot::PALETTE;

/// Figure size in pixels.
pub const WIDTH: f64 = 640.0;
/// Figure height in pixels.
pub const HEIGHT: f64 = 380.0;

/// One figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// File stem (`<name>.svg`).
    pub name: String,
    /// A sentence saying what it shows.
    pub caption: String,
    /// The SVG document.
    pub svg: String,
}

/// The time axis title and the value axis title of quantity `name`, with units from the
/// first model of the study that gives `name` one.
pub fn axis_titles(prepared: &Prepared, name: &str) -> (String, String) {
    let models = prepared.models.iter().map(|m| &m.model);
    let time = (models.clone().find(|m| m.time_unit.is_some()))
        .map_or_else(|| "time".to_string(), |m| m.time_label());
    let axis = (models.clone().find(|m| m.units.names.contains_key(name)))
        .map_or_else(|| name.to_string(), |m| m.axis_label(name));
    (time, axis)
}

/// The colour of the model at `index` in the study.
pub fn color(index: usize) -> &'static str {
    PALETTE[index % PALETTE.len()]
}

/// A model's index in the study, its representative network and setup, and the run id.
pub type TrainedModel = (usize, Network, Setup, String);
