//! Parser properties: printed expressions re-parse to the same tree, precedence is right,
//! doc comments attach, and hostile input ends in a diagnostic, never a panic.

use crate::ast::{BinOp, Expr, SExpr, Span, Spanned};
use crate::syntax::{parse, parse_expr, SyntaxError};
use proptest::prelude::*;

/// Removes spans so trees from different texts compare by structure.
fn strip(expr: &SExpr) -> SExpr {
    let node = match &expr.node {
        Expr::Num(v) => Expr::Num(*v),
        Expr::Name(n) => Expr::Name(n.clone()),
        Expr::Neg(inner) => Expr::Neg(Box::new(strip(inner))),
        Expr::Binary(op, a, b) => Expr::Binary(*op, Box::new(strip(a)), Box::new(strip(b))),
        Expr::Call(f, args) => Expr::Call(
            Spanned::new(f.node.clone(), Span::default()),
            args.iter().map(strip).collect(),
        ),
    };
    Spanned::new(node, Span::default())
}

fn shape(text: &str) -> String {
    // A fully parenthesised rendering that makes the tree's grouping visible.
    fn go(e: &SExpr) -> String {
        match &e.node {
            Expr::Num(v) => format!("{v}"),
            Expr::Name(n) => n.clone(),
            Expr::Neg(i) => format!("(-{})", go(i)),
            Expr::Binary(op, a, b) => format!("({} {} {})", go(a), op.symbol(), go(b)),
            Expr::Call(f, args) => format!(
                "{}({})",
                f.node,
                args.iter().map(go).collect::<Vec<_>>().join(", ")
            ),
        }
    }
    go(&parse_expr(text).expect("parses"))
}

#[test]
fn precedence_and_associativity() {
    let cases = [
        ("1 + 2 * 3", "(1 + (2 * 3))"),
        ("1 - 2 - 3", "((1 - 2) - 3)"),
        ("8 / 4 / 2", "((8 / 4) / 2)"),
        ("2 ^ 3 ^ 2", "(2 ^ (3 ^ 2))"),
        ("-x ^ 2", "(-(x ^ 2))"),
        ("(-x) ^ 2", "((-x) ^ 2)"),
        ("a * -b", "(a * (-b))"),
        ("2 ^ -x", "(2 ^ (-x))"),
        (
            "max(a, b + 1) * exp(-A/7 - B/7)",
            "(max(a, (b + 1)) * exp((((-A) / 7) - (B / 7))))",
        ),
        ("1.5e-2 + 3E-2 + .5", "((0.015 + 0.03) + 0.5)"),
    ];
    for (text, expected) in cases {
        assert_eq!(shape(text), expected, "{text}");
    }
}

fn arb_expr() -> impl Strategy<Value = SExpr> {
    let leaf = prop_oneof![
        (0u32..1000, 0u32..4).prop_map(|(m, e)| Expr::Num(m as f64 / 10f64.powi(e as i32))),
        "[a-zA-Z_][a-zA-Z0-9_]{0,5}"
            .prop_filter("not a keyword", |s| !KEYWORDS.contains(&s.as_str()))
            .prop_map(Expr::Name),
    ]
    .prop_map(|e| Spanned::new(e, Span::default()));
    leaf.prop_recursive(6, 64, 3, |inner| {
        let op = prop_oneof![
            Just(BinOp::Add),
            Just(BinOp::Sub),
            Just(BinOp::Mul),
            Just(BinOp::Div),
            Just(BinOp::Pow)
        ];
        prop_oneof![
            inner.clone().prop_map(|e| Expr::Neg(Box::new(e))),
            (op, inner.clone(), inner.clone()).prop_map(|(op, a, b)| Expr::Binary(
                op,
                Box::new(a),
                Box::new(b)
            )),
            (
                prop_oneof![Just("exp"), Just("max"), Just("softplus")],
                prop::collection::vec(inner, 1..3)
            )
                .prop_map(|(f, args)| Expr::Call(
                    Spanned::new(f.to_string(), Span::default()),
                    args
                )),
        ]
        .prop_map(|e| Spanned::new(e, Span::default()))
    })
}

