//! The exported one-step map run by a pure-Rust ONNX runtime (`tract-onnx`) over a free
//! run, against gbc's own online prediction, on both example systems.

use std::path::Path;

use super::*;
use crate::backend::Precision;
use crate::record::Record;
use crate::train::predict::{predict_in_range, Mode};
use crate::train::{self, History, Part, Recipe, TrainOptions, Trained, TrainingData};

/// A shipped model and the first `rows` rows of a shipped record.
fn shipped(model: &str, data: &str, rows: usize) -> (ir::Model, Record) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = crate::driver::compile_file(&root.join(model), &[])
        .unwrap()
        .model;
    let required: Vec<&str> = (model.inputs.iter().map(|i| i.name.as_str()))
        .chain(model.states.iter().map(|s| s.name.as_str()))
        .collect();
    let minimum = crate::data::MinRows::new(2, "one step");
    let data = crate::data::read(&root.join(data), &required, minimum).unwrap();
    let record = train::record_of(&model, &data).unwrap().rows(0..rows);
    (model, record)
}

/// A short one-step training run.
fn trained(model: &ir::Model, record: &Record, precision: Precision) -> Trained {
    let records = [record.clone()];
    let data = TrainingData {
        train: &records,
        validation: &[],
        part: Part::FirstPairs(None),
    };
    let options = TrainOptions {
        epochs: 2,
        precision,
        seed: 7,
        ..TrainOptions::default()
    };
    train::train_with(model, &data, &options, &Recipe::paper(), &mut |_| {}).unwrap()
}

/// tract, kept in its own namespace (its prelude has an `onnx` of its own).
mod runtime {
    use super::Exported;
    use tract_onnx::prelude::*;

    /// A loaded, optimised model.
    pub type Plan = std::sync::Arc<TypedRunnableModel>;

    /// Loads an exported file into tract for a batch of one.
    pub fn runnable(exported: &Exported) -> Plan {
        let layout = &exported.layout;
        let mut model = tract_onnx::onnx()
            .model_for_read(&mut exported.bytes.as_slice())
            .unwrap();
        let w = layout.window;
        model
            .set_input_fact(0, f32::fact([1, w, layout.states.len()]).into())
            .unwrap();
        if !layout.inputs.is_empty() {
            model
                .set_input_fact(1, f32::fact([1, w, layout.inputs.len()]).into())
                .unwrap();
        }
        model.into_optimized().unwrap().into_runnable().unwrap()
    }

    /// One call: the windows (`[1, W, S]`, `[1, W, U]`, row-major) in, every output out.
    pub fn step(plan: &Plan, exported: &Exported, states: &[f32], inputs: &[f32]) -> Vec<Vec<f32>> {
        let w = exported.layout.window;
        let s = exported.layout.states.len();
        let mut feed: TVec<TValue> = tvec![Tensor::from_shape(&[1, w, s], states).unwrap().into()];
        if !exported.layout.inputs.is_empty() {
            let u = exported.layout.inputs.len();
            feed.push(Tensor::from_shape(&[1, w, u], inputs).unwrap().into());
        }
        let outputs = plan.run(feed).unwrap();
        (outputs.iter())
            .map(|tensor| {
                tensor
                    .to_plain_array_view::<f32>()
                    .unwrap()
                    .iter()
                    .copied()
                    .collect()
            })
            .collect()
    }
}

/// Steps the exported map along `record` from knot `start` (history before it from the
/// record, held before its first row), feeding it its own predictions; returns the states
/// after each step and the closure outputs at each start.
fn free_run(exported: &Exported, record: &Record, start: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let plan = runtime::runnable(exported);
    let w = exported.layout.window;
    let clamp = |k: isize| k.max(0) as usize;
    let mut states: Vec<Vec<f32>> = (0..w)
        .map(|row| {
            let knot = clamp(start as isize + row as isize + 1 - w as isize);
            record
                .states
                .iter()
                .map(|c| c[knot].unwrap() as f32)
                .collect()
        })
        .collect();
    let (mut next_states, mut closure_outputs) = (Vec::new(), Vec::new());
    for knot in start..record.len() - 1 {
        let inputs: Vec<f32> = (0..w)
            .flat_map(|row| {
                let at = clamp(knot as isize + row as isize + 1 - w as isize);
                record.inputs.iter().map(move |u| u[at] as f32)
            })
            .collect();
        let window: Vec<f32> = states.iter().flatten().copied().collect();
        let outputs = runtime::step(&plan, exported, &window, &inputs);
        let read = |index: usize| outputs[index].clone();
        let next = read(0);
        next_states.push(next.iter().map(|&v| f64::from(v)).collect());
        closure_outputs.push(read(1).iter().map(|&v| f64::from(v)).collect());
        states.remove(0);
        states.push(next);
    }
    (next_states, closure_outputs)
}

