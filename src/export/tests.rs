//! The exported one-step map run by a pure-Rust ONNX runtime (`tract-onnx`) over a free
//! run, against gbc's own online prediction, on both example systems.

use std::path::Path;

use super::*;
use crate::engine::graph::Precision;
use crate::record::Record;
use crate::train::{self, History, Part, Recipe, TrainOptions, Trained, TrainingData};
use crate::trained::predict::{predict_in_range, Mode};

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
pub(super) mod runtime {
    use super::Exported;
    use crate::engine::graph::Precision;
    use tract_onnx::prelude::*;

    /// A loaded, optimised model.
    pub type Plan = std::sync::Arc<TypedRunnableModel>;

    /// The element type of the exported tensors.
    fn datum(exported: &Exported) -> DatumType {
        match exported.layout.precision {
            Precision::F32 => f32::datum_type(),
            Precision::F64 => f64::datum_type(),
        }
    }

    /// Loads an exported file into tract for a batch of one.
    pub fn runnable(exported: &Exported) -> Plan {
        let layout = &exported.layout;
        let mut model = tract_onnx::onnx()
            .model_for_read(&mut exported.bytes.as_slice())
            .unwrap();
        let (w, datum) = (layout.window, datum(exported));
        let fact = |width: usize| InferenceFact::dt_shape(datum, [1, w, width]);
        model.set_input_fact(0, fact(layout.states.len())).unwrap();
        if !layout.inputs.is_empty() {
            model.set_input_fact(1, fact(layout.inputs.len())).unwrap();
        }
        model.into_optimized().unwrap().into_runnable().unwrap()
    }

