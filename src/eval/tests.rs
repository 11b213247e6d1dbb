//! Compiled programs against the reference interpreter, and the scalar functions against
//! their textbook definitions.

use super::*;
use crate::ir::{
    Balance, BinOp, Closure, ClosureOutput, Const, Constraint, Dynamics, Embedding, Expr, Func,
    Input, Model, Network, Param, State, Var,
};
use proptest::prelude::*;

fn state(name: &str) -> State {
    State {
        name: name.to_string(),
        init: None,
        nonnegative: false,
    }
}

/// A model with two of every kind of quantity (one hidden state) and no meaningful
/// equations: only its layout matters here.
fn small_model() -> Model {
    let output = |name: &str| ClosureOutput {
        name: name.to_string(),
        scale: None,
        prior: None,
        constraint: Constraint::Free,
    };
    Model {
        name: "small".into(),
        description: None,
        time_unit: None,
        inputs: vec![
            Input {
                name: "u".into(),
                bounds: None,
            },
            Input {
                name: "v".into(),
                bounds: None,
            },
        ],
        states: vec![state("x"), state("y")],
        hidden: vec![state("h")],
        consts: vec![
            Const {
                name: "a".into(),
                value: 1.5,
            },
            Const {
                name: "b".into(),
                value: -0.25,
            },
        ],
        params: vec![Param {
            name: "k".into(),
            init: 2.0,
            constraint: Constraint::Positive,
        }],
        lets: vec![],
        outputs: vec![],
        closures: vec![Closure {
            name: "c".into(),
            outputs: vec![output("r"), output("q")],
            embedding: Embedding {
                observe: vec![Var::State(0)],
                delay: 1.0,
                dim: 1,
            },
            network: Network {
                hidden: vec![4],
                activation: crate::ir::Activation::Tanh,
            },
        }],
        dynamics: Dynamics::Continuous,
        balances: vec![],
        effects: vec![],
        units: Default::default(),
        noise: vec![],
    }
}

fn all_vars() -> Vec<Var> {
    vec![
        Var::Input(0),
        Var::Input(1),
        Var::State(0),
        Var::State(1),
        Var::Hidden(0),
        Var::Const(0),
        Var::Const(1),
        Var::Param(0),
        Var::ClosureOutput {
            closure: 0,
            output: 0,
        },
        Var::ClosureOutput {
            closure: 0,
            output: 1,
        },
    ]
}

fn bin(op: BinOp, a: Expr, b: Expr) -> Expr {
    Expr::Bin(op, Box::new(a), Box::new(b))
}

fn var(v: Var) -> Expr {
    Expr::Var(v)
}

fn arb_expr() -> impl Strategy<Value = Expr> {
    let vars = all_vars();
    let leaf = prop_oneof![
        (-3.0..3.0f64).prop_map(Expr::Num),
        Just(Expr::Num(2.0)),
        (0..vars.len()).prop_map(move |k| Expr::Var(vars[k])),
    ];
    leaf.prop_recursive(6, 48, 2, |inner| {
        let ops = [BinOp::Add, BinOp::Sub, BinOp::Mul, BinOp::Div, BinOp::Pow];
        prop_oneof![
            inner.clone().prop_map(|e| Expr::Neg(Box::new(e))),
            (0..ops.len(), inner.clone(), inner.clone())
                .prop_map(move |(k, a, b)| bin(ops[k], a, b)),
            (0..Func::ALL.len(), inner.clone(), inner).prop_map(|(k, a, b)| {
                let func = Func::ALL[k];
                let args = if func.arity() == 2 {
                    vec![a, b]
                } else {
                    vec![a]
                };
                Expr::Call(func, args)
            }),
        ]
    })
}

/// Equal bits, both NaN, or within a few ulps (`x ^ 2` compiles to `x * x`).
fn agrees(compiled: f64, reference: f64) -> bool {
    if compiled.is_nan() || reference.is_nan() {
        return compiled.is_nan() && reference.is_nan();
    }
    compiled == reference || (compiled - reference).abs() <= 1e-12 * reference.abs()
}

fn random_slots(layout: &Layout, values: &[f64]) -> Vec<f64> {
    let mut slots = layout.initial_slots();
    for var in all_vars() {
        if !matches!(var, Var::Const(_)) {
            slots[layout.slot(var)] = values[layout.slot(var)];
        }
    }
    slots
}

fn reference(expr: &Expr, layout: &Layout, slots: &[f64]) -> f64 {
    interpret(expr, &|v| slots[layout.slot(v)])
}

