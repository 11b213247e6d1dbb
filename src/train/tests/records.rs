//! Training on data sets: measured outputs (observables), tail splits, leave-one-out
//! cross-validation, per-column weights, and a record thinned to a quarter of its cells.

use crate::record::{Observable, Record};
use crate::train::fixtures::{chemostat, options, quiet, record};
use crate::train::*;
use crate::trained::{cv, predict};

/// The chemostat grey box whose sensor reads `absorbance = 2 S`: `S` itself is never
/// measured and starts from its declared value.
fn absorbance_model(start: f64) -> ir::Model {
    let source = format!(
        "model chemostat_absorbance\ntime s\ninput E0\nstate S = {start}\nconst S0 = 0.03\n\
         const theta = 20\nclosure rate {{\n  outputs r ~ 1e-3\n  observe S, E0\n  \
         embed delay 10 dim 5\n  network hidden [16, 16] softplus\n}}\n\
         output absorbance = 2 * S\nder S = (S0 - S) / theta + r\n"
    );
    crate::driver::compile("absorbance.gbm", &source, &[])
        .unwrap()
        .model
}

/// `data` with `S` replaced by the sensor reading `2 S`, named `name`.
fn absorbance_record(model: &ir::Model, data: &crate::data::Dataset, name: &str) -> Record {
    let substrate = data.column("S").unwrap();
    Record {
        name: name.into(),
        source: name.into(),
        times: data.times.clone(),
        inputs: vec![data.column("E0").unwrap().to_vec()],
        states: vec![vec![None; data.len()]],
        observables: vec![Observable {
            output: 0,
            name: model.outputs[0].name.clone(),
            cells: substrate.iter().map(|s| Some(2.0 * s)).collect(),
        }],
    }
}

/// A sensor reading a function of the state trains the model like the state would: its
/// cells enter the loss, and the free run of an unseen experiment follows them.
#[test]
fn a_measured_output_trains_a_model_whose_state_is_not_measured() {
    let (train_data, _) = chemostat::data(300, (0.002, 0.02), 11);
    let (test_data, _) = chemostat::data(200, (0.002, 0.02), 11);
    let start = train_data.column("S").unwrap()[0];
    let model = absorbance_model(start);
    let train = [absorbance_record(&model, &train_data, "train")];
    let mut held = absorbance_record(&model, &test_data, "held");
    // The held-out experiment starts elsewhere: its S starts at its own first reading / 2.
    let test_start = test_data.column("S").unwrap()[0];
    let data = TrainingData {
        train: &train,
        validation: std::slice::from_ref(&held),
        part: Part::All,
    };
    // The state is all fill, the model's own run: the multi-step objective trains it (a
    // one-step pair would start from the fill, not from data).
    let options = TrainOptions {
        train_points: None,
        ..options(200, 1)
    };
    let trained = train_with(&model, &data, &options, &Recipe::default(), &mut quiet).unwrap();
    let metrics = &trained.report.metrics;
    assert_eq!(trained.setup.normalisation.observables, vec![0]);
    let online = metrics.online.as_ref().unwrap();
    let names: Vec<&str> = online.per_state.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        vec!["absorbance"],
        "only the sensor has cells: {online:?}"
    );
    let before = metrics.initial_online.as_ref().unwrap().overall;
    assert!(
        online.overall < before / 5.0,
        "online {before} -> {}",
        online.overall
    );
    assert!(online.overall < 1.0, "{}", online.overall);
    assert!(trained.report.train_pairs > 250);
    // The free run's S is the sensor's reading over 2 (within the fit).
    held.states[0][0] = Some(test_start);
    let table = predict::predict(
        &model,
        &trained.network,
        &trained.setup,
        &held,
        (predict::Mode::Online, History::Held),
    )
    .unwrap();
    let truth = test_data.column("S").unwrap();
    let std = crate::numeric::mean_std(truth).1;
    let mse = (table.columns[1].iter().zip(truth))
        .map(|(p, t)| ((p - t) / std).powi(2))
        .sum::<f64>()
        / truth.len() as f64;
    assert!(mse < 1.0, "free-run S against the truth: {mse}");
}

/// A tail split trains on the head of every experiment and scores a free run from the
/// first row on the tail only.
#[test]
fn a_tail_split_scores_each_experiment_on_its_tail() {
    let model = chemostat::grey_box();
    let records: Vec<Record> = [(150, 1), (120, 2)]
        .iter()
        .map(|&(rows, seed)| {
            let mut r = record(&model, &chemostat::data(rows, (0.002, 0.02), seed).0);
            r.name = format!("e{seed}");
            r
        })
        .collect();
    let data = TrainingData {
        train: &records,
        validation: &[],
        part: Part::Tail(0.25),
    };
    let options = TrainOptions {
        train_points: None,
        ..options(2, 1)
    };
    let trained = train_with(&model, &data, &options, &Recipe::paper(), &mut quiet).unwrap();
    let validations = &trained.report.metrics.validations;
    let names: Vec<&str> = validations.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names, vec!["e1 (tail)", "e2 (tail)"]);
    // 150 rows: the last round(37.5) = 38 are held out and scored; 120: 30.
    let cells: Vec<usize> = (validations.iter())
        .map(|v| v.online.as_ref().unwrap().cells)
        .collect();
    assert_eq!(cells, vec![38, 30]);
    // Training pairs end before the tails: 111 + 89 steps from the first row.
    assert_eq!(trained.report.train_pairs, 111 + 89);
    let too_small = TrainingData {
        part: Part::Tail(0.001),
        ..data
    };
    match train_with(&model, &too_small, &options, &Recipe::paper(), &mut quiet) {
        Err(TrainError::SplitTooSmall {
            train,
            test,
            needed,
            ..
        }) => {
            assert_eq!((train, test, needed), (150, 0, 2));
        }
        Err(other) => panic!("expected a split too small, found {other}"),
        Ok(_) => panic!("expected a split too small"),
    }
}

