//! A model without closures is fitted, not trained: `gbc train` hands it to the one fitter
//! of mechanistic params ([`crate::solve::fit::mechanism`], the free-run least squares of
//! `gbc diagnose`: starts until no new basin appears, declared noise as weights, exact
//! sensitivities, standard errors), so that both commands give the same fit. The params
//! are then held fixed, no epoch runs, and the run is scored and saved like any other
//! (`docs/training.md`, "Models without closures").
//!
//! A grey box on a sparse record starts from its mechanism the same way: its params are
//! fitted with every closure output at its prior (or zero, [`ir::Model::mechanism`]) and
//! held while the networks learn the correction. On a dense record the balances give the
//! params instead ([`super::balances`]); where they cannot (hidden states, a closure in
//! every balance), the mechanism is fitted here too, whatever the record's density
//! ([`fallback`]).

use crate::ir;
use crate::solve::fit::{check_fittable, fit_mechanism, FitOptions, FitSummary, MechanismFit};

use super::coverage::{Coverage, DENSE_SHARE};
use super::prepare::Layout;
use super::{
    Objective, ParamEstimate, ParamSource, Recipe, TrainError, TrainOptions, TrainingData,
};

/// Random restarts of the fit besides the declared start, as in `gbc diagnose`.
pub const RESTARTS: usize = 15;
/// Measured rows the fit needs at least (the training split has its own checks).
const MIN_ROWS: usize = 2;

/// The model whose params are fitted by free runs before training, if any: `model` itself
/// when it has params and no closures; its mechanism when it is a grey box on a sparse
/// record (one-step pairs reach under [`DENSE_SHARE`] of the cells) trained by the
/// multi-step objective. Never with `--params train`, and only where the fitter takes the
/// records (no measured outputs; a discrete map on one uniform step).
pub fn source(
    model: &ir::Model,
    data: &TrainingData,
    recipe: &Recipe,
    coverage: &Coverage,
) -> Option<ir::Model> {
    if model.params.is_empty() || recipe.params == ParamSource::Train {
        return None;
    }
    let fitted = if model.closures.is_empty() {
        model.clone()
    } else if recipe.objective == Objective::MultiStep && coverage.one_step_share() < DENSE_SHARE {
        model.mechanism()
    } else {
        return None;
    };
    fittable(fitted, data)
}

/// The mechanism of a grey box whose balances cannot give its params (hidden states, or a
/// closure in every balance: [`super::balances::estimate`] found none) on a record of any
/// density: its params are fitted by free runs with every closure output at its prior, so
/// that no param starts training from its declared value where the record can fit it.
/// Only where the params would otherwise train with the network (`--params auto` under the
/// multi-step objective) and the fitter takes the records.
pub fn fallback(model: &ir::Model, data: &TrainingData, recipe: &Recipe) -> Option<ir::Model> {
    let trains_params = recipe.params == ParamSource::Auto
        && recipe.objective == Objective::MultiStep
        && !model.params.is_empty()
        && !model.closures.is_empty();
    if !trains_params {
        return None;
    }
    fittable(model.mechanism(), data)
}

/// `fitted` where the fitter takes the records (no measured outputs; a discrete map on one
/// uniform step).
fn fittable(fitted: ir::Model, data: &TrainingData) -> Option<ir::Model> {
    let records = data.train.iter().chain(data.validation);
    check_fittable(&fitted, records).is_ok().then_some(fitted)
}

/// Fits `model`'s params to the training rows of every training experiment of `layout`
/// (the rows its normalisation is taken over), seeded by `--seed`.
pub fn fit(
    model: &ir::Model,
    data: &TrainingData,
    layout: &Layout,
    options: &TrainOptions,
) -> Result<MechanismFit, TrainError> {
    let training: Vec<_> = (data.train.iter().zip(&layout.trainings))
        .map(|(record, part)| record.rows(part.rows.clone()))
        .collect();
    let settings = FitOptions {
        restarts: RESTARTS,
        seed: options.seed,
        fit_initial: false,
        fit_starts: false,
        noise: None,
        min_rows: MIN_ROWS,
    };
    Ok(fit_mechanism(model, &training, &settings)?)
}

/// `model` with its params' declared values replaced by the fitted ones.
pub fn with_fitted_params(model: &ir::Model, fit: &MechanismFit) -> ir::Model {
    let mut fitted = model.clone();
    for (param, value) in fitted.params.iter_mut().zip(&fit.params) {
        param.init = *value;
    }
    fitted
}

/// Where a grey box's params were fitted with its closures at their priors and held while
/// the closures then trained away from them, their standard errors are the mechanism's:
/// they count none of the closures' unknowns, and a param biased by the prior's error would
/// be reported identified and wrong (issue 35: a yield four standard errors off). Such a
/// param keeps its value and error but is not called identified.
pub fn unassessed_once_trained(estimates: &mut [ParamEstimate]) {
    for estimate in estimates {
        estimate.identified = false;
    }
}

/// The params' estimates of a fit (its fitted starts left out: a training run re-fits the
/// starts of its own experiments).
pub fn param_estimates(model: &ir::Model, summary: &FitSummary) -> Vec<ParamEstimate> {
    (summary.estimates.iter())
        .filter(|estimate| model.params.iter().any(|p| p.name == estimate.name))
        .cloned()
        .collect()
}
