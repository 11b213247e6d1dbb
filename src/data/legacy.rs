//! The single-record view: one file, one experiment, uniformly sampled and complete, as the
//! commands read data before data sets. Built on the data-set reader, so both accept the
//! same files (delimiters, units, `time`, quotes), then checked for what a single record
//! needs on top.

use super::error::DataError;
use super::request::{MinRows, Request, Wanted};
use super::set::{check_length, check_times, experiments, load};
use super::source::Source;
use std::path::{Path, PathBuf};

/// One named column of a single record.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// The requested name.
    pub name: String,
    /// Values, one per row.
    pub values: Vec<f64>,
}

/// A single uniformly sampled, complete record: what [`read`] gives (the single-record
/// view, retired once the commands read [`DataSet`](super::DataSet)s).
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Where it was read from (for messages).
    pub path: PathBuf,
    /// The time column.
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

/// Reads the data file at `path`, keeping the time column and the `required` columns (in
/// that order): one experiment, every requested cell measured, a uniform time step, and
/// at least `min_rows` rows (at least two, to define the step). `min_rows` is a bare
/// number, or a [`MinRows`] saying why.
///
/// This is the single-record view of [`read_set`](super::read_set), kept while the
/// commands move to data sets; it will be retired once they have.
pub fn read(
    path: &Path,
    required: &[&str],
    min_rows: impl Into<MinRows>,
) -> Result<Dataset, DataError> {
    record(load(path)?, required, &min_rows.into())
}

/// Reads a data file from `text`, named `name` in messages; otherwise as [`read`] (and
/// retired with it).
#[cfg(test)]
pub fn read_str(
    name: &str,
    text: &str,
    required: &[&str],
    min_rows: impl Into<MinRows>,
) -> Result<Dataset, DataError> {
    let source = Source::new(name, PathBuf::from(name), text.to_string());
    record(source, required, &min_rows.into())
}

/// Reads `source` as one complete, uniformly sampled record.
fn record(source: Source, required: &[&str], min_rows: &MinRows) -> Result<Dataset, DataError> {
    let path = source.path.clone();
    let request = Request::new(required.iter().map(|name| Wanted::state(*name)).collect());
    let mut read = experiments(vec![source], &request)?.into_iter();
    let Some(experiment) = read.next() else {
        // A file with data rows has an experiment; this is defensive.
        return Err(DataError::Unreadable {
            file: path.display().to_string(),
            reason: "expected an experiment, found none".to_string(),
        });
    };
    if let Some(second) = read.next() {
        let names: Vec<String> = std::iter::once(&experiment)
            .chain(std::iter::once(&second))
            .chain(read.as_slice())
            .map(|e| format!("`{}`", e.name))
            .collect();
        let origin = &second.origin;
        let column = origin.experiment.clone();
        return Err(DataError::SeveralExperiments {
            src: origin.source.clone(),
            span: origin.span(0, column.as_ref().map(|c| c.index)),
            count: names.len(),
            names: names.join(", "),
            at: origin.at(second.rows[0], column),
        });
    }
    experiment.require_complete()?;
    check_times(&experiment)?;
    let step = match experiment.len() {
        0 | 1 => 0.0,
        _ => experiment.require_uniform_step()?,
    };
    let needed = if min_rows.rows >= 2 {
        min_rows.clone()
    } else {
        MinRows::new(2, "two rows are needed to define the sampling step")
    };
    check_length(&experiment, &needed)?;
    Ok(Dataset {
        path,
        times: experiment.times,
        step,
        columns: experiment
            .columns
            .into_iter()
            .map(|series| Column {
                name: series.name,
                values: (series.values.into_iter())
                    .map(|value| value.unwrap_or(f64::NAN))
                    .collect(),
            })
            .collect(),
    })
}
