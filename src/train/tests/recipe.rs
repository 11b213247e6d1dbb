//! Tests of the recipes: the multi-step curriculum, free runs that stop where they leave
//! the physical range, the polish of params and their standard errors, and validation on
//! several records.

use crate::ir::Constraint;
use crate::train::fixtures::{
    chemostat, dataset, options, quiet, record, train_one, ClosureSpec, ModelBuilder, OutputSpec,
};
use crate::train::*;
use crate::trained::predict;

#[test]
fn multi_step_training_warms_up_then_rolls_out_and_improves_the_free_run() {
    let (data, _) = chemostat::data(500, (0.002, 0.02), 1);
    let recipe = Recipe {
        horizon: 8,
        warmup_share: 0.5,
        ramp_share: 0.25,
        ..Recipe::default()
    };
    let mut horizons = Vec::new();
    let train_records = [record(&chemostat::grey_box(), &data)];
    let training = TrainingData {
        train: &train_records,
        validation: &[],
        part: Part::FirstPairs(Some(350)),
    };
    let trained = train_with(
        &chemostat::grey_box(),
        &training,
        &options(12, 350),
        &recipe,
        &mut |event| {
            if let Event::Epoch { horizon, .. } = event {
                horizons.push(horizon);
            }
        },
    )
    .unwrap();
    assert_eq!(horizons, vec![1, 1, 1, 1, 1, 1, 2, 4, 6, 8, 8, 8]);
    let metrics = &trained.report.metrics;
    let before = metrics.initial_online.as_ref().unwrap().overall;
    let after = metrics.online.as_ref().unwrap().overall;
    assert!(after < before / 2.0, "online error {before} -> {after}");
    assert!(trained.report.losses.iter().all(|l| l.is_finite()));
    assert_eq!(trained.report.recipe, recipe);
}

#[test]
fn the_paper_recipe_trains_one_step_and_does_not_polish() {
    let (data, _) = chemostat::data(300, (0.002, 0.02), 2);
    let mut horizons = Vec::new();
    let model = chemostat::exact_law(chemostat::KCAT / 2.0);
    let train_records = [record(&model, &data)];
    let training = TrainingData {
        train: &train_records,
        validation: &[],
        part: Part::FirstPairs(Some(200)),
    };
    let trained = train_with(
        &model,
        &training,
        &options(3, 200),
        &Recipe::paper(),
        &mut |event| {
            if let Event::Epoch { horizon, .. } = event {
                horizons.push(horizon);
            }
        },
    )
    .unwrap();
    assert_eq!(horizons, vec![1, 1, 1]);
    assert!(trained.report.polish.is_none());
    assert_eq!(trained.report.estimates.len(), 1);
}

/// `dx/dt = a x` from x = 1 with a = 0.2: RK4 multiplies by g = 1 + z + z^2/2 + z^3/6 +
/// z^4/24 (z = 0.2) each step, so x first exceeds 10 x the training maximum (1) at
/// step 12 (g^11 = 9.02, g^12 = 11.02).
#[test]
fn an_exploding_free_run_stops_where_it_leaves_the_physical_range() {
    let model = ModelBuilder::new("growth")
        .state("x")
        .param("a", 0.2, Constraint::Positive)
        .der("x", "a * x")
        .build();
    let data = dataset(1.0, vec![("x", vec![1.0; 60])]);
    let recipe = Recipe {
        polish: Some(false),
        // Keep a = 0.2: from the balances the flat record would give a = 0.
        params: ParamSource::Train,
        ..Recipe::default()
    };
    let trained = train_one(&model, &data, Some(&data), &options(0, 59), &recipe).unwrap();
    let z: f64 = 0.2;
    let growth = 1.0 + z + z * z / 2.0 + z.powi(3) / 6.0 + z.powi(4) / 24.0;
    let online = trained.report.metrics.online.unwrap();
    let divergence = online.divergence.clone().unwrap();
    assert_eq!((divergence.row, divergence.state.as_str()), (12, "x"));
    assert!((divergence.value / growth.powi(12) - 1.0).abs() < 1e-5);
    assert_eq!(divergence.range, (-0.1, 10.0));
    assert!(online.overall.is_infinite());
    assert!(divergence.to_string().contains("t = 12"), "{divergence}");
    let table = predict::predict(
        &model,
        &trained.network,
        &trained.setup,
        &record(&model, &data),
        (predict::Mode::Online, History::Held),
    )
    .unwrap();
    let x = &table.columns[1];
    assert_eq!(x.len(), 60);
    assert!((x[11] / growth.powi(11) - 1.0).abs() < 1e-5);
    assert_eq!(x[12], divergence.value);
    assert!(x[13..].iter().all(|v| v.is_nan()));
    assert_eq!(table.divergence, Some(divergence));
}

