//! A mechanistic model's params fitted to whole training experiments: the free-run least
//! squares ([`super::model::fit_model`]: multi-start Levenberg–Marquardt on the z-scored
//! free-run residuals at every measured cell, declared noise as weights, exact
//! sensitivities, a free direction held), so that `gbc train` fits a model without
//! closures exactly as `gbc diagnose` fits it before its effects.

use super::error::FitError;
use super::fitter::Starts;
use super::model::fit_model;
use super::split::Split;
use super::summary::FitSummary;
use super::FitOptions;
use crate::ir::{Dynamics, Model};
use crate::record::Record;
use std::collections::BTreeMap;

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
/// to the rows that train first) under `options`.
pub fn fit_mechanism(
    model: &Model,
    training: &[Record],
    options: &FitOptions,
) -> Result<MechanismFit, FitError> {
    options.check()?;
    check_fittable(model, training.iter())?;
    let mut split = Split::fit_only(
        model,
        training.to_vec(),
        options.fit_initial,
        options.min_rows,
    )?;
    split.declare_noise(options.noise.as_deref().unwrap_or(&model.noise));
    if options.fit_starts {
        super::noise::fit_uncertain_starts(&mut split, model);
    }
    let declared = BTreeMap::new();
    let starts = Starts::new(options.restarts);
    let fit = fit_model(&split, model, (&declared, starts), options.task_seed(0))?;
    let params = fit.fitted.x[..model.params.len()].to_vec();
    Ok(MechanismFit {
        params,
        summary: fit.summary,
    })
}

/// What a fit by free runs needs of a model and its records: no closures, and for a
/// discrete map one uniform step (measured outputs are fitted and scored like measured
/// states).
pub fn check_fittable<'r>(
    model: &Model,
    records: impl Iterator<Item = &'r Record> + Clone,
) -> Result<(), FitError> {
    if !model.closures.is_empty() {
        let names: Vec<&str> = model.closures.iter().map(|c| c.name.as_str()).collect();
        return Err(FitError::HasClosures {
            model: model.name.clone(),
            closures: names.join(", "),
        });
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
            return Err(FitError::IrregularMap {
                experiment: record.name.clone(),
            });
        }
    }
    Ok(())
}