/// The largest error of `found` against `expected` relative to each column's largest
/// magnitude.
fn worst_relative(found: &[Vec<f64>], expected: &[Vec<f64>]) -> f64 {
    let columns = expected.first().map_or(0, Vec::len);
    (0..columns)
        .map(|column| {
            let scale = expected.iter().map(|r| r[column].abs()).fold(0.0, f64::max);
            (found.iter().zip(expected))
                .map(|(f, e)| (f[column] - e[column]).abs() / scale)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// Exports a trained run, steps it in tract over a free run and compares with
/// `gbc predict --mode online` on the same record.
fn matches_online_prediction(model_file: &str, data_file: &str, rows: usize) -> f64 {
    let (model, record) = shipped(model_file, data_file, rows);
    let trained = trained(&model, &record, Precision::F32);
    let exported = super::onnx(&model, &trained.network, &trained.setup, Precision::F32).unwrap();
    let how = (Mode::Online, History::Measured, None);
    let online = predict_in_range(&model, &trained.network, &trained.setup, &record, how).unwrap();
    let start = (record.times.iter())
        .position(|&t| t == online.columns[0][0])
        .unwrap();
    let (states, closure_outputs) = free_run(&exported, &record, start);
    let s = model.states.len();
    let rows_of = |columns: &[Vec<f64>], skip: usize| -> Vec<Vec<f64>> {
        (skip..columns[0].len())
            .map(|row| columns.iter().map(|c| c[row]).collect())
            .collect()
    };
    let expected_states = rows_of(&online.columns[1..=s], 1);
    let c = exported.layout.closure_outputs.len();
    let expected_closures = rows_of(&online.columns[1 + s..1 + s + c], 0);
    assert_eq!(states.len(), expected_states.len());
    let error = worst_relative(&states, &expected_states).max(worst_relative(
        &closure_outputs,
        &expected_closures[..states.len()],
    ));
    assert!(
        error < 1e-5,
        "{model_file}: largest relative error {error:e}"
    );
    error
}

#[test]
fn the_exported_chemostat_grey_box_steps_as_gbc_predicts_online() {
    let error = matches_online_prediction(
        "models/mm_chemostat/greybox.gbm",
        "models/mm_chemostat/data/steps.csv",
        300,
    );
    eprintln!("chemostat: largest relative error {error:e}");
}

#[test]
fn the_exported_bioreactor_gb1_steps_as_gbc_predicts_online() {
    let error = matches_online_prediction(
        "models/bioreactor/gb1.gbm",
        "models/bioreactor/data/steps.csv",
        200,
    );
    eprintln!("bioreactor GB1: largest relative error {error:e}");
}

#[test]
fn the_layout_names_the_window_and_every_column() {
    let (model, record) = shipped(
        "models/bioreactor/gb1.gbm",
        "models/bioreactor/data/steps.csv",
        120,
    );
    let trained = trained(&model, &record, Precision::F32);
    let exported = super::onnx(&model, &trained.network, &trained.setup, Precision::F32).unwrap();
    let layout = &exported.layout;
    // Delay 5, dim 10 on a step of 1: lags reach 45 knots back, plus the current knot.
    assert_eq!(layout.window, 46);
    assert_eq!(layout.states, ["X", "A", "B", "S"]);
    assert_eq!(layout.inputs, ["u"]);
    assert_eq!(layout.closure_outputs, ["mu", "mu_A", "mu_B"]);
    let decoded = onnx::ModelProto::decode(exported.bytes.as_slice()).unwrap();
    let graph = decoded.graph.unwrap();
    let names =
        |list: &[onnx::ValueInfoProto]| list.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&graph.input), ["state_window", "input_window"]);
    assert_eq!(names(&graph.output), ["next_state", "closure_outputs"]);
    let initializer = |name: &str| graph.initializer.iter().find(|t| t.name == name).unwrap();
    assert_eq!(initializer("closure.kinetics.layer0.weight").dims, [50, 20]);
    assert_eq!(initializer("params").dims, [3]);
    let window = decoded
        .metadata_props
        .iter()
        .find(|e| e.key == "gbc.window")
        .unwrap();
    assert_eq!(window.value, "46");
}
