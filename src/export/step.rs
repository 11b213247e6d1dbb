//! The one-step map as an ONNX graph: window in, next state out (see `docs/export.md`).
//!
//! At each RK4 stage (or the one evaluation of a `next` model) every closure's network
//! reads its embedding, `window_map` applied to the window and the stage state, z-scored by
//! the training statistics; the physics ([`super::expr`]) turns network outputs, held
//! inputs and params into the balances; the stages combine as in the trainable network
//! (`backend::net`): `K` sub-steps of `h / K`.

use super::expr::{Physics, Stage};
use super::graph::Builder;
use super::window::WindowMap;
use crate::engine::graph::{NamedTensor, Setup};
use crate::ir::{self, Activation, Var};
use crate::solve::ode::tableau::{Combination, RK4};

/// Graph input: the measured states at the window's knots.
pub const STATE_WINDOW: &str = "state_window";
/// Graph input: the inputs at the window's knots (the last row is held over the step).
pub const INPUT_WINDOW: &str = "input_window";
/// Graph input: the hidden states at the current knot.
pub const HIDDEN: &str = "hidden";
/// Graph output: the measured states one step on.
pub const NEXT_STATE: &str = "next_state";
/// Graph output: the hidden states one step on.
pub const NEXT_HIDDEN: &str = "next_hidden";
/// Graph output: every closure output at the current knot.
pub const CLOSURE_OUTPUTS: &str = "closure_outputs";
/// Graph output: the model's `output`s at the current knot.
pub const OUTPUTS: &str = "outputs";

/// What the step graph is built from.
pub struct Parts<'a> {
    /// The compiled model.
    pub model: &'a ir::Model,
    /// Its setup (step, sub-steps, normalisation, closure magnitudes).
    pub setup: &'a Setup,
    /// The trained tensors, named as in `weights.safetensors`.
    pub weights: &'a [NamedTensor],
    /// The window map.
    pub window: &'a WindowMap,
}

/// The tensors every stage reads: the window's features (`[batch, W (S + U)]`) and a
/// `[batch, 1]` column to spread constants like.
struct Frame {
    history: String,
    first_column: String,
}

/// A closure's initializers: `(weight, bias)` per layer, the window map per stage offset,
/// and the z-score of its embedding columns.
struct ClosureTensors {
    layers: Vec<(String, String)>,
    reads: Vec<String>,
    mean: String,
    std: String,
}

/// Adds the one-step map to `graph`, reading the graph inputs and writing the graph
/// outputs named above.
pub fn build(graph: &mut Builder, parts: &Parts) {
    let model = parts.model;
    let (states, inputs, hidden) = (model.states.len(), model.inputs.len(), model.hidden.len());
    let length = parts.window.length;
    let last = graph.ints("current", &[], &[length as i64 - 1]);
    let mut history = Vec::new();
    let state_flat = graph.ints("shape", &[2], &[-1, (length * states) as i64]);
    history.push(graph.node("Reshape", &[STATE_WINDOW, &state_flat], &[]));
    let current_state = graph.node("Gather", &[STATE_WINDOW, &last], &[("axis", 1)]);
    let mut held_inputs = None;
    if inputs > 0 {
        let input_flat = graph.ints("shape", &[2], &[-1, (length * inputs) as i64]);
        history.push(graph.node("Reshape", &[INPUT_WINDOW, &input_flat], &[]));
        held_inputs = Some(graph.node("Gather", &[INPUT_WINDOW, &last], &[("axis", 1)]));
    }
    let history: Vec<&str> = history.iter().map(String::as_str).collect();
    let history = graph.node("Concat", &history, &[("axis", 1)]);
    let start = if hidden > 0 {
        graph.node("Concat", &[&current_state, HIDDEN], &[("axis", 1)])
    } else {
        current_state
    };
    let raw_params = (parts.weights.iter())
        .find(|t| t.name == crate::vocabulary::PARAMS_TENSOR)
        .map(|t| named(graph, t));
    let first_column = graph.column(&start, 0);
    let frame = Frame {
        history,
        first_column,
    };
    let mut physics = Physics::new(model, &parts.setup.scales, held_inputs, raw_params);
    let layers = closure_tensors(graph, parts);
    let (next, mut first) = advance(graph, parts, (&frame, &layers), &mut physics, &start);
    let measured = graph.columns(&next, 0, states);
    graph.node_into("Identity", &[&measured], &[], NEXT_STATE);
    if hidden > 0 {
        let rest = graph.columns(&next, states, states + hidden);
        graph.node_into("Identity", &[&rest], &[], NEXT_HIDDEN);
    }
    let closure_outputs: Vec<_> = (model.closures.iter().enumerate())
        .flat_map(|(c, closure)| (0..closure.outputs.len()).map(move |o| (c, o)))
        .collect();
    if !closure_outputs.is_empty() {
        let values: Vec<_> = (closure_outputs.into_iter())
            .map(|at| physics.closure_output(graph, &mut first, at))
            .collect();
        let table = graph.concat(&values, &frame.first_column);
        graph.node_into("Identity", &[&table], &[], CLOSURE_OUTPUTS);
    }
    if !model.outputs.is_empty() {
        let values: Vec<_> = (model.outputs.iter())
            .map(|definition| physics.expr(graph, &mut first, &definition.expr))
            .collect();
        let table = graph.concat(&values, &frame.first_column);
        graph.node_into("Identity", &[&table], &[], OUTPUTS);
    }
}

