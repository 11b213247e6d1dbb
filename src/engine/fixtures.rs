//! Test support of the engines and of everything above them: compiled models built by hand
//! (no parser), the paper's models among them, a reference integrator for making data, and
//! records laid on their grids.
//!
//! [`ModelBuilder`] resolves names the way the front end does and inlines `let`s; its
//! expressions are read by a tiny precedence-climbing reader (`+ -` < `* /` < unary `-` <
//! `^`, right associative), enough for the fixtures' equations.

use std::collections::HashMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::engine::batch::Batch;
use crate::engine::setup::Setup;
use crate::ir::{
    self, Activation, BinOp, Closure, ClosureOutput, Constraint, Dynamics, Embedding, Expr, Func,
    Network, Prior, PriorKind, Var,
};
use crate::solve::ode::tableau::{Combination, RK4};

/// Builds an [`ir::Model`] declaration by declaration.
pub struct ModelBuilder {
    model: ir::Model,
    names: HashMap<String, Var>,
    lets: HashMap<String, Expr>,
}

/// One closure output for [`ModelBuilder::closure`]: name, `~` scale, prior.
pub struct OutputSpec<'a> {
    /// Name.
    pub name: &'a str,
    /// `~` magnitude.
    pub scale: Option<f64>,
    /// `("*=" | "+=", expression)`.
    pub prior: Option<(&'a str, &'a str)>,
}

/// A closure for [`ModelBuilder::closure`].
pub struct ClosureSpec<'a> {
    /// Name.
    pub name: &'a str,
    /// Outputs.
    pub outputs: Vec<OutputSpec<'a>>,
    /// Observed names.
    pub observe: &'a [&'a str],
    /// Embedding delay.
    pub delay: f64,
    /// Embedding dimension.
    pub dim: usize,
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Activation.
    pub activation: Activation,
}

impl ModelBuilder {
    /// An empty continuous-time model.
    pub fn new(name: &str) -> Self {
        ModelBuilder {
            model: ir::Model {
                name: name.to_string(),
                description: None,
                time_unit: None,
                inputs: Vec::new(),
                states: Vec::new(),
                hidden: Vec::new(),
                consts: Vec::new(),
                params: Vec::new(),
                lets: Vec::new(),
                outputs: Vec::new(),
                closures: Vec::new(),
                dynamics: Dynamics::Continuous,
                balances: Vec::new(),
                effects: Vec::new(),
                units: Default::default(),
                noise: Vec::new(),
            },
            names: HashMap::new(),
            lets: HashMap::new(),
        }
    }

    /// `input name`.
    pub fn input(mut self, name: &str) -> Self {
        self.names
            .insert(name.into(), Var::Input(self.model.inputs.len()));
        self.model.inputs.push(ir::Input {
            name: name.into(),
            bounds: None,
        });
        self
    }

    /// `state name`.
    pub fn state(mut self, name: &str) -> Self {
        self.names
            .insert(name.into(), Var::State(self.model.states.len()));
        self.model.states.push(ir::State {
            name: name.into(),
            init: None,
            nonnegative: false,
        });
        self
    }

    /// `hidden name = init`.
    pub fn hidden(mut self, name: &str, init: f64) -> Self {
        self.names
            .insert(name.into(), Var::Hidden(self.model.hidden.len()));
        self.model.hidden.push(ir::State {
            name: name.into(),
            init: Some(Expr::Num(init)),
            nonnegative: false,
        });
        self
    }

    /// `const name = value`.
    pub fn constant(mut self, name: &str, value: f64) -> Self {
        self.names
            .insert(name.into(), Var::Const(self.model.consts.len()));
        self.model.consts.push(ir::Const {
            name: name.into(),
            value,
        });
        self
    }

    /// `param name = init constraint`.
    pub fn param(mut self, name: &str, init: f64, constraint: Constraint) -> Self {
        self.names
            .insert(name.into(), Var::Param(self.model.params.len()));
        self.model.params.push(ir::Param {
            name: name.into(),
            init,
            constraint,
        });
        self
    }

    /// `let name = text` (inlined where used).
    pub fn define(mut self, name: &str, text: &str) -> Self {
        let expr = self.parse(text);
        self.model.lets.push(ir::Definition {
            name: name.into(),
            expr: expr.clone(),
        });
        self.lets.insert(name.into(), expr);
        self
    }

