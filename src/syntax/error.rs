//! Syntax diagnostics, and the conversion of pest's errors into words a modeller knows.

use super::Rule;
use crate::ast::Span;
use miette::{Diagnostic, SourceSpan};
use thiserror::Error;

/// A syntax error: the file is not a well-formed `.gbm` model.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum SyntaxError {
    /// The parser met a token it did not expect.
    #[error("expected {expected}, found {found}")]
    #[diagnostic(code(gbm::E0001))]
    Unexpected {
        /// Where.
        #[label("unexpected here")]
        span: SourceSpan,
        /// What would have been accepted, in words.
        expected: String,
        /// What was there.
        found: String,
        /// A hint for the fix.
        #[help]
        help: String,
    },
    /// Brackets nested too deeply.
    #[error("nesting deeper than {limit} levels")]
    #[diagnostic(code(gbm::E0002), help("split the expression with `let` declarations"))]
    TooDeep {
        /// Where the limit was crossed.
        #[label("too deep here")]
        span: SourceSpan,
        /// The limit.
        limit: usize,
    },
    /// One declaration with too many operators.
    #[error("declaration too long: more than {limit} operators or a chain of operators too long")]
    #[diagnostic(code(gbm::E0003), help("split the expression with `let` declarations"))]
    TooLong {
        /// Where the limit was crossed.
        #[label("limit reached here")]
        span: SourceSpan,
        /// The limit.
        limit: usize,
    },
    /// A number that does not fit a 64-bit float (or a whole number or unit exponent that is
    /// too large).
    #[error("number out of range: `{text}`")]
    #[diagnostic(
        code(gbm::E0004),
        help(
            "numbers must be finite 64-bit floats; whole numbers in `dim` and `hidden` below 2^32; unit exponents between -99 and 99"
        )
    )]
    BadNumber {
        /// Where.
        #[label("this number")]
        span: SourceSpan,
        /// The literal.
        text: String,
    },
    /// A declaration that is only allowed in another place.
    #[error("{what} is not allowed {place}")]
    #[diagnostic(code(gbm::E0005))]
    Misplaced {
        /// Where.
        #[label("not allowed here")]
        span: SourceSpan,
        /// The declaration.
        what: String,
        /// Where it was found.
        place: String,
        /// Where it belongs.
        #[help]
        help: String,
    },
    /// The parser produced a tree it should not have: a bug in gbc.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Internal(#[from] crate::error::Bug),
}

impl SyntaxError {
    /// An internal error at byte `at`.
    pub(crate) fn internal(at: usize, message: &str) -> Self {
        SyntaxError::Internal(crate::error::Bug::new(
            "the parser",
            format!("{message} (at byte {at})"),
        ))
    }
}

/// Converts a pest error into a located [`SyntaxError`] with rule names turned into words.
pub(crate) fn from_pest(source: &str, error: &pest::error::Error<Rule>) -> SyntaxError {
    let position = match error.location {
        pest::error::InputLocation::Pos(p) => p,
        pest::error::InputLocation::Span((start, _)) => start,
    };
    let position = position.min(source.len());
    let (found, length) = describe_found(source, position);
    let mut expected: Vec<&'static str> = match &error.variant {
        pest::error::ErrorVariant::ParsingError { positives, .. } => {
            positives.iter().map(|rule| describe_rule(*rule)).collect()
        }
        pest::error::ErrorVariant::CustomError { .. } => Vec::new(),
    };
    expected.sort_unstable();
    expected.dedup();
    // Prefer the most informative wording when both generic and specific words appear.
    if expected.len() > 1 {
        expected.retain(|word| *word != "an expression");
    }
    let expected_text = join_alternatives(&expected);
    let help = help_for(&expected, &found);
    SyntaxError::Unexpected {
        span: Span::new(position, position + length).into(),
        expected: expected_text,
        found,
        help,
    }
}

