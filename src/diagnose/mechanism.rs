//! The one fitter of a mechanistic model's params: the free-run least squares of the
//! diagnosis ([`super::fit`]: multi-start Levenberg–Marquardt on the z-scored free-run
//! residuals at every measured cell, declared noise as weights, exact sensitivities, a
//! free direction held), offered on its own so that `gbc train` fits a model without
//! closures exactly as `gbc diagnose` fits it before its effects.

use super::effects::fit_and_score;
use super::report::FitSummary;
use super::split::Split;
use super::{check_options, ranking::Blocks, Context, DiagnoseError, Options};
use crate::ir::{Dynamics, Model};
use crate::record::Record;
use crate::solve::ode::Method;

/// A mechanistic model fitted to whole training experiments.
#[derive(Debug, Clone, PartialEq)]
pub struct MechanismFit {
    /// The fitted value of each of the model's params, in model order.
    pub params: Vec<f64>,
    /// The fit: every unknown with its standard error (params, then the starts it fitted,
    /// `STATE@EXPERIMENT`), the training gap, the criteria, the starts spent and the held
    /// directions.
    pub summary: FitSummary,
}

/// Fits `model`'s params to every measured cell of `training` (whole experiments: cut them
/// to the rows that train first) with the diagnosis's fitter under `options` (`restarts`,
/// `seed`, `noise`, `fit_initial`, `min_rows`; the options about held-out data and effects
/// are not used).
pub fn fit_mechanism(
    model: &Model,
    training: &[Record],
    options: &Options,
) -> Result<MechanismFit, DiagnoseError> {
    check_options(options)?;
    check_fittable(model, training.iter())?;
    let mut split = Split::fit_only(
        model,
        training.to_vec(),
        options.fit_initial,
        options.min_rows,
    )?;
    if options.fit_starts {
        split.fit_measured_starts(model);
    }
    split.declare_noise(options.noise.as_deref().unwrap_or(&model.noise));
    let context = Context {
        problem: None,
        options,
        model,
        blocks: Blocks::new(&split),
        split,
        corrections: Method::Auto,
    };
    let declared = std::collections::BTreeMap::new();
    let scored = fit_and_score(&context, model, &declared, context.seed(0))?;
    let params = scored.fitted.x[..model.params.len()].to_vec();
    Ok(MechanismFit {
        params,
        summary: scored.summary,
    })
}

/// What a fit by free runs needs of a model and its records: no closures, no measured
/// outputs, and for a discrete map one uniform step.
pub fn check_fittable<'r>(
    model: &Model,
    records: impl Iterator<Item = &'r Record> + Clone,
) -> Result<(), DiagnoseError> {
    if !model.closures.is_empty() {
        let names: Vec<&str> = model.closures.iter().map(|c| c.name.as_str()).collect();
        return Err(DiagnoseError::HasClosures {
            model: model.name.clone(),
            closures: names.join(", "),
        });
    }
    for record in records.clone() {
        if let Some(observable) = record.observables.first() {
            return Err(DiagnoseError::MeasuredOutput {
                model: model.name.clone(),
                output: observable.name.clone(),
            });
        }
    }
    if model.dynamics == Dynamics::Discrete {
        let steps: Vec<Option<f64>> = records.clone().map(Record::uniform_step).collect();
        let first = steps.first().copied().flatten();
        let irregular = (records.zip(&steps)).find(|(_, step)| {
            step.is_none()
                || step
                    .zip(first)
                    .is_some_and(|(a, b)| (a - b).abs() > 1e-6 * b)
        });
        if let Some((record, _)) = irregular {
            return Err(DiagnoseError::IrregularMap {
                experiment: record.name.clone(),
            });
        }
    }
    Ok(())
}
