//! `gbc export`: a trained model's one-step map as a file other runtimes read.
//!
//! The ONNX export is the map from the current window of measured states and inputs (and
//! the hidden states) to the next state, one RK4 step of the run's step `h` (or one `next`
//! update) with the embedding, its normalisation, the closure networks and the physics
//! inside. Its layout (tensor names, shapes, how to step it over time) is in
//! `docs/export.md`; [`Layout`] describes one export, and the same facts are written into
//! the file's metadata (`gbc.*` keys).
//!
//! - [`onnx`]: the protocol buffer messages, derived with `prost`.
//! - [`graph`]: a graph builder (constants, compound operations written as gbc computes
//!   them).
//! - [`expr`]: the physics, one translation of [`ir::Expr`] into nodes.
//! - [`window`]: the window-to-embedding matrices, from the training code's own reads.
//! - [`step`]: the stages, networks and RK4 combination.
//! - [`ensemble`]: an ensemble run's members and the band's facts beside them.

pub mod ensemble;
pub mod expr;
pub mod graph;
pub mod onnx;
pub mod step;
pub mod window;

use prost::Message;

use crate::engine::graph::{Network, Precision, Setup};
use crate::ir;

/// What an exported file holds, for the user: window length, step and the names of the
/// columns of every tensor.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Knots in the window (`W`), the current one last.
    pub window: usize,
    /// The step `h` between knots and of one call.
    pub step: f64,
    /// RK4 sub-steps per call (`der` models).
    pub substeps: usize,
    /// Columns of `state_window` and `next_state`.
    pub states: Vec<String>,
    /// Columns of `input_window`.
    pub inputs: Vec<String>,
    /// Columns of `hidden` and `next_hidden`.
    pub hidden: Vec<String>,
    /// Columns of `closure_outputs`.
    pub closure_outputs: Vec<String>,
    /// Columns of `outputs`.
    pub outputs: Vec<String>,
    /// The element type of every floating-point tensor.
    pub precision: Precision,
}

/// An encoded model and its layout.
#[derive(Debug, Clone, PartialEq)]
pub struct Exported {
    /// The file's bytes.
    pub bytes: Vec<u8>,
    /// What it holds.
    pub layout: Layout,
}

/// Why a model cannot be exported.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum ExportError {
    /// The trained network does not fit the model (a bug: restoring checks this).
    #[error("internal error in the export: {0}")]
    #[diagnostic(code(gbm::E1100), help("this is a bug in gbc; please report it"))]
    Internal(String),
    /// A trained weight that is not finite in the element type of the export.
    #[error("expected finite weights in {precision}, found {what}")]
    #[diagnostic(
        code(gbm::E1101),
        help(
            "a weight beyond f32's range (3.4e38) exports with --precision f64; a NaN or \
             infinite one comes from a run that went non-finite: train again"
        )
    )]
    NotFinite {
        /// The weight and its value.
        what: String,
        /// The element type.
        precision: &'static str,
    },
}

/// The one-step map of a trained `network` of `model` as an ONNX model in `precision`.
pub fn onnx(
    model: &ir::Model,
    network: &Network,
    setup: &Setup,
    precision: Precision,
) -> Result<Exported, ExportError> {
    let weights = network.weights();
    let expected: usize = (model.closures.iter())
        .map(|c| 2 * (c.network.hidden.len() + 1))
        .sum::<usize>()
        + usize::from(!model.params.is_empty());
    if weights.len() != expected || setup.scales.len() != model.closures.len() {
        return Err(ExportError::Internal(format!(
            "{} trained tensors for a model that needs {expected}",
            weights.len()
        )));
    }
    check_finite(model, &weights, precision)?;
    let window = window::window_map(model, setup);
    let layout = layout_of(model, setup, &window, precision);
    let mut graph = graph::Builder::new(precision);
    let parts = step::Parts {
        model,
        setup,
        weights: &weights,
        window: &window,
    };
    step::build(&mut graph, &parts);
    let elem = graph.elem_type();
    let (inputs, outputs) = interface(&layout, elem);
    let model_proto = onnx::ModelProto {
        ir_version: onnx::IR_VERSION,
        producer_name: "gbc".into(),
        producer_version: env!("CARGO_PKG_VERSION").into(),
        domain: String::new(),
        model_version: 1,
        doc_string: format!(
            "one-step map of the trained grey-box model `{}` (see gbc's docs/export.md)",
            model.name
        ),
        graph: Some(onnx::GraphProto {
            node: graph.nodes,
            name: model.name.clone(),
            initializer: graph.initializers,
            doc_string: String::new(),
            input: inputs,
            output: outputs,
        }),
        opset_import: vec![onnx::OperatorSetIdProto {
            domain: String::new(),
            version: onnx::OPSET_VERSION,
        }],
        metadata_props: metadata(model, &layout),
    };
    Ok(Exported {
        bytes: model_proto.encode_to_vec(),
        layout,
    })
}