    /// A closure; its outputs become names.
    pub fn closure(mut self, spec: ClosureSpec) -> Self {
        let closure = self.model.closures.len();
        for (output, out) in spec.outputs.iter().enumerate() {
            self.names
                .insert(out.name.into(), Var::ClosureOutput { closure, output });
        }
        let outputs = (spec.outputs.iter())
            .map(|out| ClosureOutput {
                name: out.name.into(),
                scale: out.scale,
                prior: out.prior.map(|(op, text)| Prior {
                    kind: if op == "*=" {
                        PriorKind::Mul
                    } else {
                        PriorKind::Add
                    },
                    expr: self.parse(text),
                }),
                constraint: Constraint::Free,
            })
            .collect();
        let observe = spec.observe.iter().map(|n| self.names[*n]).collect();
        self.model.closures.push(Closure {
            name: spec.name.into(),
            outputs,
            embedding: Embedding {
                observe,
                delay: spec.delay,
                dim: spec.dim,
            },
            network: Network {
                hidden: spec.hidden,
                activation: spec.activation,
            },
        });
        self
    }

    /// `der name = text`.
    pub fn der(mut self, name: &str, text: &str) -> Self {
        let expr = self.parse(text);
        let state = self.names[name];
        self.model.balances.push(ir::Balance { state, expr });
        self
    }

    /// `next name = text` (makes the model discrete).
    pub fn next(mut self, name: &str, text: &str) -> Self {
        self.model.dynamics = Dynamics::Discrete;
        self.der(name, text)
    }

    /// The model, balances ordered measured states first then hidden.
    pub fn build(mut self) -> ir::Model {
        let measured = self.model.states.len();
        self.model.balances.sort_by_key(|b| match b.state {
            Var::State(i) => i,
            Var::Hidden(j) => measured + j,
            _ => usize::MAX,
        });
        self.model
    }

    fn parse(&self, text: &str) -> Expr {
        let tokens = tokenize(text);
        let mut reader = Reader {
            tokens,
            position: 0,
            builder: self,
        };
        let expr = reader.sum();
        assert_eq!(
            reader.position,
            reader.tokens.len(),
            "trailing input in {text}"
        );
        expr
    }
}

fn tokenize(text: &str) -> Vec<String> {
    let mut tokens = Vec::new();
    let chars: Vec<char> = text.chars().collect();
    let mut index = 0;
    while index < chars.len() {
        let c = chars[index];
        if c.is_whitespace() {
            index += 1;
        } else if c.is_ascii_digit() || c == '.' {
            let start = index;
            while index < chars.len()
                && (chars[index].is_ascii_digit()
                    || chars[index] == '.'
                    || chars[index] == 'e'
                    || (chars[index] == '-' && chars[index - 1] == 'e'))
            {
                index += 1;
            }
            tokens.push(chars[start..index].iter().collect());
        } else if c.is_alphabetic() || c == '_' {
            let start = index;
            while index < chars.len() && (chars[index].is_alphanumeric() || chars[index] == '_') {
                index += 1;
            }
            tokens.push(chars[start..index].iter().collect());
        } else {
            tokens.push(c.to_string());
            index += 1;
        }
    }
    tokens
}

struct Reader<'b> {
    tokens: Vec<String>,
    position: usize,
    builder: &'b ModelBuilder,
}

