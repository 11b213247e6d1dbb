//! Training throughput: the median time of an epoch of Adam steps (and of one step) for a
//! model on a record, timed on the same code path as `gbc train` (`gbc bench`'s training rows; `docs/performance.md` records the numbers).
//!
//! The pairs are built once as in training; then whole epochs of shuffled mini-batches each
//! take one Adam step per batch (gather the batch, forward RK4 pass through the closure
//! networks and the physics, reverse pass, update). One untimed warm-up epoch comes first;
//! every later epoch is timed on its own, and the report gives the median, which a busy
//! machine disturbs less than the mean.

use std::time::Instant;

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::engine::graph::{Network, Precision, Setup, StepSettings};
use crate::ir;

use crate::engine::pairs::{stage_fractions, PairTable};
use crate::engine::step::{Optimiser, Step, StepBatch};
use crate::train::prepare::Layout;
use crate::train::validation::{refresh, Course};
use crate::train::{analysis, hidden_initial_values, Part, TrainError, TrainOptions, TrainingData};

pub use crate::train::Engine;

/// Measured throughput.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BenchReport {
    /// The step implementation.
    pub engine: Engine,
    /// Element type.
    pub precision: Precision,
    /// Training pairs.
    pub train_points: usize,
    /// Batch size.
    pub batch_size: usize,
    /// Adam steps per epoch (`train_points / batch_size`, rounded up).
    pub steps_per_epoch: usize,
    /// Wall-clock seconds of each timed epoch, in order.
    pub epoch_seconds: Vec<f64>,
    /// Median of `epoch_seconds`.
    pub median_epoch_seconds: f64,
    /// The median epoch divided by its steps.
    pub median_step_seconds: f64,
    /// Mean training loss of the last timed epoch (a check that it trains).
    pub final_loss: f64,
}

/// Times training of `model` on the one-step pairs of `data` (the first `train_points` of
/// a single record, or every pair of every experiment) with the batch size, learning rate,
/// precision, sub-steps, seed and engine of `options`; `options.epochs` epochs are timed.
pub fn bench(
    model: &ir::Model,
    data: &TrainingData,
    options: &TrainOptions,
) -> Result<BenchReport, TrainError> {
    let (setup, network, table) = prepare(model, data, options)?;
    // What `gbc train` runs: the engine under the one optimiser.
    let mut optimiser = Optimiser::new(&network, options.precision);
    let mut step: Box<dyn Step> = match options.engine.fused_step(model, &setup)? {
        Some(fused) => Box::new(fused),
        None => Box::new(network),
    };
    let settings = StepSettings::plain(options.learning_rate);
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let mut order: Vec<usize> = (0..table.len()).collect();
    let batch_size = options.batch_size.max(1);
    let mut epoch = |step: &mut Box<dyn Step>| -> Result<f64, TrainError> {
        order.shuffle(&mut rng);
        let mut total = 0.0;
        for chunk in order.chunks(batch_size) {
            let batch = table.batch(chunk);
            let loss = optimiser.step(step.as_mut(), StepBatch::Pairs(&batch), &settings)?;
            total += loss * chunk.len() as f64;
        }
        Ok(total / order.len().max(1) as f64)
    };
    epoch(&mut step)?;
    let mut epoch_seconds = Vec::with_capacity(options.epochs.max(1));
    let mut final_loss = f64::NAN;
    for _ in 0..options.epochs.max(1) {
        let started = Instant::now();
        final_loss = epoch(&mut step)?;
        epoch_seconds.push(started.elapsed().as_secs_f64());
    }
    Ok(report(
        options,
        (table.len(), batch_size),
        epoch_seconds,
        final_loss,
    ))
}

