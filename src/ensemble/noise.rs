//! The measurement noise a band adds to each member's free run, per measured state: the
//! model's `noise` declaration where it has one (`src/ir/noise.rs`), else estimated from the
//! members' free-run residuals on the experiments they trained on, with the same combined
//! error model `sigma(y) = sqrt(absolute^2 + (relative y)^2)` fitted to the residuals by
//! maximum likelihood. The estimate is residual error (noise and
//! model error together) and sets the band's shape over time; its overall scale is what
//! the calibration corrects ([`super::calibrate`]).

use super::band::{BaseBand, Draw};
use crate::ir::{self, Measured};

/// The noise of one measured state.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StateNoise {
    /// The state.
    pub state: String,
    /// The absolute term, in the state's unit.
    #[serde(with = "crate::json")]
    pub absolute: f64,
    /// The relative term, a fraction of the value.
    #[serde(with = "crate::json")]
    pub relative: f64,
    /// Where it comes from.
    pub source: NoiseSource,
    /// The floor a measurement is censored at (0 for a state declared `nonnegative`: a
    /// Gaussian draw below reads as 0); absent for none (and in ensembles trained before
    /// floors, whose scores were computed without one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor: Option<f64>,
}

/// Where a state's noise comes from.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum NoiseSource {
    /// The model's `noise` declaration.
    Declared,
    /// Fitted to the members' free-run residuals on their own training experiments.
    Estimated {
        /// The residuals (member, cell) it was fitted to.
        residuals: usize,
    },
}

impl StateNoise {
    /// The standard deviation of a measurement whose true value is `value`.
    pub fn sigma(&self, value: f64) -> f64 {
        self.absolute.hypot(self.relative * value)
    }

    /// In words: `declared 4 % + 0.01`, `estimated 2.1 % + 0.003 from 212 residuals`, with
    /// `, censored at 0` for a floor.
    pub fn describe(&self) -> String {
        let level = format!(
            "{} % + {}",
            crate::plot::tick_label(100.0 * self.relative),
            crate::plot::tick_label(self.absolute)
        );
        let censored = (self.floor).map_or(String::new(), |f| {
            format!(", censored at {}", crate::plot::tick_label(f))
        });
        match self.source {
            NoiseSource::Declared => format!("declared {level}{censored}"),
            NoiseSource::Estimated { residuals } => {
                format!("estimated {level} from {residuals} residuals{censored}")
            }
        }
    }

    /// The base band of the members' `predictions` of a cell (non-finite ones left out),
    /// each with this noise and floor ([`BaseBand::floored`]).
    pub fn base_band(&self, predictions: impl Iterator<Item = f64>) -> Option<BaseBand> {
        let draws: Vec<Draw> = (predictions.filter(|p| p.is_finite()))
            .map(|p| (p, self.sigma(p)))
            .collect();
        BaseBand::floored(&draws, self.floor)
    }

    /// This noise with the floor of `model`'s measured state `state`: 0 where it is
    /// declared `nonnegative`.
    pub fn with_floor_of(mut self, model: &ir::Model, state: usize) -> Self {
        self.floor = (model.states.get(state))
            .is_some_and(|s| s.nonnegative)
            .then_some(0.0);
        self
    }
}

/// The declared noise of measured state `state`, if the model declares one.
pub fn declared(model: &ir::Model, state: usize) -> Option<StateNoise> {
    let noise = model.noise_of(Measured::State(state))?;
    Some(StateNoise {
        state: model.states[state].name.clone(),
        absolute: noise.absolute,
        relative: noise.relative,
        source: NoiseSource::Declared,
        floor: None,
    })
}

/// The combined error model fitted to `(prediction, residual)` pairs by maximum likelihood
/// ([`fit_variance`]).
pub fn estimated(state: &str, pairs: &[(f64, f64)]) -> StateNoise {
    let finite: Vec<(f64, f64)> = (pairs.iter().copied())
        .filter(|(p, r)| p.is_finite() && r.is_finite())
        .collect();
    let (a, b) = fit_variance(&finite);
    StateNoise {
        state: state.to_string(),
        absolute: a.sqrt(),
        relative: b.sqrt(),
        source: NoiseSource::Estimated {
            residuals: finite.len(),
        },
        floor: None,
    }
}

/// The maximum-likelihood `(absolute^2, relative^2)` of zero-mean Gaussian residuals with
/// variance `a + b p^2`: a grid over both in decades (down to `1e-8` of the residuals' own
/// scale, which stands for zero), refined by a pattern search to a thousandth of a decade.
fn fit_variance(pairs: &[(f64, f64)]) -> (f64, f64) {
    if pairs.is_empty() {
        return (0.0, 0.0);
    }
    let n = pairs.len() as f64;
    let absolute_scale = pairs.iter().map(|(_, r)| r * r).sum::<f64>() / n;
    let relative: Vec<f64> = (pairs.iter())
        .filter(|(p, _)| *p != 0.0)
        .map(|(p, r)| (r / p).powi(2))
        .collect();
    let relative_scale = relative.iter().sum::<f64>() / relative.len().max(1) as f64;
    if absolute_scale.is_nan() || absolute_scale <= 0.0 {
        return (0.0, 0.0);
    }
    let variance = |(u, v): (f64, f64)| {
        (
            absolute_scale * 10f64.powf(u),
            relative_scale * 10f64.powf(v),
        )
    };
    let cost = |point: (f64, f64)| {
        let (a, b) = variance(point);
        (pairs.iter())
            .map(|(p, r)| {
                let v = a + b * p * p;
                if v > 0.0 {
                    v.ln() + r * r / v
                } else {
                    f64::INFINITY
                }
            })
            .sum::<f64>()
    };
    let decades: Vec<f64> = (0..=36).map(|k| -8.0 + 0.25 * f64::from(k)).collect();
    let mut best = (1.0, -8.0);
    let mut best_cost = f64::INFINITY;
    for &u in &decades {
        for &v in &decades {
            let c = cost((u, v));
            if c < best_cost {
                (best, best_cost) = ((u, v), c);
            }
        }
    }
    let mut step = 0.125;
    while step > 1e-3 {
        let moves = [(step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)];
        let better = (moves.iter())
            .map(|(du, dv)| {
                (
                    (best.0 + du).clamp(-8.0, 1.0),
                    (best.1 + dv).clamp(-8.0, 1.0),
                )
            })
            .map(|point| (point, cost(point)))
            .filter(|(_, c)| *c < best_cost)
            .min_by(|x, y| x.1.total_cmp(&y.1));
        match better {
            Some((point, c)) => (best, best_cost) = (point, c),
            None => step /= 2.0,
        }
    }
    let (a, b) = variance(best);
    let floor = |value: f64, decade: f64| if decade <= -8.0 { 0.0 } else { value };
    (floor(a, best.0), floor(b, best.1))
}
