//! The abstract syntax tree of a `.gbm` file.
//!
//! Built by [`crate::syntax::parse`] and read by every later stage. Each node that a
//! diagnostic may point at carries its byte-offset [`Span`] into the source text; later
//! stages refer back to the tree (or build side tables) instead of copying it.

use std::fmt;

/// A half-open byte range `start..end` in the source text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, PartialOrd, Ord)]
pub struct Span {
    /// First byte.
    pub start: usize,
    /// One past the last byte.
    pub end: usize,
}

impl Span {
    /// A span from `start` to `end`.
    pub fn new(start: usize, end: usize) -> Self {
        Span { start, end }
    }
    /// The smallest span covering both.
    pub fn join(self, other: Span) -> Span {
        Span::new(self.start.min(other.start), self.end.max(other.end))
    }
    /// Length in bytes.
    pub fn len(&self) -> usize {
        self.end - self.start
    }
    /// Whether the span covers no bytes.
    pub fn is_empty(&self) -> bool {
        self.end <= self.start
    }
}

impl From<Span> for miette::SourceSpan {
    fn from(span: Span) -> Self {
        (span.start, span.len()).into()
    }
}

/// A node together with the source span it was parsed from.
#[derive(Debug, Clone, PartialEq)]
pub struct Spanned<T> {
    /// The node.
    pub node: T,
    /// Where it is in the source.
    pub span: Span,
}

impl<T> Spanned<T> {
    /// Wraps `node` with `span`.
    pub fn new(node: T, span: Span) -> Self {
        Spanned { node, span }
    }
}

/// A name as written, with its span.
pub type Ident = Spanned<String>;

/// A binary arithmetic operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BinOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
    /// `^` (right associative)
    Pow,
}

impl BinOp {
    /// Applies the operator to two numbers (the one scalar definition all evaluators share).
    pub fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            BinOp::Add => a + b,
            BinOp::Sub => a - b,
            BinOp::Mul => a * b,
            BinOp::Div => a / b,
            BinOp::Pow => a.powf(b),
        }
    }
    /// The operator's source symbol.
    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Pow => "^",
        }
    }
}

/// An expression node.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// A numeric literal.
    Num(f64),
    /// A reference to a named quantity (const, param, let, state, input, closure output...).
    Name(String),
    /// Unary minus.
    Neg(Box<SExpr>),
    /// A binary operation.
    Binary(BinOp, Box<SExpr>, Box<SExpr>),
    /// A function call `f(a, b)`.
    Call(Ident, Vec<SExpr>),
}

/// An expression with its span.
pub type SExpr = Spanned<Expr>;

/// How a `*=`, `+=` or `:=` modifies its target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PatchOp {
    /// `*=`: multiply.
    Mul,
    /// `+=`: add.
    Add,
    /// `:=`: replace.
    Set,
}

impl PatchOp {
    /// The operator's source symbol.
    pub fn symbol(self) -> &'static str {
        match self {
            PatchOp::Mul => "*=",
            PatchOp::Add => "+=",
            PatchOp::Set => ":=",
        }
    }
}

/// A unit of measure as written between brackets (`[g/L]`, `[g L^-1]`, `[1/h]`, `[-]`).
/// Symbols are kept as text; [`crate::units`] resolves them.
#[derive(Debug, Clone, PartialEq)]
pub enum UnitExpr {
    /// `-`: dimensionless.
    Dimensionless,
    /// `1`, as in `1/h`.
    One,
    /// A prefixed symbol such as `g`, `mg`, `mol`, `L`, `h`.
    Symbol(String),
    /// `factor^n`.
    Pow(Box<SUnit>, i32),
    /// `a b` or `a * b`.
    Mul(Box<SUnit>, Box<SUnit>),
    /// `a / b`.
    Div(Box<SUnit>, Box<SUnit>),
}

/// A unit annotation with its span (the span of the whole `[...]` at the top).
pub type SUnit = Spanned<UnitExpr>;

/// A value constraint on a param or closure output.
#[derive(Debug, Clone, PartialEq)]
pub enum Constraint {
    /// `positive`: strictly greater than zero.
    Positive(Span),
    /// `in [lo, hi]`: hard bounds.
    Bounds(SExpr, SExpr),
}

/// One parsed `.gbm` file.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// The name after `model`.
    pub name: Ident,
    /// The optional description string of the header.
    pub description: Option<String>,
    /// Doc text above the header.
    pub doc: Option<String>,
    /// Every declaration, in source order.
    pub items: Vec<Item>,
}

/// A declaration with its doc text and span.
#[derive(Debug, Clone, PartialEq)]
pub struct Item {
    /// Text of the `##` comment lines directly above the declaration.
    pub doc: Option<String>,
    /// The declaration.
    pub kind: ItemKind,
    /// Where the whole declaration is.
    pub span: Span,
}

