//! Training tests on data simulated from the paper's chemostat (spec section 4).

use super::fixtures::chemostat;
use super::*;

fn options(epochs: usize, train_points: usize) -> TrainOptions {
    TrainOptions {
        epochs,
        train_points: Some(train_points),
        seed: 3,
        ..TrainOptions::default()
    }
}

fn quiet(_: Event) {}

#[test]
fn short_training_on_chemostat_data_cuts_the_validation_error() {
    let (data, _) = chemostat::data(700, (0.002, 0.02), 1);
    let trained = train(&chemostat::grey_box(), &data, None, &options(15, 500), &mut quiet).unwrap();
    let metrics = &trained.report.metrics;
    let before = metrics.initial_offline.as_ref().unwrap().overall;
    let after = metrics.offline.as_ref().unwrap().overall;
    assert!(after < before / 20.0, "offline error {before} -> {after}");
    let online = metrics.online.as_ref().unwrap().overall;
    eprintln!("{metrics:#?} {:?}", trained.report.losses);
    assert!(online.is_finite() && online < before, "online error {online}");
    assert!(trained.report.warnings.is_empty());
}
