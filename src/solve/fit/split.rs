//! The data the diagnosis fits and scores (records spec, sections 1 and 3; spec section 5):
//! the experiments in model terms ([`Record`]), the rows of each that the fits minimise and
//! the rows that are scored, where each free run starts, and the statistics that z-score
//! every error.
//!
//! - **Whole experiments** (`--holdout NAME`, `--val FILE`): a training experiment fits on
//!   all its rows, a held-out one is scored on all its rows after the first (its start).
//! - **Tail** (`--val-fraction SHARE`, and by default, when no experiment is held out, a
//!   share of 0.3 of every experiment):
//!   the last share of each training experiment's measured rows is scored and the rows
//!   before it fit; the free run still starts at the experiment's first row, so a good score
//!   means the whole run is good.
//!
//! Every free run starts at its experiment's first row ([`Start`]): a measured state takes
//! its cell there; without one, its declared initial value; without one, a value fitted
//! with the params (in an experiment with a training part) or, in an experiment that is only
//! scored, its first measured value there (nothing may be fitted on held-out data). Hidden
//! states take their declared initial values.

use super::error::FitError;
use crate::ir::Model;
use crate::record::{Normalisation, Record};
use std::ops::Range;

/// The fewest measured rows in the training part (`--min-rows`); a held-out part with
/// fewer is still scored, and the report says its score rests on few rows.
pub const MIN_ROWS: usize = 10;
/// The fewest measured rows a held-out part is scored on.
pub const MIN_SCORED_ROWS: usize = 1;

/// One experiment's place in the diagnosis.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Part {
    /// Rows whose measured cells the fits minimise (empty for a held-out experiment).
    pub train: Range<usize>,
    /// Rows whose measured cells are scored (empty for an experiment that only trains).
    pub test: Range<usize>,
}

/// Where a measured state's free run starts in one experiment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// The experiment's cell at its first row.
    Cell,
    /// The model's declared initial value (under the current params).
    Declared,
    /// A value fitted with the params: index into the fitted starts.
    Fitted(usize),
    /// The cell at the first row of an experiment with a training part, fitted with the
    /// params (index into the fitted starts) from that cell: it is a measurement as noisy
    /// as any other, and it stays a residual of the fit, so the start moves only as far as
    /// the run after it asks and the params' standard errors count its uncertainty.
    CellFitted(usize),
    /// A fixed value (an experiment that is only scored: its first measured value).
    Fixed(f64),
}

/// How the held-out part was chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Holdout {
    /// Whole experiments are held out.
    Experiments,
    /// The last share of each training experiment's measured rows.
    Tail(f64),
}

/// The experiments, their parts and starts, and the training statistics.
#[derive(Debug, Clone, PartialEq)]
pub struct Split {
    /// Every experiment, training ones first.
    pub records: Vec<Record>,
    /// One part per record.
    pub parts: Vec<Part>,
    /// Per record, per measured state: where its free run starts.
    pub starts: Vec<Vec<Start>>,
    /// The fitted starts: `(record, state)` of each, in order.
    pub fitted_starts: Vec<(usize, usize)>,
    /// Per fitted start (in the order of [`Split::fitted_starts`]), the range a fit may
    /// move it in: a measured first cell's plausible values given its noise
    /// ([`super::noise::fit_uncertain_starts`]); `None`: free.
    pub start_bounds: Vec<Option<(f64, f64)>>,
    /// How the held-out part was chosen.
    pub holdout: Holdout,
    /// Whether hidden states start from values fitted per training experiment.
    pub fit_hidden: bool,
    /// Mean and standard deviation of each measured state over the training cells.
    pub normalisation: Normalisation,
    /// Per state, its declared measurement noise and the root mean square of its standard
    /// deviation over the training cells (`None`: not declared, estimated from the data).
    pub declared: Vec<Option<(crate::ir::Noise, f64)>>,
}

impl Split {
    /// The split of `train` (experiments that fit; with `Tail`, their tails are scored) and
    /// `held` (experiments that are only scored), the training part needing [`MIN_ROWS`].
    #[cfg(test)]
    pub fn new(
        model: &Model,
        train: Vec<Record>,
        held: Vec<Record>,
        (holdout, fit_hidden): (Holdout, bool),
    ) -> Result<Split, FitError> {
        Split::with_min_rows(model, (train, held), (holdout, fit_hidden), MIN_ROWS)
    }