/// The training pairs of `bench` built as training builds them (with the network's setup
/// and the initial network that fills their hidden states).
fn prepare(
    model: &ir::Model,
    data: &TrainingData,
    options: &TrainOptions,
) -> Result<(Setup, Network, PairTable), TrainError> {
    let part = options
        .train_points
        .map_or(Part::All, |n| Part::FirstPairs(Some(n)));
    if options.train_points == Some(0) {
        return Err(TrainError::TooManyTrainPoints {
            available: 0,
            requested: 0,
        });
    }
    let train_options = TrainOptions {
        substeps: options.substeps.max(1),
        ..TrainOptions::default()
    };
    let layout = Layout::new(model, &TrainingData { part, ..*data }, &train_options)?;
    let hidden_init = hidden_initial_values(model)?;
    let setup = setup_of(model, &layout, options, &hidden_init)?;
    let network = Network::build(model, &setup)?;
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    let weights = vec![1.0; model.states.len()];
    let observables = layout.normalisation.observables.clone();
    let pairs = (
        layout.pairs.as_slice(),
        weights.as_slice(),
        observables.as_slice(),
    );
    let mut course = Course::new(model, layout.tracks, pairs, &fractions);
    refresh(
        &network,
        model,
        &mut course,
        (&fractions, false),
        &hidden_init,
    )?;
    Ok((setup, network, course.table))
}

/// The network's setup on the pairs of `layout`, as training sets it up.
fn setup_of(
    model: &ir::Model,
    layout: &Layout,
    options: &TrainOptions,
    hidden_init: &[f64],
) -> Result<Setup, TrainError> {
    Ok(Setup {
        step: layout.grid.max_step,
        substeps: options.substeps.max(1),
        precision: options.precision,
        seed: options.seed,
        normalisation: layout.normalisation.clone(),
        scales: analysis::closure_scales(model, &layout.tracks, &layout.intervals, hidden_init)?,
    })
}

/// The report of `epoch_seconds` timed epochs over `points` pairs in batches of
/// `batch_size`.
fn report(
    options: &TrainOptions,
    (points, batch_size): (usize, usize),
    epoch_seconds: Vec<f64>,
    final_loss: f64,
) -> BenchReport {
    let steps_per_epoch = points.div_ceil(batch_size);
    let median_epoch_seconds = crate::numeric::median(&epoch_seconds).unwrap_or(f64::NAN);
    BenchReport {
        engine: options.engine,
        precision: options.precision,
        train_points: points,
        batch_size,
        steps_per_epoch,
        epoch_seconds,
        median_epoch_seconds,
        median_step_seconds: median_epoch_seconds / steps_per_epoch as f64,
        final_loss,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::fixtures::chemostat;

    fn options(engine: Engine) -> TrainOptions {
        TrainOptions {
            train_points: Some(120),
            epochs: 3,
            engine,
            ..TrainOptions::default()
        }
    }

    #[test]
    fn bench_times_whole_epochs_of_adam_steps_with_both_engines() {
        let (data, _) = chemostat::data(200, (0.002, 0.02), 1);
        let model = chemostat::grey_box();
        let records = [crate::train::fixtures::record(&model, &data)];
        let data = TrainingData {
            train: &records,
            validation: &[],
            part: Part::All,
        };
        let graph = bench(&model, &data, &options(Engine::Graph)).unwrap();
        let fused = bench(&model, &data, &options(Engine::Fused)).unwrap();
        for report in [&graph, &fused] {
            assert_eq!(report.steps_per_epoch, 3);
            assert_eq!(report.epoch_seconds.len(), 3);
            assert!(report.epoch_seconds.iter().all(|&s| s > 0.0));
            let step = report.median_epoch_seconds / 3.0;
            assert!((report.median_step_seconds / step - 1.0).abs() < 1e-12);
        }
        // Same weights, same shuffles, same arithmetic up to rounding: the same training.
        let relative = (fused.final_loss / graph.final_loss - 1.0).abs();
        assert!(
            relative < 1e-3,
            "{} vs {}",
            fused.final_loss,
            graph.final_loss
        );
        let too_many = TrainOptions {
            train_points: Some(1000),
            ..options(Engine::Graph)
        };
        assert!(bench(&model, &data, &too_many).is_err());
    }
}
