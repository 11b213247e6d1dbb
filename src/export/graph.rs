//! Building an ONNX graph: nodes with fresh output names, constants as initializers
//! (scalars shared by value), and the few compound operations every exported model needs,
//! written exactly as gbc's own scalar code computes them ([`Builder::softplus`],
//! [`Builder::sigmoid`]).

use std::collections::HashMap;

use super::onnx::{self, AttributeProto, NodeProto, TensorProto};
use crate::engine::graph::Precision;

/// A value of the graph: a constant known at export time, or a named tensor.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A number, folded at export time in `f64`.
    Const(f64),
    /// A tensor of rank 0 the same for every batch row (of params alone).
    Scalar(String),
    /// A tensor of shape `[batch, 1]`.
    Column(String),
}

impl Value {
    /// The same kind of value as `self` (a column if either is one) named `name`.
    fn like(&self, other: &Value, name: String) -> Value {
        match (self, other) {
            (Value::Column(_), _) | (_, Value::Column(_)) => Value::Column(name),
            _ => Value::Scalar(name),
        }
    }
}

/// Nodes and initializers under construction, in one element type.
pub struct Builder {
    precision: Precision,
    /// Nodes in topological order.
    pub nodes: Vec<NodeProto>,
    /// Constant tensors.
    pub initializers: Vec<TensorProto>,
    names: usize,
    scalars: HashMap<u64, String>,
}

impl Builder {
    /// An empty graph whose floating-point tensors are of `precision`.
    pub fn new(precision: Precision) -> Self {
        Builder {
            precision,
            nodes: Vec::new(),
            initializers: Vec::new(),
            names: 0,
            scalars: HashMap::new(),
        }
    }

    /// The ONNX element type of the graph's floating-point tensors.
    pub fn elem_type(&self) -> i32 {
        match self.precision {
            Precision::F32 => onnx::FLOAT,
            Precision::F64 => onnx::DOUBLE,
        }
    }

    fn fresh(&mut self, hint: &str) -> String {
        self.names += 1;
        format!("{hint}_{}", self.names)
    }

    /// Appends a node of `op` on `inputs` with integer `attributes`; returns its output.
    pub fn node(&mut self, op: &str, inputs: &[&str], attributes: &[(&str, i64)]) -> String {
        let output = self.fresh(&op.to_ascii_lowercase());
        self.node_into(op, inputs, attributes, &output);
        output
    }

    /// Appends a node whose output has the given name (a graph output).
    pub fn node_into(
        &mut self,
        op: &str,
        inputs: &[&str],
        attributes: &[(&str, i64)],
        output: &str,
    ) {
        self.nodes.push(NodeProto {
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![output.to_string()],
            name: format!("node_{}", self.nodes.len()),
            op_type: op.to_string(),
            attribute: (attributes.iter())
                .map(|(name, value)| AttributeProto {
                    name: name.to_string(),
                    i: *value,
                    r#type: onnx::ATTRIBUTE_INT,
                })
                .collect(),
        });
    }

    /// A floating-point constant tensor of shape `dims` (row-major `values`).
    pub fn floats(&mut self, hint: &str, dims: &[usize], values: &[f64]) -> String {
        let name = self.fresh(hint);
        self.named_floats(&name, dims, values)
    }

    /// A floating-point constant tensor named `name` (a trained tensor keeps its name).
    pub fn named_floats(&mut self, name: &str, dims: &[usize], values: &[f64]) -> String {
        let name = name.to_string();
        let raw_data = match self.precision {
            Precision::F32 => values
                .iter()
                .flat_map(|&v| (v as f32).to_le_bytes())
                .collect(),
            Precision::F64 => values.iter().flat_map(|&v| v.to_le_bytes()).collect(),
        };
        self.initializers.push(TensorProto {
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: self.elem_type(),
            name: name.clone(),
            raw_data,
        });
        name
    }

    /// An `int64` constant tensor of shape `dims`.
    pub fn ints(&mut self, hint: &str, dims: &[usize], values: &[i64]) -> String {
        let name = self.fresh(hint);
        self.initializers.push(TensorProto {
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: onnx::INT64,
            name: name.clone(),
            raw_data: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        });
        name
    }

    /// A scalar (rank 0) constant, one tensor per value.
    pub fn scalar(&mut self, value: f64) -> String {
        if let Some(name) = self.scalars.get(&value.to_bits()) {
            return name.clone();
        }
        let name = self.floats("const", &[], &[value]);
        self.scalars.insert(value.to_bits(), name.clone());
        name
    }

    /// The tensor of a value (a constant as a scalar tensor).
    pub fn tensor(&mut self, value: &Value) -> String {
        match value {
            Value::Const(number) => self.scalar(*number),
            Value::Scalar(name) | Value::Column(name) => name.clone(),
        }
    }

    /// Column `index` of a `[batch, n]` tensor, as `[batch, 1]`.
    pub fn column(&mut self, tensor: &str, index: usize) -> String {
        let indices = self.ints("index", &[1], &[index as i64]);
        self.node("Gather", &[tensor, &indices], &[("axis", 1)])
    }

