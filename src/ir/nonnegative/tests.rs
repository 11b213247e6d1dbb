//! The non-negativity check: the forms it proves, the terms it refuses (code, span, help),
//! effects, and the soundness of the sign analysis against evaluation at random points.

use super::*;
use crate::ir::{lower_reporting, LowerError, Model};
use miette::Diagnostic;
use proptest::prelude::*;

fn checked(source: &str) -> crate::check::Checked {
    let ast = crate::syntax::parse(source).expect("parses");
    crate::check::check(ast).expect("checks")
}

fn lowered(source: &str) -> Result<Model, Vec<LowerError>> {
    lower_reporting(&checked(source), &[])
}

/// A chemostat on one substrate: `S` is declared `nonnegative`; `closure`, `uptake` and
/// `extra` complete it.
fn chemostat(closure: &str, uptake: &str, extra: &str) -> String {
    format!(
        "model m\ninput D in [0, 0.3]\nstate X nonnegative, S = 1 nonnegative\nconst S_in = 10\n\
         param K = 0.5 positive\nclosure c {{\n{closure}\n  observe X, S\n}}\n\
         der X = (mu - D) * X\nder S = D * (S_in - S) - {uptake}\n{extra}"
    )
}

/// The E0136 errors of `source`, as (term text, label, help).
fn refused(source: &str) -> Vec<(String, String, String)> {
    let errors = lowered(source).expect_err("refused");
    errors
        .iter()
        .map(|error| {
            assert_eq!(
                error.code().map(|c| c.to_string()).as_deref(),
                Some("gbm::E0136")
            );
            let label = error.labels().and_then(|mut l| l.next()).expect("a label");
            let text = source[label.offset()..label.offset() + label.len()].to_string();
            let why = label.label().unwrap_or_default().to_string();
            (
                text,
                why,
                error.help().map(|h| h.to_string()).unwrap_or_default(),
            )
        })
        .collect()
}

#[test]
fn first_order_and_vanishing_forms_pass() {
    let passing = [
        // A rate times its substrate.
        ("  outputs mu ~ 0.1 positive, k ~ 0.1 positive", "k * S * X"),
        // Monod in S with a positive constant.
        (
            "  outputs mu ~ 0.1 positive, k ~ 0.1 positive",
            "k * X * S / (K + S)",
        ),
        // A power of S.
        (
            "  outputs mu ~ 0.1 positive, k ~ 0.1",
            "k * S^2 * X + k * sqrt(S) ^ 3 * X",
        ),
        // A free output under a `*=` prior that vanishes at S = 0.
        (
            "  outputs mu ~ 0.1 positive, q ~ 0.1\n  prior q *= S / (K + S)",
            "q * X",
        ),
        // A positive one under such a prior, through exp and a bounded input.
        (
            "  outputs mu ~ 0.1 positive, q ~ 0.1 positive\n  prior q *= exp(-X) * S * (1 + D)",
            "q * X",
        ),
    ];
    for (closure, uptake) in passing {
        let source = chemostat(closure, uptake, "");
        assert!(lowered(&source).is_ok(), "{source}");
    }
}

/// A probe lowered unguarded (the diagnosis's free corrections) is the very model the
/// guard refuses: the same balances, only the E0136 verdict dropped; other errors still stop.
#[test]
fn a_probe_lowered_unguarded_is_the_model_the_guard_refuses() {
    let source = chemostat("  outputs mu ~ 0.1 positive, q ~ 0.1", "q * X", "");
    let refused = refused(&source);
    assert_eq!(refused.len(), 1);
    let probe = crate::ir::lower_unguarded(&checked(&source), &[]).expect("lowers");
    // At S = 0, X = 2, D = 0.1 and q = 0.5: dS/dt = 0.1 * 10 - 0.5 * 2 = 0, and with
    // D = 0 it is -1: the learned consumption the guard refuses, kept as written.
    let value = |d: f64| {
        move |var: Var| match var {
            Var::Input(0) => d,
            Var::State(0) => 2.0,
            Var::State(1) => 0.0,
            Var::Const(0) => 10.0,
            Var::ClosureOutput { output: 1, .. } => 0.5,
            _ => 0.3,
        }
    };
    let balance = &probe.balances[1].expr;
    assert!(crate::eval::interpret(balance, &value(0.1)).abs() < 1e-12);
    assert!((crate::eval::interpret(balance, &value(0.0)) + 1.0).abs() < 1e-12);
    let unknown = crate::ir::lower_unguarded(&checked(&source), &["nowhere"]);
    assert!(matches!(
        unknown.as_ref().map_err(Vec::as_slice),
        Err([LowerError::UnknownEffect { .. }])
    ));
}