impl Reader<'_> {
    fn peek(&self) -> Option<&str> {
        self.tokens.get(self.position).map(String::as_str)
    }

    fn take(&mut self) -> String {
        self.position += 1;
        self.tokens[self.position - 1].clone()
    }

    fn sum(&mut self) -> Expr {
        let mut left = self.product();
        while let Some(op) = self.peek().and_then(|t| match t {
            "+" => Some(BinOp::Add),
            "-" => Some(BinOp::Sub),
            _ => None,
        }) {
            self.take();
            left = Expr::Bin(op, Box::new(left), Box::new(self.product()));
        }
        left
    }

    fn product(&mut self) -> Expr {
        let mut left = self.unary();
        while let Some(op) = self.peek().and_then(|t| match t {
            "*" => Some(BinOp::Mul),
            "/" => Some(BinOp::Div),
            _ => None,
        }) {
            self.take();
            left = Expr::Bin(op, Box::new(left), Box::new(self.unary()));
        }
        left
    }

    fn unary(&mut self) -> Expr {
        if self.peek() == Some("-") {
            self.take();
            return Expr::Neg(Box::new(self.unary()));
        }
        self.power()
    }

    fn power(&mut self) -> Expr {
        let base = self.atom();
        if self.peek() == Some("^") {
            self.take();
            return Expr::Bin(BinOp::Pow, Box::new(base), Box::new(self.unary()));
        }
        base
    }

    fn atom(&mut self) -> Expr {
        let token = self.take();
        if token == "(" {
            let inner = self.sum();
            assert_eq!(self.take(), ")");
            return inner;
        }
        if let Ok(value) = token.parse::<f64>() {
            return Expr::Num(value);
        }
        if self.peek() == Some("(") {
            self.take();
            let func = Func::from_name(&token).unwrap_or_else(|| panic!("no function {token}"));
            let mut args = vec![self.sum()];
            while self.peek() == Some(",") {
                self.take();
                args.push(self.sum());
            }
            assert_eq!(self.take(), ")");
            return Expr::Call(func, args);
        }
        if let Some(expr) = self.builder.lets.get(&token) {
            return expr.clone();
        }
        let var = (self.builder.names.get(&token)).unwrap_or_else(|| panic!("unknown {token}"));
        Expr::Var(*var)
    }
}

/// `substeps` classical RK4 steps of `rhs` over `step` from `start` (a reference
/// integrator written independently of the backend, on RK4's tableau).
pub fn rk4_reference(
    rhs: impl Fn(&[f64]) -> Vec<f64>,
    start: &[f64],
    step: f64,
    substeps: usize,
) -> Vec<f64> {
    let dt = step / substeps as f64;
    // `x + (dt / d) (n_0 k_0 + n_1 k_1 + ...)`, the sum left to right.
    let shifted = |x: &[f64], slopes: &[Vec<f64>], combination: &Combination<4>| -> Vec<f64> {
        let factor = dt / combination.divisor();
        let combined = |i: usize| {
            let mut terms = combination.terms();
            let first = terms.next().map_or(0.0, |(j, n)| n * slopes[j][i]);
            terms.fold(first, |sum, (j, n)| sum + n * slopes[j][i])
        };
        x.iter()
            .enumerate()
            .map(|(i, a)| a + factor * combined(i))
            .collect()
    };
    let mut x = start.to_vec();
    for _ in 0..substeps {
        let mut slopes: Vec<Vec<f64>> = Vec::with_capacity(RK4.stages.len());
        for coupling in &RK4.stages {
            let estimate = match coupling.is_empty() {
                true => x.clone(),
                false => shifted(&x, &slopes, coupling),
            };
            slopes.push(rhs(&estimate));
        }
        x = shifted(&x, &slopes, &RK4.weights);
    }
    x
}

/// A piecewise-constant input: random levels in `[lo, hi]` held for a random whole number
/// of samples in `holds`.
pub fn random_steps(
    rows: usize,
    (lo, hi): (f64, f64),
    holds: (usize, usize),
    rng: &mut impl rand::Rng,
) -> Vec<f64> {
    let mut values = Vec::with_capacity(rows);
    while values.len() < rows {
        let level = rng.gen_range(lo..=hi);
        let hold = rng.gen_range(holds.0..=holds.1);
        values.extend(std::iter::repeat_n(level, hold));
    }
    values.truncate(rows);
    values
}

/// Samples a truth model every `step` with inputs held over each interval, integrating
/// with `substeps` RK4 steps per sample. Returns the state at every row.
pub fn sample_truth(
    rhs: impl Fn(&[f64], &[f64]) -> Vec<f64>,
    start: &[f64],
    inputs: &[Vec<f64>],
    step: f64,
    substeps: usize,
) -> Vec<Vec<f64>> {
    let rows = inputs.first().map_or(0, Vec::len);
    let mut states = vec![start.to_vec()];
    for row in 0..rows.saturating_sub(1) {
        let held: Vec<f64> = inputs.iter().map(|u| u[row]).collect();
        let next = rk4_reference(|x| rhs(x, &held), &states[row], step, substeps);
        states.push(next);
    }
    states
}

