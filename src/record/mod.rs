//! A data set in model terms (records spec, sections 1-3): one [`Record`] per experiment,
//! with the model's inputs held between their given values, its measured states and
//! measured outputs (observables) as cells that may be missing, and the statistics that
//! z-score every error ([`Normalisation`], over measured cells only).
//!
//! Training lays each record on its integration grid ([`grid::Track`]); the diagnosis runs
//! its simulator along the record's own rows. Both read data through this one type.

pub mod bind;
mod experiment;
pub mod grid;
pub mod measure;
#[cfg(test)]
mod tests;

pub use bind::{bind, request};
#[cfg(test)]
pub use experiment::{uniform_step, Observable};
pub use experiment::{Cells, Record};
pub use grid::{GridOptions, Track};

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

    /// The measured columns a fit scores: the measured states, then the observables.
    pub fn columns(&self) -> usize {
        self.state_std.len() + self.observables.len()
    }

    /// The standard deviation of column `k` ([`Normalisation::columns`] order).
    pub fn column_std(&self, k: usize) -> f64 {
        match k.checked_sub(self.state_std.len()) {
            None => self.state_std[k],
            Some(j) => self.observable_std[j],
        }
    }

    /// The mean of column `k` ([`Normalisation::columns`] order).
    pub fn column_mean(&self, k: usize) -> f64 {
        match k.checked_sub(self.state_mean.len()) {
            None => self.state_mean[k],
            Some(j) => self.observable_mean[j],
        }
    }
}
