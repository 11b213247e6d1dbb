//! What the data and the balances say before training, and `positive` outputs under a
//! prior in training: the learned rate vanishes where its prior does.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::train::fixtures::{dataset, options, random_steps, sample_truth, track, train_one};
use crate::train::*;
use crate::trained::predict::{predict_in_range, Mode};

/// Monod growth on a substrate that runs out: `mu = top S / (0.1 + S)`, yield 0.5.
fn batch_monod(top: f64, rows: usize, step: f64) -> crate::data::Dataset {
    let rhs = |x: &[f64], _: &[f64]| {
        let mu = top * x[1] / (0.1 + x[1]);
        vec![mu * x[0], -mu * x[0] / 0.5]
    };
    let held = vec![vec![0.0; rows]];
    let states = sample_truth(rhs, &[0.1, 4.0], &held, step, 20);
    dataset(
        step,
        vec![
            ("X", states.iter().map(|x| x[0]).collect()),
            ("S", states.iter().map(|x| x[1]).collect()),
        ],
    )
}

fn compile(source: &str) -> ir::Model {
    crate::driver::compile("test.gbm", source, &[])
        .unwrap()
        .model
}

/// The true rate is the prior times 1. With the old positive map `s softplus(p (1 + n) /
/// s)` the rate had a floor of `s ln 2` (0.69 1/h at s = 1) once the substrate was gone.
#[test]
fn a_positive_rate_under_a_monod_prior_vanishes_when_the_substrate_is_gone() {
    let model = compile(
        "model batch\nstate X, S\nclosure growth {\n  outputs mu positive\n  observe S\n  \
         network hidden [6] tanh\n  prior mu *= 0.5 * S / (0.1 + S)\n}\n\
         der X = mu * X\nder S = -mu * X / 0.5\n",
    );
    let data = batch_monod(0.5, 200, 0.1);
    let trained = train_one(&model, &data, None, &options(20, 150), &Recipe::default()).unwrap();
    let record = record_of(&model, &data).unwrap();
    let how = (Mode::Offline, History::Measured, None);
    let table = predict_in_range(&model, &trained.network, &trained.setup, &record, how).unwrap();
    let (times, substrate, rate) = (&table.columns[0], &table.columns[2], &table.columns[3]);
    let mut gone = 0;
    for row in 0..times.len() {
        let (s, mu) = (substrate[row], rate[row]);
        let truth = 0.5 * s.max(0.0) / (0.1 + s.max(0.0));
        assert!(mu >= 0.0, "t = {}: mu {mu}", times[row]);
        if s < 1e-4 {
            gone += 1;
            assert!(mu < 2e-3, "t = {}: S {s}, mu {mu}", times[row]);
        } else if s > 0.5 {
            assert!(
                (mu / truth - 1.0).abs() < 0.1,
                "t = {}: mu {mu} vs {truth}",
                times[row]
            );
        }
    }
    assert!(gone > 50, "only {gone} rows without substrate");
}

/// The default magnitudes of `model` on `data`, every pair of the record a row.
fn default_scales(model: &ir::Model, data: &crate::data::Dataset) -> Vec<Vec<f64>> {
    let track = track(model, data);
    let pairs: Vec<(usize, usize)> = (0..track.len() - 1).map(|r| (0, r)).collect();
    analysis::closure_scales(model, std::slice::from_ref(&track), &pairs, &[]).unwrap()
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, count) = values.fold((0.0, 0), |(s, c), v| (s + v * v, c + 1));
    (sum / count as f64).sqrt()
}

/// `der X = mu * X` in seconds: the magnitude of mu is `dX/dt / X` (5e-4 1/s at most), not
/// `dX/dt`. (Before, a `positive` output counted as `ln 2` at network output 0 in the known
/// part, which put the default near 1: 2000x off.)
#[test]
fn the_default_magnitude_of_a_rate_multiplying_its_own_state_is_the_rate() {
    let model = compile(
        "model growth\nstate X, S\nclosure growth {\n  outputs mu positive\n  observe S\n}\n\
         der X = mu * X\nder S = -mu * X / 0.5\n",
    );
    let data = batch_monod(5e-4, 200, 50.0);
    let substrate = &data.columns[1].values;
    let truth = rms(substrate[..199].iter().map(|s| 5e-4 * s / (0.1 + s)));
    let ratio = default_scales(&model, &data)[0][0] / truth;
    assert!(
        (1.0 / 3.0..3.0).contains(&ratio),
        "default / truth = {ratio}"
    );
}

