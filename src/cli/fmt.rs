//! `gbc fmt FILE... [--check]`: rewrite model files in the canonical layout (see
//! `gbc::api::format_source`), or with `--check` only report the files that are not in it.
//!
//! Directories are searched recursively for `.gbm` files; `-` formats standard input to
//! standard output.

use super::{CommandError, CommandResult};
use gbc::api::{format_source, read_source, write_atomic, FormatError, Span};
use miette::{Diagnostic, NamedSource, Report};
use std::io::Read;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Arguments of `gbc fmt`.
#[derive(Debug, clap::Args)]
pub struct FmtArgs {
    /// Model files, or directories to search for `.gbm` files; `-` for standard input.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Change nothing: report each file that is not formatted and exit with code 1.
    #[arg(long)]
    pub check: bool,
}

/// A problem `gbc fmt` reports.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum FmtError {
    /// `--check` found a file that is not in the canonical layout.
    #[error("`{path}` is not formatted")]
    #[diagnostic(code(gbm::E1001))]
    NotFormatted {
        /// The file.
        path: String,
        /// The first line that differs.
        #[label("the layout differs from here")]
        span: miette::SourceSpan,
        /// The fix.
        #[help]
        help: String,
    },
    /// A directory argument holds no model file.
    #[error("expected `.gbm` files in `{path}`, found none")]
    #[diagnostic(
        code(gbm::E1002),
        help("give model files, or a directory that contains some")
    )]
    NoModels {
        /// The directory.
        path: String,
    },
}

/// Formats (or checks) every file named.
pub fn run(args: &FmtArgs) -> CommandResult {
    let mut reports = Vec::new();
    for argument in &args.files {
        if argument.as_os_str() == "-" {
            format_stdin()?;
            continue;
        }
        let files = match model_files(argument) {
            Ok(files) => files,
            Err(report) => {
                reports.push(report);
                continue;
            }
        };
        for path in files {
            if let Some(report) = format_file(&path, args.check)? {
                reports.push(report);
            }
        }
    }
    if reports.is_empty() {
        Ok(())
    } else {
        Err(CommandError::User(reports))
    }
}

fn format_stdin() -> CommandResult {
    let mut source = String::new();
    std::io::stdin()
        .read_to_string(&mut source)
        .map_err(|error| CommandError::Internal(format!("cannot read standard input: {error}")))?;
    let formatted = format_or_report("<stdin>", &source)?;
    print!("{formatted}");
    Ok(())
}

/// `path` itself, or the `.gbm` files under it, sorted.
fn model_files(path: &Path) -> Result<Vec<PathBuf>, Report> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut found = Vec::new();
    let mut stack = vec![path.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let entry_path = entry.path();
            if entry_path.is_dir() {
                stack.push(entry_path);
            } else if entry_path.extension().is_some_and(|e| e == "gbm") {
                found.push(entry_path);
            }
        }
    }
    found.sort();
    if found.is_empty() {
        return Err(Report::new(FmtError::NoModels {
            path: path.display().to_string(),
        }));
    }
    Ok(found)
}

fn format_or_report(name: &str, source: &str) -> Result<String, CommandError> {
    match format_source(source) {
        Ok(formatted) => Ok(formatted),
        Err(FormatError::Syntax(error)) => {
            Err(CommandError::User(vec![Report::new(error)
                .with_source_code(NamedSource::new(
                    name,
                    source.to_string(),
                ))]))
        }
        Err(FormatError::Internal(message)) => {
            Err(CommandError::Internal(format!("{name}: {message}")))
        }
    }
}

/// Formats one file: rewrites it, or (with `check`) reports it when it would change.
fn format_file(path: &Path, check: bool) -> Result<Option<Report>, CommandError> {
    let name = path.display().to_string();
    let source = match read_source(path) {
        Ok(source) => source,
        Err(report) => return Ok(Some(report)),
    };
    let formatted = match format_or_report(&name, &source) {
        Ok(formatted) => formatted,
        Err(CommandError::User(mut reports)) => return Ok(reports.pop()),
        Err(internal) => return Err(internal),
    };
    if formatted == source {
        return Ok(None);
    }
    if check {
        let at = first_difference(&source, &formatted);
        let line_end = source[at..].find('\n').map_or(source.len(), |i| at + i);
        let error = FmtError::NotFormatted {
            path: name.clone(),
            span: Span::new(at, line_end.max(at)).into(),
            help: format!("run `gbc fmt {name}` to rewrite it"),
        };
        return Ok(Some(
            Report::new(error).with_source_code(NamedSource::new(name, source)),
        ));
    }
    write_atomic(path, formatted.as_bytes())
        .map_err(|e| CommandError::User(vec![Report::new(e)]))?;
    println!("formatted {name}");
    Ok(None)
}

/// The byte offset of the start of the first line where `a` and `b` differ.
fn first_difference(a: &str, b: &str) -> usize {
    let mut offset = 0;
    for (line_a, line_b) in a.split_inclusive('\n').zip(b.split_inclusive('\n')) {
        if line_a != line_b {
            return offset;
        }
        offset += line_a.len();
    }
    offset.min(a.len())
}
