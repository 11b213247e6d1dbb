//! Measured data: data sets of experiments read from CSV files (records.md), and CSV
//! writing.
//!
//! Every command that reads data goes through [`read_set`]: a list of files and a
//! [`Request`] (the columns the model reads, with their [`Role`]s, the `--column`
//! mappings, and how many rows an experiment needs) give a [`DataSet`] of [`Experiment`]s,
//! each with its own time axis and its requested columns as [`Series`] of cells that may be
//! missing. Every defect is a [`DataError`] with a code, naming file, row and column, with
//! a label on the cell. The rules, in full:
//!
//! - **Text.** A file is UTF-8 (a leading byte-order mark is skipped; a file that is not is
//!   an error at its first bad byte); lines end in `\n` or `\r\n`; blank lines before the
//!   header and at the end are ignored, a blank line among the data rows is an error.
//! - **Delimiter.** `,`, `;` or tab, sniffed from the header and the first data rows: the
//!   one that splits the header into the most fields and each of those rows into as many
//!   (ties go to tab, then `;`). Fields may be quoted with `"` (a quoted field may hold the
//!   delimiter; `""` is a quote). A row that does not split into the header's fields is an
//!   error; one that would with another delimiter is reported as a file mixing delimiters.
//! - **Header.** The first line that is not blank: every cell named, no name twice. A
//!   header `X [g/L]` names column `X`, with unit `g/L` (kept for labels); two headers with
//!   the same name are an error even with different units. Columns nobody asks for are
//!   never parsed.
//! - **Time column.** The header named by `--column t=HEADER`; else the column `t` (`t [h]`
//!   included); else the single column named `time` in any case (`Time [h]`); else an error
//!   whose help lists the headers.
//! - **Experiments.** A file is one experiment named by its stem, unless it has an
//!   experiment column (the header `experiment`, or the one named by `--column
//!   experiment=HEADER`): then each distinct value of that column is an experiment, in the
//!   order of its first row; its rows need not be contiguous, and their file order is their
//!   time order. Files with and without an experiment column may be mixed. Two experiments
//!   of a set with the same name are an error naming both places.
//! - **Columns.** A requested column is the header with its name, or the header named by
//!   `--column NAME=HEADER` (matched as written, or without its unit). A mapping whose NAME
//!   is not requested (nor `t` or `experiment`), or given twice, is an error. A mapped
//!   header missing from a file is an error there, unless the column is optional (or is
//!   the experiment column) and another file of the set has it. An input or a state the
//!   file lacks is an error; an optional column it lacks is simply absent.
//! - **Cells.** Cells are trimmed of spaces. A number is a finite decimal (`20`, `-0.5`,
//!   `1.5e-2`); in a file separated by `;` or tabs a decimal comma is accepted (`1,5` is
//!   1.5). An empty cell, `NA`, `N/A` or `NaN` (any case) means *not measured* (`None`).
//!   Infinity (`inf`, `Infinity`, `1e999`) and text are errors; so is a time or an
//!   experiment name that is not given.
//! - **Time.** Strictly increasing within an experiment, with any spacing, from any start:
//!   two rows at the same time are an error naming both rows, time going back is an error.
//! - **Roles.** An [`Role::Input`] has a value at its experiment's first row (it holds its
//!   last value until the next: zero-order hold is the consumer's business). A
//!   [`Role::State`] has at least one value in each experiment. A [`Role::Optional`] column
//!   may be absent or empty.
//! - **Length.** Each experiment has at least [`Request::min_rows`] rows; the error says
//!   how many it has, how many are needed, and why.
//!
//! Rows are numbered like lines, the header being row 1 (in a file with leading blank
//! lines, the header's own line); columns from 1. [`read`] and [`read_str`] are the
//! single-record view (one experiment, complete, uniform step) that the commands use until
//! they move to data sets.

mod cells;
mod error;
mod experiment;
mod file;
mod header;
mod legacy;
mod request;
mod scan;
mod set;
mod sniff;
mod source;