    /// [`Split::new`], the training part needing `min_rows` measured rows (`--min-rows`) and
    /// the held-out part [`MIN_SCORED_ROWS`]: sparse assays are the norm, and a held-out
    /// experiment of a few rows is scored (the report says how few), not refused.
    pub fn with_min_rows(
        model: &Model,
        (train, held): (Vec<Record>, Vec<Record>),
        (holdout, fit_hidden): (Holdout, bool),
        min_rows: usize,
    ) -> Result<Split, FitError> {
        let mut parts = Vec::with_capacity(train.len() + held.len());
        for record in &train {
            parts.push(match holdout {
                Holdout::Tail(share) => tail(record, share)?,
                Holdout::Experiments => Part {
                    train: 0..record.len(),
                    test: 0..0,
                },
            });
        }
        // A held-out experiment's free run starts from its first row: those cells are the
        // start, not a prediction, and are not scored (as `gbc train` and `gbc predict`
        // score; `docs/error-measure.md`).
        parts.extend(held.iter().map(|record| Part {
            train: 0..0,
            test: 1.min(record.len())..record.len(),
        }));
        let mut records = train;
        records.extend(held);
        let count = |pick: &dyn Fn(&Part) -> Range<usize>| -> usize {
            (records.iter().zip(&parts))
                .map(|(record, part)| measured_rows(record, pick(part)).count())
                .sum()
        };
        let (fit, scored) = (count(&|p| p.train.clone()), count(&|p| p.test.clone()));
        if fit < min_rows || scored < MIN_SCORED_ROWS {
            return Err(FitError::TooFewRows {
                needed: min_rows,
                train: fit,
                test: scored,
                how: describe(&records, &parts, holdout),
            });
        }
        Ok(Split::from_parts(
            model,
            (records, parts),
            (holdout, fit_hidden),
        ))
    }

    /// A split that only fits: every row of every experiment in `train` trains and none is
    /// scored (a mechanism fitted for `gbc train`, which scores on its own split). Needs
    /// `min_rows` measured rows.
    pub fn fit_only(
        model: &Model,
        train: Vec<Record>,
        fit_hidden: bool,
        min_rows: usize,
    ) -> Result<Split, FitError> {
        let parts: Vec<Part> = (train.iter())
            .map(|record| Part {
                train: 0..record.len(),
                test: 0..0,
            })
            .collect();
        let fit: usize = (train.iter())
            .map(|record| measured_rows(record, 0..record.len()).count())
            .sum();
        if fit < min_rows {
            return Err(FitError::TooFewRows {
                needed: min_rows,
                train: fit,
                test: 0,
                how: "every row of the training experiments fits".into(),
            });
        }
        let split = (train, parts);
        Ok(Split::from_parts(
            model,
            split,
            (Holdout::Experiments, fit_hidden),
        ))
    }

    /// The split of `records` into `parts`: the training statistics and every start.
    fn from_parts(
        model: &Model,
        (records, parts): (Vec<Record>, Vec<Part>),
        (holdout, fit_hidden): (Holdout, bool),
    ) -> Split {
        let trained: Vec<(&Record, Range<usize>)> = (records.iter().zip(&parts))
            .filter(|(_, part)| !part.train.is_empty())
            .map(|(record, part)| (record, part.train.clone()))
            .collect();
        let normalisation = Normalisation::over(&trained, model.states.len(), model.inputs.len());
        let mut records = records;
        let names: Vec<String> = model.outputs.iter().map(|o| o.name.clone()).collect();
        for record in &mut records {
            record.align_observables(&normalisation.observables, &names);
        }
        let columns = normalisation.columns();
        let mut split = Split {
            records,
            parts,
            starts: Vec::new(),
            fitted_starts: Vec::new(),
            start_bounds: Vec::new(),
            holdout,
            fit_hidden,
            normalisation,
            declared: vec![None; columns],
        };
        split.plan_starts(model, &[]);
        split
    }

    /// The share of the training cells (after each experiment's first row) whose previous
    /// row measures the same state: the one-step pairs a correction can be fitted on. Dense
    /// records have 1; off-line assays between on-line rows, much less.
    pub fn one_step_share(&self) -> f64 {
        let (mut paired, mut cells) = (0usize, 0usize);
        for (_, record, rows) in self.training() {
            for column in record.columns() {
                for row in rows.clone().skip(1) {
                    if column[row].is_some() {
                        cells += 1;
                        paired += usize::from(column[row - 1].is_some());
                    }
                }
            }
        }
        paired as f64 / cells.max(1) as f64
    }

    /// Takes the declared measurement noise of the measured states and observables
    /// (`ir::Noise`): their noise floor and the weights of their cells in the fits.
    pub fn declare_noise(&mut self, noise: &[crate::ir::Noise]) {
        let norm = &self.normalisation;
        for declared in noise {
            let k = match declared.target {
                crate::ir::Measured::State(k) => k,
                crate::ir::Measured::Output(output) => {
                    match norm.observables.iter().position(|&o| o == output) {
                        Some(j) => norm.state_std.len() + j,
                        None => continue,
                    }
                }
            };
            let variances: Vec<f64> = (self.training())
                .flat_map(|(_, record, rows)| record.column(k)[rows].iter().flatten().copied())
                .map(|value| declared.variance(value))
                .collect();
            let mean = variances.iter().sum::<f64>() / variances.len().max(1) as f64;
            if mean > 0.0 && mean.is_finite() {
                self.declared[k] = Some((*declared, mean.sqrt()));
            }
        }
    }

