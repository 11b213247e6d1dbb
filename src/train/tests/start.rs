//! A fresh grey box is its mechanism (`docs/training.md`, "Starting from the mechanism"):
//! the last layer of every closure network starts at zero, so one predicted step of a fresh
//! network is one RK4 step (or the map of a `next` model) of the model with every closure
//! output at its prior, or 0 without one, computed here by the scalar evaluator through the
//! simulator's `ModelSystem`, independently of the backend. No output is an exception: a
//! `positive` output without a prior is `s |n|`, 0 at the start.

use std::path::{Path, PathBuf};

use crate::engine::graph::{Network, Precision};
use crate::ir::{self, Expr};
use crate::solve::ode::{ModelSystem, OdeSystem};
use crate::train::fixtures::{random_batch, rk4_reference, setup};

/// Every shipped model file with a closure: models/, bench/ and the `gbc init` templates.
fn shipped_grey_boxes() -> Vec<(PathBuf, ir::Model)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for folder in ["models", "bench", "src/init/templates"] {
        collect(&root.join(folder), &mut files);
    }
    files.sort();
    (files.into_iter())
        .filter_map(|path| {
            let model = crate::driver::compile_file(&path, &[]).ok()?.model;
            (!model.closures.is_empty()).then_some((path, model))
        })
        .collect()
}

fn collect(folder: &Path, files: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(folder).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.is_dir() {
            collect(&path, files);
        } else if path.extension().is_some_and(|e| e == "gbm") {
            files.push(path);
        }
    }
}

/// The model the fresh network is, written out independently of
/// [`ir::Model::mechanism`]: every closure output at its prior, or 0 without one.
fn start_model(model: &ir::Model) -> ir::Model {
    let stand_in = |closure: usize, output: usize| -> Expr {
        let spec = &model.closures[closure].outputs[output];
        match &spec.prior {
            Some(prior) => prior.expr.clone(),
            None => Expr::Num(0.0),
        }
    };
    model.with_closure_outputs_as(&stand_in)
}

#[test]
fn a_fresh_grey_box_predicts_as_its_mechanism() {
    let models = shipped_grey_boxes();
    assert!(models.len() >= 10, "only {} grey boxes found", models.len());
    let mut exact_mechanisms = 0;
    for (path, model) in &models {
        let setup = setup(model, Precision::F64, 2);
        let network = Network::build(model, &setup).unwrap();
        let batch = random_batch(model, &setup, 5, 7);
        let predicted = network.predict(&batch).unwrap().next_states;
        let start = start_model(model);
        if start == model.mechanism() {
            exact_mechanisms += 1;
        }
        let system = std::cell::RefCell::new(ModelSystem::new(&start).unwrap());
        let inputs = system.borrow().layout().input_range();
        let width = model.states.len() + model.hidden.len();
        for row in 0..batch.rows {
            let u = &batch.inputs[row * inputs.len()..(row + 1) * inputs.len()];
            system.borrow_mut().slots_mut()[inputs.clone()].copy_from_slice(u);
            let x = &batch.states[row * width..(row + 1) * width];
            let rhs = |y: &[f64]| {
                let mut out = vec![0.0; y.len()];
                system.borrow_mut().rhs(0.0, y, &mut out);
                out
            };
            let expected = match model.dynamics {
                ir::Dynamics::Continuous => rk4_reference(rhs, x, setup.step, 2),
                ir::Dynamics::Discrete => rhs(x),
            };
            let found = &predicted[row * width..(row + 1) * width];
            for (state, (f, e)) in found.iter().zip(&expected).enumerate() {
                let tolerance = 1e-12 * (1.0 + e.abs());
                assert!(
                    (f - e).abs() <= tolerance,
                    "{}: row {row}, state {state}: {f} vs {e}",
                    path.display()
                );
            }
        }
    }
    // Most shipped grey boxes start at exactly their mechanism (all but those with an
    // output in a range that its prior, or 0, does not sit well inside).
    assert!(exact_mechanisms >= models.len() / 2, "{exact_mechanisms}");
}

/// An output `in [lo, hi]` starts at its prior (0 without one) clamped into the range
/// `(hi - lo) / 16` short of its ends, exactly, whatever the prior's kind.
#[test]
fn a_bounded_output_starts_at_its_prior_clamped_into_its_range() {
    let source = "model m\ninput u\nstate x\nstate y\n\
        closure c {\n  outputs a ~ 0.5 in [-1, 3], b ~ 0.5 in [0, 2], m ~ 0.5 in [0, 2], f ~ 2 in [-2, 2]\n  \
        network hidden [4] tanh\n  prior a += x * u\n  prior m *= 0.5 * y\n}\n\
        der x = a + f - x\nder y = b + m - y\n";
    let model = crate::driver::compile("m.gbm", source, &[]).unwrap().model;
    let setup = setup(&model, Precision::F64, 1);
    let network = Network::build(&model, &setup).unwrap();
    let batch = random_batch(&model, &setup, 6, 3);
    let outputs = network.predict(&batch).unwrap().closure_outputs;
    let clamp = |p: f64, lo: f64, hi: f64| {
        let margin = (hi - lo) / 16.0;
        p.clamp(lo + margin, hi - margin)
    };
    let mut clamped = 0;
    for row in 0..batch.rows {
        let (x, y) = (batch.states[2 * row], batch.states[2 * row + 1]);
        let u = batch.inputs[row];
        let expected = [
            clamp(x * u, -1.0, 3.0),
            clamp(0.0, 0.0, 2.0),
            clamp(0.5 * y, 0.0, 2.0),
            0.0,
        ];
        clamped += usize::from(expected[1] != 0.0);
        for (found, expected) in outputs[4 * row..4 * row + 4].iter().zip(expected) {
            assert!(
                (found - expected).abs() < 1e-12,
                "row {row}: {found} vs {expected}"
            );
        }
    }
    assert_eq!(clamped, batch.rows, "0 is an end of [0, 2]: clamped inside");
}