/// A name with an optional value: `X = 1.2` in `state`, `hidden`, `const` declarations.
#[derive(Debug, Clone, PartialEq)]
pub struct Binding {
    /// The declared name.
    pub name: Ident,
    /// Its unit, if declared.
    pub unit: Option<SUnit>,
    /// Its value or initial value, if written.
    pub value: Option<SExpr>,
    /// `nonnegative` (states and hidden states only): where it is written. A learned term
    /// may not drive the state below zero (checked after lowering, [`crate::ir::nonnegative`]).
    pub nonnegative: Option<Span>,
}

/// An actuator: `u in [0, 1]`.
#[derive(Debug, Clone, PartialEq)]
pub struct InputDecl {
    /// The input's name (a data column).
    pub name: Ident,
    /// Its unit, if declared.
    pub unit: Option<SUnit>,
    /// `in [lo, hi]`, used by input generators.
    pub bounds: Option<(SExpr, SExpr)>,
}

/// A trainable constant: `Y_X = 0.5 positive`.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamDecl {
    /// The param's name.
    pub name: Ident,
    /// Its unit, if declared.
    pub unit: Option<SUnit>,
    /// Initial guess.
    pub init: SExpr,
    /// Optional constraint.
    pub constraint: Option<Constraint>,
}

/// A named equation: `let mu = ...`, `output P = ...`, `der X = ...`, `next X = ...`.
#[derive(Debug, Clone, PartialEq)]
pub struct Equation {
    /// The defined or targeted name.
    pub name: Ident,
    /// The declared unit (`let` and `output` only).
    pub unit: Option<SUnit>,
    /// The right-hand side.
    pub expr: SExpr,
}

/// One declaration.
#[derive(Debug, Clone, PartialEq)]
pub enum ItemKind {
    /// `time UNIT`.
    Time(Ident),
    /// `input ...`.
    Input(Vec<InputDecl>),
    /// `state ...`: measured states.
    State(Vec<Binding>),
    /// `hidden ...`: unmeasured states.
    Hidden(Vec<Binding>),
    /// `const ...`: known parameters.
    Const(Vec<Binding>),
    /// `param ...`: trainable constants.
    Param(Vec<ParamDecl>),
    /// `let NAME = expr`.
    Let(Equation),
    /// `output NAME = expr`.
    Output(Equation),
    /// `closure NAME { ... }`.
    Closure(ClosureDecl),
    /// `der X = expr`.
    Der(Equation),
    /// `der X += expr` (only meaningful inside an effect).
    DerPatch(Equation),
    /// `next X = expr`.
    Next(Equation),
    /// `effect NAME "..." { ... }`.
    Effect(EffectDecl),
    /// `NAME *= expr` and friends (only inside an effect).
    Patch(Patch),
    /// `noise X, S = 4 % + 0.01 [g/L]`: measurement noise (top level only).
    Noise(NoiseDecl),
}

/// `noise X, S = 4 % + 0.01 [g/L]`: the standard deviation of a measurement of each named
/// quantity, `sigma(y) = sqrt(absolute^2 + (relative * y)^2)`.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseDecl {
    /// The measured quantities it is declared for.
    pub targets: Vec<Ident>,
    /// Its terms as written, in order (the checks allow one of each kind).
    pub terms: Vec<NoiseTerm>,
}

/// One term of a noise declaration: `4 %` or `0.01 [g/L]`.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseTerm {
    /// The number with its sign (its span covers the literal, sign included).
    pub value: Spanned<f64>,
    /// Relative or absolute.
    pub kind: NoiseKind,
    /// The whole term.
    pub span: Span,
}

/// The kind of a noise term.
#[derive(Debug, Clone, PartialEq)]
pub enum NoiseKind {
    /// `4 %`: a percentage of the measured value.
    Relative,
    /// `0.01 [g/L]` or `0.01`: in the unit written, or without one in the quantity's unit.
    Absolute(Option<SUnit>),
}

/// `NAME op expr` inside an effect.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    /// The patched name.
    pub target: Ident,
    /// How it is patched.
    pub op: PatchOp,
    /// The patch expression.
    pub expr: SExpr,
    /// Span of the operator.
    pub op_span: Span,
}

/// One value a closure provides: `mu ~ 0.05 positive`.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosureOutputDecl {
    /// The output's name.
    pub name: Ident,
    /// Its unit, if declared.
    pub unit: Option<SUnit>,
    /// `~ v`: typical magnitude.
    pub scale: Option<SExpr>,
    /// Optional constraint on the output's value.
    pub constraint: Option<Constraint>,
}

/// A prior inside a closure: `prior mu *= expr`.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorDecl {
    /// The closure output it applies to.
    pub target: Ident,
    /// `*=` (multiplicative) or `+=` (additive).
    pub op: PatchOp,
    /// The prior expression.
    pub expr: SExpr,
}

/// One line of a closure block.
#[derive(Debug, Clone, PartialEq)]
pub enum ClosureItem {
    /// `outputs ...`.
    Outputs(Vec<ClosureOutputDecl>),
    /// `observe ...`.
    Observe(Vec<Ident>),
    /// `embed delay D dim N`.
    Embed {
        /// The delay between lags.
        delay: Option<SExpr>,
        /// The number of lags.
        dim: Option<Spanned<u64>>,
    },
    /// `network hidden [..] activation`.
    Network {
        /// Hidden layer widths, if given.
        hidden: Option<Vec<Spanned<u64>>>,
        /// Activation name, if given.
        activation: Option<Ident>,
    },
    /// `prior ...`.
    Prior(PriorDecl),
}