/// Every closure's tensors.
type Layers = Vec<ClosureTensors>;

fn closure_tensors(graph: &mut Builder, parts: &Parts) -> Layers {
    (parts.model.closures.iter().enumerate())
        .map(|(index, closure)| {
            let layers = (0..=closure.network.hidden.len())
                .map(|layer| {
                    let prefix = format!("closure.{}.layer{layer}", closure.name);
                    let find = |suffix: &str| {
                        let name = format!("{prefix}.{suffix}");
                        parts.weights.iter().find(|t| t.name == name)
                    };
                    let weight = find("weight").map(|t| named(graph, t)).unwrap_or_default();
                    let bias = find("bias").map(|t| named(graph, t)).unwrap_or_default();
                    (weight, bias)
                })
                .collect();
            let width = closure.embedding.width();
            let dims = [parts.window.features, width];
            let reads = (parts.window.matrices[index].iter())
                .map(|matrix| {
                    graph.floats(&format!("closure.{}.window", closure.name), &dims, matrix)
                })
                .collect();
            let (mean, std) = column_statistics(closure, parts.setup);
            let mean = graph.floats(&format!("closure.{}.mean", closure.name), &[width], &mean);
            let std = graph.floats(&format!("closure.{}.std", closure.name), &[width], &std);
            ClosureTensors {
                layers,
                reads,
                mean,
                std,
            }
        })
        .collect()
}

/// A trained tensor as an initializer of its own name.
fn named(graph: &mut Builder, tensor: &NamedTensor) -> String {
    graph.named_floats(&tensor.name, &tensor.shape, &tensor.values)
}

/// The state after one step from `start`, and the first stage (for the values at `t`).
fn advance(
    graph: &mut Builder,
    parts: &Parts,
    (frame, layers): (&Frame, &Layers),
    physics: &mut Physics,
    start: &str,
) -> (String, Stage) {
    let (k1, first) = stage(graph, parts, (frame, layers), physics, (start, 0));
    if parts.model.dynamics == ir::Dynamics::Discrete {
        return (k1, first);
    }
    let substeps = parts.setup.substeps.max(1);
    let dt = parts.setup.step / substeps as f64;
    let factors = Factors::new(graph, dt);
    let (mut state, mut first_slope) = (start.to_string(), Some(k1));
    for substep in 0..substeps {
        let mut slopes = Vec::with_capacity(RK4.stages.len());
        for (index, coupling) in RK4.stages.iter().enumerate() {
            let offset = RK4.stage_offset(substep, index);
            let slope = match first_slope.take() {
                Some(slope) => slope,
                None if coupling.is_empty() => {
                    stage(graph, parts, (frame, layers), physics, (&state, offset)).0
                }
                None => {
                    let slope = factors.combine(graph, coupling, &slopes);
                    let estimate = axpy(graph, &state, &factors.stages[index], &slope);
                    stage(graph, parts, (frame, layers), physics, (&estimate, offset)).0
                }
            };
            slopes.push(slope);
        }
        let sum = factors.combine(graph, &RK4.weights, &slopes);
        state = axpy(graph, &state, &factors.weights, &sum);
    }
    (state, first)
}

/// `x + factor * k` as nodes.
fn axpy(graph: &mut Builder, x: &str, factor: &str, k: &str) -> String {
    let scaled = graph.node("Mul", &[k, factor], &[]);
    graph.node("Add", &[x, &scaled], &[])
}

/// The scalars of a sub-step of `dt`, made once before the first (in this order: the
/// stages' `dt / d_i`, the weights' `dt / d_b`, then every numerator other than 1).
struct Factors {
    /// `dt / d_i` of each stage (none for the first, which reads no slope).
    stages: Vec<String>,
    /// `dt / d_b` of the weights.
    weights: String,
    /// The scalar of each numerator other than 1.
    numerators: Vec<(i32, String)>,
}

impl Factors {
    fn new(graph: &mut Builder, dt: f64) -> Factors {
        let stages = (RK4.stages.iter())
            .map(|row| match row.is_empty() {
                true => String::new(),
                false => graph.scalar(dt / row.divisor()),
            })
            .collect();
        let weights = graph.scalar(dt / RK4.weights.divisor());
        let rows = RK4.stages.iter().chain([&RK4.weights]);
        let numerators = (rows.flat_map(|row| row.numerators))
            .filter(|&numerator| numerator != 0 && numerator != 1)
            .map(|numerator| (numerator, graph.scalar(f64::from(numerator))))
            .collect();
        Factors {
            stages,
            weights,
            numerators,
        }
    }