proptest! {
    #[test]
    fn program_matches_interpreter(
        expr in arb_expr(),
        values in prop::collection::vec(-4.0..4.0f64, 10),
    ) {
        let model = small_model();
        let layout = Layout::new(&model);
        let slots = random_slots(&layout, &values);
        let program = Program::compile(&expr, &layout).unwrap();
        let mut scratch = Vec::new();
        let compiled = program.eval(&slots, &mut scratch);
        let expected = reference(&expr, &layout, &slots);
        prop_assert!(agrees(compiled, expected), "{compiled} vs {expected} for {expr:?}");
        // A second evaluation with a dirty scratch gives the same value.
        prop_assert_eq!(program.eval(&slots, &mut scratch).to_bits(), compiled.to_bits());
    }

    #[test]
    fn program_set_matches_interpreter(
        exprs in prop::collection::vec(arb_expr(), 1..5),
        values in prop::collection::vec(-4.0..4.0f64, 10),
    ) {
        let layout = Layout::new(&small_model());
        let slots = random_slots(&layout, &values);
        let set = ProgramSet::compile(&exprs, &layout).unwrap();
        let mut out = vec![0.0; exprs.len()];
        set.eval_into(&slots, &mut Vec::new(), &mut out);
        for (expr, compiled) in exprs.iter().zip(&out) {
            let expected = reference(expr, &layout, &slots);
            prop_assert!(agrees(*compiled, expected), "{compiled} vs {expected} for {expr:?}");
        }
    }
}

#[test]
fn layout_gives_every_var_its_own_slot() {
    let layout = Layout::new(&small_model());
    let mut slots: Vec<usize> = all_vars().into_iter().map(|v| layout.slot(v)).collect();
    slots.sort_unstable();
    assert_eq!(slots, (0..10).collect::<Vec<_>>());
    assert_eq!(layout.len(), 10);
    assert_eq!(layout.state_range(), 2..5);
    assert_eq!(layout.slot(Var::Hidden(0)), 4);
    assert!(!layout.contains(Var::State(2)));
    assert!(!layout.contains(Var::ClosureOutput {
        closure: 0,
        output: 2
    }));
    let initial = layout.initial_slots();
    assert_eq!(initial[layout.slot(Var::Const(0))], 1.5);
    assert_eq!(initial[layout.slot(Var::Const(1))], -0.25);
    assert_eq!(initial[layout.slot(Var::Param(0))], 2.0);
    assert_eq!(initial[layout.slot(Var::State(0))], 0.0);
}

#[test]
fn literals_and_consts_fold_and_subexpressions_are_shared() {
    let layout = Layout::new(&small_model());
    let folded = bin(
        BinOp::Mul,
        var(Var::Const(0)),
        Expr::Call(Func::Exp, vec![Expr::Num(0.0)]),
    );
    let program = Program::compile(&folded, &layout).unwrap();
    assert_eq!(program.as_constant(), Some(1.5));
    assert_eq!(program.instruction_count(), 0);

    let shared = || {
        Expr::Call(
            Func::Exp,
            vec![bin(BinOp::Mul, var(Var::Param(0)), var(Var::State(0)))],
        )
    };
    let twice = bin(BinOp::Add, shared(), shared());
    let program = Program::compile(&twice, &layout).unwrap();
    assert_eq!(program.instruction_count(), 3);
    let mut slots = layout.initial_slots();
    slots[layout.slot(Var::State(0))] = 0.5;
    assert_eq!(program.eval(&slots, &mut Vec::new()), 2.0 * 1.0f64.exp());
}

#[test]
fn unknown_variable_is_an_error() {
    let layout = Layout::new(&small_model());
    let error = Program::compile(&var(Var::Param(3)), &layout).unwrap_err();
    assert_eq!(error, CompileError::UnknownVar(Var::Param(3)));
}

#[test]
fn rhs_is_ordered_by_state_whatever_the_balance_order() {
    let mut model = small_model();
    let balance = |state: Var, value: f64| Balance {
        state,
        expr: bin(BinOp::Mul, Expr::Num(value), var(state)),
    };
    model.balances = vec![
        balance(Var::Hidden(0), 3.0),
        balance(Var::State(1), 2.0),
        balance(Var::State(0), 1.0),
    ];
    let layout = Layout::new(&model);
    let rhs = CompiledRhs::new(&model, &layout).unwrap();
    let mut slots = layout.initial_slots();
    slots[layout.state_range()].copy_from_slice(&[10.0, 20.0, 30.0]);
    let mut out = [0.0; 3];
    rhs.eval(&slots, &mut Vec::new(), &mut out);
    assert_eq!(out, [10.0, 40.0, 90.0]);

    model.balances.pop();
    assert_eq!(
        CompiledRhs::new(&model, &layout).unwrap_err(),
        CompileError::Balances
    );
}