pub use error::DataError;
pub use experiment::{DataSet, Experiment, Series};
#[cfg(test)]
pub use legacy::read_str;
pub use legacy::{read, Column, Dataset};
pub use request::{parse_mapping, MinRows, Request, Wanted};
pub use set::{read_set, read_set_str};

use crate::io::{write_atomic, IoError};
use std::path::Path;

/// Writes a table as CSV, atomically: a header line, then one line per row. Numbers are
/// written in their shortest form that reads back to the same `f64` (plain decimals, or
/// scientific notation such as `1e-7` for very small or large magnitudes). A table holding
/// a value that is not finite is not written: [`IoError::NotFinite`] names the earliest
/// (see [`crate::finite`]).
pub fn write_csv(path: &Path, header: &[String], columns: &[Vec<f64>]) -> Result<(), IoError> {
    write_table(path, None, header, columns)
}

/// Writes a table as [`write_csv`] does, with a leading text column `(name, labels)` (one
/// label per row, quoted where it needs to be), e.g. the experiment of each row.
pub fn write_table(
    path: &Path,
    labels: Option<(&str, &[String])>,
    header: &[String],
    columns: &[Vec<f64>],
) -> Result<(), IoError> {
    let malformed = |detail: String| {
        IoError::MalformedTable(crate::error::Bug::new(
            "a table writer",
            format!("cannot write `{}`: {detail}", path.display()),
        ))
    };
    if header.len() != columns.len() {
        return Err(malformed(format!(
            "expected {} columns (one per header name), found {}",
            header.len(),
            columns.len()
        )));
    }
    let rows = columns.first().map_or(0, Vec::len);
    if let Some((index, column)) = columns.iter().enumerate().find(|(_, c)| c.len() != rows) {
        return Err(malformed(format!(
            "expected {rows} values in column {} `{}`, found {}",
            index + 1,
            header[index],
            column.len()
        )));
    }
    if let Some((_, names)) = labels.filter(|(_, names)| names.len() != rows) {
        return Err(malformed(format!(
            "expected {rows} row labels, found {}",
            names.len()
        )));
    }
    let named: Vec<(&str, &[f64])> = (header.iter().zip(columns))
        .map(|(name, values)| (name.as_str(), values.as_slice()))
        .collect();
    crate::finite::refuse(path, crate::finite::in_table(&named), NOT_FINITE_HELP)?;
    let quote = |text: &str| {
        if text.contains([',', '"', '\n', '\r']) {
            format!("\"{}\"", text.replace('"', "\"\""))
        } else {
            text.to_string()
        }
    };
    let mut text = String::new();
    if let Some((name, _)) = labels {
        text.push_str(&quote(name));
        text.push(',');
    }
    text.push_str(
        &header
            .iter()
            .map(|h| quote(h))
            .collect::<Vec<_>>()
            .join(","),
    );
    text.push('\n');
    for row in 0..rows {
        if let Some((_, names)) = labels {
            text.push_str(&quote(&names[row]));
            text.push(',');
        }
        for (index, column) in columns.iter().enumerate() {
            if index > 0 {
                text.push(',');
            }
            text.push_str(&format_number(column[row]));
        }
        text.push('\n');
    }
    write_atomic(path, text.as_bytes())
}

/// What to do about a table that went non-finite.
pub const NOT_FINITE_HELP: &str = "the run that computed it went non-finite there; check the \
     model's expressions at that time (a division by zero, a log or square root of a negative \
     value) or shorten the run";

/// The shortest text that parses back to exactly `value`: Rust's `Display` (which never
/// uses an exponent) for ordinary magnitudes, `LowerExp` outside `[1e-5, 1e16)`.
pub fn format_number(value: f64) -> String {
    let magnitude = value.abs();
    if magnitude == 0.0 || !value.is_finite() || (1e-5..1e16).contains(&magnitude) {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_set;
#[cfg(test)]
mod tests_set_errors;