#[test]
fn a_learned_consumption_without_a_prior_is_refused_at_its_term() {
    let source = chemostat("  outputs mu ~ 0.1 positive, q ~ 0.1", "q * X", "");
    let errors = refused(&source);
    assert_eq!(errors.len(), 1, "{errors:?}");
    let (text, why, help) = &errors[0];
    assert_eq!(text, "q * X");
    assert!(
        why.contains("subtracted") && why.contains("`S = 0`"),
        "{why}"
    );
    assert!(
        help.contains("- k * S * X") && help.contains("`q`"),
        "{help}"
    );
    // `positive` alone does not vanish at S = 0 either.
    let positive = chemostat("  outputs mu ~ 0.1 positive, q ~ 0.1 positive", "q * X", "");
    assert_eq!(refused(&positive).len(), 1);
    // Nor does a prior that is not zero there.
    let prior = "  outputs mu ~ 0.1 positive, q ~ 0.1 positive\n  prior q *= 1 + S";
    assert_eq!(refused(&chemostat(prior, "q * X", "")).len(), 1);
    // An additive positive prior keeps the output >= 0 but not 0.
    let added = "  outputs mu ~ 0.1 positive, q ~ 0.1 positive\n  prior q += S";
    assert_eq!(refused(&chemostat(added, "q * X", "")).len(), 1);
}

#[test]
fn terms_are_split_through_lets_and_only_the_learned_bad_one_is_reported() {
    let closure = "  outputs mu ~ 0.1 positive, k ~ 0.1 positive, q ~ 0.1";
    let extra = "let uptake = k * S * X + 0.2 * X + q * X\n";
    let errors = refused(&chemostat(closure, "uptake", extra));
    let texts: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
    // `0.2 * X` is the modeller's own mechanism: not judged.
    assert_eq!(texts, ["q * X"]);
}

#[test]
fn a_production_term_must_be_nonnegative_and_its_factors_declared() {
    let model = |x: &str| {
        format!(
            "model m\nstate X {x}, A nonnegative\nclosure c {{\n  outputs mu ~ 0.1 positive, \
             r ~ 0.1\n  observe X, A\n}}\nder X = -X\nder A = mu * X - 0.1 * A + r\n"
        )
    };
    // `mu * X` needs `X >= 0`; `r` is free.
    let errors = refused(&model(""));
    let texts: Vec<&str> = errors.iter().map(|e| e.0.as_str()).collect();
    assert_eq!(texts, ["mu * X", "r"]);
    assert!(
        errors[1].2.contains("declare `r` `positive`"),
        "{}",
        errors[1].2
    );
    let errors = refused(&model("nonnegative"));
    assert_eq!(errors.len(), 1);
    assert_eq!(errors[0].0, "r");
}

#[test]
fn a_possible_division_by_zero_is_not_proven() {
    let closure = "  outputs mu ~ 0.1 positive, k ~ 0.1 positive";
    let errors = refused(&chemostat(closure, "k * S * X / X", ""));
    assert!(errors[0].1.contains("not be finite"), "{:?}", errors[0]);
}

#[test]
fn states_not_declared_and_mechanistic_terms_are_not_judged() {
    let free = "model m\nstate S\nclosure c {\n  outputs q ~ 0.1\n}\nder S = -q\n";
    assert!(lowered(free).is_ok());
    let mechanism = "model m\nstate S nonnegative, X\nparam k = 1 positive\nclosure c {\n  \
                     outputs r ~ 0.1\n}\nder S = -k * X\nder X = r\n";
    assert!(lowered(mechanism).is_ok());
}

