//! The program text: `KIND(ARG, KEY=VALUE, ...)` split into spanned pieces and bound to the
//! keys each kind accepts.

use super::error::{ArgumentSource, SignalError};
use crate::suggest::did_you_mean;
use miette::SourceSpan;

/// The kinds of program and the keys each accepts, in positional order.
pub(super) const KINDS: [(&str, &[&str]); 5] = [
    ("steps", &["lo", "hi", "hold", "seed"]),
    ("const", &["value"]),
    ("chirp", &["lo", "hi", "f0", "f1", "period"]),
    ("csv", &["file", "column", "experiment"]),
    (SCHEDULE, &[]),
];

/// The one kind whose arguments are a list: `schedule(T:V, T:V, ...)`, switches without keys.
pub(super) const SCHEDULE: &str = "schedule";

/// A piece of the argument text with its byte range in the whole argument.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Piece {
    /// The text (quotes removed).
    pub text: String,
    /// Where it lies in the argument.
    pub span: SourceSpan,
}

/// One argument as written.
#[derive(Debug, Clone, PartialEq)]
struct RawArgument {
    key: Option<Piece>,
    value: Piece,
}

/// A program whose arguments are bound to its kind's keys.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Bound {
    /// The kind's name.
    pub name: &'static str,
    /// Where the name is written.
    pub span: SourceSpan,
    /// One slot per key of the kind, in [`KINDS`] order: the value given, if any; for
    /// [`SCHEDULE`], one filled slot per argument.
    pub values: Vec<Option<Piece>>,
}

/// Parses the program starting at byte `start` of `source` (the whole `--input` argument).
pub(super) fn parse_bound(source: &ArgumentSource, start: usize) -> Result<Bound, SignalError> {
    let mut scanner = Scanner {
        source,
        text: source.inner().as_str(),
        position: start,
    };
    let kind = scanner.kind()?;
    let arguments = scanner.arguments(&kind)?;
    let Some(&(name, keys)) = KINDS.iter().find(|(name, _)| *name == kind.text) else {
        let names: Vec<&str> = KINDS.iter().map(|(name, _)| *name).collect();
        return Err(SignalError::UnknownProgram {
            src: source.clone(),
            span: kind.span,
            name: kind.text.clone(),
            help: did_you_mean(&kind.text, &names, "input programs"),
        });
    };
    if name == SCHEDULE {
        return bind_list(source, (name, kind.span), arguments);
    }
    bind(source, (name, kind.span), keys, arguments)
}

/// Binds the arguments of a list program: every one positional, at least one.
fn bind_list(
    source: &ArgumentSource,
    (name, span): (&'static str, SourceSpan),
    arguments: Vec<RawArgument>,
) -> Result<Bound, SignalError> {
    let example = "write the levels with the times they start at, e.g. \
                   `schedule(0:0.2, 10:0.5, 24:0)`";
    if arguments.is_empty() {
        return Err(SignalError::MissingArgument {
            src: source.clone(),
            span,
            program: name,
            key: "T:V",
            reason: String::new(),
            help: example.to_string(),
        });
    }
    let mut values = Vec::with_capacity(arguments.len());
    for argument in arguments {
        if let Some(key) = argument.key {
            return Err(SignalError::UnknownKey {
                src: source.clone(),
                span: key.span,
                program: name,
                key: key.text,
                help: format!("`{name}` takes no keys: {example}"),
            });
        }
        values.push(Some(argument.value));
    }
    Ok(Bound { name, span, values })
}

/// Binds positional arguments to keys in order, then keyword arguments by name.
fn bind(
    source: &ArgumentSource,
    (name, span): (&'static str, SourceSpan),
    keys: &'static [&'static str],
    arguments: Vec<RawArgument>,
) -> Result<Bound, SignalError> {
    let mut values: Vec<Option<Piece>> = vec![None; keys.len()];
    let mut keyed = false;
    let usage = || {
        let listed: Vec<String> = keys.iter().map(|key| format!("{key}=...")).collect();
        format!("write `{name}({})`", listed.join(", "))
    };
    for (index, argument) in arguments.into_iter().enumerate() {
        let slot = match &argument.key {
            Some(key) => {
                keyed = true;
                keys.iter()
                    .position(|k| *k == key.text)
                    .ok_or_else(|| SignalError::UnknownKey {
                        src: source.clone(),
                        span: key.span,
                        program: name,
                        key: key.text.clone(),
                        help: did_you_mean(&key.text, keys, "its arguments"),
                    })?
            }
            None if keyed || index >= keys.len() => {
                return Err(SignalError::UnexpectedArgument {
                    src: source.clone(),
                    span: argument.value.span,
                    program: name,
                    found: argument.value.text.clone(),
                    help: format!(
                        "positional arguments come first and there are at most {}; {}",
                        keys.len(),
                        usage()
                    ),
                })
            }
            None => index,
        };
        if let Some(first) = &values[slot] {
            return Err(SignalError::DuplicateKey {
                src: source.clone(),
                span: argument.key.map_or(argument.value.span, |key| key.span),
                first_span: first.span,
                key: keys[slot],
            });
        }
        values[slot] = Some(argument.value);
    }
    Ok(Bound { name, span, values })
}

/// Walks the argument text.
struct Scanner<'a> {
    source: &'a ArgumentSource,
    text: &'a str,
    position: usize,
}