    /// The scalar of `numerator`.
    fn numerator(&self, numerator: f64) -> &str {
        let found = self
            .numerators
            .iter()
            .find(|(n, _)| f64::from(*n) == numerator);
        found.map_or("", |(_, name)| name.as_str())
    }

    /// `n_0 k_0 + n_1 k_1 + ...` over the stages that enter `combination`, left to right,
    /// as nodes (a numerator of 1 multiplies nothing).
    fn combine<const S: usize>(
        &self,
        graph: &mut Builder,
        combination: &Combination<S>,
        slopes: &[String],
    ) -> String {
        let mut sum: Option<String> = None;
        for (stage, numerator) in combination.terms() {
            let term = if numerator == 1.0 {
                slopes[stage].clone()
            } else {
                graph.node("Mul", &[&slopes[stage], self.numerator(numerator)], &[])
            };
            sum = Some(match sum {
                None => term,
                Some(sum) => graph.node("Add", &[&sum, &term], &[]),
            });
        }
        sum.unwrap_or_default()
    }
}

/// The balances at the stage state `state`, stage offset `offset`.
fn stage(
    graph: &mut Builder,
    parts: &Parts,
    (frame, layers): (&Frame, &Layers),
    physics: &mut Physics,
    (state, offset): (&str, usize),
) -> (String, Stage) {
    let model = parts.model;
    let features = graph.node("Concat", &[&frame.history, state], &[("axis", 1)]);
    let nets = (model.closures.iter().zip(layers))
        .map(|(closure, tensors)| {
            let raw = graph.node("MatMul", &[&features, &tensors.reads[offset]], &[]);
            let centred = graph.node("Sub", &[&raw, &tensors.mean], &[]);
            let mut hidden = graph.node("Div", &[&centred, &tensors.std], &[]);
            let last = tensors.layers.len().saturating_sub(1);
            for (layer, (weight, bias)) in tensors.layers.iter().enumerate() {
                let product = graph.node("MatMul", &[&hidden, weight], &[]);
                hidden = graph.node("Add", &[&product, bias], &[]);
                if layer < last {
                    hidden = activation(graph, &hidden, closure.network.activation);
                }
            }
            hidden
        })
        .collect();
    let mut stage = Stage::new(state.to_string(), nets);
    let mut balances = vec![None; model.states.len() + model.hidden.len()];
    for balance in &model.balances {
        let index = match balance.state {
            Var::State(i) => i,
            Var::Hidden(j) => model.states.len() + j,
            _ => continue,
        };
        balances[index] = Some(physics.expr(graph, &mut stage, &balance.expr));
    }
    let values: Vec<_> = balances.into_iter().flatten().collect();
    let derivative = graph.concat(&values, &frame.first_column);
    (derivative, stage)
}

/// The z-score of each embedding column: its variable's training mean and std.
fn column_statistics(closure: &ir::Closure, setup: &Setup) -> (Vec<f64>, Vec<f64>) {
    let norm = &setup.normalisation;
    (closure.embedding.layout().into_iter())
        .map(|(var, _)| match var {
            Var::Input(i) => (norm.input_mean[i], norm.input_std[i]),
            Var::State(i) => (norm.state_mean[i], norm.state_std[i]),
            _ => (0.0, 1.0),
        })
        .unzip()
}

/// A hidden-layer activation, as the trainable network computes it.
fn activation(graph: &mut Builder, x: &str, activation: Activation) -> String {
    match activation {
        Activation::Softplus => graph.softplus(x),
        Activation::Tanh => graph.unary("Tanh", x),
        Activation::Relu => graph.unary("Relu", x),
        Activation::Sigmoid => graph.sigmoid(x),
        Activation::Linear => x.to_string(),
        Activation::Gelu => {
            // 0.5 x (1 + tanh(sqrt(2/pi) (x + 0.044715 x^3))), dfdx's fast GeLU.
            let (three, kappa) = (graph.scalar(3.0), graph.scalar(0.044715));
            let cube = graph.node("Pow", &[x, &three], &[]);
            let term = graph.node("Mul", &[&kappa, &cube], &[]);
            let alpha = graph.node("Add", &[x, &term], &[]);
            let beta = graph.scalar(std::f64::consts::FRAC_2_PI.sqrt());
            let inner = graph.node("Mul", &[&beta, &alpha], &[]);
            let tanh = graph.unary("Tanh", &inner);
            let one = graph.scalar(1.0);
            let sum = graph.node("Add", &[&one, &tanh], &[]);
            let half = graph.scalar(0.5);
            let left = graph.node("Mul", &[&half, x], &[]);
            graph.node("Mul", &[&left, &sum], &[])
        }
    }
}
