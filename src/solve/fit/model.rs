//! A model fitted to the training parts of a split: the multi-start fit, its uncertainty,
//! and a refit held along a direction the data leave free.

use super::fitter::{fit, Fitted, Objective, Starts};
use super::simulate::{tolerances, Simulator};
use super::split::Split;
use super::summary::FitSummary;
use super::uncertainty::summarise;
use super::unknowns::Unknowns;
use super::FitError;
use crate::ir::Model;
use std::collections::BTreeMap;
use std::time::Instant;

/// A fit pinned along a free direction is kept when its training gap is within this share
/// of the free fit's.
pub const PIN_TOLERANCE: f64 = 1e-6;

/// Components of a free direction within this share of the largest are equally large.
const PIN_TIE: f64 = 0.9;

/// A model fitted on the training parts of a split.
#[derive(Debug, Clone)]
pub struct ModelFit {
    /// The model compiled for free runs (its params not yet set to the fitted values).
    pub simulator: Simulator,
    /// The unknowns fitted (params, then fitted starts).
    pub unknowns: Unknowns,
    /// The fitted unknowns and their training gap.
    pub fitted: Fitted,
    /// Uncertainty, criteria and the starts spent (its `seconds` is the fit's).
    pub summary: FitSummary,
    /// Per measured state, the sum of its squared normalised training residuals and their
    /// count (empty if the fit's free runs failed): an upper bound of its noise.
    pub training_squares: Vec<(f64, usize)>,
}

impl ModelFit {
    /// The fitted unknowns by name (params, `STATE@EXPERIMENT` starts).
    pub fn named(&self) -> BTreeMap<String, f64> {
        (self.unknowns.names.iter().cloned())
            .zip(self.fitted.x.iter().copied())
            .collect()
    }
}

/// Fits `model` on the training parts of `split` from the unknowns `start` (by name:
/// params and `STATE@EXPERIMENT` starts; others from their defaults) with a budget of
/// `starts`. When the data leave a direction free, its largest component is held at its
/// declared value and the fit redone: kept if the gap stays within [`PIN_TOLERANCE`], so
/// that fits are compared at one point of the ridge, not at arbitrary ones.
pub fn fit_model(
    split: &Split,
    model: &Model,
    (start, starts): (&BTreeMap<String, f64>, Starts),
    seed: u64,
) -> Result<ModelFit, FitError> {
    let started = Instant::now();
    let mut simulator = Simulator::new(model, &[], tolerances())?;
    simulator.observe(model, &split.normalisation.observables)?;
    let unknowns = Unknowns::of(split, model, &simulator);
    let x = unknowns.values(start);
    let constraints = &unknowns.constraints;
    let objective = Objective {
        simulator: &simulator,
        split,
    };
    let free = vec![false; x.len()];
    let mut fitted = fit(&objective, constraints, &x, (starts, &free), seed);
    let names = unknowns.names.as_slice();
    let mut summary = summarise(&objective, constraints, &fitted.x, (names, &free));
    if let Some(pinned) = pin(&summary, names) {
        let mut fixed = free;
        fixed[pinned] = true;
        let mut held = fitted.x.clone();
        held[pinned] = unknowns.defaults[pinned];
        let refit = fit(
            &objective,
            constraints,
            &held,
            (Starts::new(0), &fixed),
            seed,
        );
        if refit.gap <= fitted.gap * (1.0 + PIN_TOLERANCE) {
            let starts = fitted.starts + refit.starts;
            summary = summarise(&objective, constraints, &refit.x, (names, &fixed));
            fitted = Fitted { starts, ..refit };
        }
    }
    let training_squares = (objective.residuals(&fitted.x))
        .map(|r| super::noise::by_state(split, &r))
        .unwrap_or_default();
    summary.starts = fitted.starts;
    summary.seconds = started.elapsed().as_secs_f64();
    Ok(ModelFit {
        simulator,
        unknowns,
        fitted,
        summary,
        training_squares,
    })
}

/// The unknown to pin when a fit leaves a direction free: among the direction's largest
/// components (within [`PIN_TIE`] of the largest; an exact scaling symmetry gives several
/// of equal size) the first declared, if it is not identified.
fn pin(summary: &FitSummary, names: &[String]) -> Option<usize> {
    let largest = summary.free_direction.first()?.1.abs();
    let index = (summary.free_direction.iter())
        .filter(|(_, v)| v.abs() >= PIN_TIE * largest)
        .filter_map(|(name, _)| names.iter().position(|n| n == name))
        .min()?;
    let estimate = summary.estimates.iter().find(|e| e.name == names[index])?;
    (!estimate.identified).then_some(index)
}