/// `closure NAME { ... }`.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosureDecl {
    /// The closure's name.
    pub name: Ident,
    /// Its lines, with spans.
    pub items: Vec<Spanned<ClosureItem>>,
}

/// `effect NAME "description" { ... }`.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectDecl {
    /// The effect's name.
    pub name: Ident,
    /// Optional description.
    pub description: Option<String>,
    /// Its declarations (params, hidden states, lets, ders) and patches.
    pub items: Vec<Item>,
}

impl NoiseDecl {
    /// The terms in canonical text: `4 % + 0.01 [g/L]` (numbers in their shortest form).
    pub fn terms_text(&self) -> String {
        let text = |term: &NoiseTerm| {
            let number = format_number(term.value.node);
            match &term.kind {
                NoiseKind::Relative => format!("{number} %"),
                NoiseKind::Absolute(Some(unit)) => format!("{number} [{}]", unit.node),
                NoiseKind::Absolute(None) => number,
            }
        };
        self.terms.iter().map(text).collect::<Vec<_>>().join(" + ")
    }
}

impl fmt::Display for Expr {
    /// Prints the expression fully parenthesised where needed, so that printing and
    /// re-parsing yields the same tree.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_expr(f, self, 0)
    }
}

fn precedence(op: BinOp) -> u8 {
    match op {
        BinOp::Add | BinOp::Sub => 1,
        BinOp::Mul | BinOp::Div => 2,
        BinOp::Pow => 4,
    }
}

fn write_expr(f: &mut fmt::Formatter<'_>, expr: &Expr, outer: u8) -> fmt::Result {
    match expr {
        Expr::Num(v) => write!(f, "{}", format_number(*v)),
        Expr::Name(n) => write!(f, "{n}"),
        Expr::Neg(inner) => {
            let wrap = outer > 3;
            if wrap {
                write!(f, "(")?;
            }
            write!(f, "-")?;
            write_expr(f, &inner.node, 3)?;
            if wrap {
                write!(f, ")")?;
            }
            Ok(())
        }
        Expr::Binary(op, lhs, rhs) => {
            let prec = precedence(*op);
            let wrap = prec < outer;
            if wrap {
                write!(f, "(")?;
            }
            // Left associative operators bind the right operand one level tighter; `^` is
            // right associative so its left operand is the tighter one.
            let (left_prec, right_prec) = if *op == BinOp::Pow {
                (prec + 1, prec)
            } else {
                (prec, prec + 1)
            };
            write_expr(f, &lhs.node, left_prec)?;
            write!(f, " {} ", op.symbol())?;
            write_expr(f, &rhs.node, right_prec)?;
            if wrap {
                write!(f, ")")?;
            }
            Ok(())
        }
        Expr::Call(name, args) => {
            write!(f, "{}(", name.node)?;
            for (i, arg) in args.iter().enumerate() {
                if i > 0 {
                    write!(f, ", ")?;
                }
                write_expr(f, &arg.node, 0)?;
            }
            write!(f, ")")
        }
    }
}

/// Formats a number so that it parses back to the same `f64` (shortest round-trip form).
pub fn format_number(v: f64) -> String {
    if v.is_finite() && v == v.trunc() && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v:?}")
    }
}

impl fmt::Display for UnitExpr {
    /// Prints the unit (without brackets) so that it re-parses to the same tree: factors by
    /// juxtaposition, `/` for division, parentheses only where the tree needs them.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            UnitExpr::Dimensionless => write!(f, "-"),
            UnitExpr::One => write!(f, "1"),
            UnitExpr::Symbol(symbol) => write!(f, "{symbol}"),
            UnitExpr::Pow(base, exponent) => {
                write_unit_operand(f, &base.node, !is_unit_atom(&base.node))?;
                write!(f, "^{exponent}")
            }
            UnitExpr::Mul(lhs, rhs) | UnitExpr::Div(lhs, rhs) => {
                write_unit_operand(f, &lhs.node, false)?;
                let separator = if matches!(self, UnitExpr::Mul(..)) {
                    " "
                } else {
                    "/"
                };
                write!(f, "{separator}")?;
                let grouped = matches!(rhs.node, UnitExpr::Mul(..) | UnitExpr::Div(..));
                write_unit_operand(f, &rhs.node, grouped)
            }
        }
    }
}

fn is_unit_atom(unit: &UnitExpr) -> bool {
    matches!(unit, UnitExpr::One | UnitExpr::Symbol(_))
}

fn write_unit_operand(f: &mut fmt::Formatter<'_>, unit: &UnitExpr, grouped: bool) -> fmt::Result {
    if grouped {
        write!(f, "({unit})")
    } else {
        write!(f, "{unit}")
    }
}
