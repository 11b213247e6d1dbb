//! Measured data records: strict CSV reading (spec section 4).
//!
//! A record is a CSV file with a header, a time column `t`, and one column per input and
//! measured state, uniformly sampled. Every defect is a [`DataError`] naming file, row and
//! column.

use std::path::PathBuf;

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
