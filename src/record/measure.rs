//! The one error measure every command reports (`docs/error-measure.md`).
//!
//! A cell's error is its squared z-score error, `((predicted - measured) / std)²`, with the
//! standard deviation of the state over the training split ([`super::Normalisation`]). A
//! state's error, its **NMSE**, is the mean of its cells' errors (the paper's normalised
//! MSE: `1` is the error of predicting the training mean everywhere when the mean is right).
//! The **error** of a run, a set of runs or a model is the mean of its states' NMSEs over
//! the states with at least one scored cell, so a state measured at ten assays counts as
//! much as one measured every minute. `gbc train`, `gbc predict`, `gbc experiment` and the
//! reports print it as "error"; `gbc diagnose` prints it beside its pooled gap
//! (`gap_before_per_state`), which weighs cells instead of states because the noise floor
//! it is compared with is a per-cell quantity.

/// The squared z-scored error of one cell: `((predicted - measured) / std)²`.
pub fn cell_error(predicted: f64, measured: f64, std: f64) -> f64 {
    ((predicted - measured) / std).powi(2)
}

/// The error of a set of states: the mean of the finite-or-infinite NMSEs given (`NaN` for
/// none). An infinite NMSE (a diverged run) makes the error infinite.
pub fn mean_over_states(nmse: impl IntoIterator<Item = f64>) -> f64 {
    let (sum, count) = (nmse.into_iter()).fold((0.0, 0usize), |(s, n), e| (s + e, n + 1));
    if count == 0 {
        f64::NAN
    } else {
        sum / count as f64
    }
}

/// Cell errors summed per state (column), with their counts: the sums of several runs pool
/// into one set of NMSEs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StateErrors {
    squared: Vec<f64>,
    cells: Vec<usize>,
}

impl StateErrors {
    /// No cells yet, for `columns` states.
    pub fn new(columns: usize) -> Self {
        StateErrors {
            squared: vec![0.0; columns],
            cells: vec![0; columns],
        }
    }

    /// Adds one cell's error to column `column`.
    pub fn add(&mut self, column: usize, error: f64) {
        self.squared[column] += error;
        self.cells[column] += 1;
    }

    /// Adds another set's sums, column by column.
    pub fn merge(&mut self, other: &StateErrors) {
        for column in 0..self.squared.len().min(other.squared.len()) {
            self.squared[column] += other.squared[column];
            self.cells[column] += other.cells[column];
        }
    }

    /// The number of cells scored in all columns.
    pub fn cells(&self) -> usize {
        self.cells.iter().sum()
    }

    /// Per column, its NMSE (`None` for a column without cells).
    pub fn nmse(&self) -> Vec<Option<f64>> {
        (self.squared.iter().zip(&self.cells))
            .map(|(&sum, &cells)| (cells > 0).then(|| sum / cells as f64))
            .collect()
    }

    /// The error: the mean of the NMSEs of the columns with cells.
    pub fn error(&self) -> f64 {
        mean_over_states(self.nmse().into_iter().flatten())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_state_counts_once_however_many_cells_it_has() {
        // State 0: 4 cells of error 1; state 1: 1 cell of error 9. Pooled cells would give
        // 13 / 5 = 2.6; the mean over states is (1 + 9) / 2 = 5.
        let mut errors = StateErrors::new(3);
        for _ in 0..4 {
            errors.add(0, cell_error(3.0, 1.0, 2.0));
        }
        errors.add(1, cell_error(0.0, 6.0, 2.0));
        assert_eq!(errors.nmse(), vec![Some(1.0), Some(9.0), None]);
        assert_eq!(errors.error(), 5.0);
        assert_eq!(errors.cells(), 5);
    }

    #[test]
    fn merged_sums_pool_cells_within_a_state() {
        let mut first = StateErrors::new(1);
        first.add(0, 1.0);
        let mut second = StateErrors::new(1);
        second.add(0, 3.0);
        second.add(0, 5.0);
        first.merge(&second);
        assert_eq!(first.nmse(), vec![Some(3.0)]);
    }

    #[test]
    fn no_state_gives_nan_and_an_infinite_state_an_infinite_error() {
        assert!(mean_over_states([]).is_nan());
        assert_eq!(mean_over_states([1.0, f64::INFINITY]), f64::INFINITY);
    }
}