/// A dataset with a time column and the named columns.
pub fn dataset(step: f64, columns: Vec<(&str, Vec<f64>)>) -> crate::data::Dataset {
    let rows = columns.first().map_or(0, |c| c.1.len());
    crate::data::Dataset {
        path: std::path::PathBuf::from("memory.csv"),
        times: (0..rows).map(|i| i as f64 * step).collect(),
        step,
        columns: (columns.into_iter())
            .map(|(name, values)| crate::data::Column {
                name: name.to_string(),
                values,
            })
            .collect(),
    }
}

/// Chemostat constants (paper 3.1).
pub mod chemostat {
    use super::*;
    use rand::SeedableRng;

    /// Inlet substrate.
    pub const S0: f64 = 3e-2;
    /// Residence time.
    pub const THETA: f64 = 20.0;
    /// Turnover number.
    pub const KCAT: f64 = 0.14;
    /// Michaelis constant.
    pub const K_M: f64 = 1.5e-2;

    /// Truth right-hand side over `[S, E]` with input `[E0]`.
    pub fn rhs(state: &[f64], input: &[f64]) -> Vec<f64> {
        let (s, e) = (state[0], state[1]);
        vec![
            (S0 - s) / THETA - KCAT * e * s / (K_M + s),
            (input[0] - e) / THETA,
        ]
    }

    /// The true rate `r` of the grey-box model (`dS/dt = (S0 - S)/theta + r`).
    pub fn rate(state: &[f64]) -> f64 {
        -KCAT * state[1] * state[0] / (K_M + state[0])
    }

    /// Steady substrate at enzyme level `e`.
    pub fn steady_substrate(e: f64) -> f64 {
        let b = S0 - K_M - THETA * KCAT * e;
        (b + (b * b + 4.0 * S0 * K_M).sqrt()) / 2.0
    }

    /// Data as the paper describes: `E0` steps in `range` held 20-60 s, sampled every
    /// second from the steady state at the first level. Returns the dataset (`E0`, `S`)
    /// and the hidden enzyme level at every row.
    pub fn data(rows: usize, range: (f64, f64), seed: u64) -> (crate::data::Dataset, Vec<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let inlet = random_steps(rows, range, (20, 60), &mut rng);
        let start = [steady_substrate(inlet[0]), inlet[0]];
        let states = sample_truth(rhs, &start, std::slice::from_ref(&inlet), 1.0, 20);
        let substrate = states.iter().map(|x| x[0]).collect();
        let enzyme = states.iter().map(|x| x[1]).collect();
        (dataset(1.0, vec![("E0", inlet), ("S", substrate)]), enzyme)
    }

    /// The paper's grey-box model: `dS/dt = (S0 - S)/theta + r`, `r` learned from `S` and
    /// `E0` (delay 10 s, dim 5).
    pub fn grey_box() -> ir::Model {
        ModelBuilder::new("chemostat_gb")
            .input("E0")
            .state("S")
            .constant("S0", S0)
            .constant("theta", THETA)
            .closure(ClosureSpec {
                name: "rate",
                outputs: vec![OutputSpec {
                    name: "r",
                    scale: None,
                    prior: None,
                }],
                observe: &["S", "E0"],
                delay: 10.0,
                dim: 5,
                hidden: vec![20, 20, 20],
                activation: Activation::Softplus,
            })
            .der("S", "(S0 - S) / theta + r")
            .build()
    }

    /// The paper's black-box model: `next S = n(z_e)` with the same embedding.
    pub fn black_box() -> ir::Model {
        ModelBuilder::new("chemostat_bb")
            .input("E0")
            .state("S")
            .closure(ClosureSpec {
                name: "map",
                outputs: vec![OutputSpec {
                    name: "n",
                    scale: None,
                    prior: None,
                }],
                observe: &["S", "E0"],
                delay: 10.0,
                dim: 5,
                hidden: vec![20, 20, 20],
                activation: Activation::Softplus,
            })
            .next("S", "n")
            .build()
    }

    /// The truth with its rate law as a `let`, `kcat` a positive param starting at `kcat`.
    pub fn exact_law(kcat: f64) -> ir::Model {
        ModelBuilder::new("chemostat_exact")
            .input("E0")
            .state("S")
            .hidden("E", 0.0)
            .constant("S0", S0)
            .constant("theta", THETA)
            .constant("K_M", K_M)
            .param("kcat", kcat, Constraint::Positive)
            .define("r", "kcat * E * S / (K_M + S)")
            .der("S", "(S0 - S) / theta - r")
            .der("E", "(E0 - E) / theta")
            .build()
    }
}