    /// One call: the windows (`[1, W, S]`, `[1, W, U]`, row-major) in, every output out,
    /// in the export's element type (values cast to and from `f64` here).
    pub fn step(plan: &Plan, exported: &Exported, states: &[f64], inputs: &[f64]) -> Vec<Vec<f64>> {
        let (w, datum) = (exported.layout.window, datum(exported));
        let tensor = |values: &[f64], width: usize| -> TValue {
            let tensor = Tensor::from_shape(&[1, w, width], values).unwrap();
            tensor.cast_to_dt(datum).unwrap().into_owned().into()
        };
        let mut feed: TVec<TValue> = tvec![tensor(states, exported.layout.states.len())];
        if !exported.layout.inputs.is_empty() {
            feed.push(tensor(inputs, exported.layout.inputs.len()));
        }
        let outputs = plan.run(feed).unwrap();
        (outputs.iter())
            .map(|output| {
                let values = output.cast_to::<f64>().unwrap();
                values
                    .to_plain_array_view::<f64>()
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
/// after each step and the closure outputs at each start. Values pass through the export's
/// element type on the way in.
pub(super) fn free_run(
    exported: &Exported,
    record: &Record,
    start: usize,
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let plan = runtime::runnable(exported);
    let w = exported.layout.window;
    let clamp = |k: isize| k.max(0) as usize;
    let mut states: Vec<Vec<f64>> = (0..w)
        .map(|row| {
            let knot = clamp(start as isize + row as isize + 1 - w as isize);
            record.states.iter().map(|c| c[knot].unwrap()).collect()
        })
        .collect();
    let (mut next_states, mut closure_outputs) = (Vec::new(), Vec::new());
    for knot in start..record.len() - 1 {
        let inputs: Vec<f64> = (0..w)
            .flat_map(|row| {
                let at = clamp(knot as isize + row as isize + 1 - w as isize);
                record.inputs.iter().map(move |u| u[at])
            })
            .collect();
        let window: Vec<f64> = states.iter().flatten().copied().collect();
        let mut outputs = runtime::step(&plan, exported, &window, &inputs);
        closure_outputs.push(outputs.remove(1));
        let next = outputs.remove(0);
        next_states.push(next.clone());
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

/// Exports a trained run in `precision`, steps it in tract over a free run and compares
/// with `gbc predict --mode online-trained-step` on the same record (trained in that precision); the
/// largest relative error must stay below `tolerance`.
fn matches_online_prediction(
    (model_file, data_file, rows): (&str, &str, usize),
    precision: Precision,
    tolerance: f64,
) -> f64 {
    let (model, record) = shipped(model_file, data_file, rows);
    let trained = trained(&model, &record, precision);
    let exported = super::onnx(&model, &trained.network, &trained.setup, precision).unwrap();
    // The exported map is the trained step; `gbc predict --mode online-trained-step`
    // iterates it.
    let how = (Mode::OnlineTrainedStep, History::Measured, None);
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
        error < tolerance,
        "{model_file}: largest relative error {error:e} above {tolerance:e}"
    );
    error
}

const CHEMOSTAT: (&str, &str, usize) = (
    "models/mm_chemostat/greybox.gbm",
    "models/mm_chemostat/data/steps.csv",
    300,
);
const GB1: (&str, &str, usize) = (
    "models/bioreactor/gb1.gbm",
    "models/bioreactor/data/steps.csv",
    200,
);

#[test]
fn the_exported_chemostat_grey_box_steps_as_gbc_predicts_online() {
    let error = matches_online_prediction(CHEMOSTAT, Precision::F32, 1e-5);
    eprintln!("chemostat, f32: largest relative error {error:e}");
}

#[test]
fn the_exported_bioreactor_gb1_steps_as_gbc_predicts_online() {
    let error = matches_online_prediction(GB1, Precision::F32, 1e-5);
    eprintln!("bioreactor GB1, f32: largest relative error {error:e}");
}

const GB2: (&str, &str, usize) = (
    "models/bioreactor/gb2.gbm",
    "models/bioreactor/data/steps.csv",
    200,
);

/// GB2's outputs are `positive` under `*=` priors: `max(p, 0) (max(n + 7/8, 0) + exp(8 min(0, n + 7/8)) / 8)`.
#[test]
fn the_exported_gb2_with_positive_priors_steps_as_gbc_predicts_online() {
    let error = matches_online_prediction(GB2, Precision::F64, 1e-11);
    eprintln!("bioreactor GB2, f64: largest relative error {error:e}");
}

/// In `f64` the export is the trainable network's arithmetic up to summation order.
#[test]
fn an_f64_export_steps_as_gbc_predicts_online_to_rounding() {
    for system in [CHEMOSTAT, GB1] {
        let error = matches_online_prediction(system, Precision::F64, 1e-11);
        eprintln!("{}, f64: largest relative error {error:e}", system.0);
    }
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

/// Weights are checked in the export's element type: one beyond f32's range exports in f64
/// only, a NaN in neither; each refusal names the weight.
#[test]
fn weights_that_are_not_finite_in_the_element_type_are_refused() {
    let (model, _) = shipped(
        "models/bioreactor/gb1.gbm",
        "models/bioreactor/data/steps.csv",
        120,
    );
    let setup = crate::train::fixtures::setup(&model, Precision::F64, 1);
    let mut network = crate::engine::graph::Network::build(&model, &setup).unwrap();
    let mut weights = network.weights();
    weights[0].values[3] = 1e39;
    network.set_weights(&weights).unwrap();
    let refused = super::onnx(&model, &network, &setup, Precision::F32).unwrap_err();
    let message = refused.to_string();
    assert!(
        message.contains(&format!("`{}`[3] = inf", weights[0].name)),
        "{message}"
    );
    assert!(message.contains("in f32"), "{message}");
    assert!(super::onnx(&model, &network, &setup, Precision::F64).is_ok());
    let last = weights.len() - 1;
    weights[last].values[1] = f64::NAN;
    network.set_weights(&weights).unwrap();
    let refused = super::onnx(&model, &network, &setup, Precision::F64).unwrap_err();
    assert!(
        refused.to_string().contains("param `Y_A` = NaN"),
        "{refused}"
    );
    use miette::Diagnostic;
    assert_eq!(
        refused.code().map(|c| c.to_string()).as_deref(),
        Some("gbm::E1101")
    );
}

/// An output `in [lo, hi]` with an additive prior (`backend::program::outputs`: the prior
/// clamped short of the ends, moved through a sigmoid) exports as the network computes it.
#[test]
fn a_bounded_output_exports_as_gbc_predicts_online() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let source = std::fs::read_to_string(root.join(CHEMOSTAT.0)).unwrap();
    let bounded = source
        .replace(
            "outputs r [mol/L/s] ~ 1e-3",
            "outputs r [mol/L/s] ~ 1e-3 in [-0.004, 0.001]",
        )
        .replace(
            "network hidden [20, 20, 20] softplus",
            "network hidden [20, 20, 20] softplus\n  prior r += -0.05 * S",
        );
    assert_ne!(bounded, source);
    let path = std::env::temp_dir().join(format!("gbc-export-bounded-{}.gbm", std::process::id()));
    std::fs::write(&path, bounded).unwrap();
    let file = path.display().to_string();
    let error = matches_online_prediction((&file, CHEMOSTAT.1, CHEMOSTAT.2), Precision::F64, 1e-11);
    let _ = std::fs::remove_file(&path);
    eprintln!("bounded chemostat, f64: largest relative error {error:e}");
}
