//! The held-out spread against the spread it predicts: a correct model (logistic growth)
//! fitted again and again on one noisy batch and scored on another, by Monte Carlo. The
//! mean held-out gap of the draws is the noise plus the spread, not the noise alone: under
//! absolute noise declared in the model, and under relative noise estimated (pooled) as the
//! diagnosis estimates it.

use super::*;
use crate::record::Record;
use crate::solve::fit::fitter::Starts;
use crate::solve::fit::model::fit_model;
use crate::solve::fit::split::Holdout;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::collections::BTreeMap;

const SOURCE: &str = "model logistic\nstate X = 0.2\nparam r = 0.5 positive\n\
                      param K = 4 positive\nder X = r * X * (1 - X / K)\n";
/// Relative noise of the second kind of draw.
const RELATIVE: f64 = 0.06;

/// How the cells are perturbed.
#[derive(Clone, Copy)]
enum Noise {
    /// Standard deviation [`SIGMA`], declared in the model (`noise X = 0.08`).
    Declared,
    /// [`RELATIVE`] of the value, not declared: the pooled level is given.
    Relative,
}
/// The truth: growth rate, capacity, and the noise's standard deviation.
const R: f64 = 0.6;
const K: f64 = 5.0;
const SIGMA: f64 = 0.08;

/// The closed form of logistic growth from `x0`, measured every hour for `hours`, each
/// cell (the first included) with Gaussian noise of `kind`.
fn batch(name: &str, (x0, hours): (f64, usize), kind: Noise, rng: &mut ChaCha8Rng) -> Record {
    let times: Vec<f64> = (0..=hours).map(|h| h as f64).collect();
    let cells = (times.iter())
        .map(|t| {
            let clean = K / (1.0 + (K / x0 - 1.0) * (-R * t).exp());
            let z: f64 = StandardNormal.sample(rng);
            match kind {
                Noise::Declared => clean + SIGMA * z,
                Noise::Relative => clean * (1.0 + RELATIVE * z),
            }
        })
        .collect();
    Record::complete(name, times, vec![], vec![cells])
}

/// One draw: the fit on a noisy batch from 0.2 over 8 h, scored on one from 0.5 over 10 h
/// (`tail`: one batch from 0.2 over 12 h, fitted on its first 70 % and scored on the rest,
/// the free run starting at its first row); returns (held-out gap, noise floor, predicted
/// spread), z-scored.
fn draw(seed: u64, kind: Noise, tail: bool) -> (f64, f64, f64) {
    let source = match kind {
        Noise::Declared => format!("{SOURCE}noise X = {SIGMA}\n"),
        Noise::Relative => SOURCE.to_string(),
    };
    let model = crate::driver::compile("m", &source, &[]).unwrap().model;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (parts, holdout) = if tail {
        let batch = batch("a", (0.2, 12), kind, &mut rng);
        ((vec![batch], vec![]), Holdout::Tail(0.3))
    } else {
        let train = batch("a", (0.2, 8), kind, &mut rng);
        let held = batch("b", (0.5, 10), kind, &mut rng);
        ((vec![train], vec![held]), Holdout::Experiments)
    };
    let mut split = Split::with_min_rows(&model, parts, (holdout, false), 5).unwrap();
    split.declare_noise(&model.noise);
    let fit = fit_model(&split, &model, (&BTreeMap::new(), Starts::new(4)), seed).unwrap();
    let x = &fit.fitted.x;
    let std = split.normalisation.state_std[0];
    // The noise level in z-scored units: the declared one, or relative noise pooled over
    // the training cells (the mean of its variance at each cell).
    let (_, training, rows) = split.training().next().unwrap();
    let cells: Vec<f64> = training.states[0][rows].iter().flatten().copied().collect();
    let pooled = cells.iter().map(|v| (RELATIVE * v).powi(2)).sum::<f64>() / cells.len() as f64;
    let noise = match kind {
        Noise::Declared => [SIGMA * SIGMA / (std * std)],
        Noise::Relative => [pooled / (std * std)],
    };
    let fixed = vec![false; x.len()];
    let spread = held_out_spread(
        (&split, &fit.simulator),
        (&fit.unknowns, x, &fixed),
        (&noise, seed),
    )
    .unwrap();
    let mut simulator = fit.simulator.clone();
    simulator.set_params(x);
    let (_, record, rows) = split.scored().next().unwrap();
    let run = simulator.free_run(record, &[None], rows.end).unwrap();
    let expected = |row: usize| match kind {
        Noise::Declared => SIGMA * SIGMA,
        Noise::Relative => (RELATIVE * run.row(row)[0]).powi(2),
    };
    let floor = (rows.clone()).map(expected).sum::<f64>() / (rows.len() as f64 * std * std);
    let squares: Vec<f64> = (rows.clone())
        .map(|row| ((run.row(row)[0] - record.states[0][row].unwrap()) / std).powi(2))
        .collect();
    let gap = squares.iter().sum::<f64>() / squares.len() as f64;
    (gap, floor, spread)
}