    /// The weight of a measured cell of column `k` (a measured state or an observable,
    /// [`Record::columns`]) with value `value` in the fits: the
    /// declared noise's root mean square over the state's training cells divided by the
    /// cell's own (1 without a declaration). Relative noise weighs small values more; the
    /// weights of a state average 1 in the square, so the fit's gap stays on the scale of the
    /// variance-normalised error.
    pub fn weight(&self, k: usize, value: f64) -> f64 {
        match &self.declared[k] {
            Some((noise, rms)) => {
                let sigma = noise.sigma(value);
                if sigma > 0.0 {
                    rms / sigma
                } else {
                    1.0
                }
            }
            None => 1.0,
        }
    }

    /// Fits the first row's measured cells of every training experiment as unknowns
    /// ([`Start::CellFitted`]) where `uncertain[record][state]` says so, instead of starting
    /// the free runs at them.
    pub fn fit_measured_starts(&mut self, model: &Model, uncertain: &[Vec<bool>]) {
        self.starts.clear();
        self.fitted_starts.clear();
        self.start_bounds.clear();
        self.plan_starts(model, uncertain);
    }

    /// Decides where every measured state's free run starts (see the module documentation);
    /// a training experiment's measured first cells are fitted starts where `fit_cells`
    /// says so (empty: none).
    fn plan_starts(&mut self, model: &Model, fit_cells: &[Vec<bool>]) {
        for (index, (record, part)) in self.records.iter().zip(&self.parts).enumerate() {
            let mut starts = Vec::with_capacity(model.states.len());
            for (k, state) in model.states.iter().enumerate() {
                let cells = &record.states[k];
                let measured = cells.first().copied().flatten().is_some();
                let fit = (fit_cells.get(index)).is_some_and(|row| row.get(k) == Some(&true));
                starts.push(if fit && measured && !part.train.is_empty() {
                    self.fitted_starts.push((index, k));
                    Start::CellFitted(self.fitted_starts.len() - 1)
                } else if measured {
                    Start::Cell
                } else if state.init.is_some() {
                    Start::Declared
                } else if !part.train.is_empty() {
                    self.fitted_starts.push((index, k));
                    Start::Fitted(self.fitted_starts.len() - 1)
                } else {
                    let first = cells.iter().flatten().next().copied();
                    Start::Fixed(first.unwrap_or(self.normalisation.state_mean[k]))
                });
            }
            self.starts.push(starts);
        }
    }

    /// Per state (measured, then the `hidden` hidden ones) of `record`: the value its free
    /// run starts from when not read from the data or the declaration, given the fitted
    /// starts `fitted` (the measured ones of [`Split::fitted_starts`], then, with
    /// `fit_hidden`, `hidden` per training record in [`Split::training`] order).
    pub fn overrides(&self, record: usize, fitted: &[f64], hidden: usize) -> Vec<Option<f64>> {
        let mut overrides: Vec<Option<f64>> = (self.starts[record].iter())
            .map(|start| match *start {
                Start::Fitted(index) | Start::CellFitted(index) => fitted.get(index).copied(),
                Start::Fixed(value) => Some(value),
                Start::Cell | Start::Declared => None,
            })
            .collect();
        let first = self.first_hidden_start(record, hidden);
        overrides.extend((0..hidden).map(|h| first.and_then(|f| fitted.get(f + h).copied())));
        overrides
    }

    /// The index into the fitted starts of `record`'s first hidden start, where its hidden
    /// starts are fitted (`--fit-initial` and a training record).
    fn first_hidden_start(&self, record: usize, hidden: usize) -> Option<usize> {
        let slot = self
            .fit_hidden
            .then(|| self.training_slot(record))
            .flatten()?;
        Some(self.fitted_starts.len() + slot * hidden)
    }

    /// Per state (measured, then the `hidden` hidden ones) of `record`: the index into the
    /// fitted starts of the value it starts from, where that is one (as
    /// [`Split::overrides`] reads them).
    pub fn fitted_indices(&self, record: usize, hidden: usize) -> Vec<Option<usize>> {
        let mut indices: Vec<Option<usize>> = (self.starts[record].iter())
            .map(|start| match *start {
                Start::Fitted(index) | Start::CellFitted(index) => Some(index),
                _ => None,
            })
            .collect();
        let first = self.first_hidden_start(record, hidden);
        indices.extend((0..hidden).map(|h| first.map(|f| f + h)));
        indices
    }

