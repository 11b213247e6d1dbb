//! What the reader gives: a data set of experiments, each with its own time axis and the
//! requested columns, with cells that may be missing.

use super::error::{ColumnRef, DataError, DataSource, Location};
use super::scan::{clean, clean_range, scan_record};
use super::source::span;
use crate::numeric::OffGrid;
use miette::SourceSpan;
use std::path::PathBuf;

/// A data set: the experiments of one or more files, in the order read (files in the order
/// given, experiments of a file in the order of their first row).
#[derive(Debug, Clone)]
pub struct DataSet {
    /// The experiments; their names are distinct.
    pub experiments: Vec<Experiment>,
}

impl DataSet {
    /// The experiment named `name`, if any.
    #[cfg(test)]
    pub fn experiment(&self, name: &str) -> Option<&Experiment> {
        self.experiments.iter().find(|e| e.name == name)
    }
    /// The experiments' names, in order.
    #[cfg(test)]
    pub fn names(&self) -> Vec<&str> {
        self.experiments.iter().map(|e| e.name.as_str()).collect()
    }
    /// Number of experiments.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.experiments.len()
    }
    /// Whether every experiment has a value in every requested cell.
    #[cfg(test)]
    pub fn is_complete(&self) -> bool {
        self.experiments.iter().all(Experiment::is_complete)
    }
}

/// One experiment: one run of the process with its own time axis, initial state and
/// history. Nothing is carried from one experiment to the next.
#[derive(Debug, Clone)]
pub struct Experiment {
    /// Its name: the file's stem, or its value in the experiment column.
    pub name: String,
    /// The file it was read from.
    pub file: PathBuf,
    /// Sample times: strictly increasing, any spacing, not necessarily from 0.
    pub times: Vec<f64>,
    /// The 1-based row (line) of each sample in its file, for messages.
    pub rows: Vec<usize>,
    /// The requested columns that the file has, in the order requested.
    pub columns: Vec<Series>,
    /// The unit of the time column, from a header such as `t [h]`.
    #[cfg(test)]
    pub time_unit: Option<String>,
    /// Where the samples lie in the file, for diagnostics about them.
    pub origin: Origin,
}

/// One requested column of an experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// The model's name for it.
    pub name: String,
    /// Its header as written in the file, e.g. `Biomass [g/L]`.
    pub header: String,
    /// Its unit, from a header such as `X [g/L]`.
    pub unit: Option<String>,
    /// 1-based position of the column in its file.
    pub index: usize,
    /// One value per sample; `None` where it was not measured.
    pub values: Vec<Option<f64>>,
}

impl Series {
    /// The column as a [`ColumnRef`], for locations.
    pub fn column(&self) -> ColumnRef {
        ColumnRef {
            index: self.index,
            name: self.header.clone(),
        }
    }
    /// The samples where it was measured: `(sample index, value)`.
    #[cfg(test)]
    pub fn measured(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.values
            .iter()
            .enumerate()
            .filter_map(|(sample, value)| value.map(|value| (sample, value)))
    }
}

/// Where an experiment's samples lie in their file.
#[derive(Debug, Clone)]
pub struct Origin {
    /// The file as the user named it.
    pub file: String,
    /// The file's text.
    pub source: DataSource,
    /// The file's delimiter: `,`, `;` or tab.
    pub delimiter: u8,
    /// Byte offset of each sample's record in the file.
    pub starts: Vec<usize>,
    /// The time column.
    pub time: ColumnRef,
    /// The experiment column, where the file has one.
    pub experiment: Option<ColumnRef>,
}

impl Origin {
    /// The span of the cell of `sample` in the column at 1-based `index`, or of its whole
    /// record when `index` is `None` (or past the row's end).
    pub fn span(&self, sample: usize, index: Option<usize>) -> SourceSpan {
        let text = self.source.inner();
        let start = self.starts.get(sample).copied().unwrap_or_default();
        let mut fields = Vec::new();
        let end = scan_record(text, start, self.delimiter, &mut fields);
        match index.and_then(|index| fields.get(index.wrapping_sub(1))) {
            Some(raw) => span(clean_range(text, raw.clone())),
            None => span(start..end),
        }
    }
    /// The cleaned text of the cell of `sample` in the column at 1-based `index`.
    pub fn cell_text(&self, sample: usize, index: usize) -> &str {
        let span = self.span(sample, Some(index));
        let range = span.offset()..span.offset() + span.len();
        self.source
            .inner()
            .get(range)
            .map(clean)
            .unwrap_or_default()
    }
    /// A location at `row` of this file.
    pub fn at(&self, row: usize, column: Option<ColumnRef>) -> Box<Location> {
        Box::new(Location {
            file: self.file.clone(),
            row,
            column,
        })
    }
}

