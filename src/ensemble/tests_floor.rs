//! The band of a state declared `nonnegative`: the measurement censored at 0, against the
//! censored mixture computed here from its definition, and its calibration on out-of-bag
//! experiments (the same split-conformal quantile, of the censored readings' scores).

use super::band::BaseBand;
use super::calibrate::{calibrate, cells, count, MemberRuns};
use super::noise::{NoiseSource, StateNoise};
use super::Run;
use crate::record::Record;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// `Phi`, written out here from `erfc` (not the band module's).
fn phi(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// The distribution function of a reading `max(0, p_k + sigma_k e)` of the mixture of
/// `draws`: no mass below 0, the uncensored mass below 0 sitting at 0.
fn censored_cdf(draws: &[(f64, f64)], y: f64) -> f64 {
    if y < 0.0 {
        return 0.0;
    }
    draws.iter().map(|(p, s)| phi((y - p) / s)).sum::<f64>() / draws.len() as f64
}

/// The smallest `y` with `censored_cdf(y) >= q`, by bisection on `[0, 100]`.
fn censored_quantile(draws: &[(f64, f64)], q: f64) -> f64 {
    if censored_cdf(draws, 0.0) >= q {
        return 0.0;
    }
    let (mut low, mut high) = (0.0, 100.0);
    for _ in 0..200 {
        let middle = 0.5 * (low + high);
        if censored_cdf(draws, middle) >= q {
            high = middle;
        } else {
            low = middle;
        }
    }
    high
}

fn noise(floor: Option<f64>) -> StateNoise {
    StateNoise {
        state: "S".into(),
        absolute: 0.05,
        relative: 0.1,
        source: NoiseSource::Declared,
        floor,
    }
}

#[test]
fn a_floored_band_takes_the_censored_mixtures_quantiles_and_stops_at_zero() {
    let noise = noise(Some(0.0));
    for members in [&[0.02, 0.3, 0.8][..], &[-0.01, 0.01, 0.04], &[2.0, 2.5]] {
        let draws: Vec<(f64, f64)> = members.iter().map(|&p| (p, noise.sigma(p))).collect();
        let band = noise.base_band(members.iter().copied()).unwrap();
        let lower = censored_quantile(&draws, 0.05);
        let upper = censored_quantile(&draws, 0.95);
        let median = crate::numeric::median(members).unwrap();
        assert!(
            (band.median - band.below - lower.min(median)).abs() < 1e-9,
            "{members:?}: {band:?}, censored 5 % quantile {lower}"
        );
        assert!((band.median + band.above - upper).abs() < 1e-9, "{band:?}");
        for factor in [0.5, 1.0, 3.0] {
            let (lo, hi) = band.stretched(factor);
            assert!(lo >= 0.0 && lo <= hi, "{members:?} x {factor}: {lo} {hi}");
            // A reading below 0 is read as 0: inside exactly where 0 is.
            assert_eq!(band.covers(factor, -0.2), lo == 0.0);
        }
    }
    // Far from zero the floor changes nothing.
    let free = super::noise::StateNoise {
        floor: None,
        ..noise.clone()
    };
    let high = [2.0, 2.5];
    assert_eq!(
        noise
            .base_band(high.iter().copied())
            .map(|b| b.stretched(1.0)),
        free.base_band(high.iter().copied())
            .map(|b| b.stretched(1.0))
    );
}

/// Three training experiments of a state decaying to 0, measured with noise and read as 0
/// below it (as an assay does); four members, each experiment out of bag for two of them.
fn decaying() -> (Vec<Record>, Vec<MemberRuns>) {
    let mut random = ChaCha8Rng::seed_from_u64(11);
    let rows = 30;
    let truth = |e: usize, t: f64| (2.0 + 0.3 * e as f64) * (-t / 5.0).exp();
    let records: Vec<Record> = (0..3)
        .map(|e| {
            let times: Vec<f64> = (0..rows).map(|k| k as f64).collect();
            let values = (times.iter())
                .map(|&t| {
                    let z: f64 = StandardNormal.sample(&mut random);
                    (truth(e, t) + 0.05 * z).max(0.0)
                })
                .collect();
            Record::complete(&format!("e{e}"), times, vec![], vec![values])
        })
        .collect();
    let out_of_bag = [vec![0, 1], vec![1, 2], vec![0, 2], vec![]];
    let members = (out_of_bag.iter().enumerate())
        .map(|(k, out)| MemberRuns {
            index: k + 1,
            out_of_bag: out.clone(),
            runs: (0..3)
                .map(|e| Run {
                    start: 0,
                    states: vec![(0..rows)
                        .map(|row| truth(e, row as f64) * (0.9 + 0.1 * k as f64) - 0.03)
                        .collect()],
                })
                .collect(),
        })
        .collect();
    (records, members)
}

#[test]
fn a_floored_band_is_calibrated_on_censored_readings_out_of_bag() {
    let (records, members) = decaying();
    let states = ["S".to_string()];
    let floored = [noise(Some(0.0))];
    let calibration = calibrate(&states, &records, &members, &floored);
    assert!(calibration.calibrated && !calibration.states[0].pooled);
    // The scores, recomputed here: each out-of-bag cell's reading max(y, 0), its distance
    // from the out-of-bag members' median over the censored mixture's half-width.
    let mut expected = Vec::new();
    for (e, record) in records.iter().enumerate() {
        let out: Vec<&MemberRuns> = members
            .iter()
            .filter(|m| m.out_of_bag.contains(&e))
            .collect();
        for row in 1..record.len() {
            let predictions: Vec<f64> = out.iter().map(|m| m.runs[e].states[0][row]).collect();
            let draws: Vec<(f64, f64)> = (predictions.iter())
                .map(|&p| (p, floored[0].sigma(p)))
                .collect();
            let median = crate::numeric::median(&predictions).unwrap();
            let reading = record.states[0][row].unwrap().max(0.0);
            let score = if reading >= median {
                (reading - median) / (censored_quantile(&draws, 0.95) - median)
            } else {
                (median - reading) / (median - censored_quantile(&draws, 0.05).min(median))
            };
            expected.push(score);
        }
    }
    expected.sort_by(f64::total_cmp);
    let scores = &calibration.states[0].scores;
    assert_eq!(scores.len(), expected.len());
    for (got, want) in scores.iter().zip(&expected) {
        assert!(
            (got - want).abs() <= 1e-9 * want.abs().max(1.0),
            "{got} {want}"
        );
    }
    // The band at 90 % holds at least 90 % of the cells it was calibrated on, and never
    // reaches below zero; without the floor the same members' band does.
    let factor = calibration.factor(0, 0.9).unwrap();
    let unfloored = [noise(None)];
    let (mut inside, mut total, mut below_zero) = (0, 0, 0);
    for (e, record) in records.iter().enumerate() {
        let runs: Vec<&Run> = (members.iter())
            .filter(|m| m.out_of_bag.contains(&e))
            .map(|m| &m.runs[e])
            .collect();
        let (counts, _) = count(record, &runs, (&floored, &calibration), 0.9);
        (inside, total) = (inside + counts[0].inside, total + counts[0].cells);
        for cell in cells(record, &runs, &floored) {
            assert!(cell.base.unwrap().stretched(factor).0 >= 0.0);
        }
        below_zero += (cells(record, &runs, &unfloored).iter())
            .filter(|c| {
                c.base
                    .is_some_and(|b: BaseBand| b.stretched(factor).0 < 0.0)
            })
            .count();
    }
    assert!(inside as f64 >= 0.9 * total as f64, "{inside} of {total}");
    assert!(
        below_zero > 0,
        "the unfloored band reaches below zero somewhere"
    );
}
