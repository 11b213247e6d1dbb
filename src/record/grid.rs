//! A record laid on its integration grid (records spec, section 3): the [`Track`] the
//! grey-box network steps along.
//!
//! - **Knots.** Every row of the record is a knot (a time at which something is measured
//!   or an input changes); an interval longer than [`GridOptions::max_step`] is cut into
//!   equal steps no longer than it. The network takes one RK4 step (of `--substeps`
//!   sub-steps) from each knot to the next. On a uniform record whose step is the maximum
//!   step, the knots are the rows: the paper's network.
//! - **Inputs** are held: at a knot, the value of the row at or before it.
//! - **Reference states.** Each measured state has a value at every knot: its measured cell
//!   where there is one; between two measurements at most its *gap limit* apart (the
//!   embedding's delay), their linear interpolant — both are *known* (from data); elsewhere
//!   (before the first measurement, after the last, across a longer gap) a provisional
//!   value (the interpolant regardless of the gap, held flat beyond the ends) that training
//!   replaces with the model's own run ([`Track::fill`]). At the first knot a state without
//!   a measured cell takes the initial value given for it.
//! - **Positions.** Embeddings read the reference at fractional knot positions: linear
//!   between knots (exact for the linear interpolant of the measurements, whose times are
//!   knots), clamped to the first knot before the record (history held at its first value)
//!   and to the last after it.

use super::experiment::Record;
use crate::numeric::rounding;

/// How a record is laid on its grid.
#[derive(Debug, Clone, PartialEq)]
pub struct GridOptions {
    /// The longest step between knots (`--dt`).
    pub max_step: f64,
    /// Per measured state: two measurements at most this far apart are joined by their
    /// linear interpolant (known from data); farther apart, the model fills the gap.
    pub gap_limits: Vec<f64>,
    /// Whether intervals longer than `max_step` are cut (not for `next` models, which step
    /// from row to row).
    pub subdivide: bool,
}

/// A record on its integration grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// The experiment's name.
    pub name: String,
    /// Knot times, strictly increasing.
    pub times: Vec<f64>,
    /// Per knot: the record row at that time (`None` for a knot cut into an interval).
    pub rows: Vec<Option<usize>>,
    /// Per knot: the step to the next knot (0 at the last).
    pub steps: Vec<f64>,
    /// The common step when the knots lie on a uniform grid within [`Track::tolerance`]:
    /// positions are then computed by arithmetic, as on the paper's uniform records.
    pub uniform: Option<f64>,
    /// The distance below which two times are the same time: the record's
    /// ([`Record::time_tolerance`]), so that times that jitter around a grid fall on its
    /// knots.
    pub tolerance: f64,
    /// `inputs[i][knot]`: the value held from that knot to the next.
    pub inputs: Vec<Vec<f64>>,
    /// `states[i][knot]`: the reference value of measured state `i`.
    pub states: Vec<Vec<f64>>,
    /// `known[i][knot]`: the reference comes from data (a cell or a short gap's
    /// interpolant).
    pub known: Vec<Vec<bool>>,
    /// `measured[i][knot]`: a measured cell sits at that knot (a loss target).
    pub measured: Vec<Vec<bool>>,
    /// `observed[j][knot]`: the measured value of observable `j` (model output
    /// `observed_outputs[j]`), if any.
    pub observed: Vec<Vec<Option<f64>>>,
    /// The model outputs the rows of `observed` are.
    pub observed_outputs: Vec<usize>,
}

/// Positions this close to a knot are that knot (rounding of stage times).
const SNAP: f64 = 1e-9;

