//! Measurement noise added to a simulated record (`gbc simulate --noise SPEC`).
//!
//! Without `--noise` the record is exact. With specs, the noise is the model's `noise`
//! declarations with the specs laid over them (`ir::merge_noise`): `--noise declared` adds
//! the declared noise, `--noise X=4%+0.01` sets `X`'s, a bare `--noise 0.01` (relative, 1 %)
//! sets every measured state's and every output's that declares noise. A quantity with
//! noise of standard deviation `sigma(y) = sqrt(absolute^2 + (relative * y)^2)` becomes
//! `y + sigma(y) * z`, `z` standard normal; a purely relative noise is applied as
//! `y * (1 + relative * z)`, the same bits as before the combined model. The draws come row
//! by row from a ChaCha8 generator seeded with `--seed`: one per measured state (noisy or
//! not, so that a state's draws do not depend on the others' noise), then one per noisy
//! output. Hidden states and outputs without noise stay exact.

use crate::api::ApiError;
use crate::ir::{merge_noise, Measured, Model, Noise, NoiseSpec};
use crate::solve::ode::Trajectory;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// The noise the specs ask for: none without specs, else the declarations with the specs
/// laid over them, a bare level covering [`Model::measured`].
pub fn record_noise(model: &Model, specs: &[NoiseSpec]) -> Result<Vec<Noise>, ApiError> {
    if specs.is_empty() {
        return Ok(Vec::new());
    }
    merge_noise(model, specs, &model.measured()).map_err(ApiError::user)
}

/// Adds `noise` to the trajectory's measured states and outputs, row by row.
pub fn add_noise(trajectory: &mut Trajectory, noise: &[Noise], seed: u64) {
    if noise.is_empty() {
        return;
    }
    let of = |target: Measured| noise.iter().find(|n| n.target == target);
    let states: Vec<Option<&Noise>> = (0..trajectory.states.len())
        .map(|i| of(Measured::State(i)))
        .collect();
    let outputs: Vec<(usize, &Noise)> = (0..trajectory.outputs.len())
        .filter_map(|j| Some((j, of(Measured::Output(j))?)))
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for k in 0..trajectory.len() {
        for (column, level) in trajectory.states.iter_mut().zip(&states) {
            let draw: f64 = StandardNormal.sample(&mut rng);
            if let Some(level) = level {
                column[k] = perturb(column[k], level, draw);
            }
        }
        for &(j, level) in &outputs {
            let draw: f64 = StandardNormal.sample(&mut rng);
            trajectory.outputs[j][k] = perturb(trajectory.outputs[j][k], level, draw);
        }
    }
}

/// One measurement of `value` with standard normal draw `draw`.
fn perturb(value: f64, noise: &Noise, draw: f64) -> f64 {
    if noise.absolute == 0.0 {
        value * (1.0 + noise.relative * draw)
    } else {
        value + noise.sigma(value) * draw
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trajectory(states: Vec<Vec<f64>>, outputs: Vec<Vec<f64>>) -> Trajectory {
        let samples = states.first().map_or(0, Vec::len);
        Trajectory {
            times: vec![0.0; samples],
            inputs: vec![],
            states,
            hidden: vec![vec![1.0; samples]],
            outputs,
            lets: vec![],
            stats: Default::default(),
        }
    }

    fn level(target: Measured, relative: f64, absolute: f64) -> Noise {
        Noise {
            target,
            relative,
            absolute,
        }
    }

    /// Mean and population standard deviation.
    fn moments(values: &[f64]) -> (f64, f64) {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
        (mean, variance.sqrt())
    }

    #[test]
    fn relative_noise_has_the_requested_spread() {
        let samples = 20_000;
        let mut record = trajectory(vec![vec![2.0; samples], vec![-5.0; samples]], vec![]);
        let noise = [
            level(Measured::State(0), 0.05, 0.0),
            level(Measured::State(1), 0.05, 0.0),
        ];
        add_noise(&mut record, &noise, 1);
        for (column, value) in record.states.iter().zip([2.0, -5.0]) {
            let draws: Vec<f64> = column.iter().map(|y| (y / value - 1.0) / 0.05).collect();
            let (mean, std) = moments(&draws);
            assert!(mean.abs() < 0.03, "mean {mean}");
            assert!((std - 1.0).abs() < 0.03, "std {std}");
        }
        assert!(record.hidden[0].iter().all(|&h| h == 1.0));
    }

    #[test]
    fn absolute_noise_has_its_standard_deviation_whatever_the_value() {
        let samples = 40_000;
        let ramp: Vec<f64> = (0..samples).map(|k| k as f64 * 1e-3).collect();
        let mut record = trajectory(vec![ramp.clone(), ramp.clone()], vec![ramp.clone()]);
        let noise = [
            level(Measured::State(1), 0.0, 0.02),
            level(Measured::Output(0), 0.0, 0.5),
        ];
        add_noise(&mut record, &noise, 7);
        assert_eq!(record.states[0], ramp, "a state without noise stays exact");
        for (column, sigma) in [(&record.states[1], 0.02), (&record.outputs[0], 0.5)] {
            let errors: Vec<f64> = column.iter().zip(&ramp).map(|(y, x)| y - x).collect();
            let (mean, std) = moments(&errors);
            assert!(
                mean.abs() < 4.0 * sigma / (samples as f64).sqrt(),
                "mean {mean}"
            );
            assert!((std / sigma - 1.0).abs() < 0.02, "std {std} for {sigma}");
        }
    }

    #[test]
    fn combined_noise_follows_sigma_of_the_value() {
        let samples = 40_000;
        let mut record = trajectory(vec![vec![3.0; samples]], vec![]);
        add_noise(&mut record, &[level(Measured::State(0), 0.04, 0.09)], 3);
        let (_, std) = moments(&record.states[0]);
        // sqrt(0.09^2 + (0.04 * 3)^2) = sqrt(0.0081 + 0.0144) = 0.15
        assert!((std / 0.15 - 1.0).abs() < 0.02, "std {std}");
    }

    #[test]
    fn purely_relative_noise_keeps_the_bits_of_the_scalar_form() {
        let samples = 50;
        let values: Vec<f64> = (0..samples).map(|k| 0.3 + k as f64 / 7.0).collect();
        let mut record = trajectory(vec![values.clone(), values.clone()], vec![]);
        let noise = [
            level(Measured::State(0), 0.01, 0.0),
            level(Measured::State(1), 0.01, 0.0),
        ];
        add_noise(&mut record, &noise, 9);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut expected = vec![values.clone(), values];
        for k in 0..samples {
            for column in &mut expected {
                let draw: f64 = StandardNormal.sample(&mut rng);
                column[k] *= 1.0 + 0.01 * draw;
            }
        }
        assert_eq!(record.states, expected);
    }
}