#[test]
fn softplus_is_accurate_and_finite_everywhere() {
    for x in [-30.0, -3.0, -0.5, 0.0, 0.7, 4.0, 30.0] {
        let naive = (1.0 + f64::exp(x)).ln();
        assert!(
            (softplus(x) - naive).abs() <= 1e-14 * naive.max(1.0),
            "x = {x}"
        );
    }
    assert_eq!(softplus(1000.0), 1000.0);
    let tiny = softplus(-700.0);
    assert!((tiny / f64::exp(-700.0) - 1.0).abs() < 1e-14);
    assert_eq!(softplus(-1e6), 0.0);
}

#[test]
fn sigmoid_is_accurate_and_finite_everywhere() {
    for x in [-30.0, -3.0, -0.5, 0.0, 0.7, 4.0, 30.0] {
        let naive = 1.0 / (1.0 + f64::exp(-x));
        assert!((sigmoid(x) - naive).abs() <= 1e-15, "x = {x}");
    }
    assert_eq!(sigmoid(1000.0), 1.0);
    assert!((sigmoid(-700.0) / f64::exp(-700.0) - 1.0).abs() < 1e-14);
    assert_eq!(sigmoid(-1e6), 0.0);
    assert!((sigmoid(2.0) + sigmoid(-2.0) - 1.0).abs() <= f64::EPSILON);
}

/// The central difference of `expr` in slot `slot` with step `h`.
fn central(expr: &Expr, layout: &Layout, slots: &[f64], slot: usize, h: f64) -> f64 {
    let mut moved = slots.to_vec();
    moved[slot] += h;
    let up = reference(expr, layout, &moved);
    moved[slot] -= 2.0 * h;
    let down = reference(expr, layout, &moved);
    (up - down) / (2.0 * h)
}

/// A one-sided difference of `expr` in slot `slot` with signed step `h`, extrapolated to
/// second order (`2 D(h/2) - D(h)`).
fn one_sided(expr: &Expr, layout: &Layout, slots: &[f64], slot: usize, h: f64) -> f64 {
    let at = |shift: f64| {
        let mut moved = slots.to_vec();
        moved[slot] += shift;
        reference(expr, layout, &moved)
    };
    let base = at(0.0);
    let coarse = (at(h) - base) / h;
    let fine = (at(h / 2.0) - base) / (h / 2.0);
    2.0 * fine - coarse
}

/// The derivative by Richardson-extrapolated central differences, where two step sizes
/// and both one-sided differences agree (a smooth neighbourhood); `None` near a kink, a
/// pole or a non-finite value.
fn smooth_difference(expr: &Expr, layout: &Layout, slots: &[f64], slot: usize) -> Option<f64> {
    let h = 1e-4 * slots[slot].abs().max(1.0);
    let coarse = central(expr, layout, slots, slot, h);
    let fine = central(expr, layout, slots, slot, h / 2.0);
    let extrapolated = (4.0 * fine - coarse) / 3.0;
    let finer = central(expr, layout, slots, slot, h / 4.0);
    let check = (4.0 * finer - fine) / 3.0;
    let forward = one_sided(expr, layout, slots, slot, h);
    let backward = one_sided(expr, layout, slots, slot, -h);
    let scale = extrapolated.abs().max(1.0);
    let smooth =
        (extrapolated - check).abs() < 1e-7 * scale && (forward - backward).abs() < 1e-4 * scale;
    (extrapolated.is_finite() && smooth).then_some(extrapolated)
}

/// Whether every subexpression of `expr` is finite at `slots` (where an intermediate is
/// NaN or infinite, `min`/`max` may still give a finite value, but no derivative exists).
fn finite_throughout(expr: &Expr, layout: &Layout, slots: &[f64]) -> bool {
    let children: Vec<&Expr> = match expr {
        Expr::Num(_) | Expr::Var(_) => Vec::new(),
        Expr::Neg(inner) => vec![inner],
        Expr::Bin(_, a, b) => vec![a, b],
        Expr::Call(_, args) => args.iter().collect(),
    };
    reference(expr, layout, slots).is_finite()
        && children.iter().all(|c| finite_throughout(c, layout, slots))
}

