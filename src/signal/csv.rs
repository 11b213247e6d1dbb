//! `csv(FILE, COLUMN, EXPERIMENT)`: an input column of a data file, read by the one data
//! reader ([`crate::data::read_set`]) as any record's input is, and held between its values.

use super::error::SignalError;
use super::generate::Context;
use super::parse::Piece;
use super::piecewise::Signal;
use crate::data::{read_set, Experiment, Request, Series, Wanted};
use crate::suggest::did_you_mean;
use std::path::PathBuf;

/// What a `csv(...)` program names: the file, the column and the experiment, as written.
pub(super) struct CsvSource<'a> {
    pub file: &'a Piece,
    pub column: Option<&'a Piece>,
    pub experiment: Option<&'a Piece>,
}

impl Context<'_> {
    /// Column `column` (default: the input's name) of one experiment of a data file, as an
    /// input: a value at its first row, then each value held until the next given one
    /// (empty and `NA` cells hold), at any spacing of times. The file must cover the grid.
    pub fn csv(&self, csv: &CsvSource) -> Result<Signal, SignalError> {
        let name = csv
            .column
            .map_or(self.input.name.as_str(), |piece| &piece.text);
        let request = Request::new(vec![Wanted::input(name)]);
        let set = read_set(&[PathBuf::from(&csv.file.text)], &request)?;
        let experiment = self.experiment_of(csv, &set.experiments)?;
        let series = experiment.series(name).ok_or_else(|| {
            SignalError::InvalidSignal(crate::error::Bug::new(
                "a csv input",
                format!("expected the column `{name}` the reader was asked for, found none"),
            ))
        })?;
        self.covers(csv.file, experiment)?;
        let values = self.held(csv.file, experiment, series)?;
        Signal::at_changes(&experiment.times, &values)
    }

    /// The experiment `experiment=` names, or the file's only one.
    fn experiment_of<'e>(
        &self,
        csv: &CsvSource,
        experiments: &'e [Experiment],
    ) -> Result<&'e Experiment, SignalError> {
        let names: Vec<&str> = experiments.iter().map(|e| e.name.as_str()).collect();
        if let Some(chosen) = csv.experiment {
            let found = experiments.iter().find(|e| e.name == chosen.text);
            return found.ok_or_else(|| SignalError::CsvUnknownExperiment {
                src: self.source.clone(),
                span: chosen.span,
                file: csv.file.text.clone(),
                name: chosen.text.clone(),
                help: did_you_mean(&chosen.text, &names, "its experiments"),
            });
        }
        match experiments {
            [only] => Ok(only),
            _ => Err(SignalError::CsvSeveralExperiments {
                src: self.source.clone(),
                span: csv.file.span,
                file: csv.file.text.clone(),
                count: names.len(),
                names: quoted(&names),
                help: format!(
                    "choose one with `csv(FILE, COLUMN, experiment=NAME)`, e.g. \
                     `experiment={}`",
                    names.first().copied().unwrap_or("NAME")
                ),
            }),
        }
    }

    /// Checks that the experiment covers the grid: its first time at or before the start,
    /// its last time held for one more interval (its last step or the sampling step, the
    /// longer) at or after the end.
    fn covers(&self, file: &Piece, experiment: &Experiment) -> Result<(), SignalError> {
        let times = &experiment.times;
        let (Some(&first), Some(&last)) = (times.first(), times.last()) else {
            return Ok(());
        };
        let last_step = match times.len() {
            0 | 1 => 0.0,
            n => times[n - 1] - times[n - 2],
        };
        let slack = 1e-6 * self.grid.dt;
        let reach = last + last_step.max(self.grid.dt);
        if first > self.grid.t_start + slack || reach < self.grid.t_end - slack {
            return Err(SignalError::CsvCoverage {
                src: self.source.clone(),
                span: file.span,
                file: file.text.clone(),
                t_start: self.grid.t_start,
                t_end: self.grid.t_end,
                first,
                last,
            });
        }
        Ok(())
    }

    /// The value in force at each row: the given one, else the last given one (the reader
    /// has checked that the first row has one); each given value within the input's bounds.
    fn held(
        &self,
        file: &Piece,
        experiment: &Experiment,
        series: &Series,
    ) -> Result<Vec<f64>, SignalError> {
        let mut values = Vec::with_capacity(series.values.len());
        let mut last = f64::NAN;
        for (sample, given) in series.values.iter().enumerate() {
            if let Some(value) = *given {
                let origin = format!(
                    " in `{}` row {}, column `{}`",
                    file.text, experiment.rows[sample], series.header
                );
                self.within(value, file.span, origin)?;
                last = value;
            }
            values.push(last);
        }
        Ok(values)
    }
}

/// Names in backquotes, separated by commas.
fn quoted(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|name| format!("`{name}`")).collect();
    quoted.join(", ")
}