impl Track {
    /// Lays `record` on its grid; `initial[i]` is the value of state `i` at the first knot
    /// when the record has no cell there (ignored where it has one).
    pub fn lay(record: &Record, options: &GridOptions, initial: &[f64]) -> Track {
        let tolerance = record.time_tolerance();
        let (times, rows) = knots(record, options, tolerance);
        let steps = (0..times.len())
            .map(|k| times.get(k + 1).map_or(0.0, |next| next - times[k]))
            .collect();
        let uniform = crate::numeric::grid_step(&times, tolerance).ok().flatten();
        let row_at = held_rows(&rows);
        let inputs = (record.inputs.iter())
            .map(|column| row_at.iter().map(|&row| column[row]).collect())
            .collect();
        let mut track = Track {
            name: record.name.clone(),
            times,
            rows,
            steps,
            uniform,
            tolerance,
            inputs,
            states: Vec::new(),
            known: Vec::new(),
            measured: Vec::new(),
            observed: Vec::new(),
            observed_outputs: record.observables.iter().map(|o| o.output).collect(),
        };
        track.observed = (record.observables.iter())
            .map(|o| {
                (track.rows.iter())
                    .map(|row| row.and_then(|r| o.cells[r]))
                    .collect()
            })
            .collect();
        for (index, cells) in record.states.iter().enumerate() {
            let limit = options.gap_limits.get(index).copied().unwrap_or(0.0);
            let start = initial.get(index).copied();
            let (values, known, measured) = track.reference(record, cells, limit, start);
            track.states.push(values);
            track.known.push(known);
            track.measured.push(measured);
        }
        if let Some(step) = track.uniform {
            track.steps = (0..track.len())
                .map(|k| if k + 1 < track.len() { step } else { 0.0 })
                .collect();
        }
        track
    }

    /// Number of knots.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the track has no knots.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The fractional knot index of `time`, clamped to the track; a time within
    /// [`Track::tolerance`] of a knot is that knot.
    pub fn position(&self, time: f64) -> f64 {
        let last = self.len().saturating_sub(1);
        if let Some(step) = self.uniform {
            let position = (time - self.times[0]) / step;
            return self.snap_knot(position).clamp(0.0, last as f64);
        }
        let after = self.times.partition_point(|&t| t <= time);
        if after == 0 {
            return 0.0;
        }
        if after > last {
            return last as f64;
        }
        let below = after - 1;
        if time - self.times[below] <= self.tolerance {
            return below as f64;
        }
        if self.times[after] - time <= self.tolerance {
            return after as f64;
        }
        let fraction = (time - self.times[below]) / (self.times[after] - self.times[below]);
        snap(below as f64 + fraction)
    }

    /// `lag` delays in knots of a uniform track of step `step`: a delay within
    /// [`Track::tolerance`] of a whole number of steps is that number (a jittered grid's mean
    /// step is not exactly its rounded version's).
    fn lag_knots(&self, lag: usize, delay: f64, step: f64) -> f64 {
        let ratio = delay / step;
        let whole = rounding::round(ratio);
        let ratio = if (delay - whole * step).abs() <= self.tolerance {
            whole
        } else {
            ratio
        };
        lag as f64 * ratio
    }

    /// A position on a uniform track snapped onto the nearest knot when within
    /// [`Track::tolerance`] of it (or within rounding, [`snap`]).
    fn snap_knot(&self, position: f64) -> f64 {
        let nearest = rounding::round(position);
        let step = self.uniform.unwrap_or(0.0);
        if (position - nearest).abs() * step <= self.tolerance {
            nearest
        } else {
            snap(position)
        }
    }

    /// The position `lag` delays of `delay` before the stage at `fraction` of the step
    /// from `knot` (time `t_k + fraction h_k - lag delay`), unclamped below: a negative
    /// position lies before the record. On a uniform track this is
    /// `knot + fraction - lag (delay / h)`, the paper's arithmetic.
    pub fn stage_position(&self, knot: usize, fraction: f64, (lag, delay): (usize, f64)) -> f64 {
        match self.uniform {
            Some(step) => self.snap_knot(knot as f64 + fraction - self.lag_knots(lag, delay, step)),
            None => {
                let step = self.steps.get(knot).copied().unwrap_or(0.0);
                let time = self.times[knot] + fraction * step - lag as f64 * delay;
                if time < self.times[0] - self.tolerance {
                    return snap((time - self.times[0]) / self.steps[0].max(f64::MIN_POSITIVE));
                }
                self.position(time)
            }
        }
    }