/// Refuses weights that are not finite once cast to `precision`.
fn check_finite(
    model: &ir::Model,
    weights: &[crate::engine::graph::NamedTensor],
    precision: Precision,
) -> Result<(), ExportError> {
    let cast: Vec<crate::engine::graph::NamedTensor> = (weights.iter())
        .map(|tensor| crate::engine::graph::NamedTensor {
            values: (tensor.values.iter())
                .map(|&v| match precision {
                    Precision::F32 => f64::from(v as f32),
                    Precision::F64 => v,
                })
                .collect(),
            ..tensor.clone()
        })
        .collect();
    let params: Vec<String> = model.params.iter().map(|p| p.name.clone()).collect();
    match crate::finite::in_tensors(&cast, &params) {
        Some(what) => Err(ExportError::NotFinite {
            what,
            precision: precision.name(),
        }),
        None => Ok(()),
    }
}

fn layout_of(
    model: &ir::Model,
    setup: &Setup,
    window: &window::WindowMap,
    precision: Precision,
) -> Layout {
    let names = |list: &[ir::State]| list.iter().map(|s| s.name.clone()).collect();
    Layout {
        window: window.length,
        step: setup.step,
        substeps: setup.substeps.max(1),
        states: names(&model.states),
        inputs: model.inputs.iter().map(|i| i.name.clone()).collect(),
        hidden: names(&model.hidden),
        closure_outputs: (model.closures.iter())
            .flat_map(|c| c.outputs.iter().map(|o| o.name.clone()))
            .collect(),
        outputs: model.outputs.iter().map(|o| o.name.clone()).collect(),
        precision,
    }
}

/// The graph's inputs and outputs (those with no column are left out).
fn interface(layout: &Layout, elem: i32) -> (Vec<onnx::ValueInfoProto>, Vec<onnx::ValueInfoProto>) {
    let w = Some(layout.window);
    let info =
        |name: &str, dims: &[Option<usize>], doc: &str| onnx::value_info(name, elem, dims, doc);
    let mut inputs = vec![info(
        step::STATE_WINDOW,
        &[None, w, Some(layout.states.len())],
        "measured states at the window's knots, oldest first, the current one last",
    )];
    if !layout.inputs.is_empty() {
        inputs.push(info(
            step::INPUT_WINDOW,
            &[None, w, Some(layout.inputs.len())],
            "inputs at the window's knots; the last row is held over the step",
        ));
    }
    if !layout.hidden.is_empty() {
        inputs.push(info(
            step::HIDDEN,
            &[None, Some(layout.hidden.len())],
            "hidden states now",
        ));
    }
    let mut outputs = vec![info(
        step::NEXT_STATE,
        &[None, Some(layout.states.len())],
        "measured states one step on",
    )];
    let optional = [
        (
            step::NEXT_HIDDEN,
            layout.hidden.len(),
            "hidden states one step on",
        ),
        (
            step::CLOSURE_OUTPUTS,
            layout.closure_outputs.len(),
            "closure outputs now",
        ),
        (step::OUTPUTS, layout.outputs.len(), "model outputs now"),
    ];
    for (name, width, doc) in optional {
        if width > 0 {
            outputs.push(info(name, &[None, Some(width)], doc));
        }
    }
    (inputs, outputs)
}

/// `gbc.*` metadata entries: the layout in words a user's code can read.
fn metadata(model: &ir::Model, layout: &Layout) -> Vec<onnx::StringStringEntryProto> {
    let entry = |key: &str, value: String| onnx::StringStringEntryProto {
        key: format!("gbc.{key}"),
        value,
    };
    vec![
        entry("model", model.name.clone()),
        entry("step", format!("{:?}", layout.step)),
        entry("window", layout.window.to_string()),
        entry("substeps", layout.substeps.to_string()),
        entry("states", layout.states.join(",")),
        entry("inputs", layout.inputs.join(",")),
        entry("hidden", layout.hidden.join(",")),
        entry("closure_outputs", layout.closure_outputs.join(",")),
        entry("outputs", layout.outputs.join(",")),
        entry("hidden_initial", hidden_initial(model)),
        entry("time_unit", model.time_unit.clone().unwrap_or_default()),
    ]
}

/// The hidden states' declared initial values, comma separated (`nan` where one cannot
/// be evaluated).
fn hidden_initial(model: &ir::Model) -> String {
    let values = crate::train::hidden_initial_values(model)
        .unwrap_or_else(|_| vec![f64::NAN; model.hidden.len()]);
    (values.iter())
        .map(|v| format!("{v:?}"))
        .collect::<Vec<_>>()
        .join(",")
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_ensemble;
