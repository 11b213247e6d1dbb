//! Syntax: the pest binding. Turns source text into the [`ast`](crate::ast); nothing outside
//! this module sees a pest `Pair`.
//!
//! Parsing is guarded against pathological input before pest runs (see [`guard`]): nesting
//! deeper than [`MAX_NESTING`] is a diagnostic, not a stack overflow.

mod build;
mod error;
mod guard;
mod span;
#[cfg(test)]
mod tests_properties;
mod unit;

pub use error::SyntaxError;

use crate::ast;
use pest::Parser;

/// The deepest nesting of parentheses, brackets or operator chains accepted.
pub const MAX_NESTING: usize = 200;

/// The pest-generated parser; its `Rule` enum names the grammar's rules.
#[allow(missing_docs)]
mod grammar {
    #[derive(pest_derive::Parser)]
    #[grammar = "../grammar/gbm.pest"]
    pub struct GbmParser;
}
pub(crate) use grammar::{GbmParser, Rule};

/// Parses a whole `.gbm` file into its AST, or the first syntax error.
pub fn parse(source: &str) -> Result<ast::Model, SyntaxError> {
    guard::check(source)?;
    let mut pairs =
        GbmParser::parse(Rule::file, source).map_err(|error| error::from_pest(source, &error))?;
    let file = pairs
        .next()
        .ok_or_else(|| SyntaxError::internal(source.len(), "empty parse tree"))?;
    build::model(source, file)
}

/// Where the comment of a line starts, if it has one (`#` outside a string).
pub fn comment_start(line: &str) -> Option<usize> {
    let mut in_string = false;
    for (index, byte) in line.bytes().enumerate() {
        match byte {
            b'"' => in_string = !in_string,
            b'#' if !in_string => return Some(index),
            _ => {}
        }
    }
    None
}

/// Parses one expression (used by tests and tools that take expressions on the command line).
#[cfg(test)]
pub fn parse_expr(source: &str) -> Result<ast::SExpr, SyntaxError> {
    guard::check(source)?;
    let mut pairs = GbmParser::parse(Rule::expr_only, source)
        .map_err(|error| error::from_pest(source, &error))?;
    let pair = pairs
        .next()
        .and_then(|p| p.into_inner().next())
        .ok_or_else(|| SyntaxError::internal(source.len(), "empty parse tree"))?;
    build::expr(pair)
}