    /// [`Track::stage_position`] of the stage at `fraction` of step `step` of a window
    /// starting at knot `start`, counted from `start` (snapped onto a knot within rounding).
    /// On a uniform track it is `step + fraction - lag (delay / h)` whatever the start.
    pub fn stage_offset(
        &self,
        start: usize,
        (step, fraction): (usize, f64),
        (lag, delay): (usize, f64),
    ) -> f64 {
        match self.uniform {
            Some(h) => self.snap_knot(step as f64 + fraction - self.lag_knots(lag, delay, h)),
            None => {
                let position = self.stage_position(start + step, fraction, (lag, delay));
                snap(position - start as f64)
            }
        }
    }

    /// Whether the reference of state `state` is known from data all along the stretch
    /// between positions `from` and `to` (the knots around each end included).
    pub fn known_between(&self, state: usize, from: f64, to: f64) -> bool {
        let known = &self.known[state];
        let first = from.floor().max(0.0) as usize;
        let last = (to.ceil().max(0.0) as usize).min(known.len().saturating_sub(1));
        (first..=last).all(|k| known[k])
    }

    /// Replaces the reference of state `state` at the knots where it is not known by
    /// `values[knot]` (the model's own run along the track).
    pub fn fill(&mut self, state: usize, values: &[f64]) {
        for ((slot, &known), &value) in self.states[state]
            .iter_mut()
            .zip(&self.known[state])
            .zip(values)
        {
            if !known {
                *slot = value;
            }
        }
    }

    /// The measured value of model output `output` at `knot`, if any.
    pub fn observed_cell(&self, output: usize, knot: usize) -> Option<f64> {
        let index = self.observed_outputs.iter().position(|&o| o == output)?;
        self.observed[index].get(knot).copied().flatten()
    }

    /// Whether any measured state or observable has a cell at `knot`.
    pub fn has_cell(&self, knot: usize) -> bool {
        self.measured.iter().any(|m| m[knot]) || self.observed.iter().any(|o| o[knot].is_some())
    }

    /// Whether every state is known at every knot (no model fill needed).
    pub fn fully_known(&self) -> bool {
        self.known.iter().flatten().all(|&k| k)
    }

    /// One state's reference, known and measured flags at every knot.
    fn reference(
        &self,
        record: &Record,
        cells: &[Option<f64>],
        gap_limit: f64,
        initial: Option<f64>,
    ) -> (Vec<f64>, Vec<bool>, Vec<bool>) {
        let samples: Vec<(f64, f64)> = (record.times.iter().zip(cells))
            .filter_map(|(&t, cell)| cell.map(|v| (t, v)))
            .collect();
        let mut values = Vec::with_capacity(self.len());
        let mut known = Vec::with_capacity(self.len());
        let mut measured = Vec::with_capacity(self.len());
        let start = self.times[0];
        let has_first = cells.first().copied().flatten().is_some();
        for (k, &time) in self.times.iter().enumerate() {
            let is_cell = self.rows[k].is_some_and(|row| cells[row].is_some());
            let after = samples.partition_point(|&(t, _)| t <= time);
            let (value, from_data) =
                match (after.checked_sub(1).map(|i| samples[i]), samples.get(after)) {
                    (Some((t, v)), _) if t == time => (v, true),
                    (Some((ta, va)), Some(&(tb, vb))) => {
                        let value = va + (vb - va) * (time - ta) / (tb - ta);
                        let within = tb - ta <= gap_limit * (1.0 + SNAP) + self.tolerance;
                        (value, within)
                    }
                    (Some((_, v)), None) => (v, false),
                    (None, Some(&(tb, vb))) => match initial.filter(|_| !has_first) {
                        Some(first) => {
                            (first + (vb - first) * (time - start) / (tb - start), false)
                        }
                        None => (vb, false),
                    },
                    (None, None) => (initial.unwrap_or(0.0), false),
                };
            let value = if k == 0 && !is_cell {
                initial.unwrap_or(value)
            } else {
                value
            };
            values.push(value);
            known.push(from_data);
            measured.push(is_cell);
        }
        (values, known, measured)
    }
}