/// Two uptake rates share the substrate balance: each gets half of what the balance needs.
#[test]
fn outputs_sharing_a_balance_split_its_rate() {
    let model = compile(
        "model shared\ninput Sin\nstate S\nclosure uptake {\n  outputs r1 positive, r2 positive\n\
         observe S\n}\nder S = 0.001 * (Sin - S) - r1 - r2\n",
    );
    let laws = |s: f64| (2e-3 * s / (0.5 + s), 1e-3 * s);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let inlet = random_steps(400, (1.0, 5.0), (10, 30), &mut rng);
    let rhs = |x: &[f64], u: &[f64]| {
        let (r1, r2) = laws(x[0]);
        vec![0.001 * (u[0] - x[0]) - r1 - r2]
    };
    let states = sample_truth(rhs, &[1.0], std::slice::from_ref(&inlet), 20.0, 10);
    let substrate: Vec<f64> = states.iter().map(|x| x[0]).collect();
    let data = dataset(20.0, vec![("Sin", inlet), ("S", substrate.clone())]);
    let scales = default_scales(&model, &data);
    let rows = || substrate[..399].iter().map(|&s| laws(s));
    for (k, truth) in [rms(rows().map(|r| r.0)), rms(rows().map(|r| r.1))]
        .iter()
        .enumerate()
    {
        let ratio = scales[0][k] / truth;
        assert!(
            (1.0 / 3.0..3.0).contains(&ratio),
            "r{}: default / truth = {ratio}",
            k + 1
        );
    }
}

/// Chemostat with a Monod uptake of small `K` (a stiff substrate balance) and a product made
/// at a rate `q X`, sampled every 0.05 h with 0.1 % noise.
mod stiff_chemostat {
    pub const K: f64 = 0.01;
    pub const TOP: f64 = 2.0;
    pub const D: f64 = 0.1;
    pub const STEP: f64 = 0.05;

    pub fn rhs(x: &[f64], u: &[f64]) -> Vec<f64> {
        let (biomass, substrate) = (x[0], x[1]);
        let uptake = TOP * biomass * substrate / (K + substrate);
        let q = 0.3 * substrate / (0.5 + substrate) + 0.05;
        vec![
            0.5 * uptake - D * biomass,
            D * (u[0] - substrate) - uptake,
            q * biomass,
        ]
    }

    /// The most negative eigenvalue of the `(X, S)` block of the Jacobian.
    pub fn stiffest(x: &[f64]) -> f64 {
        let (biomass, substrate) = (x[0], x[1]);
        let by_biomass = TOP * substrate / (K + substrate);
        let by_substrate = TOP * biomass * K / (K + substrate).powi(2);
        let (a, b, c, d) = (
            0.5 * by_biomass - D,
            0.5 * by_substrate,
            -by_biomass,
            -D - by_substrate,
        );
        let half_trace = (a + d) / 2.0;
        let determinant = a * d - b * c;
        half_trace - (half_trace * half_trace - determinant).max(0.0).sqrt()
    }

    pub const MODEL: &str = "model product\ninput Sin\nstate X, S, P\nconst D = 0.1\n\
        closure rates {\n  outputs r positive, q positive\n  observe X, S, P, Sin\n}\n\
        der X = 0.5 * r - D * X\nder S = D * (Sin - S) - r\nder P = q * X\n";
}

#[test]
fn a_production_balance_is_not_stiff_and_a_stiff_uptake_warns_with_the_jacobians_count() {
    use stiff_chemostat::*;
    let model = compile(MODEL);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let inlet = random_steps(400, (1.0, 5.0), (20, 60), &mut rng);
    let steady = K * D / (0.5 * TOP - D);
    let start = [0.5 * (inlet[0] - steady), steady, 0.0];
    let truth = sample_truth(rhs, &start, std::slice::from_ref(&inlet), STEP, 40);
    let mut noisy = |i: usize| -> Vec<f64> {
        (truth.iter())
            .map(|x| x[i] * (1.0 + rng.gen_range(-1e-3..1e-3)))
            .collect()
    };
    let columns = vec![("X", noisy(0)), ("S", noisy(1)), ("P", noisy(2))];
    let mut named = vec![("Sin", inlet)];
    named.extend(columns);
    let data = dataset(STEP, named);
    let tracks = [track(&model, &data)];
    let pairs: Vec<(usize, usize)> = (0..399).map(|r| (0, r)).collect();
    let warnings = |substeps| analysis::stiffness(&model, (&tracks, &pairs), &[], substeps);
    let found = warnings(1).unwrap();
    let names: Vec<&str> = found.iter().map(|w| w.balance.as_str()).collect();
    assert_eq!(names, ["S"], "{found:?}");
    let eigenvalues: Vec<f64> = truth[..399].iter().map(|x| stiffest(x)).collect();
    let exact = crate::numeric::order_statistic(&eigenvalues, 0.01).unwrap();
    let warning = &found[0];
    let ratio = warning.eigenvalue / exact;
    assert!((0.8..2.0).contains(&ratio), "{warning}; Jacobian {exact}");
    let needed = (STEP * -exact / analysis::RK4_STABILITY_LIMIT).ceil() as usize;
    assert!(needed >= 4, "the case is stiff: {needed}");
    let count = warning.substeps_needed;
    assert!(
        (needed..=2 * needed).contains(&count),
        "{count} vs {needed}"
    );
    assert!(warnings(count).unwrap().is_empty());
}
