//! Measured data records: strict CSV reading (spec section 4) and CSV writing.
//!
//! A record is a CSV file with a header, a time column `t`, and one column per input and
//! measured state, uniformly sampled. Every defect is a [`DataError`] naming file, row and
//! column. The rules, in full:
//!
//! - The file is UTF-8 text (a leading byte-order mark is skipped); lines end in `\n` or
//!   `\r\n`; blank lines at the end are ignored, a blank line anywhere else is an error.
//! - The first line is the header: comma-separated column names, each non-empty and unique.
//!   One column is named `t` (time); each name the model needs must be present; other
//!   columns are ignored (never parsed).
//! - Every later line is one sample with exactly one cell per header column. Cells are
//!   trimmed of surrounding spaces and may be wrapped in double quotes; quoted commas are
//!   not supported. The cells of `t` and of the needed columns are finite decimal numbers
//!   (`20`, `-0.5`, `1.5e-2`); empty cells, `NaN` and infinities are errors.
//! - Time strictly increases with a uniform step: every step lies within a relative
//!   [`STEP_TOLERANCE`] of the median step (plus a few ulps of the largest time). The
//!   dataset's [`Dataset::step`] is the mean step.
//! - At least two data rows (to define the step), and at least as many as the model needs.
//!
//! Rows are numbered like lines, the header being row 1; columns from 1.

mod error;
mod read;

pub use error::{ColumnRef, DataError, DataSource, Location};
pub use read::STEP_TOLERANCE;

use crate::io::{write_atomic, IoError};
use std::path::{Path, PathBuf};

/// One named column of a record.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// Header name.
    pub name: String,
    /// Values, one per row.
    pub values: Vec<f64>,
}

/// A uniformly sampled record read from a CSV file.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Where it was read from (for messages).
    pub path: PathBuf,
    /// The time column `t`.
    pub times: Vec<f64>,
    /// The sampling step (uniform).
    pub step: f64,
    /// The requested columns, in the order asked for.
    pub columns: Vec<Column>,
}

impl Dataset {
    /// The values of column `name`, if present.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns
            .iter()
            .find(|c| c.name == name)
            .map(|c| c.values.as_slice())
    }
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.times.len()
    }
    /// Whether the record has no rows.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }
}

/// How many data rows a model needs, and why (for the message when a file has fewer).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MinRows {
    /// The least number of data rows (header excluded).
    pub rows: usize,
    /// Why, in words completing "expected at least N data rows (...)", e.g. "the embedding
    /// needs 46 rows of history".
    pub reason: String,
}

impl MinRows {
    /// A requirement of `rows` data rows for `reason`.
    pub fn new(rows: usize, reason: impl Into<String>) -> Self {
        MinRows {
            rows,
            reason: reason.into(),
        }
    }
}

impl From<usize> for MinRows {
    fn from(rows: usize) -> Self {
        MinRows::new(rows, format!("the model needs {rows}"))
    }
}

/// Reads the data file at `path`, keeping the time column and the `required` columns (in
/// that order), and checking every rule of the module documentation. `min_rows` is the
/// number of data rows the model needs: a bare number, or a [`MinRows`] saying why.
pub fn read(
    path: &Path,
    required: &[&str],
    min_rows: impl Into<MinRows>,
) -> Result<Dataset, DataError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| DataError::Unreadable {
        file: file.clone(),
        reason: crate::io::describe(&error),
    })?;
    let mut dataset = read::read_bytes(&file, bytes, required, &min_rows.into())?;
    dataset.path = path.to_path_buf();
    Ok(dataset)
}

/// Reads a data file from `text`, named `name` in messages; otherwise as [`read`].
pub fn read_str(
    name: &str,
    text: &str,
    required: &[&str],
    min_rows: impl Into<MinRows>,
) -> Result<Dataset, DataError> {
    read::read_text(name, text.to_string(), required, &min_rows.into())
}

/// Writes a table as CSV, atomically: a header line, then one line per row. Numbers are
/// written in their shortest form that reads back to the same `f64` (plain decimals, or
/// scientific notation such as `1e-7` for very small or large magnitudes). A non-finite
/// value is written as `NaN`, `inf` or `-inf` (which [`read`] rejects).
pub fn write_csv(path: &Path, header: &[String], columns: &[Vec<f64>]) -> Result<(), IoError> {
    let malformed = |detail: String| IoError::MalformedTable {
        path: path.display().to_string(),
        detail,
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
    let mut text = header.join(",");
    text.push('\n');
    for row in 0..rows {
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