/// Three training experiments and one held out, each a short chemostat record.
fn chemostat_experiments() -> (ir::Model, Vec<crate::record::Record>, crate::record::Record) {
    use crate::train::fixtures::{chemostat, record};
    let model = chemostat::grey_box();
    let mut records: Vec<crate::record::Record> = (1..=4)
        .map(|seed| {
            let mut r = record(&model, &chemostat::data(80, (0.002, 0.02), seed).0);
            r.name = format!("run{seed}");
            r
        })
        .collect();
    let held = records.pop().unwrap();
    (model, records, held)
}

/// `auto` trains one fold per training experiment (never the held-out one), scores each
/// stop by the folds' held-out online errors from the mechanism (epoch 0) on, and the run
/// ends at the stop chosen: no later than the best, and within one standard error of it;
/// at 0 the run is its mechanism. With one training experiment it trains every epoch
/// without a pull, saying why.
#[test]
fn auto_chooses_the_stop_by_cross_validation_over_the_training_experiments() {
    use crate::train::toward::ChoiceEvent;
    use crate::train::{
        train_with, Event, Part, Recipe, TowardMechanism, TrainOptions, TrainingData,
    };
    let (model, train, held) = chemostat_experiments();
    let options = TrainOptions {
        epochs: 6,
        seed: 3,
        toward_mechanism: TowardMechanism::Auto,
        ..TrainOptions::default()
    };
    let data = TrainingData {
        train: &train,
        validation: std::slice::from_ref(&held),
        part: Part::All,
    };
    let (mut done, mut chosen) = (Vec::new(), None);
    let mut listen = |event: Event| match event {
        Event::Strength(ChoiceEvent::FoldDone { held_out, .. }) => done.push(held_out.to_string()),
        Event::Strength(ChoiceEvent::Chosen(choice)) => chosen = Some(choice.chosen),
        _ => {}
    };
    let trained = train_with(&model, &data, &options, &Recipe::paper(), &mut listen).unwrap();
    done.sort();
    assert_eq!(done, vec!["run1", "run2", "run3"]);
    let report = trained.report.toward_mechanism.as_ref().unwrap();
    let choice = report.choice.as_ref().unwrap();
    assert_eq!(choice.held_out, vec!["run1", "run2", "run3"]);
    let epochs: Vec<usize> = choice.candidates.iter().map(|c| c.epoch).collect();
    assert_eq!(epochs, (0..=6).collect::<Vec<_>>());
    // The best has the lowest mean, recomputed from the folds' errors; the choice is no
    // later than it and no worse than one standard error of the paired differences.
    let mean = |epoch: usize| {
        let c = choice.at(epoch).unwrap();
        c.errors.iter().map(|e| e.unwrap()).sum::<f64>() / c.errors.len() as f64
    };
    assert!(epochs.iter().all(|&e| mean(choice.best) <= mean(e)));
    assert!(choice.chosen <= choice.best);
    assert_eq!((chosen, report.strength), (Some(choice.chosen), 0.0));
    assert_eq!(trained.report.losses.len(), choice.chosen);
    if choice.chosen == 0 {
        assert!(report.outputs.iter().all(|o| o.moved == 0.0));
    }
    let alone = TrainingData {
        train: &train[..1],
        ..data
    };
    let trained = train_with(&model, &alone, &options, &Recipe::paper(), &mut |_| {}).unwrap();
    let report = trained.report.toward_mechanism.unwrap();
    assert!(report.choice.is_none());
    assert!(report.unchosen.unwrap().contains("1 training experiment"));
    assert_eq!(trained.report.losses.len(), 6);
}

/// A strong pull keeps the last layer nearer zero, and the outputs nearer the mechanism,
/// than no pull on the same run; the loss it reports includes the penalty.
#[test]
fn a_strong_pull_keeps_the_grey_box_near_its_mechanism() {
    use crate::train::{train_with, Part, Recipe, TowardMechanism, TrainOptions, TrainingData};
    let (model, train, held) = chemostat_experiments();
    let data = TrainingData {
        train: &train,
        validation: std::slice::from_ref(&held),
        part: Part::All,
    };
    let run = |strength: f64| {
        let options = TrainOptions {
            epochs: 5,
            seed: 3,
            toward_mechanism: TowardMechanism::Strength(strength),
            ..TrainOptions::default()
        };
        train_with(&model, &data, &options, &Recipe::paper(), &mut |_| {}).unwrap()
    };
    let last_rms = |trained: &crate::train::Trained| {
        let last = format!("layer{}", model.closures[0].network.hidden.len());
        let values: Vec<f64> = (trained.network.weights().into_iter())
            .filter(|t| t.name.contains(&last))
            .flat_map(|t| t.values)
            .collect();
        crate::numeric::root_mean_square(&values)
    };
    let moved = |trained: &crate::train::Trained| {
        trained.report.toward_mechanism.as_ref().unwrap().outputs[0].moved
    };
    let (free, pulled) = (run(0.0), run(1e4));
    assert!(last_rms(&free) > 0.0);
    assert!(
        last_rms(&pulled) < 0.5 * last_rms(&free),
        "{} vs {}",
        last_rms(&pulled),
        last_rms(&free)
    );
    assert!(
        moved(&pulled) < moved(&free),
        "{} vs {}",
        moved(&pulled),
        moved(&free)
    );
    assert_eq!(
        pulled.report.toward_mechanism.as_ref().unwrap().strength,
        1e4
    );
}
