//! `gbc fmt`: the canonical layout of a `.gbm` file.
//!
//! One declaration per line, two spaces of indentation per block, one space around binary
//! operators (none around `^`), `, ` in lists, units after the name (after the value for
//! `const` and `param`), single blank lines, runs of one-line declarations of one kind
//! aligned on `=`, and lines wrapped after an operator or a comma beyond
//! [`WIDTH`] columns with a four-space continuation. Comments and doc comments stay where
//! they are (a comment inside a multi-line declaration keeps that declaration as written);
//! parentheses the author wrote are kept; number literals keep their spelling.
//!
//! Invariants, checked on every call (a violation is an internal error, never a changed
//! file): the output parses to the same syntax tree (up to spans) and holds the same
//! comments in the same order; formatting it again changes nothing.

mod expr;
mod layout;

#[cfg(test)]
pub use layout::WIDTH;

use crate::ast;
use crate::syntax::{self, SyntaxError};
use miette::Diagnostic;
use thiserror::Error;

/// Why a file could not be formatted.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum FormatError {
    /// The file does not parse.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Syntax(#[from] SyntaxError),
    /// The formatter broke one of its invariants: a bug in gbc.
    #[error("internal formatter error: {0} (this is a bug in gbc)")]
    Internal(String),
}

/// Formats `source` in the canonical layout.
pub fn format_source(source: &str) -> Result<String, FormatError> {
    let model = syntax::parse(source)?;
    let formatted = layout::print(source, &model);
    let reparsed = syntax::parse(&formatted).map_err(|error| {
        FormatError::Internal(format!("the formatted text does not parse: {error}"))
    })?;
    if shape(&model) != shape(&reparsed) {
        return Err(FormatError::Internal(
            "the formatted text parses to a different model".to_string(),
        ));
    }
    if comments(source) != comments(&formatted) {
        return Err(FormatError::Internal(
            "the formatted text lost or reordered a comment".to_string(),
        ));
    }
    if layout::print(&formatted, &reparsed) != formatted {
        return Err(FormatError::Internal(
            "formatting the formatted text changes it again".to_string(),
        ));
    }
    Ok(formatted)
}

/// The syntax tree without its spans, as comparable text.
fn shape(model: &ast::Model) -> String {
    let debug = format!("{model:?}");
    let mut out = String::with_capacity(debug.len());
    let mut rest = debug.as_str();
    while let Some(at) = rest.find("Span { start: ") {
        out.push_str(&rest[..at]);
        rest = &rest[at..];
        match rest.find('}') {
            Some(end) => rest = &rest[end + 1..],
            None => break,
        }
        out.push_str("Span");
    }
    out.push_str(rest);
    out
}

/// Every comment of `source` (from `#` to the end of its line, trailing spaces removed),
/// in order. `#` inside a string does not start a comment.
pub fn comments(source: &str) -> Vec<&str> {
    source
        .lines()
        .filter_map(|line| comment_start(line).map(|at| line[at..].trim_end()))
        .collect()
}

pub(crate) use crate::syntax::comment_start;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_properties;
