//! Locating and rendering diagnostics. The library builds `miette` reports; this module
//! turns them into text (`human`, `short`) or JSON records. Only `src/cli/` decides where
//! they go and whether colour is used.

use miette::{Diagnostic, GraphicalReportHandler, GraphicalTheme, Report};
use serde::Serialize;

/// How diagnostics are printed (`--message-format`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageFormat {
    /// Source excerpt with labels and help, as compilers print.
    Human,
    /// One line each: `file:line:column: error[code]: message`.
    Short,
    /// One JSON object per line.
    Json,
}

/// A diagnostic reduced to plain, serialisable facts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlainDiagnostic {
    /// Code such as `gbm::E0101`.
    pub code: Option<String>,
    /// The message.
    pub message: String,
    /// Source name (file) when the diagnostic has source.
    pub file: Option<String>,
    /// 1-based line of the first label.
    pub line: Option<usize>,
    /// 1-based column (in characters) of the first label.
    pub column: Option<usize>,
    /// The help line.
    pub help: Option<String>,
}

/// Extracts the plain facts of a report.
pub fn record(report: &Report) -> PlainDiagnostic {
    let diagnostic: &dyn Diagnostic = report.as_ref();
    let mut record = PlainDiagnostic {
        code: diagnostic.code().map(|c| c.to_string()),
        message: diagnostic.to_string(),
        file: None,
        line: None,
        column: None,
        help: diagnostic.help().map(|h| h.to_string()),
    };
    let label = diagnostic.labels().and_then(|mut labels| labels.next());
    if let (Some(source), Some(label)) = (diagnostic.source_code(), label) {
        if let Ok(contents) = source.read_span(label.inner(), 0, 0) {
            record.file = contents.name().map(str::to_string);
            record.line = Some(contents.line() + 1);
            record.column = Some(contents.column() + 1);
        }
    }
    record
}

/// Renders one report in `format`. `color` applies to `human` only; `width` is the
/// terminal width used for wrapping.
pub fn render(report: &Report, format: MessageFormat, color: bool, width: usize) -> String {
    match format {
        MessageFormat::Human => {
            let theme = if color {
                GraphicalTheme::unicode()
            } else {
                GraphicalTheme::unicode_nocolor()
            };
            let handler = GraphicalReportHandler::new_themed(theme).with_width(width);
            let mut out = String::new();
            match handler.render_report(&mut out, report.as_ref()) {
                Ok(()) => out,
                Err(_) => format!("{report}\n"),
            }
        }
        MessageFormat::Short => {
            let r = record(report);
            let location = match (&r.file, r.line, r.column) {
                (Some(file), Some(line), Some(column)) => format!("{file}:{line}:{column}: "),
                _ => String::new(),
            };
            let code = r.code.map(|c| format!("[{c}]")).unwrap_or_default();
            format!("{location}error{code}: {}\n", r.message)
        }
        MessageFormat::Json => {
            let text =
                serde_json::to_string(&record(report)).unwrap_or_else(|_| String::from("{}"));
            format!("{text}\n")
        }
    }
}
