//! The front-end driver: source text through every stage (parse, check, lower), with each
//! failure turned into reports that carry the named source, ready for rendering.

use crate::{ast, check, ir, syntax};
use miette::{Diagnostic, NamedSource, Report};
use std::path::Path;
use thiserror::Error;

/// A model file that cannot be read as text.
#[derive(Debug, Error, Diagnostic)]
pub enum SourceError {
    /// The file could not be read.
    #[error("cannot read `{path}`: {reason}")]
    #[diagnostic(code(gbm::E0008), help("check the path and its permissions"))]
    Unreadable {
        /// The path.
        path: String,
        /// The operating system's reason.
        reason: String,
    },
    /// The file is not UTF-8 text.
    #[error("`{path}` is not UTF-8 text (invalid byte at offset {offset})")]
    #[diagnostic(
        code(gbm::E0006),
        help("a .gbm model is a plain text file; save it as UTF-8")
    )]
    NotText {
        /// The path.
        path: String,
        /// The first invalid byte.
        offset: usize,
    },
}

/// A model through the front end.
#[derive(Debug, Clone)]
pub struct Compiled {
    /// The checked model (its AST inside).
    pub checked: check::Checked,
    /// The lowered model with the requested effects applied.
    pub model: ir::Model,
}

/// Reads a model file as text.
pub fn read_source(path: &Path) -> Result<String, Report> {
    let bytes = std::fs::read(path).map_err(|error| {
        Report::new(SourceError::Unreadable {
            path: path.display().to_string(),
            reason: error.to_string(),
        })
    })?;
    String::from_utf8(bytes).map_err(|error| {
        Report::new(SourceError::NotText {
            path: path.display().to_string(),
            offset: error.utf8_error().valid_up_to(),
        })
    })
}

fn with_source(
    name: &str,
    source: &str,
    diagnostic: impl Diagnostic + Send + Sync + 'static,
) -> Report {
    Report::new(diagnostic).with_source_code(NamedSource::new(name, source.to_string()))
}

/// Parses `source` (named `name` in messages).
pub fn parse(name: &str, source: &str) -> Result<ast::Model, Vec<Report>> {
    syntax::parse(source).map_err(|error| vec![with_source(name, source, error)])
}

/// Parses and checks `source`, reporting every check error at once.
pub fn check(name: &str, source: &str) -> Result<check::Checked, Vec<Report>> {
    let model = parse(name, source)?;
    check::check(model).map_err(|errors| {
        errors
            .into_iter()
            .map(|error| with_source(name, source, error))
            .collect()
    })
}

/// Parses, checks and lowers `source` with the named effects applied. Without effects,
/// each effect is also applied alone to check that it adds no learned term a `nonnegative`
/// state cannot take (E0136).
pub fn compile(name: &str, source: &str, effects: &[&str]) -> Result<Compiled, Vec<Report>> {
    let checked = check(name, source)?;
    let reports = |errors: Vec<ir::LowerError>| -> Vec<Report> {
        (errors.into_iter())
            .map(|error| with_source(name, source, error))
            .collect()
    };
    let model = ir::lower_reporting(&checked, effects).map_err(reports)?;
    if effects.is_empty() {
        let violations = ir::effect_violations(&checked);
        if !violations.is_empty() {
            return Err(reports(violations));
        }
    }
    Ok(Compiled { checked, model })
}

/// Reads and compiles the model file at `path`.
pub fn compile_file(path: &Path, effects: &[&str]) -> Result<Compiled, Vec<Report>> {
    let source = read_source(path).map_err(|r| vec![r])?;
    compile(&path.display().to_string(), &source, effects)
}