const KEYWORDS: [&str; 17] = [
    "model",
    "time",
    "input",
    "state",
    "hidden",
    "const",
    "param",
    "let",
    "output",
    "closure",
    "der",
    "next",
    "effect",
    "noise",
    "positive",
    "nonnegative",
    "in",
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    #[test]
    fn printed_expressions_reparse_to_the_same_tree(expr in arb_expr()) {
        let text = expr.node.to_string();
        let reparsed = parse_expr(&text).map_err(|e| TestCaseError::fail(format!("{text}: {e}")))?;
        prop_assert_eq!(strip(&reparsed), strip(&expr), "{}", text);
    }

    #[test]
    fn arbitrary_text_never_panics(text in "\\PC{0,200}") {
        let _ = parse(&text);
    }

    #[test]
    fn arbitrary_model_like_text_never_panics(
        lines in prop::collection::vec(
            prop_oneof![
                Just("model m".to_string()), Just("state X = 1".to_string()),
                Just("der X = -X".to_string()), Just("closure c {".to_string()), Just("}".to_string()),
                Just("outputs r ~ 0.1".to_string()), Just("effect e {".to_string()),
                Just("r *= 2".to_string()), Just("noise X = 1 % + 0.1".to_string()),
                "[ -~]{0,30}",
            ],
            0..12,
        )
    ) {
        let text = lines.join("\n");
        let _ = crate::driver::compile("fuzz.gbm", &text, &[]);
    }
}

#[test]
fn doc_comments_attach_to_the_declaration_below() {
    let model = parse(
        "## A test model\nmodel m\n## the biomass\n## in g/L\nstate X = 1\n# plain\nder X = -X\n",
    )
    .expect("parses");
    assert_eq!(model.doc.as_deref(), Some("A test model"));
    assert_eq!(model.items[0].doc.as_deref(), Some("the biomass\nin g/L"));
    assert_eq!(model.items[1].doc, None);
}

#[test]
fn continuation_after_operators_commas_and_backslash() {
    let model =
        parse("model m\nstate X = 1,\n  Y = 2\nder X = -X +\n  Y\nder Y = max(X,\n Y) \\\n - 1\n")
            .expect("parses");
    assert_eq!(model.items.len(), 3);
}

fn expect_error(source: &str) -> SyntaxError {
    match parse(source) {
        Err(error) => error,
        Ok(model) => panic!("expected a syntax error, parsed {model:?}"),
    }
}

#[test]
fn hostile_inputs_end_in_diagnostics() {
    let deep = format!(
        "model m\nstate X = 1\nder X = {}X{}\n",
        "(".repeat(100_000),
        ")".repeat(100_000)
    );
    assert!(matches!(expect_error(&deep), SyntaxError::TooDeep { .. }));
    let negations = format!("model m\nstate X = 1\nder X = {}X\n", "- ".repeat(100_000));
    assert!(matches!(
        expect_error(&negations),
        SyntaxError::TooLong { .. }
    ));
    let powers = format!("model m\nstate X = 1\nder X = X{}\n", "^X".repeat(300_000));
    assert!(matches!(expect_error(&powers), SyntaxError::TooLong { .. }));
    let long_line = format!("model m\nstate X = 1\nder X = {}\n", "a".repeat(1 << 20));
    let _ = crate::driver::compile("long.gbm", &long_line, &[]).expect_err("unknown name");
    let garbage: String = (0..100_000u32)
        .map(|i| char::from_u32(33 + (i * 7919) % 90).unwrap_or('x'))
        .collect();
    let _ = expect_error(&garbage);
    assert!(matches!(expect_error(""), SyntaxError::Unexpected { .. }));
}

#[test]
fn syntax_errors_say_what_was_expected_in_words() {
    let cases = [
        (
            "model m\nstate X = 1\nder X = 2 *\n",
            "expected a name or a number",
            "found end of file",
        ),
        (
            "model m\nstate X = 1\nder X = 2 *\nder Y = 1\n",
            "expected",
            "found `der`",
        ),
        (
            "model m\nstate const = 1\n",
            "expected a name",
            "found `const`",
        ),
        (
            "model m\nstate X = 1\nder X == 2\n",
            "expected",
            "found `=`",
        ),
        ("state X = 1\n", "expected `model NAME`", "found `state`"),
        (
            "model m\nstate X = 1\nder X = (X\n",
            "expected",
            "found end of",
        ),
    ];
    for (source, expected, found) in cases {
        let message = expect_error(source).to_string();
        assert!(message.contains(expected), "{source:?}: {message}");
        assert!(message.contains(found), "{source:?}: {message}");
    }
}

#[test]
fn syntax_error_points_at_the_offending_token() {
    let source = "model m\nstate X = 1\nder X = 2 * * X\n";
    match expect_error(source) {
        SyntaxError::Unexpected { span, .. } => {
            assert_eq!(&source[span.offset()..span.offset() + 1], "*");
            assert_eq!(span.offset(), source.rfind("* X").unwrap_or(0));
        }
        other => panic!("unexpected error {other:?}"),
    }
}

