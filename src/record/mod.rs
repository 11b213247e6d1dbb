//! A data set in model terms (records spec, sections 1-3): one [`Record`] per experiment,
//! with the model's inputs held between their given values, its measured states and
//! measured outputs (observables) as cells that may be missing, and the statistics that
//! z-score every error ([`Normalisation`], over measured cells only).
//!
//! Training lays each record on its integration grid ([`grid::Track`]); the diagnosis runs
//! its simulator along the record's own rows. Both read data through this one type.

pub mod bind;
pub mod grid;
pub mod measure;
#[cfg(test)]
mod tests;

pub use bind::{bind, request};
pub use grid::{GridOptions, Track};

/// One column of cells: `None` where nothing was measured at that row.
pub type Cells = Vec<Option<f64>>;

/// One experiment in model terms.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// The experiment's name (a file stem or a value of the experiment column).
    pub name: String,
    /// Where it was read from, for messages.
    pub source: String,
    /// Sample times, strictly increasing.
    pub times: Vec<f64>,
    /// `inputs[i][row]`: input `i` held from `row` until the next row (zero-order hold,
    /// already carried forward over rows that gave no value).
    pub inputs: Vec<Vec<f64>>,
    /// `states[i][row]`: measured state `i` (model order); a state without a data
    /// column has every cell `None`.
    pub states: Vec<Cells>,
    /// The model outputs that are measured (observables), with their cells.
    pub observables: Vec<Observable>,
}

/// A model `output` matched to a data column: it enters the loss and the gap at its
/// measured cells like a measured state.
#[derive(Debug, Clone, PartialEq)]
pub struct Observable {
    /// Index into the model's outputs.
    pub output: usize,
    /// The output's name.
    pub name: String,
    /// Its cells, one per row.
    pub cells: Cells,
}

impl Record {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the record has no rows.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// A uniform, complete record (every state measured at every row) from columns of
    /// values, as the paper's data are.
    pub fn complete(
        name: &str,
        times: Vec<f64>,
        inputs: Vec<Vec<f64>>,
        states: Vec<Vec<f64>>,
    ) -> Record {
        Record {
            name: name.to_string(),
            source: name.to_string(),
            times,
            inputs,
            states: (states.into_iter())
                .map(|column| column.into_iter().map(Some).collect())
                .collect(),
            observables: Vec::new(),
        }
    }

    /// Whether every state cell is measured.
    pub fn is_complete(&self) -> bool {
        self.states.iter().flatten().all(Option::is_some)
    }

    /// The sampling step when the rows lie on a uniform grid within
    /// [`Record::time_tolerance`]: the mean step. `None` for irregular times or fewer than
    /// two rows.
    pub fn uniform_step(&self) -> Option<f64> {
        uniform_step(&self.times)
    }

    /// The distance below which two times of this record are the same time, fitted to its
    /// times ([`crate::numeric::time_tolerance`]: their printed precision and the scatter
    /// of their steps, at most a small share of the step).
    pub fn time_tolerance(&self) -> f64 {
        crate::numeric::time_tolerance(&self.times)
    }

    /// The rows `range` as a record of their own (a tail split's training part).
    pub fn rows(&self, range: std::ops::Range<usize>) -> Record {
        let cut = |cells: &Cells| cells[range.clone()].to_vec();
        Record {
            name: self.name.clone(),
            source: self.source.clone(),
            times: self.times[range.clone()].to_vec(),
            inputs: (self.inputs.iter())
                .map(|column| column[range.clone()].to_vec())
                .collect(),
            states: self.states.iter().map(cut).collect(),
            observables: (self.observables.iter())
                .map(|o| Observable {
                    cells: cut(&o.cells),
                    ..o.clone()
                })
                .collect(),
        }
    }

    /// The cells of model output `output` when it is measured here.
    pub fn observable(&self, output: usize) -> Option<&Cells> {
        (self.observables.iter())
            .find(|o| o.output == output)
            .map(|o| &o.cells)
    }

