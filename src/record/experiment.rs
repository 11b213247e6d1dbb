//! One experiment in model terms: its inputs held between their given values, and its
//! measured states and outputs as cells that may be missing.

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

    /// The measured columns: every state's cells (model order), then every observable's
    /// (in [`Record::observables`] order; [`Record::align_observables`] makes that order
    /// the same in every record of a fit).
    pub fn columns(&self) -> impl Iterator<Item = &Cells> + Clone {
        (self.states.iter()).chain(self.observables.iter().map(|o| &o.cells))
    }

    /// The cells of column `k` ([`Record::columns`] order).
    pub fn column(&self, k: usize) -> &Cells {
        match k.checked_sub(self.states.len()) {
            None => &self.states[k],
            Some(j) => &self.observables[j].cells,
        }
    }

    /// Lays the observables out as `outputs` lists them (model output indices): one per
    /// entry, with no measured cell where this record does not measure it; an output
    /// measured here but not listed is dropped.
    pub fn align_observables(&mut self, outputs: &[usize], names: &[String]) {
        let rows = self.len();
        let mut aligned = Vec::with_capacity(outputs.len());
        for &output in outputs {
            let cells = (self.observable(output).cloned()).unwrap_or_else(|| vec![None; rows]);
            aligned.push(Observable {
                output,
                name: names[output].clone(),
                cells,
            });
        }
        self.observables = aligned;
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
