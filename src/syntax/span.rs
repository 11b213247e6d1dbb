//! The span of a parsed pair as the AST records it: its text without the blanks and
//! comments pest's implicit whitespace leaves at its end.

use super::Rule;
use crate::ast::Span;
use pest::iterators::Pair;

/// The span of a pair without the spaces and comments pest's implicit whitespace leaves at
/// its end (after a trailing optional part that is absent, `X = 1 # note` would otherwise
/// end at the end of the comment).
pub(super) fn span_of(pair: &Pair<Rule>) -> Span {
    let start = pair.as_span().start();
    Span::new(start, start + significant_len(pair.as_str()))
}

/// The length of `text` without trailing blanks, comments and `\` line continuations.
fn significant_len(text: &str) -> usize {
    let mut end = text.len();
    loop {
        let trimmed = text[..end].trim_end_matches([' ', '\t', '\u{feff}']);
        let line_start = trimmed.rfind('\n').map_or(0, |i| i + 1);
        let next = if let Some(at) = super::comment_start(&trimmed[line_start..]) {
            line_start + at
        } else if let Some(rest) = trimmed.strip_suffix('\n') {
            let rest = rest.strip_suffix('\r').unwrap_or(rest);
            rest.strip_suffix('\\').map_or(trimmed.len(), str::len)
        } else {
            trimmed.len()
        };
        if next == end {
            return end;
        }
        end = next;
    }
}