    /// Whether fitted start `index` is a first row's measured cell ([`Start::CellFitted`]):
    /// its data pin it, so random restarts leave it where the cell is.
    pub fn cell_fitted(&self, index: usize) -> bool {
        (self.fitted_starts.get(index))
            .is_some_and(|&(record, k)| matches!(self.starts[record][k], Start::CellFitted(_)))
    }

    /// The position of `record` among the records with a training part.
    pub fn training_slot(&self, record: usize) -> Option<usize> {
        self.training().position(|(index, _, _)| index == record)
    }

    /// Number of fitted starts of a model with `hidden` hidden states.
    pub fn fitted_count(&self, hidden: usize) -> usize {
        let per_record = if self.fit_hidden { hidden } else { 0 };
        self.fitted_starts.len() + per_record * self.training().count()
    }

    /// The measured column (state or observable) of every training cell, in the order of
    /// the fits' residuals (experiment by experiment, row by row, column by column).
    pub fn training_cell_states(&self) -> Vec<usize> {
        let mut states = Vec::with_capacity(self.training_cells());
        for (_, record, rows) in self.training() {
            for row in rows {
                for (k, column) in record.columns().enumerate() {
                    if column[row].is_some() {
                        states.push(k);
                    }
                }
            }
        }
        states
    }

    /// The records with a training part, with their indices and training rows.
    pub fn training(&self) -> impl Iterator<Item = (usize, &Record, Range<usize>)> + '_ {
        self.with(|part| part.train.clone())
    }

    /// The records with a scored part, with their indices and scored rows.
    pub fn scored(&self) -> impl Iterator<Item = (usize, &Record, Range<usize>)> + '_ {
        self.with(|part| part.test.clone())
    }

    fn with<'a>(
        &'a self,
        pick: impl Fn(&Part) -> Range<usize> + 'a,
    ) -> impl Iterator<Item = (usize, &'a Record, Range<usize>)> + 'a {
        (self.records.iter().zip(&self.parts).enumerate())
            .map(move |(index, (record, part))| (index, record, pick(part)))
            .filter(|(_, _, rows)| !rows.is_empty())
    }

    /// Measured cells (states and observables) in the training parts.
    pub fn training_cells(&self) -> usize {
        (self.training())
            .map(|(_, record, rows)| cells_in(record, rows))
            .sum()
    }

    /// Measured rows in the training and in the scored parts.
    pub fn measured_rows(&self) -> (usize, usize) {
        let count = |rows: &mut dyn Iterator<Item = (usize, &Record, Range<usize>)>| {
            rows.map(|(_, record, rows)| measured_rows(record, rows).count())
                .sum()
        };
        (count(&mut self.training()), count(&mut self.scored()))
    }
}

/// The rows of `rows` with at least one measured cell (a state or an observable).
pub fn measured_rows(record: &Record, rows: Range<usize>) -> impl Iterator<Item = usize> + '_ {
    rows.filter(|&row| record.columns().any(|cells| cells[row].is_some()))
}

/// Measured cells (states and observables) of `record` in `rows`.
pub fn cells_in(record: &Record, rows: Range<usize>) -> usize {
    (record.columns())
        .map(|cells| cells[rows.clone()].iter().flatten().count())
        .sum()
}

/// The tail split of one experiment: the last `share` of its measured rows is scored.
fn tail(record: &Record, share: f64) -> Result<Part, FitError> {
    let rows: Vec<usize> = measured_rows(record, 0..record.len()).collect();
    let held = ((rows.len() as f64) * share).round() as usize;
    if held == 0 || held >= rows.len() {
        return Err(FitError::TailTooSmall {
            experiment: record.name.clone(),
            share,
            train: rows.len().saturating_sub(held),
            test: held.min(rows.len()),
        });
    }
    let first_test = rows[rows.len() - held];
    Ok(Part {
        train: 0..first_test,
        test: first_test..record.len(),
    })
}

/// What was held out, in words (for messages).
fn describe(records: &[Record], parts: &[Part], holdout: Holdout) -> String {
    let held: Vec<&str> = (records.iter().zip(parts))
        .filter(|(_, part)| part.train.is_empty())
        .map(|(record, _)| record.name.as_str())
        .collect();
    let experiments = match held.as_slice() {
        [] => String::new(),
        [one] => format!("experiment `{one}` held out"),
        many => format!("experiments {} held out", many.join(", ")),
    };
    match holdout {
        Holdout::Tail(share) => {
            let tail = format!("the last {} % of each experiment held out", 100.0 * share);
            if experiments.is_empty() {
                tail
            } else {
                format!("{tail}, {experiments}")
            }
        }
        Holdout::Experiments => experiments,
    }
}

#[cfg(test)]
mod tests;
