//! Training throughput: Adam steps per second and seconds per epoch for a model on a record,
//! timed on the same code path as `gbc train` (the entry point of `gbc bench`).

use std::time::Instant;

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::backend::{Network, Precision, Setup};
use crate::data::Dataset;
use crate::ir;

use super::evaluate::run_in_hidden;
use super::pairs::{first_pair_row, stage_fractions, PairTable};
use super::{analysis, hidden_initial_values, normalise, record_of, TrainError};

/// What to time.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchOptions {
    /// Training pairs (the first ones of the record).
    pub train_points: usize,
    /// Pairs per Adam step.
    pub batch_size: usize,
    /// Epochs timed (after one untimed warm-up epoch).
    pub epochs: usize,
    /// Element type.
    pub precision: Precision,
    /// RK4 sub-steps per sample.
    pub substeps: usize,
    /// Seed.
    pub seed: u64,
}

/// Measured throughput.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BenchReport {
    /// Element type.
    pub precision: Precision,
    /// Training pairs.
    pub train_points: usize,
    /// Batch size.
    pub batch_size: usize,
    /// Adam steps timed.
    pub steps: usize,
    /// Wall-clock seconds of the timed epochs.
    pub seconds: f64,
    /// Adam steps per second.
    pub steps_per_second: f64,
    /// Seconds per epoch (`train_points / batch_size` steps, rounded up).
    pub seconds_per_epoch: f64,
}

/// Times training of `model` on the first `train_points` pairs of `data`.
pub fn bench(
    model: &ir::Model,
    data: &Dataset,
    options: &BenchOptions,
) -> Result<BenchReport, TrainError> {
    let record = record_of(model, data)?;
    let first = first_pair_row(model, record.step);
    let available = record.len().saturating_sub(first + 1);
    if options.train_points == 0 || options.train_points > available {
        return Err(TrainError::TooManyTrainPoints {
            available,
            requested: options.train_points,
        });
    }
    let rows: Vec<usize> = (first..first + options.train_points).collect();
    let hidden_init = hidden_initial_values(model)?;
    let setup = Setup {
        step: record.step,
        substeps: options.substeps.max(1),
        precision: options.precision,
        seed: options.seed,
        normalisation: normalise(&record, first + options.train_points + 1),
        scales: analysis::closure_scales(model, &record, &rows, &hidden_init)?,
    };
    let mut network = Network::build(model, &setup)?;
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    let hidden = run_in_hidden(&network, model, &record, &fractions, &hidden_init)?;
    let table = PairTable::build(model, &record, &rows, &hidden, &fractions);
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let mut order: Vec<usize> = (0..table.len()).collect();
    let batch_size = options.batch_size.max(1);
    let mut epoch = |network: &mut Network| -> Result<usize, TrainError> {
        order.shuffle(&mut rng);
        let mut steps = 0;
        for chunk in order.chunks(batch_size) {
            network.train_step(&table.batch(chunk), 1e-3)?;
            steps += 1;
        }
        Ok(steps)
    };
    epoch(&mut network)?;
    let started = Instant::now();
    let mut steps = 0;
    for _ in 0..options.epochs.max(1) {
        steps += epoch(&mut network)?;
    }
    let seconds = started.elapsed().as_secs_f64();
    let steps_per_epoch = options.train_points.div_ceil(batch_size);
    Ok(BenchReport {
        precision: options.precision,
        train_points: options.train_points,
        batch_size,
        steps,
        seconds,
        steps_per_second: steps as f64 / seconds,
        seconds_per_epoch: seconds / steps as f64 * steps_per_epoch as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::fixtures::chemostat;

    #[test]
    fn bench_times_whole_epochs_of_adam_steps() {
        let (data, _) = chemostat::data(200, (0.002, 0.02), 1);
        let options = BenchOptions {
            train_points: 120,
            batch_size: 50,
            epochs: 2,
            precision: Precision::F32,
            substeps: 1,
            seed: 0,
        };
        let report = bench(&chemostat::grey_box(), &data, &options).unwrap();
        assert_eq!(report.steps, 6);
        assert!(report.seconds > 0.0 && report.steps_per_second > 0.0);
        let per_epoch = report.seconds / 2.0;
        assert!((report.seconds_per_epoch / per_epoch - 1.0).abs() < 1e-9);
        let too_many = BenchOptions {
            train_points: 1000,
            ..options
        };
        assert!(bench(&chemostat::grey_box(), &data, &too_many).is_err());
    }
}
