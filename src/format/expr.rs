//! Expressions as text with break opportunities: [`Piece`]s that the layout joins and
//! wraps. Numbers keep their source spelling, the author's parentheses are kept, and
//! parentheses the precedence needs are added (a tree from the parser always has them).

use crate::ast::{BinOp, Expr, SExpr};

/// A piece of a line: text, or a place where the line may break.
#[derive(Debug, Clone, PartialEq)]
pub enum Piece {
    /// Text printed as is (a leading space is dropped at the start of a continuation line).
    Text(String),
    /// A line may end here (after an operator or a comma); lines break where the cost is
    /// lowest (shallowest nesting, loosest operator).
    Break(u32),
}

/// Appends text to `pieces`.
pub fn text(pieces: &mut Vec<Piece>, text: impl Into<String>) {
    pieces.push(Piece::Text(text.into()));
}

/// Appends `items` separated by `, ` with a break after each comma, at nesting `depth`.
pub fn list<T>(
    pieces: &mut Vec<Piece>,
    depth: u32,
    items: &[T],
    mut each: impl FnMut(&mut Vec<Piece>, &T),
) {
    for (index, item) in items.iter().enumerate() {
        if index > 0 {
            text(pieces, ",");
            pieces.push(Piece::Break(depth * 10));
            text(pieces, " ");
        }
        each(pieces, item);
    }
}

/// Binding strength of a binary operator (unary minus is 3).
fn precedence(op: BinOp) -> u8 {
    match op {
        BinOp::Add | BinOp::Sub => 1,
        BinOp::Mul | BinOp::Div => 2,
        BinOp::Pow => 4,
    }
}

/// Whether the author wrote parentheses around `expr` (the parser gives a parenthesised
/// node the span of its parentheses).
fn parenthesised(source: &str, expr: &SExpr) -> bool {
    if source.as_bytes().get(expr.span.start) != Some(&b'(') {
        return false;
    }
    match &expr.node {
        Expr::Binary(_, lhs, _) => lhs.span.start != expr.span.start,
        _ => true,
    }
}

/// Appends `expr` printed for a context of binding strength `outer`, inside `depth`
/// parentheses.
pub fn push_expr(pieces: &mut Vec<Piece>, source: &str, expr: &SExpr, outer: u8, depth: u32) {
    let needed = match &expr.node {
        Expr::Neg(_) => outer > 3,
        Expr::Binary(op, _, _) => precedence(*op) < outer,
        _ => false,
    };
    let wrap = needed || parenthesised(source, expr);
    let depth = depth + u32::from(wrap);
    if wrap {
        text(pieces, "(");
    }
    match &expr.node {
        Expr::Num(value) => {
            let written = source
                .get(expr.span.start..expr.span.end)
                .unwrap_or_default();
            let literal = written.trim_start_matches('(').trim_end_matches(')').trim();
            if literal.parse::<f64>().ok() == Some(*value) {
                text(pieces, literal);
            } else {
                text(pieces, crate::ast::format_number(*value));
            }
        }
        Expr::Name(name) => text(pieces, name.clone()),
        Expr::Neg(inner) => {
            text(pieces, "-");
            push_expr(pieces, source, inner, 3, depth);
        }
        Expr::Binary(op, lhs, rhs) => {
            let prec = precedence(*op);
            let (left, right) = if *op == BinOp::Pow {
                (prec + 1, prec)
            } else {
                (prec, prec + 1)
            };
            push_expr(pieces, source, lhs, left, depth);
            if *op == BinOp::Pow {
                text(pieces, "^");
            } else {
                text(pieces, format!(" {}", op.symbol()));
                pieces.push(Piece::Break(depth * 10 + u32::from(prec)));
                text(pieces, " ");
            }
            push_expr(pieces, source, rhs, right, depth);
        }
        Expr::Call(name, args) => {
            text(pieces, format!("{}(", name.node));
            list(pieces, depth + 1, args, |pieces, arg| {
                push_expr(pieces, source, arg, 0, depth + 1)
            });
            text(pieces, ")");
        }
    }
    if wrap {
        text(pieces, ")");
    }
}

/// The pieces of `expr` at the top level.
pub fn pieces(source: &str, expr: &SExpr) -> Vec<Piece> {
    let mut out = Vec::new();
    push_expr(&mut out, source, expr, 0, 0);
    out
}

/// Joins pieces into lines no wider than `width` where breaks allow: the first line starts
/// with `indent`, continuation lines with `indent` plus four spaces. A line that is too
/// long breaks at its cheapest break that leaves it short enough (the last of equals).
pub fn wrap(pieces: &[Piece], indent: &str, width: usize) -> Vec<String> {
    let mut words: Vec<(u32, String)> = vec![(0, String::new())];
    for piece in pieces {
        match piece {
            Piece::Text(text) => {
                if let Some((_, word)) = words.last_mut() {
                    word.push_str(text);
                }
            }
            Piece::Break(cost) => words.push((*cost, String::new())),
        }
    }
    let continuation = format!("{indent}    ");
    let mut lines = Vec::new();
    let mut line: Vec<(u32, String)> = Vec::new();
    let mut prefix = indent.to_string();
    for word in words {
        line.push(word);
        while line_width(&prefix, &line) > width && line.len() > 1 {
            let fitting: Vec<usize> = (1..line.len())
                .filter(|&k| line_width(&prefix, &line[..k]) <= width)
                .collect();
            let candidates = if fitting.is_empty() { vec![1] } else { fitting };
            let best = candidates
                .into_iter()
                .min_by_key(|&k| (line[k].0, std::cmp::Reverse(k)))
                .unwrap_or(1);
            let rest = line.split_off(best);
            lines.push(format!("{prefix}{}", join(&line)));
            line = rest;
            if let Some((_, first)) = line.first_mut() {
                *first = first.trim_start().to_string();
            }
            prefix = continuation.clone();
        }
    }
    lines.push(format!("{prefix}{}", join(&line)));
    lines
}

fn join(words: &[(u32, String)]) -> String {
    words.iter().map(|(_, word)| word.as_str()).collect()
}

fn line_width(prefix: &str, words: &[(u32, String)]) -> usize {
    prefix.chars().count() + words.iter().map(|(_, w)| w.chars().count()).sum::<usize>()
}