/// The mean gap, noise floor and predicted spread of 60 draws of `kind`.
fn means(kind: Noise, tail: bool) -> (f64, f64, f64) {
    let draws: Vec<(f64, f64, f64)> = (0..60).map(|seed| draw(seed, kind, tail)).collect();
    let mean = |pick: fn(&(f64, f64, f64)) -> f64| {
        draws.iter().map(pick).sum::<f64>() / draws.len() as f64
    };
    (mean(|d| d.0), mean(|d| d.1), mean(|d| d.2))
}

#[test]
fn a_correct_models_held_out_gap_is_the_noise_plus_the_predicted_spread() {
    assert_calibrated(false);
}

/// Under both kinds of noise, the noise alone explains too little of the mean held-out
/// gap, and the noise plus the predicted spread explains it (within 25 %).
fn assert_calibrated(tail: bool) {
    for kind in [Noise::Declared, Noise::Relative] {
        let (gap, floor, spread) = means(kind, tail);
        assert!(gap / floor > 1.4, "gap {gap}, floor {floor}");
        let ratio = gap / (floor + spread);
        assert!(
            (ratio - 1.0).abs() < 0.25,
            "gap {gap}, floor {floor}, spread {spread}"
        );
    }
}

/// Scored on its own tail, a run starts from the very first cell its fit was fitted from:
/// that cell's noise is drawn once, with the params it moves, not a second time for the
/// scored run.
#[test]
fn a_tail_scored_after_its_training_part_is_calibrated_too() {
    assert_calibrated(true);
}

/// A watched fit tells every round: starts counted up to the number it ran, within its
/// budget, the best gap never rising and the last one the fit's own.
#[test]
fn a_watched_fit_tells_every_round_of_its_starts() {
    let model = crate::driver::compile("m", SOURCE, &[]).unwrap().model;
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let train = batch("a", (0.2, 8), Noise::Relative, &mut rng);
    let parts = (vec![train], vec![]);
    let split = Split::with_min_rows(&model, parts, (Holdout::Tail(0.3), false), 5).unwrap();
    let rounds = std::sync::Mutex::new(Vec::new());
    let watch = |round: crate::solve::fit::fitter::Round| rounds.lock().unwrap().push(round);
    let starts = Starts::new(9).watched(&watch);
    let fit = fit_model(&split, &model, (&BTreeMap::new(), starts), 1).unwrap();
    let rounds = rounds.into_inner().unwrap();
    assert!(!rounds.is_empty());
    for pair in rounds.windows(2) {
        assert!(pair[1].done > pair[0].done && pair[1].best <= pair[0].best);
    }
    let last = rounds.last().unwrap();
    assert!(rounds.iter().all(|r| r.max == 10 && r.done <= r.max));
    assert_eq!(last.done, fit.fitted.starts);
    assert!((last.best - fit.fitted.gap).abs() <= 1e-12 * fit.fitted.gap.max(1e-300));
}