    /// Columns `from..to` of a `[batch, n]` tensor.
    pub fn columns(&mut self, tensor: &str, from: usize, to: usize) -> String {
        let starts = self.ints("starts", &[1], &[from as i64]);
        let ends = self.ints("ends", &[1], &[to as i64]);
        let axes = self.ints("axes", &[1], &[1]);
        self.node("Slice", &[tensor, &starts, &ends, &axes], &[])
    }

    /// `[batch, 1]` columns side by side; values the same for every row are spread over
    /// the batch like the `[batch, 1]` tensor `like`.
    pub fn concat(&mut self, values: &[Value], like: &str) -> String {
        let mut names = Vec::with_capacity(values.len());
        for value in values {
            names.push(match value {
                Value::Column(name) => name.clone(),
                other => {
                    let scalar = self.tensor(other);
                    let shape = self.node("Shape", &[like], &[]);
                    self.node("Expand", &[&scalar, &shape], &[])
                }
            });
        }
        let inputs: Vec<&str> = names.iter().map(String::as_str).collect();
        self.node("Concat", &inputs, &[("axis", 1)])
    }

    /// A binary operator on two values (`Add`, `Sub`, `Mul`, `Div`, `Pow`, `Min`, `Max`),
    /// folded when both are constants.
    pub fn binary(&mut self, op: &str, a: &Value, b: &Value) -> Value {
        if let (Value::Const(x), Value::Const(y)) = (a, b) {
            return Value::Const(fold(op, *x, *y));
        }
        let (x, y) = (self.tensor(a), self.tensor(b));
        let name = self.node(op, &[&x, &y], &[]);
        a.like(b, name)
    }

    /// A unary operator (`Neg`, `Exp`, `Log`, `Sqrt`, `Abs`, `Tanh`) on a tensor.
    pub fn unary(&mut self, op: &str, a: &str) -> String {
        self.node(op, &[a], &[])
    }

    /// `op` applied to a value's tensor, keeping its kind (never a constant).
    pub fn map(&mut self, value: &Value, op: impl FnOnce(&mut Builder, &str) -> String) -> Value {
        let tensor = self.tensor(value);
        let name = op(self, &tensor);
        value.like(value, name)
    }

    /// `ln(1 + e)` for `e >= 0` with Goldberg's correction, as gbc's scalar code computes
    /// it: `e` where `1 + e` rounds to 1, else `ln(1 + e) * e / ((1 + e) - 1)`.
    fn ln_one_plus(&mut self, e: &str) -> String {
        let one = self.scalar(1.0);
        let sum = self.node("Add", &[&one, e], &[]);
        let is_one = self.node("Equal", &[&sum, &one], &[]);
        let log = self.node("Log", &[&sum], &[]);
        let scaled = self.node("Mul", &[&log, e], &[]);
        let denominator = self.node("Sub", &[&sum, &one], &[]);
        let corrected = self.node("Div", &[&scaled, &denominator], &[]);
        self.node("Where", &[&is_one, e, &corrected], &[])
    }

    /// `e^-|x|`.
    fn decay(&mut self, x: &str) -> String {
        let magnitude = self.unary("Abs", x);
        let negative = self.unary("Neg", &magnitude);
        self.unary("Exp", &negative)
    }

    /// `softplus(x) = max(x, 0) + ln(1 + e^-|x|)`: neither overflows nor loses the tail.
    pub fn softplus(&mut self, x: &str) -> String {
        let zero = self.scalar(0.0);
        let positive = self.node("Max", &[x, &zero], &[]);
        let decay = self.decay(x);
        let tail = self.ln_one_plus(&decay);
        self.node("Add", &[&positive, &tail], &[])
    }

    /// `sigmoid(x)`: `1 / (1 + e)` for `x >= 0`, `e / (1 + e)` below, `e = e^-|x|`.
    pub fn sigmoid(&mut self, x: &str) -> String {
        let (zero, one) = (self.scalar(0.0), self.scalar(1.0));
        let decay = self.decay(x);
        let denominator = self.node("Add", &[&one, &decay], &[]);
        let upper = self.node("Div", &[&one, &denominator], &[]);
        let lower = self.node("Div", &[&decay, &denominator], &[]);
        let non_negative = self.node("GreaterOrEqual", &[x, &zero], &[]);
        self.node("Where", &[&non_negative, &upper, &lower], &[])
    }
}

/// A binary operator on two numbers, as gbc's scalar code computes it.
pub fn fold(op: &str, a: f64, b: f64) -> f64 {
    match op {
        "Add" => a + b,
        "Sub" => a - b,
        "Mul" => a * b,
        "Div" => a / b,
        "Pow" => a.powf(b),
        "Min" => {
            if b < a {
                b
            } else {
                a
            }
        }
        _ => {
            if b > a {
                b
            } else {
                a
            }
        }
    }
}