/// The knot times of `record` and the row at each (rows, plus equal cuts of intervals
/// longer than the maximum step by more than `tolerance`).
fn knots(record: &Record, options: &GridOptions, tolerance: f64) -> (Vec<f64>, Vec<Option<usize>>) {
    let mut times = Vec::with_capacity(record.len());
    let mut rows = Vec::with_capacity(record.len());
    for (row, &time) in record.times.iter().enumerate() {
        if let (Some(&previous), true) = (times.last(), options.subdivide) {
            let gap: f64 = time - previous;
            let longest = options.max_step + tolerance;
            let pieces = (gap / longest - SNAP).ceil().max(1.0) as usize;
            for piece in 1..pieces {
                times.push(previous + gap * piece as f64 / pieces as f64);
                rows.push(None);
            }
        }
        times.push(time);
        rows.push(Some(row));
    }
    (times, rows)
}

/// Per knot, the record row at or before it.
fn held_rows(rows: &[Option<usize>]) -> Vec<usize> {
    let mut current = 0;
    rows.iter()
        .map(|row| {
            if let Some(row) = row {
                current = *row;
            }
            current
        })
        .collect()
}

/// A position snapped onto the nearest knot when within rounding of it.
pub fn snap(position: f64) -> f64 {
    let nearest = rounding::round(position);
    if (position - nearest).abs() < SNAP {
        nearest
    } else {
        position
    }
}

/// Linear interpolation of `values` (one per knot) at a fractional `position`, clamped.
pub fn interpolate(values: &[f64], position: f64) -> f64 {
    let last = values.len().saturating_sub(1);
    let position = snap(position).clamp(0.0, last as f64);
    let below = rounding::floor(position);
    interpolate_at(values, below as isize, position - below)
}

/// [`interpolate`] at knot `below` plus `fraction` (in `[0, 1)`), the position already
/// split: clamped to the first knot before the track and to the last from it on.
pub fn interpolate_at(values: &[f64], below: isize, fraction: f64) -> f64 {
    let last = values.len().saturating_sub(1);
    if below < 0 {
        return values[0];
    }
    let below = below as usize;
    if fraction == 0.0 || below >= last {
        return values[below.min(last)];
    }
    values[below] * (1.0 - fraction) + values[below + 1] * fraction
}

/// Zero-order hold of `values` at a fractional `position`: the knot at or before it, or
/// with `left_limit` the knot strictly before it when it falls on a knot (the end of a
/// step sees the value held over the step).
pub fn hold(values: &[f64], position: f64, left_limit: bool) -> f64 {
    let last = values.len().saturating_sub(1) as f64;
    let position = snap(position);
    let index = if left_limit {
        rounding::ceil(position) - 1.0
    } else {
        rounding::floor(position)
    };
    values[index.clamp(0.0, last) as usize]
}

/// The grid of `model` with longest step `max_step`: each measured state's gap limit is the
/// shortest delay of the closures that look back at it (the longest step when none does).
pub fn grid_for(model: &crate::ir::Model, max_step: f64) -> GridOptions {
    let gap_limits = (0..model.states.len())
        .map(|index| {
            (model.closures.iter())
                .filter(|c| c.embedding.dim > 1)
                .filter(|c| c.embedding.observe.contains(&crate::ir::Var::State(index)))
                .map(|c| c.embedding.delay)
                .fold(f64::INFINITY, f64::min)
        })
        .map(|limit| if limit.is_finite() { limit } else { max_step })
        .collect();
    GridOptions {
        max_step,
        gap_limits,
        subdivide: model.dynamics == crate::ir::Dynamics::Continuous,
    }
}