/// Priors of both kinds, a scaled output, a positive and a bounded param, a hidden state,
/// a power: every path of the physics program carries gradient.
pub fn kitchen_sink(activation: Activation) -> ir::Model {
    let output = |name, scale, prior| OutputSpec { name, scale, prior };
    ModelBuilder::new("kitchen_sink")
        .input("u")
        .state("X")
        .state("S")
        .hidden("E", 0.2)
        .constant("D", 0.1)
        .param("Y", 0.5, Constraint::Positive)
        .param("k", 1.5, Constraint::Bounds(0.5, 3.0))
        .closure(ClosureSpec {
            name: "rates",
            outputs: vec![
                output("a", None, Some(("*=", "0.5 * S / (1 + S)"))),
                output("b", Some(0.3), Some(("+=", "0.1 * u * X * Y"))),
                output("c", Some(0.2), None),
            ],
            observe: &["X", "S", "u"],
            delay: 1.0,
            dim: 3,
            hidden: vec![5, 4],
            activation,
        })
        .der("X", "(a - D) * X + c")
        .der("S", "D * (2 - S) - a / Y * X + b - 0.1 * E * S ^ k")
        .der("E", "(u - E) / 2")
        .build()
}

/// A setup for engine tests: step 0.4, non-trivial normalisation (state std growing with
/// the index), closure output scale 0.7, seed 5.
pub fn setup(
    model: &ir::Model,
    precision: crate::engine::graph::Precision,
    substeps: usize,
) -> Setup {
    let measured = model.states.len();
    Setup {
        step: 0.4,
        substeps,
        precision,
        seed: 5,
        normalisation: crate::engine::graph::Normalisation {
            state_mean: vec![1.0; measured],
            state_std: (0..measured).map(|i| 0.5 + 0.3 * i as f64).collect(),
            input_mean: vec![0.5; model.inputs.len()],
            input_std: vec![0.3; model.inputs.len()],
            ..Default::default()
        },
        scales: (model.closures.iter())
            .map(|c| vec![0.7; c.outputs.len()])
            .collect(),
    }
}

/// Random states in [0.5, 2] (so that `S ^ k` is defined), inputs and embeddings.
pub fn random_batch(model: &ir::Model, setup: &Setup, rows: usize, seed: u64) -> Batch {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut uniform = |count: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..count).map(|_| rng.gen_range(lo..hi)).collect()
    };
    let states = model.states.len() + model.hidden.len();
    let offsets = setup.stage_offsets(model.dynamics);
    let embeddings = (model.closures.iter())
        .map(|c| {
            (0..offsets)
                .map(|_| uniform(rows * c.embedding.width(), 0.5, 2.0))
                .collect()
        })
        .collect();
    Batch {
        rows,
        states: uniform(rows * states, 0.5, 2.0),
        inputs: uniform(rows * model.inputs.len(), 0.0, 1.0),
        embeddings,
        targets: uniform(rows * model.states.len(), 0.5, 2.0),
        ..Batch::default()
    }
}

/// The complete record of `model`'s columns in `data` (a missing column panics: fixtures).
pub fn record(model: &ir::Model, data: &crate::data::Dataset) -> crate::record::Record {
    let column = |name: &str| {
        data.column(name)
            .unwrap_or_else(|| panic!("fixture data without column `{name}`"))
            .to_vec()
    };
    let name = data.path.display().to_string();
    let mut record = crate::record::Record::complete(
        &name,
        data.times.clone(),
        model.inputs.iter().map(|i| column(&i.name)).collect(),
        model.states.iter().map(|s| column(&s.name)).collect(),
    );
    record.source = name;
    record
}

/// The record of `data` laid on its own uniform grid (gap limits: the model's delays).
pub fn track(model: &ir::Model, data: &crate::data::Dataset) -> crate::record::Track {
    let record = record(model, data);
    let step = record.uniform_step().unwrap();
    let grid = crate::record::grid::grid_for(model, step);
    crate::record::Track::lay(&record, &grid, &[])
}

/// Normalisation over the first `rows` rows of a complete record.
pub fn normalise(
    record: &crate::record::Record,
    rows: usize,
) -> crate::engine::graph::Normalisation {
    crate::record::Normalisation::over(
        &[(record, 0..rows.min(record.len()))],
        record.states.len(),
        record.inputs.len(),
    )
}
