//! Test support of training: the engines' fixtures ([`crate::engine::fixtures`]) and
//! training's own (options, a silent listener, one training under the paper's protocol).

pub use crate::engine::fixtures::*;

use crate::ir;

/// Training options of the training tests: `epochs`, the first `train_points` pairs, seed 3.
pub fn options(epochs: usize, train_points: usize) -> crate::train::TrainOptions {
    crate::train::TrainOptions {
        epochs,
        train_points: Some(train_points),
        seed: 3,
        ..Default::default()
    }
}

/// A training-event sink that ignores every event.
pub fn quiet(_: crate::train::Event) {}

/// Trains `model` on the record `data` under the paper's protocol (the first
/// `options.train_points` pairs), validated by the rest or by `validation` when given.
pub fn train_one(
    model: &ir::Model,
    data: &crate::data::Dataset,
    validation: Option<&crate::data::Dataset>,
    options: &crate::train::TrainOptions,
    recipe: &crate::train::Recipe,
) -> Result<crate::train::Trained, crate::train::TrainError> {
    let train = [record(model, data)];
    let held: Vec<crate::record::Record> =
        validation.map(|v| record(model, v)).into_iter().collect();
    let data = crate::train::TrainingData {
        train: &train,
        validation: &held,
        part: crate::train::Part::FirstPairs(options.train_points),
    };
    crate::train::train_with(model, &data, options, recipe, &mut quiet)
}