#[test]
fn the_polish_recovers_a_rate_constant_and_flags_an_unidentifiable_pair() {
    let (data, _) = chemostat::data(300, (0.002, 0.02), 4);
    // Params trained by Adam, then polished (without `--params train` a model without
    // closures is fitted by free runs instead, `tests_mechanism`).
    let recipe = Recipe {
        polish: Some(true),
        params: ParamSource::Train,
        ..Recipe::default()
    };
    let options = TrainOptions {
        precision: Precision::F64,
        ..options(0, 250)
    };
    let fit = |model: &ir::Model| {
        train_one(model, &data, None, &options, &recipe)
            .unwrap()
            .report
    };
    // The truth starts at the steady state of the first inlet level; so does E here.
    let inlet = data.column("E0").unwrap()[0];
    let law = |builder: ModelBuilder| {
        builder
            .input("E0")
            .state("S")
            .hidden("E", inlet)
            .constant("S0", chemostat::S0)
            .constant("theta", chemostat::THETA)
            .constant("K_M", chemostat::K_M)
    };
    let exact = law(ModelBuilder::new("exact"))
        .param("kcat", chemostat::KCAT / 2.0, Constraint::Positive)
        .define("r", "kcat * E * S / (K_M + S)")
        .der("S", "(S0 - S) / theta - r")
        .der("E", "(E0 - E) / theta")
        .build();
    let report = fit(&exact);
    let kcat = &report.estimates[0];
    assert!(
        (kcat.value / chemostat::KCAT - 1.0).abs() < 1e-3,
        "{kcat:?}"
    );
    assert!(kcat.identified && kcat.std_error.is_some_and(|s| s < 1e-3 * kcat.value));
    let polish = report.polish.unwrap();
    assert!(polish.loss_after < polish.loss_before / 100.0);
    assert!((polish.params_before[0] / (chemostat::KCAT / 2.0) - 1.0).abs() < 1e-12);
    // Only the product a * b enters the balance: neither is determined.
    let product = law(ModelBuilder::new("product"))
        .param("a", 0.1, Constraint::Positive)
        .param("b", 0.7, Constraint::Positive)
        .define("r", "a * b * E * S / (K_M + S)")
        .der("S", "(S0 - S) / theta - r")
        .der("E", "(E0 - E) / theta")
        .build();
    let report = fit(&product);
    let values: Vec<f64> = report.estimates.iter().map(|e| e.value).collect();
    assert!((values[0] * values[1] / chemostat::KCAT - 1.0).abs() < 1e-3);
    assert!(report.estimates.iter().all(|e| !e.identified));
}

/// Whole experiments validate each on its own, and the headline pools their cells: per
/// state the mean squared error over every experiment's measured cells.
#[test]
fn every_validation_experiment_is_reported_and_the_headline_pools_their_cells() {
    let (data, _) = chemostat::data(300, (0.002, 0.02), 5);
    let (first, _) = chemostat::data(200, (0.002, 0.02), 6);
    let (second, _) = chemostat::data(150, (0.002, 0.02), 7);
    let model = chemostat::grey_box();
    let named = |data: &crate::data::Dataset, name: &str| {
        let mut r = record(&model, data);
        r.name = name.into();
        r
    };
    let train_records = [named(&data, "train")];
    let held = [named(&first, "first"), named(&second, "second")];
    let training = TrainingData {
        train: &train_records,
        validation: &held,
        part: Part::All,
    };
    let options = TrainOptions {
        train_points: None,
        ..options(2, 1)
    };
    let trained = train_with(&model, &training, &options, &Recipe::default(), &mut quiet);
    let trained = trained.unwrap();
    let metrics = &trained.report.metrics;
    let names: Vec<&str> = metrics
        .validations
        .iter()
        .map(|v| v.name.as_str())
        .collect();
    assert_eq!(names, vec!["first", "second"]);
    // Offline pairs have their history inside the record: 40 rows of it.
    assert_eq!(metrics.validations[0].pairs, 200 - 1 - 40);
    assert_eq!(metrics.validations[1].pairs, 150 - 1 - 40);
    assert_eq!(trained.report.validation_pairs, 159 + 109);
    let online: Vec<&ErrorSet> = (metrics.validations.iter())
        .map(|v| v.online.as_ref().unwrap())
        .collect();
    // Held history: each free run starts at its first row and scores every later one.
    assert_eq!((online[0].cells, online[1].cells), (199, 149));
    let pooled = metrics.online.as_ref().unwrap();
    let expected = (online[0].overall * 199.0 + online[1].overall * 149.0) / 348.0;
    assert!((pooled.overall / expected - 1.0).abs() < 1e-12);
    assert_eq!(pooled.cells, 348);
}