/// The token at `position`, in words, and its length in bytes.
fn describe_found(source: &str, position: usize) -> (String, usize) {
    let rest = &source[position..];
    let Some(first) = rest.chars().next() else {
        return ("end of file".to_string(), 0);
    };
    if first == '\n' || first == '\r' {
        return ("end of line".to_string(), first.len_utf8());
    }
    let word_len: usize = rest
        .char_indices()
        .take_while(|(_, c)| c.is_ascii_alphanumeric() || *c == '_' || *c == '.')
        .map(|(i, c)| i + c.len_utf8())
        .last()
        .unwrap_or(0);
    if word_len > 0 {
        let word = &rest[..word_len.min(40)];
        return (format!("`{word}`"), word_len);
    }
    if first.is_control() || !first.is_ascii() && !first.is_alphanumeric() {
        return (
            format!("character U+{:04X}", first as u32),
            first.len_utf8(),
        );
    }
    (format!("`{first}`"), first.len_utf8())
}

/// A grammar rule in words a modeller knows.
fn describe_rule(rule: Rule) -> &'static str {
    match rule {
        Rule::ident | Rule::closure_output => "a name",
        Rule::number => "a number",
        Rule::integer => "a whole number",
        Rule::string | Rule::string_body => "a description string",
        Rule::expr | Rule::expr_only | Rule::neg | Rule::call => "an expression",
        Rule::add | Rule::sub | Rule::mul | Rule::div | Rule::pow => "an operator",
        Rule::header => "`model NAME`",
        Rule::time_decl
        | Rule::input_decl
        | Rule::state_decl
        | Rule::hidden_decl
        | Rule::const_decl
        | Rule::param_decl
        | Rule::let_decl
        | Rule::output_decl
        | Rule::closure_decl
        | Rule::der_decl
        | Rule::next_decl
        | Rule::effect_decl
        | Rule::noise_decl => "a declaration",
        Rule::noise_term => "a noise term such as `4 %` or `0.01 [g/L]`",
        Rule::percent => "`%`",
        Rule::outputs_item
        | Rule::observe_item
        | Rule::embed_item
        | Rule::network_item
        | Rule::prior_item => "a closure line (`outputs`, `observe`, `embed`, `network`, `prior`)",
        Rule::patch => "a patch (`NAME *= ...`, `NAME += ...`, `NAME := ...`)",
        Rule::embed_delay => "`delay`",
        Rule::embed_dim => "`dim`",
        Rule::hidden_layers => "`hidden [...]`",
        Rule::bounds => "`in [lo, hi]`",
        Rule::positive => "`positive`",
        Rule::nonnegative => "`nonnegative`",
        Rule::assign => "`=`",
        Rule::add_assign => "`+=`",
        Rule::mul_assign => "`*=`",
        Rule::set_assign => "`:=`",
        Rule::input_entry | Rule::init_entry | Rule::value_entry | Rule::param_entry => "a name",
        Rule::keyword => "a keyword",
        Rule::paren => "an expression",
        Rule::unit
        | Rule::unit_none
        | Rule::unit_product
        | Rule::unit_mul
        | Rule::unit_div
        | Rule::unit_factor
        | Rule::unit_group
        | Rule::unit_one
        | Rule::unit_symbol => "a unit such as `[g/L]`",
        Rule::unit_exponent => "a whole exponent",
        Rule::EOI => "end of file",
        Rule::file => "a model file",
        _ => "a declaration",
    }
}

fn join_alternatives(words: &[&str]) -> String {
    match words {
        [] => "something else".to_string(),
        [one] => one.to_string(),
        [init @ .., last] => format!("{} or {}", init.join(", "), last),
    }
}

fn help_for(expected: &[&str], found: &str) -> String {
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
    let bare = found.trim_matches('`');
    if expected.contains(&"a name") && KEYWORDS.contains(&bare) {
        return format!("`{bare}` is a reserved word and cannot be used as a name");
    }
    if expected.contains(&"a declaration") || expected.contains(&"end of file") {
        return "each declaration starts with a keyword (`input`, `state`, `const`, `param`, `let`, \
                `der`, ...) and ends at a newline or `;`"
            .to_string();
    }
    if expected.contains(&"an expression") || expected.contains(&"a number") {
        return "an expression is numbers and names joined by `+ - * / ^`, with function calls \
                such as `exp(x)`"
            .to_string();
    }
    if found == "end of line" {
        return "a line may only continue after an operator, `(`, `[` or `,`, or with a trailing `\\`"
            .to_string();
    }
    "see docs/language.md for the syntax of each declaration".to_string()
}