impl Experiment {
    /// Number of samples (rows).
    pub fn len(&self) -> usize {
        self.times.len()
    }
    /// The column the model calls `name`, if the file has it.
    pub fn series(&self, name: &str) -> Option<&Series> {
        self.columns.iter().find(|series| series.name == name)
    }
    /// Whether every requested column present has a value at every sample.
    #[cfg(test)]
    pub fn is_complete(&self) -> bool {
        self.columns
            .iter()
            .all(|series| series.values.iter().all(Option::is_some))
    }
    /// The mean step, when the times lie on a uniform grid within the tolerance fitted to
    /// them ([`crate::numeric::times`]: their printed precision and the scatter of their
    /// steps, at most a small share of the step). `None` for irregular times or fewer than
    /// two samples.
    #[cfg(test)]
    pub fn uniform_step(&self) -> Option<f64> {
        step_defect(&self.times).ok().flatten()
    }
    /// The uniform step, for a command that needs one: an error at the first step off the
    /// median step (E0215), or where there are fewer than two samples (E0216).
    pub fn require_uniform_step(&self) -> Result<f64, DataError> {
        match step_defect(&self.times) {
            Ok(Some(step)) => Ok(step),
            Ok(None) => {
                let last = self.len().saturating_sub(1);
                Err(DataError::TooFewRows {
                    src: self.origin.source.clone(),
                    span: self.origin.span(last, None),
                    needed: 2,
                    found: self.len(),
                    reason: "two rows are needed to define the sampling step".to_string(),
                    experiment: self.name.clone(),
                    at: self
                        .origin
                        .at(self.rows.get(last).copied().unwrap_or(1), None),
                })
            }
            Err(OffGrid { sample, expected }) => Err(DataError::UnevenStep {
                src: self.origin.source.clone(),
                span: self.origin.span(sample, Some(self.origin.time.index)),
                expected,
                found: self.times[sample] - self.times[sample - 1],
                previous: self.times[sample - 1],
                at: self
                    .origin
                    .at(self.rows[sample], Some(self.origin.time.clone())),
            }),
        }
    }
    /// Checks that no requested cell is missing, for a command that reads a complete record:
    /// the first missing cell (in file order) is an error, E0210 (E0212 for `NaN`).
    pub fn require_complete(&self) -> Result<(), DataError> {
        let mut order: Vec<&Series> = self.columns.iter().collect();
        order.sort_by_key(|series| series.index);
        for sample in 0..self.len() {
            for series in &order {
                if series.values[sample].is_none() {
                    return Err(self.missing_cell(sample, series));
                }
            }
        }
        Ok(())
    }

    /// The error for a missing cell where a complete record is needed.
    fn missing_cell(&self, sample: usize, series: &Series) -> DataError {
        let text = self.origin.cell_text(sample, series.index).to_string();
        let src = self.origin.source.clone();
        let span = self.origin.span(sample, Some(series.index));
        let at = self.origin.at(self.rows[sample], Some(series.column()));
        let help = "fill in the missing value: this command reads a complete record, and \
                    gaps in it are not interpolated"
            .to_string();
        let nan = text
            .trim_start_matches(['+', '-'])
            .eq_ignore_ascii_case("nan");
        if nan {
            return DataError::NotFinite {
                src,
                span,
                found: text,
                at,
                help,
            };
        }
        let found = if text.is_empty() {
            "an empty cell".to_string()
        } else {
            format!("`{text}`")
        };
        DataError::EmptyCell {
            src,
            span,
            expected: "a number",
            found,
            at,
            help,
        }
    }
}

/// The mean step of `times` if they lie on a uniform grid within their own fitted
/// tolerance ([`crate::numeric::time_tolerance`]; `None` for fewer than two times), else
/// the first sample off it.
fn step_defect(times: &[f64]) -> Result<Option<f64>, OffGrid> {
    crate::numeric::grid_step(times, crate::numeric::time_tolerance(times))
}