#[test]
fn bad_recipe_values_are_refused_naming_the_flag() {
    let (data, _) = chemostat::data(120, (0.002, 0.02), 7);
    let refused = |recipe: Recipe| match train_one(
        &chemostat::grey_box(),
        &data,
        None,
        &options(1, 60),
        &recipe,
    ) {
        Err(TrainError::BadOption { option, .. }) => option,
        Err(other) => panic!("expected a bad option, found {other}"),
        Ok(_) => panic!("expected a bad option, found a trained network"),
    };
    let horizon = Recipe {
        horizon: 0,
        ..Recipe::default()
    };
    assert_eq!(refused(horizon), "horizon");
    let factor = Recipe {
        range_factor: 0.5,
        ..Recipe::default()
    };
    assert_eq!(refused(factor), "range_factor");
    let rate = Recipe {
        param_learning_rate: Some(-1.0),
        ..Recipe::default()
    };
    assert_eq!(refused(rate), "param_learning_rate");
}

/// Trains `model` on `data` with the graph engine and the default one from the same seed in
/// f64; returns the graph run and the default run, which ran on the fused step.
fn train_both(
    model: &ir::Model,
    data: &crate::data::Dataset,
    options: &TrainOptions,
    recipe: &Recipe,
) -> (Trained, Trained) {
    let run = |engine: Engine| {
        let options = TrainOptions {
            precision: Precision::F64,
            engine,
            ..options.clone()
        };
        train_one(model, data, None, &options, recipe).unwrap()
    };
    let (graph, fused) = (run(Engine::Graph), run(Engine::Auto));
    assert_eq!(graph.report.engine, Engine::Graph);
    assert_eq!(
        fused.report.engine,
        Engine::Fused,
        "auto runs the fused step"
    );
    (graph, fused)
}

/// Epoch losses, final weights and validation errors of two runs agree to `tolerance`
/// (relative), and the second epoch improved on the first.
fn assert_same_training(graph: &Trained, fused: &Trained, tolerance: f64) {
    let (expected, found) = (&graph.report.losses, &fused.report.losses);
    assert_eq!(expected.len(), found.len());
    assert!(expected[1] < expected[0], "{expected:?}");
    for (epoch, (e, f)) in expected.iter().zip(found).enumerate() {
        assert!((f / e - 1.0).abs() < tolerance, "epoch {epoch}: {f} vs {e}");
    }
    for (a, b) in graph.network.weights().iter().zip(fused.network.weights()) {
        let largest = a.values.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        for (x, y) in a.values.iter().zip(&b.values) {
            assert!(
                (x - y).abs() <= tolerance * largest,
                "{}: {x} vs {y}",
                a.name
            );
        }
    }
    let offline = |t: &Trained| t.report.metrics.offline.as_ref().unwrap().overall;
    assert!((offline(fused) / offline(graph) - 1.0).abs() < tolerance);
}

#[test]
fn one_step_epochs_on_the_fused_step_train_as_the_graph_backend() {
    let (data, _) = chemostat::data(300, (0.002, 0.02), 8);
    let (graph, fused) = train_both(
        &chemostat::grey_box(),
        &data,
        &options(4, 200),
        &Recipe::paper(),
    );
    assert_same_training(&graph, &fused, 1e-9);
}