#[test]
fn an_effect_that_adds_a_bad_term_is_refused_when_checked_and_when_applied() {
    let closure = "  outputs mu ~ 0.1 positive, k ~ 0.1 positive, q ~ 0.1";
    let extra = "effect leak \"a learned loss\" {\n  der S += -q * X\n}\n\
                 effect fine \"first order\" {\n  uptake += q * 0 + k * S * X\n}\n\
                 let uptake = k * S * X\n";
    let source = chemostat(closure, "uptake", extra);
    assert!(lowered(&source).is_ok());
    let model = checked(&source);
    let errors = lower_reporting(&model, &["leak"]).expect_err("refused");
    assert_eq!(errors.len(), 1);
    assert!(
        errors[0].to_string().contains("with effect `leak` applied"),
        "{}",
        errors[0]
    );
    assert!(lower_reporting(&model, &["fine"]).is_ok());
    // `gbc check` (no effect applied) tries each effect alone.
    let reports = crate::driver::compile("m.gbm", &source, &[]).expect_err("refused");
    assert_eq!(reports.len(), 1);
    assert!(format!("{:?}", reports[0]).contains("E0136"));
}

#[test]
fn a_learned_term_through_a_patched_let_is_judged() {
    let closure = "  outputs mu ~ 0.1 positive, q ~ 0.1";
    let extra = "let uptake = 0.1 * S * X\neffect e \"\" {\n  uptake += q * X\n}\n";
    let model = checked(&chemostat(closure, "uptake", extra));
    assert!(lower_reporting(&model, &[]).is_ok());
    let errors = lower_reporting(&model, &["e"]).expect_err("refused");
    assert_eq!(errors.len(), 1);
}

#[test]
fn hidden_states_and_next_models() {
    let hidden = "model m\ninput u in [0, 1]\nstate X\nhidden E = 0 nonnegative\nclosure c {\n  \
                  outputs g ~ 0.1 positive\n  prior g *= E\n}\nder X = -X + E\n\
                  der E = u - g\n";
    assert!(lowered(hidden).is_ok());
    let next = |sign: &str| {
        format!(
            "model m\nstate S nonnegative\nclosure c {{\n  outputs q ~ 0.1 positive\n}}\n\
             next S = 0.9 * S {sign} q\n"
        )
    };
    assert!(lowered(&next("+")).is_ok());
    let errors = refused(&next("-"));
    assert!(errors[0].2.contains("`next` model"), "{:?}", errors[0]);
}

// ---------------------------------------------------------------- soundness

/// Quantities of every sign class the analysis distinguishes, with `Z` the state at zero.
const SOUNDNESS_MODEL: &str = "model p\ninput u in [0, 1], w in [-1, 1]\n\
    state Z, P nonnegative, F\nconst c = 2, m = -3, z0 = 0\nparam k = 1 positive, f = 0.5\n\
    closure net {\n  outputs a ~ 1, b ~ 1 positive\n  observe u\n}\n\
    der Z = a + b\nder P = -P\nder F = -F\n";

fn leaf() -> impl Strategy<Value = Expr> {
    let vars = [
        Var::Input(0),
        Var::Input(1),
        Var::State(0),
        Var::State(1),
        Var::State(2),
        Var::Const(0),
        Var::Const(1),
        Var::Const(2),
        Var::Param(0),
        Var::Param(1),
        Var::ClosureOutput {
            closure: 0,
            output: 0,
        },
        Var::ClosureOutput {
            closure: 0,
            output: 1,
        },
    ];
    prop_oneof![
        prop::sample::select(vars.to_vec()).prop_map(Expr::Var),
        prop::sample::select(vec![0.0, 0.5, 1.0, 2.0, -1.0]).prop_map(Expr::Num),
    ]
}

fn expr() -> impl Strategy<Value = Expr> {
    leaf().prop_recursive(3, 24, 2, |inner| {
        let binary = [BinOp::Add, BinOp::Sub, BinOp::Mul, BinOp::Div, BinOp::Pow];
        let exponent = prop::sample::select(vec![0.0, 0.5, 2.0, 3.0, -1.0, 1.5]);
        prop_oneof![
            (
                prop::sample::select(binary.to_vec()),
                inner.clone(),
                inner.clone()
            )
                .prop_map(|(op, a, b)| Expr::Bin(op, Box::new(a), Box::new(b))),
            (inner.clone(), exponent).prop_map(|(a, c)| Expr::Bin(
                BinOp::Pow,
                Box::new(a),
                Box::new(Expr::Num(c))
            )),
            inner.clone().prop_map(|a| Expr::Neg(Box::new(a))),
            (
                prop::sample::select(Func::ALL.to_vec()),
                inner.clone(),
                inner
            )
                .prop_map(|(f, a, b)| match f.arity() {
                    1 => Expr::Call(f, vec![a]),
                    _ => Expr::Call(f, vec![a, b]),
                }),
        ]
    })
}

