//! A piecewise-constant signal: the values an input holds between its breaks.

use super::error::SignalError;

/// A piecewise-constant signal: `values[i]` holds on `[breaks[i], breaks[i + 1])`, and the
/// last value holds from the last break on. Before the first break the first value holds.
///
/// Invariant (checked by [`Signal::new`], kept by every constructor here): `breaks` and
/// `values` have the same, non-zero length, `breaks` are finite and strictly increasing,
/// `values` are finite. A signal built by hand that breaks it still never panics:
/// [`Signal::value_at`] gives NaN for an empty signal.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    /// Switch times, strictly increasing; `breaks[0]` is the start.
    pub breaks: Vec<f64>,
    /// The value held from each switch.
    pub values: Vec<f64>,
}

impl Signal {
    /// A signal holding `value` forever from `start`.
    pub fn constant(start: f64, value: f64) -> Self {
        Signal {
            breaks: vec![start],
            values: vec![value],
        }
    }

    /// A signal from switch times and values, checking the invariant.
    pub fn new(breaks: Vec<f64>, values: Vec<f64>) -> Result<Self, SignalError> {
        let invalid = |expected: &str, found: String| {
            SignalError::InvalidSignal(crate::error::Bug::new(
                "a signal",
                format!("expected {expected}, found {found}"),
            ))
        };
        if breaks.is_empty() || breaks.len() != values.len() {
            let found = format!("{} breaks and {} values", breaks.len(), values.len());
            return Err(invalid("as many values as breaks, at least one", found));
        }
        let finite = |v: &f64| v.is_finite();
        if let Some(bad) = breaks.iter().chain(&values).find(|v| !finite(v)) {
            return Err(invalid("finite break times and values", bad.to_string()));
        }
        if let Some(index) = breaks.windows(2).position(|pair| pair[1] <= pair[0]) {
            let found = format!("{} after {}", breaks[index + 1], breaks[index]);
            return Err(invalid("strictly increasing break times", found));
        }
        Ok(Signal { breaks, values })
    }

    /// A signal holding `values[i]` from `times[i]`, with a break only where the value
    /// changes (the simulator restarts its integrator at every break), checking the
    /// invariant.
    pub fn at_changes(times: &[f64], values: &[f64]) -> Result<Self, SignalError> {
        if times.len() != values.len() {
            return Signal::new(times.to_vec(), values.to_vec());
        }
        let mut breaks = Vec::with_capacity(times.len());
        let mut held: Vec<f64> = Vec::with_capacity(values.len());
        for (&time, &value) in times.iter().zip(values) {
            if held.last() != Some(&value) {
                breaks.push(time);
                held.push(value);
            }
        }
        Signal::new(breaks, held)
    }

    /// The value held at time `t`; NaN for an empty signal (which [`Signal::new`] refuses).
    pub fn value_at(&self, t: f64) -> f64 {
        let index = self.breaks.partition_point(|&b| b <= t).saturating_sub(1);
        let last = self.values.len().checked_sub(1);
        last.and_then(|last| self.values.get(index.min(last)))
            .copied()
            .unwrap_or(f64::NAN)
    }

    /// The values held at each of `times`.
    pub fn sample(&self, times: &[f64]) -> Vec<f64> {
        times.iter().map(|&t| self.value_at(t)).collect()
    }
}