    /// The number of measured state cells.
    pub fn measured_cells(&self) -> usize {
        self.states.iter().flatten().filter(|c| c.is_some()).count()
    }
}

/// The mean step of `times` when they lie on a uniform grid within the tolerance fitted to
/// them ([`crate::numeric::times`]); `None` otherwise.
pub fn uniform_step(times: &[f64]) -> Option<f64> {
    crate::numeric::uniform_step(times)
}

/// Per-column normalisation from the training split (records spec, section 3): the mean
/// and standard deviation that z-score network inputs and errors, over measured cells only,
/// and the range a free run must stay in.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Normalisation {
    /// Mean of each measured state.
    #[serde(with = "crate::json")]
    pub state_mean: Vec<f64>,
    /// Standard deviation of each measured state (never zero).
    #[serde(with = "crate::json")]
    pub state_std: Vec<f64>,
    /// Mean of each input.
    #[serde(with = "crate::json")]
    pub input_mean: Vec<f64>,
    /// Standard deviation of each input (never zero).
    #[serde(with = "crate::json")]
    pub input_std: Vec<f64>,
    /// Smallest measured value of each state over the training split (empty when unknown,
    /// as in runs saved before it was recorded).
    #[serde(default)]
    #[serde(with = "crate::json")]
    pub state_min: Vec<f64>,
    /// Largest measured value of each state over the training split (empty when unknown).
    #[serde(default)]
    #[serde(with = "crate::json")]
    pub state_max: Vec<f64>,
    /// The model outputs that are measured (observables), as indices into the model's
    /// outputs: every output measured in some training experiment.
    #[serde(default)]
    pub observables: Vec<usize>,
    /// Mean of each observable, in [`Normalisation::observables`] order.
    #[serde(default)]
    #[serde(with = "crate::json")]
    pub observable_mean: Vec<f64>,
    /// Standard deviation of each observable (never zero).
    #[serde(default)]
    #[serde(with = "crate::json")]
    pub observable_std: Vec<f64>,
}

/// The part of a record the statistics are taken over: `rows` of `record`.
pub type Part<'a> = (&'a Record, std::ops::Range<usize>);

impl Normalisation {
    /// Statistics over the measured cells of `parts` (records of the training split and the
    /// rows of each that train). A state with no measured cell there gets mean 0, std 1.
    pub fn over(parts: &[Part], states: usize, inputs: usize) -> Normalisation {
        let gather = |pick: &dyn Fn(&Record) -> Option<&Cells>| -> Vec<f64> {
            let mut values = Vec::new();
            for (record, rows) in parts {
                if let Some(cells) = pick(record) {
                    values.extend(cells[rows.clone()].iter().flatten());
                }
            }
            values
        };
        let mut norm = Normalisation::default();
        for state in 0..states {
            let values = gather(&|r: &Record| r.states.get(state));
            let (mean, std) = crate::numeric::mean_std(&values);
            norm.state_mean.push(mean);
            norm.state_std.push(std);
            norm.state_min
                .push(values.iter().copied().fold(f64::INFINITY, f64::min));
            norm.state_max
                .push(values.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        }
        for input in 0..inputs {
            let mut values = Vec::new();
            for (record, rows) in parts {
                values.extend_from_slice(&record.inputs[input][rows.clone()]);
            }
            let (mean, std) = crate::numeric::mean_std(&values);
            norm.input_mean.push(mean);
            norm.input_std.push(std);
        }
        let mut observables: Vec<usize> = (parts.iter())
            .flat_map(|(r, _)| r.observables.iter().map(|o| o.output))
            .collect();
        observables.sort_unstable();
        observables.dedup();
        for &output in &observables {
            let values = gather(&|r: &Record| r.observable(output));
            let (mean, std) = crate::numeric::mean_std(&values);
            norm.observable_mean.push(mean);
            norm.observable_std.push(std);
        }
        norm.observables = observables;
        norm
    }
}