/// A value of each variable consistent with its declaration (`Z` is 0), from `draws`.
fn point(draws: &[f64; 9]) -> impl Fn(Var) -> f64 + '_ {
    // Half of the draws of a non-negative quantity are exactly 0.
    let nonnegative = |d: f64| if d < 0.5 { 0.0 } else { 6.0 * (d - 0.5) };
    let positive = |d: f64| 1e-3 + 3.0 * d;
    let any = |d: f64| {
        if (0.45..0.55).contains(&d) {
            0.0
        } else {
            6.0 * d - 3.0
        }
    };
    move |var| match var {
        Var::Input(0) => nonnegative(draws[0]).min(1.0),
        Var::Input(_) => any(draws[1]) / 3.0,
        Var::State(0) => 0.0,
        Var::State(1) => nonnegative(draws[2]),
        Var::State(_) => any(draws[3]),
        Var::Const(0) => 2.0,
        Var::Const(1) => -3.0,
        Var::Const(_) => 0.0,
        Var::Param(0) => positive(draws[4]),
        Var::Param(_) => any(draws[5]),
        Var::ClosureOutput { output: 0, .. } => any(draws[6]),
        Var::ClosureOutput { .. } => positive(draws[7]),
        Var::Hidden(_) => draws[8],
    }
}

/// The value of `expr`, or `None` where an operation on finite values overflowed (the
/// analysis assumes finite intermediate values, as the models it judges do).
fn evaluate(expr: &Expr, value: &dyn Fn(Var) -> f64) -> Option<f64> {
    let result = |inputs: &[f64], out: f64, legit: bool| {
        let overflow = out.is_infinite() && inputs.iter().all(|v| v.is_finite()) && !legit;
        (!overflow).then_some(out)
    };
    match expr {
        Expr::Num(v) => Some(*v),
        Expr::Var(var) => Some(value(*var)),
        Expr::Neg(a) => Some(-evaluate(a, value)?),
        Expr::Bin(op, a, b) => {
            let (x, y) = (evaluate(a, value)?, evaluate(b, value)?);
            let legit = match op {
                BinOp::Div => y == 0.0,
                BinOp::Pow => x == 0.0 && y < 0.0,
                _ => false,
            };
            result(&[x, y], op.apply(x, y), legit)
        }
        Expr::Call(func, args) => {
            let values: Option<Vec<f64>> = args.iter().map(|a| evaluate(a, value)).collect();
            let values = values?;
            let (x, y) = (values[0], values.get(1).copied().unwrap_or(0.0));
            let legit = match func {
                Func::Log => x == 0.0,
                Func::Pow => x == 0.0 && y < 0.0,
                _ => false,
            };
            result(&values, func.apply(x, y), legit)
        }
    }
}

fn admits(signs: Signs, value: f64) -> bool {
    if value.is_nan() {
        return !signs.is_finite();
    }
    let sign = if value > 0.0 {
        Signs::POSITIVE
    } else if value < 0.0 {
        Signs::POSITIVE.negate()
    } else {
        Signs::ZERO
    };
    if value.is_infinite() {
        return !signs.is_finite();
    }
    signs.0 & sign.0 != 0
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    #[test]
    fn the_signs_found_contain_every_value_taken(
        expr in expr(),
        draws in prop::collection::vec(prop::array::uniform9(0.0f64..1.0), 40),
    ) {
        let model = lowered(SOUNDNESS_MODEL).expect("lowers");
        let signs = super::signs(&model, Some(Var::State(0)), &expr);
        for draw in &draws {
            let value = point(draw);
            if let Some(v) = evaluate(&expr, &value) {
                prop_assert!(admits(signs, v), "{} = {v} outside {signs:?} at {draw:?}",
                    crate::ir::expr_text(&model, &expr));
            }
        }
    }
}