impl<'a> Scanner<'a> {
    fn rest(&self) -> &'a str {
        &self.text[self.position..]
    }

    fn skip_whitespace(&mut self) {
        let rest = self.rest();
        self.position += rest.len() - rest.trim_start().len();
    }

    fn span(&self, start: usize, end: usize) -> SourceSpan {
        SourceSpan::new(start.into(), end - start)
    }

    /// What lies at the cursor, in words, and its span: the character there, or at the end
    /// of the text its last character (a span past the end would not be drawn).
    fn found_here(&self) -> (String, SourceSpan) {
        match self.rest().chars().next() {
            Some(next) => (
                format!("`{next}`"),
                self.span(self.position, self.position + next.len_utf8()),
            ),
            None => {
                let last = self.text.chars().next_back().map_or(0, char::len_utf8);
                let start = self.position.saturating_sub(last);
                (
                    "the end of the argument".to_string(),
                    self.span(start, self.position),
                )
            }
        }
    }

    fn syntax(&self, expected: &str, help: &str) -> SignalError {
        let (found, span) = self.found_here();
        SignalError::Syntax {
            src: self.source.clone(),
            span,
            expected: expected.to_string(),
            found,
            help: help.to_string(),
        }
    }

    /// The program's kind: an identifier followed by `(`.
    fn kind(&mut self) -> Result<Piece, SignalError> {
        self.skip_whitespace();
        let start = self.position;
        let length = identifier_length(self.rest());
        if length == 0 {
            return Err(self.syntax(
                "a program such as `steps(...)`, `const(...)`, `chirp(...)`, `schedule(...)` or \
                 `csv(...)`",
                "write e.g. `u=const(0.5)` or `u=steps(hold=5..40, seed=1)`",
            ));
        }
        self.position += length;
        let kind = Piece {
            text: self.text[start..self.position].to_string(),
            span: self.span(start, self.position),
        };
        self.skip_whitespace();
        if !self.rest().starts_with('(') {
            return Err(self.syntax(
                &format!("`(` after `{}`", kind.text),
                &format!("write the arguments in parentheses: `{}(...)`", kind.text),
            ));
        }
        self.position += 1;
        Ok(kind)
    }

    /// The arguments up to the closing `)`, which must end the text.
    fn arguments(&mut self, kind: &Piece) -> Result<Vec<RawArgument>, SignalError> {
        let mut arguments = Vec::new();
        self.skip_whitespace();
        if self.rest().starts_with(')') {
            self.position += 1;
        } else {
            loop {
                arguments.push(self.argument()?);
                match self.rest().chars().next() {
                    Some(',') => self.position += 1,
                    Some(')') => {
                        self.position += 1;
                        break;
                    }
                    _ => {
                        let help = format!("close the argument list: `{}(...)`", kind.text);
                        return Err(self.syntax("`,` or `)`", &help));
                    }
                }
            }
        }
        self.skip_whitespace();
        if !self.rest().is_empty() {
            return Err(self.syntax(
                "the end of the argument after `)`",
                "give one program per input; quote the whole argument in the shell",
            ));
        }
        Ok(arguments)
    }

    /// One `VALUE` or `KEY=VALUE`, leaving the cursor on the `,` or `)` after it.
    fn argument(&mut self) -> Result<RawArgument, SignalError> {
        self.skip_whitespace();
        let start = self.position;
        let length = identifier_length(self.rest());
        let after_name = self.text[start + length..].trim_start();
        if length > 0 && after_name.starts_with('=') {
            let key = Piece {
                text: self.text[start..start + length].to_string(),
                span: self.span(start, start + length),
            };
            self.position = self.text.len() - after_name.len() + 1;
            let value = self.value(&format!("a value after `{}=`", key.text))?;
            return Ok(RawArgument {
                key: Some(key),
                value,
            });
        }
        let value = self.value("an argument")?;
        Ok(RawArgument { key: None, value })
    }

    /// A value: a double-quoted string, or the text up to the next `,` or `)`.
    fn value(&mut self, expected: &str) -> Result<Piece, SignalError> {
        self.skip_whitespace();
        let start = self.position;
        if let Some(quoted) = self.rest().strip_prefix('"') {
            let Some(length) = quoted.find('"') else {
                return Err(self.syntax("a closing `\"`", "close the quoted text"));
            };
            self.position += length + 2;
            self.skip_whitespace();
            return Ok(Piece {
                text: quoted[..length].to_string(),
                span: self.span(start, start + length + 2),
            });
        }
        let length = self.rest().find([',', ')']).unwrap_or(self.rest().len());
        let raw = &self.text[start..start + length];
        let text = raw.trim_end();
        if text.is_empty() {
            return Err(self.syntax(expected, "remove the stray `,` or give a value"));
        }
        self.position += length;
        Ok(Piece {
            text: text.to_string(),
            span: self.span(start, start + text.len()),
        })
    }
}

/// Length in bytes of the identifier `[A-Za-z_][A-Za-z0-9_]*` starting `text`, or 0.
pub(super) fn identifier_length(text: &str) -> usize {
    let mut chars = text.char_indices();
    match chars.next() {
        Some((_, first)) if first.is_ascii_alphabetic() || first == '_' => {}
        _ => return 0,
    }
    chars
        .find(|(_, c)| !(c.is_ascii_alphanumeric() || *c == '_'))
        .map_or(text.len(), |(index, _)| index)
}
