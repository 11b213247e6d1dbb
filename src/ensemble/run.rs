//! A member's free run along one experiment, matched to the experiment's rows by time.

/// A member's free run along one experiment: per measured state, its value at each of the
/// experiment's rows (NaN where it did not run: before its start, after it stopped).
#[derive(Debug, Clone, PartialEq)]
pub struct Run {
    /// The row the free run starts at: its cells are the data's, never scored.
    pub start: usize,
    /// `states[i][row]`.
    pub states: Vec<Vec<f64>>,
}

impl Run {
    /// A run that reached no row (its prediction failed).
    pub fn none(record: &crate::record::Record, states: usize) -> Run {
        Run {
            start: record.len(),
            states: vec![vec![f64::NAN; record.len()]; states],
        }
    }

    /// The run of a prediction table along `record`: the first `states` columns after `t`,
    /// matched to the record's rows by time.
    pub fn of_table(
        table: &crate::trained::predict::PredictionTable,
        record: &crate::record::Record,
        states: usize,
    ) -> Run {
        let mut run = Run::none(record, states);
        let Some(times) = table.columns.first() else {
            return run;
        };
        let tolerance = record.time_tolerance();
        for (position, time) in times.iter().enumerate() {
            let Some(row) = row_at(record, *time, tolerance) else {
                continue;
            };
            run.start = run.start.min(row);
            for (state, values) in run.states.iter_mut().enumerate() {
                if let Some(value) = table.columns.get(state + 1).map(|c| c[position]) {
                    values[row] = value;
                }
            }
        }
        run
    }
}

/// The record row at `time`, within `tolerance` (the record's,
/// [`crate::record::Record::time_tolerance`]).
pub fn row_at(record: &crate::record::Record, time: f64, tolerance: f64) -> Option<usize> {
    let index = record.times.partition_point(|t| *t < time - tolerance);
    (record.times.get(index)).and_then(|t| ((t - time).abs() <= tolerance).then_some(index))
}
