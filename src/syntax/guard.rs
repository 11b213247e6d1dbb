//! A linear pre-scan that rejects input pest (a recursive-descent parser) or the recursive
//! later stages could not handle without exhausting the stack: deeply nested brackets and
//! extremely long operator chains in one declaration.

use super::{SyntaxError, MAX_NESTING};
use crate::ast::Span;

/// The most operators one declaration may contain.
pub const MAX_OPERATORS: usize = 2000;

/// Scans `source` and returns an error at the first place that is nested too deeply or
/// holds too many operators.
pub fn check(source: &str) -> Result<(), SyntaxError> {
    let bytes = source.as_bytes();
    let mut depth = 0usize;
    let mut operators = 0usize;
    let mut prefix_run = 0usize;
    let mut continues = false; // the last significant byte lets the line continue
    let mut i = 0;
    while i < bytes.len() {
        let byte = bytes[i];
        match byte {
            b'#' => {
                while i < bytes.len() && bytes[i] != b'\n' {
                    i += 1;
                }
                continue;
            }
            b'"' => {
                i += 1;
                while i < bytes.len() && bytes[i] != b'"' && bytes[i] != b'\n' {
                    i += 1;
                }
            }
            b'(' | b'[' => {
                depth += 1;
                if depth > MAX_NESTING {
                    return Err(SyntaxError::TooDeep {
                        span: Span::new(i, i + 1).into(),
                        limit: MAX_NESTING,
                    });
                }
                continues = true;
            }
            b')' | b']' => {
                depth = depth.saturating_sub(1);
                continues = false;
            }
            b'+' | b'-' | b'*' | b'/' | b'^' => {
                operators += 1;
                prefix_run += 1;
                if operators > MAX_OPERATORS || prefix_run > MAX_NESTING {
                    return Err(SyntaxError::TooLong {
                        span: Span::new(i, i + 1).into(),
                        limit: MAX_OPERATORS,
                    });
                }
                continues = true;
            }
            b',' | b'\\' | b'=' => continues = true,
            b';' => {
                operators = 0;
                continues = false;
            }
            b'\n' => {
                if !continues {
                    operators = 0;
                }
            }
            b' ' | b'\t' | b'\r' => {}
            _ => {
                prefix_run = 0;
                continues = false;
            }
        }
        if !matches!(byte, b'+' | b'-' | b'*' | b'/' | b'^' | b' ' | b'\t') {
            prefix_run = 0;
        }
        i += 1;
    }
    Ok(())
}