/// The default engine runs the warm-up and the rollouts on the fused step, long enough
/// (12 steps, the embedding reaching 10 back) that predictions are fed back into the
/// embedding: every epoch is the graph run's to rounding.
#[test]
fn the_fused_step_runs_the_warm_up_and_the_rollouts_as_the_graph_backend() {
    let (data, _) = chemostat::data(300, (0.002, 0.02), 9);
    let recipe = Recipe {
        horizon: 12,
        warmup_share: 0.5,
        ramp_share: 0.25,
        polish: Some(false),
        ..Recipe::default()
    };
    let (graph, fused) = train_both(&chemostat::grey_box(), &data, &options(6, 200), &recipe);
    assert_eq!(recipe.horizon_at(3, 6), 1);
    assert_eq!(recipe.horizon_at(4, 6), 2);
    assert_eq!(recipe.horizon_at(6, 6), 12);
    assert_same_training(&graph, &fused, 1e-8);
}

/// A hidden state whose rate is a trained param: each epoch's refresh of the hidden
/// estimates needs the fused step's current weights, and the param learns at its own rate.
#[test]
fn hidden_states_refresh_with_the_fused_steps_weights() {
    let (data, _) = chemostat::data(300, (0.002, 0.02), 10);
    let inlet = data.column("E0").unwrap()[0];
    let model = ModelBuilder::new("hidden_rate")
        .input("E0")
        .state("S")
        .hidden("E", inlet)
        .constant("S0", chemostat::S0)
        .param("k", 0.1, Constraint::Positive)
        .closure(chemostat_rate())
        .der("S", "(S0 - S) / 20 + r - 0.1 * E * S")
        .der("E", "k * (E0 - E)")
        .build();
    let recipe = Recipe {
        param_learning_rate: Some(1e-2),
        max_gradient_norm: Some(1.0),
        ..Recipe::paper()
    };
    let (graph, fused) = train_both(&model, &data, &options(4, 200), &recipe);
    assert_same_training(&graph, &fused, 1e-9);
    let k = |t: &Trained| t.report.params[0].1;
    assert!((k(&graph) - 0.1).abs() > 1e-3, "k moved: {}", k(&graph));
}

/// The grey-box chemostat's rate closure, a small network.
fn chemostat_rate() -> ClosureSpec<'static> {
    ClosureSpec {
        name: "rate",
        outputs: vec![OutputSpec {
            name: "r",
            scale: None,
            prior: None,
        }],
        observe: &["S", "E0"],
        delay: 10.0,
        dim: 3,
        hidden: vec![8, 8],
        activation: crate::ir::Activation::Softplus,
    }
}

/// The default recipe takes GB1's yields from the balances and holds them while the
/// network trains, on either engine; the paper's recipe trains them.
#[test]
fn yields_from_the_balances_are_held_through_training() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = crate::driver::compile_file(&root.join("models/bioreactor/gb1.gbm"), &[])
        .unwrap()
        .model;
    let data = crate::data::read(
        &root.join("models/bioreactor/data/steps.csv"),
        &["u", "X", "A", "B", "S"],
        crate::data::MinRows::new(2, "one step"),
    )
    .unwrap();
    let recipe = Recipe {
        horizon: 4,
        ..Recipe::default()
    };
    for engine in [Engine::Graph, Engine::Fused] {
        let options = TrainOptions {
            engine,
            precision: crate::engine::graph::Precision::F64,
            ..options(4, 200)
        };
        let trained = train_one(&model, &data, None, &options, &recipe).unwrap();
        let report = &trained.report;
        let fit = report
            .balance_fit
            .as_ref()
            .expect("estimated from the balances");
        assert!(report.polish.is_none());
        for ((name, value), (estimate, truth)) in
            (report.params.iter()).zip(fit.estimates.iter().zip([0.435, 0.607, 0.3]))
        {
            assert_eq!(name, &estimate.name);
            assert!(
                (value / estimate.value - 1.0).abs() < 1e-12,
                "{name} moved: {value}"
            );
            assert!((value / truth - 1.0).abs() < 1e-6, "{name} = {value}");
        }
    }
    let paper = train_one(&model, &data, None, &options(2, 200), &Recipe::paper()).unwrap();
    assert!(paper.report.balance_fit.is_none());
    assert!(paper
        .report
        .params
        .iter()
        .all(|(_, v)| (v - 0.5).abs() > 1e-9));
}