/// Each fold trains without its experiment and is scored on it; the medians are over folds.
#[test]
fn cross_validation_holds_out_each_experiment_once() {
    let model = chemostat::grey_box();
    let records: Vec<Record> = (1..=3)
        .map(|seed| {
            let mut r = record(&model, &chemostat::data(100, (0.002, 0.02), seed).0);
            r.name = format!("run{seed}");
            r
        })
        .collect();
    let options = TrainOptions {
        train_points: None,
        ..options(1, 1)
    };
    let mut started = Vec::new();
    let result = cv::cross_validate(
        &model,
        &records,
        (&options, &Recipe::paper()),
        None,
        (&mut |fold, folds| started.push((fold, folds)), &mut quiet),
    )
    .unwrap();
    assert_eq!(started, vec![(0, 3), (1, 3), (2, 3)]);
    let held: Vec<&str> = result.folds.iter().map(|f| f.held_out.as_str()).collect();
    assert_eq!(held, vec!["run1", "run2", "run3"]);
    let mut online: Vec<f64> = (result.folds.iter())
        .map(|f| f.online.as_ref().unwrap().overall)
        .collect();
    online.sort_by(f64::total_cmp);
    assert_eq!(result.median_online, Some(online[1]));
    let alone = cv::cross_validate(
        &model,
        &records[..1],
        (&options, &Recipe::paper()),
        None,
        (&mut |_, _| {}, &mut quiet),
    );
    assert!(matches!(alone, Err(TrainError::BadOption { .. })));
}

/// `--weight S=W` scales every cell of S: the loss of the same network is W times larger.
#[test]
fn a_column_weight_scales_its_cells_in_the_loss() {
    let model = chemostat::grey_box();
    let records = [record(&model, &chemostat::data(120, (0.002, 0.02), 3).0)];
    let data = TrainingData {
        train: &records,
        validation: &[],
        part: Part::FirstPairs(Some(60)),
    };
    // One epoch at a vanishing learning rate: the loss of the initial network.
    let zero = |weight: f64| {
        let options = TrainOptions {
            column_weights: vec![("S".into(), weight)],
            learning_rate: 1e-300,
            ..options(1, 60)
        };
        train_with(&model, &data, &options, &Recipe::paper(), &mut quiet)
            .unwrap()
            .report
            .losses[0]
    };
    let (one, three) = (zero(1.0), zero(3.0));
    assert!((three / one - 3.0).abs() < 1e-6, "{one} {three}");
    let bad = TrainOptions {
        column_weights: vec![("Q".into(), 2.0)],
        ..options(1, 60)
    };
    match train_with(&model, &data, &bad, &Recipe::paper(), &mut quiet) {
        Err(TrainError::BadOption {
            option, expected, ..
        }) => {
            assert_eq!(option, "column_weights");
            assert!(expected.contains("measured state"), "{expected}");
        }
        _ => panic!("expected a bad --weight"),
    }
}

/// A state without a cell at the first row and without a declared value starts at its
/// first measured value, then is fitted with the trained model: here the exact law, so the
/// fit recovers the true initial substrate that the first measured cell misses.
#[test]
fn an_unmeasured_initial_state_is_fitted_per_experiment() {
    use crate::train::fixtures::ModelBuilder;
    let (data, _) = chemostat::data(120, (0.002, 0.02), 9);
    let inlet = data.column("E0").unwrap()[0];
    let model = ModelBuilder::new("exact")
        .input("E0")
        .state("S")
        .hidden("E", inlet)
        .constant("S0", chemostat::S0)
        .constant("theta", chemostat::THETA)
        .constant("K_M", chemostat::K_M)
        .param("kcat", chemostat::KCAT, crate::ir::Constraint::Positive)
        .define("r", "kcat * E * S / (K_M + S)")
        .der("S", "(S0 - S) / theta - r")
        .der("E", "(E0 - E) / theta")
        .build();
    let mut thinned = record(&model, &data);
    let truth = thinned.states[0][0].unwrap();
    // Hide the cells until S has moved 2 %: the first one left is a poor start.
    let cut = (thinned.states[0].iter())
        .position(|c| (c.unwrap() / truth - 1.0).abs() > 0.02)
        .unwrap();
    assert!(cut < 100, "{cut}");
    for cell in &mut thinned.states[0][..cut] {
        *cell = None;
    }
    let train = [thinned];
    let data = TrainingData {
        train: &train,
        validation: &[],
        part: Part::All,
    };
    let options = TrainOptions {
        train_points: None,
        precision: crate::engine::graph::Precision::F64,
        ..options(0, 1)
    };
    let recipe = Recipe {
        params: ParamSource::Train,
        ..Recipe::paper()
    };
    let trained = train_with(&model, &data, &options, &recipe, &mut quiet).unwrap();
    let start = &trained.report.initial_states[0];
    let (name, value, origin) = &start.states[0];
    assert_eq!((name.as_str(), *origin), ("S", Origin::Fitted));
    assert!(
        (value / truth - 1.0).abs() < 1e-4,
        "fitted {value}, truth {truth}"
    );
}