proptest! {
    #[test]
    fn derivatives_match_finite_differences(
        exprs in prop::collection::vec(arb_expr(), 1..4),
        values in prop::collection::vec(-4.0..4.0f64, 10),
    ) {
        let layout = Layout::new(&small_model());
        let slots = random_slots(&layout, &values);
        let wrt: Vec<usize> = [Var::State(0), Var::Hidden(0), Var::Param(0), Var::Input(1)]
            .iter()
            .map(|&v| layout.slot(v))
            .collect();
        let program = JacobianProgram::compile(&exprs, &layout, &wrt).unwrap();
        let (mut values_out, mut jacobian) = (vec![0.0; exprs.len()], vec![f64::NAN; exprs.len() * wrt.len()]);
        program.eval(&slots, &mut Vec::new(), &mut values_out, &mut jacobian);
        for (row, expr) in exprs.iter().enumerate() {
            let expected = reference(expr, &layout, &slots);
            prop_assert!(agrees(values_out[row], expected), "value {expr:?}");
            if !finite_throughout(expr, &layout, &slots) {
                continue;
            }
            for (column, &slot) in wrt.iter().enumerate() {
                let exact = jacobian[row * wrt.len() + column];
                if let Some(numeric) = smooth_difference(expr, &layout, &slots, slot) {
                    let scale = numeric.abs().max(1.0);
                    prop_assert!(
                        (exact - numeric).abs() < 1e-6 * scale,
                        "d/d{column} of {expr:?}: exact {exact} vs {numeric}"
                    );
                }
            }
        }
    }
}

#[test]
fn derivatives_are_sparse_and_exact_on_a_rate_law() {
    use crate::ir::Var::{Param, State};
    let layout = Layout::new(&small_model());
    // mu = k x / (a + x): depends on x and k only.
    let x = var(State(0));
    let rate = bin(
        BinOp::Div,
        bin(BinOp::Mul, var(Param(0)), x.clone()),
        bin(BinOp::Add, var(Var::Const(0)), x),
    );
    let wrt: Vec<usize> = [State(0), State(1), Param(0)]
        .iter()
        .map(|&v| layout.slot(v))
        .collect();
    let program = JacobianProgram::compile([&rate], &layout, &wrt).unwrap();
    assert_eq!(program.nonzeros(), 2, "d/dy is structurally zero");
    let mut slots = layout.initial_slots();
    slots[layout.slot(State(0))] = 0.8;
    let (mut value, mut jacobian) = ([0.0], [f64::NAN; 3]);
    program.eval(&slots, &mut Vec::new(), &mut value, &mut jacobian);
    let (k, a, s) = (2.0, 1.5, 0.8);
    assert!((value[0] - k * s / (a + s)).abs() < 1e-15);
    assert!((jacobian[0] - k * a / (a + s).powi(2)).abs() < 1e-14);
    assert_eq!(jacobian[1], 0.0);
    assert!((jacobian[2] - s / (a + s)).abs() < 1e-15);
}

#[test]
fn an_infinite_slope_over_an_inner_function_that_does_not_move_gives_zero() {
    // sqrt(2 - min(2, x)): above x = 2 the inner function is 0 and flat, so the function
    // is flat (0), though sqrt's slope there is infinite; below, the chain rule holds.
    let layout = Layout::new(&small_model());
    let x = var(Var::State(0));
    let inner = bin(
        BinOp::Sub,
        Expr::Num(2.0),
        Expr::Call(Func::Min, vec![Expr::Num(2.0), x]),
    );
    let expr = Expr::Call(Func::Sqrt, vec![inner]);
    let wrt = [layout.slot(Var::State(0))];
    let program = JacobianProgram::compile([&expr], &layout, &wrt).unwrap();
    let mut slots = layout.initial_slots();
    for (at, want) in [(3.0, 0.0), (1.0, -0.5)] {
        slots[layout.slot(Var::State(0))] = at;
        let mut jacobian = [f64::NAN];
        program.eval(&slots, &mut Vec::new(), &mut [0.0], &mut jacobian);
        // d/dx sqrt(2 - x) = -1 / (2 sqrt(2 - x)) = -0.5 at x = 1.
        assert!(
            (jacobian[0] - want).abs() < 1e-15,
            "at {at}: {}",
            jacobian[0]
        );
    }
}

#[test]
fn kinks_take_their_one_sided_derivative() {
    let layout = Layout::new(&small_model());
    let x = var(Var::State(0));
    let exprs = [
        Expr::Call(Func::Abs, vec![x.clone()]),
        Expr::Call(Func::Min, vec![x.clone(), Expr::Num(0.0)]),
        Expr::Call(Func::Max, vec![x, Expr::Num(0.0)]),
    ];
    let wrt = [layout.slot(Var::State(0))];
    let program = JacobianProgram::compile(&exprs, &layout, &wrt).unwrap();
    let mut slots = layout.initial_slots();
    let mut jacobian = [f64::NAN; 3];
    for (x, want) in [
        (-2.0, [-1.0, 1.0, 0.0]),
        (0.0, [0.0, 1.0, 1.0]),
        (3.0, [1.0, 0.0, 1.0]),
    ] {
        slots[layout.slot(Var::State(0))] = x;
        program.eval(&slots, &mut Vec::new(), &mut [0.0; 3], &mut jacobian);
        assert_eq!(jacobian, want, "at {x}");
    }
}
