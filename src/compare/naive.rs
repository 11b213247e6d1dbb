//! The naive forecast: what the training experiments did, on average, at the same time
//! since their start, with no model at all.
//!
//! The rule (`docs/compare.md`): each training experiment's measured cells of a state are
//! joined by straight lines in time since the experiment's first row; at a time `tau` since
//! the held-out experiment's first row, the forecast is the mean over the training
//! experiments whose cells of that state reach both sides of `tau` (first cell at or before
//! it, last at or after it) of their lines' values there. Where no experiment reaches `tau`
//! (before every first cell or after every last one) each experiment's nearest cell is held
//! and those are averaged. A state no training experiment measures has no forecast.

use crate::record::measure::cell_error;
use crate::record::{Normalisation, Record};
use crate::train::ErrorSet;

use super::comparison::Curve;

/// One training experiment's measured cells of one state: `(time since start, value)`,
/// in time order.
type Cells = Vec<(f64, f64)>;

/// The naive forecast of every state of `training`'s records.
#[derive(Debug, Clone, PartialEq)]
pub struct Naive {
    /// `cells[state][experiment]`.
    cells: Vec<Vec<Cells>>,
}

impl Naive {
    /// The forecast from `training` (records of one model: the same states).
    pub fn new(training: &[Record]) -> Naive {
        let states = training.first().map_or(0, |r| r.states.len());
        let cells = (0..states)
            .map(|state| {
                (training.iter())
                    .map(|record| {
                        let start = record.times.first().copied().unwrap_or(0.0);
                        (record.times.iter().zip(&record.states[state]))
                            .filter_map(|(t, cell)| cell.map(|v| (t - start, v)))
                            .collect::<Cells>()
                    })
                    .filter(|cells| !cells.is_empty())
                    .collect()
            })
            .collect();
        Naive { cells }
    }

    /// The forecast of `state` at `tau` since the start (`None`: no training experiment
    /// measures it).
    pub fn at(&self, state: usize, tau: f64) -> Option<f64> {
        let experiments = self.cells.get(state)?;
        let covering: Vec<f64> = (experiments.iter())
            .filter_map(|cells| interpolate(cells, tau))
            .collect();
        let values = if covering.is_empty() {
            (experiments.iter())
                .filter_map(|cells| nearest(cells, tau))
                .collect()
        } else {
            covering
        };
        (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
    }

    /// The forecast along `record`'s rows.
    pub fn curve(&self, record: &Record) -> Curve {
        let start = record.times.first().copied().unwrap_or(0.0);
        let states = (0..record.states.len())
            .map(|state| {
                (record.times.iter())
                    .map(|t| self.at(state, t - start).unwrap_or(f64::NAN))
                    .collect()
            })
            .collect();
        Curve {
            times: record.times.clone(),
            states,
        }
    }

    /// Its error on `record`'s measured state cells after the first row, z-scored by
    /// `normalisation` (the one error measure; `None` without a scored cell). `names` are
    /// the states' names.
    pub fn error(
        &self,
        record: &Record,
        normalisation: &Normalisation,
        names: &[String],
    ) -> Option<ErrorSet> {
        let start = record.times.first().copied().unwrap_or(0.0);
        let mut errors = crate::record::measure::StateErrors::new(names.len());
        let mut rows = 0;
        for (row, &t) in record.times.iter().enumerate().skip(1) {
            let mut scored = false;
            for (state, cells) in record.states.iter().enumerate() {
                let (Some(measured), Some(forecast)) = (cells[row], self.at(state, t - start))
                else {
                    continue;
                };
                let std = normalisation.state_std.get(state).copied().unwrap_or(1.0);
                errors.add(state, cell_error(forecast, measured, std));
                scored = true;
            }
            rows += usize::from(scored);
        }
        let cells = errors.cells();
        (cells > 0).then(|| ErrorSet {
            per_state: (names.iter().zip(errors.nmse()))
                .filter_map(|(name, nmse)| Some((name.clone(), nmse?)))
                .collect(),
            overall: errors.error(),
            rows,
            cells,
            divergence: None,
        })
    }
}

/// The line through `cells` at `tau`, when `tau` lies between the first and last cell.
fn interpolate(cells: &[(f64, f64)], tau: f64) -> Option<f64> {
    let (first, last) = (cells.first()?, cells.last()?);
    if tau < first.0 || tau > last.0 {
        return None;
    }
    let after = cells.partition_point(|c| c.0 < tau);
    let Some(&(t1, v1)) = cells.get(after) else {
        return Some(last.1);
    };
    if after == 0 || t1 == tau {
        return Some(v1);
    }
    let (t0, v0) = cells[after - 1];
    Some(v0 + (v1 - v0) * (tau - t0) / (t1 - t0))
}

/// The value of the cell nearest `tau` in time (the first or the last).
fn nearest(cells: &[(f64, f64)], tau: f64) -> Option<f64> {
    let (first, last) = (cells.first()?, cells.last()?);
    Some(if tau < first.0 { first.1 } else { last.1 })
}
