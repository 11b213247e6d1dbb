//! Input programs: piecewise-constant actuator signals (spec section 4: inputs are held
//! constant between switches).

/// A piecewise-constant signal: `values[i]` holds on `[breaks[i], breaks[i + 1])`, and the
/// last value holds from the last break on. Before the first break the first value holds.
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
    /// The value held at time `t`.
    pub fn value_at(&self, t: f64) -> f64 {
        let index = self.breaks.partition_point(|&b| b <= t);
        self.values[index.saturating_sub(1).min(self.values.len() - 1)]
    }
}