#[test]
fn noise_declarations_parse_with_their_terms_in_order() {
    use crate::ast::{ItemKind, NoiseKind};
    let source = "model m\nstate X = 1, S = 2\nder X = -X\nder S = -S\n\
                  ## assay precision\nnoise X, \n  S = 0.01 [g/L] +\n 4%\nnoise X=1e-3;noise S = - 2 %\n";
    let model = parse(source).expect("parses");
    let noise: Vec<_> = (model.items.iter())
        .filter_map(|item| match &item.kind {
            ItemKind::Noise(noise) => Some((item.doc.clone(), noise)),
            _ => None,
        })
        .collect();
    assert_eq!(noise.len(), 3);
    let (doc, first) = &noise[0];
    assert_eq!(doc.as_deref(), Some("assay precision"));
    let targets: Vec<&str> = first.targets.iter().map(|t| t.node.as_str()).collect();
    assert_eq!(targets, ["X", "S"]);
    assert_eq!(first.terms.len(), 2);
    assert_eq!(first.terms[0].value.node, 0.01);
    assert!(
        matches!(&first.terms[0].kind, NoiseKind::Absolute(Some(unit)) if unit.node.to_string() == "g/L")
    );
    assert_eq!(first.terms[1].value.node, 4.0);
    assert_eq!(first.terms[1].kind, NoiseKind::Relative);
    assert_eq!(
        &source[first.terms[1].span.start..first.terms[1].span.end],
        "4%"
    );
    assert_eq!(first.terms_text(), "0.01 [g/L] + 4 %");
    assert_eq!(noise[1].1.terms[0].kind, NoiseKind::Absolute(None));
    // A sign is parsed (for the check to refuse it in words), with the literal in its span.
    let negative = &noise[2].1.terms[0];
    assert_eq!(negative.value.node, -2.0);
    assert_eq!(
        &source[negative.value.span.start..negative.value.span.end],
        "- 2"
    );
}

#[test]
fn malformed_noise_declarations_say_what_was_expected() {
    let head = "model m\nstate X = 1\nder X = -X\n";
    let cases = [
        ("noise = 4 %", "expected a name"),
        ("noise X 4 %", "expected"),
        (
            "noise X =",
            "expected a noise term such as `4 %` or `0.01 [g/L]`",
        ),
        ("noise X = 4 % - 1", "found `-`"),
        ("noise X = 4 % *", "found `*`"),
        ("noise X = k", "expected a noise term"),
    ];
    for (line, expected) in cases {
        let source = format!("{head}{line}\n");
        let message = expect_error(&source).to_string();
        assert!(message.contains(expected), "{line:?}: {message}");
    }
}

#[test]
fn nonnegative_ends_state_and_hidden_entries_only() {
    use crate::ast::ItemKind;
    let source = "model m\nstate S [g/L] = 8 nonnegative, X nonnegative, P = 1 [g/L]\n\
                  hidden E = 0 [g/L] nonnegative\nder S = -S\nder X = -X\nder P = -P\nder E = -E\n";
    let model = parse(source).expect("parses");
    let flags: Vec<(String, Option<&str>)> = (model.items.iter())
        .filter_map(|item| match &item.kind {
            ItemKind::State(list) | ItemKind::Hidden(list) => Some(list),
            _ => None,
        })
        .flatten()
        .map(|b| {
            let text = b.nonnegative.map(|span| &source[span.start..span.end]);
            (b.name.node.clone(), text)
        })
        .collect();
    let expected = [
        ("S", Some("nonnegative")),
        ("X", Some("nonnegative")),
        ("P", None),
        ("E", Some("nonnegative")),
    ];
    let expected: Vec<(String, Option<&str>)> =
        expected.iter().map(|(n, f)| (n.to_string(), *f)).collect();
    assert_eq!(flags, expected);
    // Not on consts or params, not before the value, and it is no name.
    for wrong in [
        "model m\nconst k = 1 nonnegative\n",
        "model m\nparam k = 1 nonnegative\n",
        "model m\nstate S nonnegative = 1\n",
        "model m\nstate S = 1 nonnegativeX\n",
    ] {
        assert!(parse(wrong).is_err(), "{wrong}");
    }
    let reserved = expect_error("model m\nstate nonnegative\n").to_string();
    let help = format!("{:?}", expect_error("model m\nstate nonnegative\n"));
    assert!(
        help.contains("reserved word") || reserved.contains("reserved"),
        "{reserved} {help}"
    );
}
