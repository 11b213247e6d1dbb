//! From the window of past values to each closure's embedding at each RK4 stage.
//!
//! An exported model steps on a uniform grid of the run's step `h`. The embedding of a
//! closure at stage fraction `f` of the step from knot `k` reads each observed variable at
//! `t_k + f h - lag * delay`: states by linear interpolation between knots, inputs held
//! (the end of the step sees the value held over it), exactly as in training
//! ([`crate::engine::pairs::embedding_row`]). Those reads are linear in the values at the
//! knots, so each is a constant matrix applied to the window: found here by running the
//! training code itself on unit impulses along a uniform track, never re-derived.
//!
//! Features, in order: the state window `[W, S]` row-major (row 0 the oldest knot, row
//! `W - 1` the current one), the input window `[W, U]` likewise, then the stage state
//! `[S + H]` (a lag-0 state column is the RK4 stage estimate, not the window).

use crate::engine::graph::Setup;
use crate::engine::pairs::{embedding_row, stage_fractions};
use crate::ir::{self, Var};
use crate::record::Track;

/// One nonzero read: `(variable, knot, embedding column, coefficient)`.
type Read = (Var, usize, usize, f64);

/// How the window feeds every closure's embedding.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowMap {
    /// Knots in the window, the current one last.
    pub length: usize,
    /// Number of features: `W S + W U + S + H`.
    pub features: usize,
    /// `matrices[closure][offset]`: `features x width`, row-major, the raw embedding at
    /// stage offset `offset` (fraction `offset / 2K`) is `features . matrix`.
    pub matrices: Vec<Vec<Vec<f64>>>,
}

/// The window map of `model` on the grid of step `setup.step`.
pub fn window_map(model: &ir::Model, setup: &Setup) -> WindowMap {
    let (states, inputs) = (model.states.len(), model.inputs.len());
    let stage_width = states + model.hidden.len();
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    let span = (model.closures.iter())
        .map(|c| c.embedding.span())
        .fold(0.0, f64::max);
    let knots = (span / setup.step).floor() as usize + 3;
    let current = knots - 1;
    let mut track = uniform_track(model, setup.step, knots);
    let mut reads: Vec<Vec<Vec<Read>>> =
        vec![vec![Vec::new(); fractions.len()]; model.closures.len()];
    let variables: Vec<Var> = ((0..states).map(Var::State))
        .chain((0..inputs).map(Var::Input))
        .collect();
    for &var in &variables {
        for knot in 0..knots {
            set(&mut track, var, knot, 1.0);
            for (closure, per_offset) in model.closures.iter().zip(&mut reads) {
                let layout = closure.embedding.layout();
                for (offset, &fraction) in fractions.iter().enumerate() {
                    let row = embedding_row(closure, &track, current, fraction);
                    for (column, &value) in row.iter().enumerate() {
                        let stage_state = matches!(layout[column], (Var::State(_), 0));
                        if value != 0.0 && !stage_state {
                            per_offset[offset].push((var, knot, column, value));
                        }
                    }
                }
            }
            set(&mut track, var, knot, 0.0);
        }
    }
    let oldest = (reads.iter().flatten().flatten())
        .map(|&(_, knot, _, _)| knot)
        .min()
        .unwrap_or(current);
    let length = current - oldest + 1;
    let features = length * (states + inputs) + stage_width;
    let matrices = (model.closures.iter().zip(&reads))
        .map(|(closure, per_offset)| {
            let width = closure.embedding.width();
            let layout = closure.embedding.layout();
            (per_offset.iter())
                .map(|entries| {
                    let mut matrix = vec![0.0; features * width];
                    for &(var, knot, column, value) in entries {
                        let row = knot - oldest;
                        let feature = match var {
                            Var::State(i) => row * states + i,
                            Var::Input(j) => length * states + row * inputs + j,
                            _ => continue,
                        };
                        matrix[feature * width + column] += value;
                    }
                    for (column, &(var, lag)) in layout.iter().enumerate() {
                        if let (Var::State(i), 0) = (var, lag) {
                            let feature = length * (states + inputs) + i;
                            matrix[feature * width + column] = 1.0;
                        }
                    }
                    matrix
                })
                .collect()
        })
        .collect();
    WindowMap {
        length,
        features,
        matrices,
    }
}

/// A complete uniform track of `knots` knots of step `step`, every value 0.
fn uniform_track(model: &ir::Model, step: f64, knots: usize) -> Track {
    let zeros = || vec![0.0; knots];
    let times: Vec<f64> = (0..knots).map(|k| k as f64 * step).collect();
    Track {
        name: "window".into(),
        tolerance: crate::numeric::time_tolerance(&times),
        times,
        rows: (0..knots).map(Some).collect(),
        steps: (0..knots)
            .map(|k| if k + 1 < knots { step } else { 0.0 })
            .collect(),
        uniform: Some(step),
        inputs: model.inputs.iter().map(|_| zeros()).collect(),
        states: model.states.iter().map(|_| zeros()).collect(),
        known: model.states.iter().map(|_| vec![true; knots]).collect(),
        measured: model.states.iter().map(|_| vec![true; knots]).collect(),
        observed: Vec::new(),
        observed_outputs: Vec::new(),
    }
}

fn set(track: &mut Track, var: Var, knot: usize, value: f64) {
    match var {
        Var::State(i) => track.states[i][knot] = value,
        Var::Input(j) => track.inputs[j][knot] = value,
        _ => {}
    }
}
