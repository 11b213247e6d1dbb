//! How far a trained grey box moved from its mechanism: each closure output against its
//! value at network output 0 (its prior at the trained params, or 0 without one) over the
//! training points, and each param from its start.

use crate::engine::graph::{BackendError, Batch, Network};
use crate::ir::{self, PriorKind};

use super::super::ParamEstimate;

/// How far one closure output moved, over the training points.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OutputDistance {
    /// `closure.output`.
    pub name: String,
    /// `*=`, `+=` or `none`.
    pub prior: String,
    /// The distance: for `*=` the RMS of `o / p - 1` (the correction factor's distance
    /// from 1, over the points where the prior is not 0); for `+=` the RMS of `o - p` over
    /// the RMS of `p`; without a prior the RMS of `o` itself.
    #[serde(with = "crate::json")]
    pub moved: f64,
    /// The RMS of the output's change from its value at network output 0, in its unit.
    #[serde(with = "crate::json")]
    pub rms_change: f64,
    /// The training points it was measured over (every knot of every training track).
    pub points: usize,
}

/// How far one param moved from its start (the fitted mechanism's value, or the
/// declared one).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParamDistance {
    /// The param.
    pub name: String,
    /// Its value at the start of training.
    #[serde(with = "crate::json")]
    pub start: f64,
    /// Its value after training.
    #[serde(with = "crate::json")]
    pub value: f64,
    /// `(value - start) / standard error`, when a statistical standard error is known
    /// ([`ParamEstimate::statistical_error`]: none for a held param, an unbounded one, or
    /// one below round-off, where the quotient would be meaningless).
    #[serde(with = "crate::json")]
    pub standard_errors: Option<f64>,
}

/// Each closure output's distance from its mechanism over `batch` (the training points):
/// the network's outputs as trained against the same network with its last layers at zero.
pub fn output_distances(
    network: &mut Network,
    model: &ir::Model,
    batch: &Batch,
) -> Result<Vec<OutputDistance>, BackendError> {
    if batch.rows == 0 || model.closures.is_empty() {
        return Ok(Vec::new());
    }
    let trained = network.weights();
    let outputs = network.predict(batch)?.closure_outputs;
    let mut silent = trained.clone();
    for tensor in &mut silent {
        let last = (model.closures.iter()).any(|c| {
            let prefix = format!("closure.{}.layer{}.", c.name, c.network.hidden.len());
            tensor.name.starts_with(&prefix)
        });
        if last {
            tensor.values.fill(0.0);
        }
    }
    network.set_weights(&silent)?;
    let at_zero = network.predict(batch);
    network.set_weights(&trained)?;
    let at_zero = at_zero?.closure_outputs;
    let specs: Vec<(String, Option<PriorKind>)> = (model.closures.iter())
        .flat_map(|c| {
            (c.outputs.iter()).map(|o| {
                (
                    format!("{}.{}", c.name, o.name),
                    o.prior.as_ref().map(|p| p.kind),
                )
            })
        })
        .collect();
    let width = specs.len();
    Ok((specs.into_iter().enumerate())
        .map(|(column, (name, kind))| {
            let pairs: Vec<(f64, f64)> = (0..batch.rows)
                .map(|row| (outputs[row * width + column], at_zero[row * width + column]))
                .collect();
            distance(name, kind, &pairs)
        })
        .collect())
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, count) = values.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if count == 0 {
        f64::NAN
    } else {
        (sum / count as f64).sqrt()
    }
}

/// One output's distance from `(value, value at n = 0)` per point.
fn distance(name: String, kind: Option<PriorKind>, pairs: &[(f64, f64)]) -> OutputDistance {
    let rms_change = rms(pairs.iter().map(|(o, p)| o - p));
    let moved = match kind {
        Some(PriorKind::Mul) => rms((pairs.iter())
            .filter(|(_, p)| *p != 0.0)
            .map(|(o, p)| o / p - 1.0)),
        Some(PriorKind::Add) => rms_change / rms(pairs.iter().map(|(_, p)| *p)),
        None => rms(pairs.iter().map(|(o, _)| *o)),
    };
    OutputDistance {
        name,
        prior: match kind {
            Some(PriorKind::Mul) => "*=",
            Some(PriorKind::Add) => "+=",
            None => "none",
        }
        .into(),
        moved,
        rms_change,
        points: pairs.len(),
    }
}

/// Each param's distance from `start` (the run's initial values), in standard errors
/// where `estimates` give a statistical one ([`ParamEstimate::statistical_error`]).
pub fn param_distances(
    model: &ir::Model,
    values: &[(String, f64)],
    estimates: &[ParamEstimate],
) -> Vec<ParamDistance> {
    (model.params.iter().zip(values))
        .map(|(param, (name, value))| {
            let start = param.init;
            let error = (estimates.iter())
                .find(|e| &e.name == name)
                .and_then(ParamEstimate::statistical_error);
            ParamDistance {
                name: name.clone(),
                start,
                value: *value,
                standard_errors: error.map(|s| (value - start) / s),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_kind_of_output_measures_its_own_distance() {
        let pairs = [(2.0, 1.0), (1.0, 2.0), (3.0, 3.0)];
        // *=: factors 2, 0.5, 1.
        let mul = distance("c.a".into(), Some(PriorKind::Mul), &pairs);
        let expected = ((1.0 + 0.25 + 0.0) / 3.0f64).sqrt();
        assert!((mul.moved - expected).abs() < 1e-15);
        // +=: changes 1, -1, 0 over the prior's RMS.
        let add = distance("c.b".into(), Some(PriorKind::Add), &pairs);
        let expected = (2.0f64 / 3.0).sqrt() / (14.0f64 / 3.0).sqrt();
        assert!((add.moved - expected).abs() < 1e-15);
        // none: the output's own RMS.
        let none = distance("c.c".into(), None, &pairs);
        assert!((none.moved - (14.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert_eq!(none.points, 3);
    }

    /// Issue 43: a yield fixed exactly by noise-free balances has a standard error of
    /// round-off (1e-14 of 0.435); a move of 1e-9 is not 96721 standard errors. A held
    /// param has none; a fitted param's move is counted in its standard errors.
    #[test]
    fn a_standard_error_of_round_off_or_a_held_param_gives_no_distance() {
        let source = "model t\nstate X = 1\nparam Y_X = 0.435 positive, k = 0.3 positive, \
                      K = 2 positive\nder X = -k * Y_X * X / (K + X)\n";
        let model = crate::driver::compile("t.gbm", source, &[]).unwrap().model;
        let values = [
            ("Y_X".to_string(), 0.435 + 9.67e-10),
            ("k".to_string(), 0.33),
            ("K".to_string(), 2.0),
        ];
        let estimates = [
            ParamEstimate::fitted("Y_X".into(), values[0].1, 1e-14),
            ParamEstimate::fitted("k".into(), 0.33, 0.01),
            ParamEstimate::held_at("K".into(), 2.0),
        ];
        let distances = param_distances(&model, &values, &estimates);
        assert_eq!(distances[0].standard_errors, None, "{distances:?}");
        let k = distances[1].standard_errors.unwrap();
        assert!((k - 3.0).abs() < 1e-9, "{distances:?}");
        assert_eq!(distances[2].standard_errors, None, "{distances:?}");
        // Just above the rounding level the error is a statistical one again.
        let above = ParamEstimate::fitted("Y_X".into(), 0.435, 1e-8);
        assert_eq!(above.statistical_error(), Some(1e-8));
    }
}
