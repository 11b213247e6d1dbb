//! The measured record as the diagnosis sees it: input and measured-state columns in model
//! order, the split into a training and a held-out part, and the training statistics that
//! z-score every error (spec section 5).

use super::DiagnoseError;
use crate::data::Dataset;
use crate::ir::Model;

/// A uniformly sampled record with the model's inputs and measured states.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Sample times.
    pub times: Vec<f64>,
    /// Sampling step.
    pub step: f64,
    /// One column per model input, in declaration order.
    pub inputs: Vec<Vec<f64>>,
    /// One column per measured state, in declaration order.
    pub states: Vec<Vec<f64>>,
}

impl Record {
    /// The columns of `model`'s inputs and measured states taken from `dataset`.
    pub fn from_dataset(model: &Model, dataset: &Dataset) -> Result<Record, DiagnoseError> {
        let column = |name: &str| {
            dataset
                .column(name)
                .map(<[f64]>::to_vec)
                .ok_or_else(|| DiagnoseError::MissingColumn {
                    file: dataset.path.display().to_string(),
                    column: name.to_string(),
                })
        };
        Ok(Record {
            times: dataset.times.clone(),
            step: dataset.step,
            inputs: (model.inputs.iter())
                .map(|i| column(&i.name))
                .collect::<Result<_, _>>()?,
            states: (model.states.iter())
                .map(|s| column(&s.name))
                .collect::<Result<_, _>>()?,
        })
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the record has no rows.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The input values held over the interval that starts at `row`.
    pub fn inputs_at(&self, row: usize) -> impl Iterator<Item = f64> + '_ {
        self.inputs.iter().map(move |column| column[row])
    }

    /// The first `rows` rows.
    pub fn head(&self, rows: usize) -> Record {
        let cut = |columns: &[Vec<f64>]| columns.iter().map(|c| c[..rows].to_vec()).collect();
        Record {
            times: self.times[..rows].to_vec(),
            step: self.step,
            inputs: cut(&self.inputs),
            states: cut(&self.states),
        }
    }
}

/// Where the diagnosis fits and where it scores.
#[derive(Debug, Clone, PartialEq)]
pub struct Split {
    /// The record the free run used for fitting starts at (row 0).
    pub train: Record,
    /// The record the held-out free run starts at (row 0): the whole record when the
    /// held-out part is its tail, the test file otherwise.
    pub test: Record,
    /// Rows of `train` whose errors the fit minimises.
    pub train_rows: std::ops::Range<usize>,
    /// Rows of `test` that are scored.
    pub test_rows: std::ops::Range<usize>,
}

impl Split {
    /// The last `holdout` fraction of `record` held out; the free run still starts at row 0.
    pub fn tail(record: Record, holdout: f64) -> Result<Split, DiagnoseError> {
        let rows = record.len();
        let held = ((rows as f64) * holdout).round() as usize;
        let first_test = rows.saturating_sub(held);
        if held < MIN_ROWS || first_test < MIN_ROWS {
            return Err(DiagnoseError::TooFewRows {
                rows,
                needed: 2 * MIN_ROWS,
            });
        }
        Ok(Split {
            train: record.head(first_test),
            train_rows: 0..first_test,
            test_rows: first_test..rows,
            test: record,
        })
    }

    /// Fitting on `train`, scoring on all of `test`.
    pub fn separate(train: Record, test: Record) -> Result<Split, DiagnoseError> {
        for record in [&train, &test] {
            if record.len() < MIN_ROWS {
                return Err(DiagnoseError::TooFewRows {
                    rows: record.len(),
                    needed: MIN_ROWS,
                });
            }
        }
        Ok(Split {
            train_rows: 0..train.len(),
            test_rows: 0..test.len(),
            train,
            test,
        })
    }

    /// Mean and standard deviation of each measured state over the training rows.
    pub fn normalisation(&self) -> Normalisation {
        let (mean, std) = self
            .train
            .states
            .iter()
            .map(|column| crate::numeric::mean_std(&column[self.train_rows.clone()]))
            .unzip();
        Normalisation { mean, std }
    }
}

/// The fewest rows in each part of a split.
pub const MIN_ROWS: usize = 10;

/// Per measured state: the training mean and standard deviation that z-score errors.
#[derive(Debug, Clone, PartialEq)]
pub struct Normalisation {
    /// Means.
    pub mean: Vec<f64>,
    /// Standard deviations (a constant column gets 1, so its errors stay in its units).
    pub std: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(rows: usize) -> Record {
        Record {
            times: (0..rows).map(|k| k as f64).collect(),
            step: 1.0,
            inputs: vec![vec![0.5; rows]],
            states: vec![(0..rows).map(|k| k as f64).collect()],
        }
    }

    #[test]
    fn tail_split_holds_out_the_last_rows_and_normalises_on_the_rest() {
        let split = Split::tail(record(100), 0.3).unwrap();
        assert_eq!(split.train_rows, 0..70);
        assert_eq!(split.test_rows, 70..100);
        assert_eq!(split.train.len(), 70);
        assert_eq!(split.test.len(), 100);
        let norm = split.normalisation();
        // 0..70: mean 34.5, population variance (70^2 - 1) / 12.
        assert!((norm.mean[0] - 34.5).abs() < 1e-12);
        assert!((norm.std[0] - ((4900.0f64 - 1.0) / 12.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn short_records_are_refused() {
        assert!(matches!(
            Split::tail(record(15), 0.3),
            Err(DiagnoseError::TooFewRows { .. })
        ));
        assert!(Split::separate(record(12), record(5)).is_err());
    }
}
