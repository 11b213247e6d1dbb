//! The physical range a free run must stay in (the training data's extremes widened by
//! `--range-factor`, nonnegative floors) and where a run that left it stopped
//! ([`Divergence`]).

use std::fmt;

use crate::engine::graph::Normalisation;
use crate::ir;

/// The range each measured state of a free run must stay in.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicalRange {
    /// Lower bound per measured state.
    pub lower: Vec<f64>,
    /// Upper bound per measured state.
    pub upper: Vec<f64>,
    /// Per measured state, the lower bound it gets where the model declares it
    /// `nonnegative` ([`PhysicalRange::declared`]): `-UNDERSHOOT` times its largest
    /// magnitude in training, whatever the sign of its measured cells.
    pub nonnegative_floor: Vec<f64>,
}

/// How far below zero, as a share of its training maximum, a state never negative in
/// training may go before a free run counts as diverged. A concentration near zero that a
/// model undershoots by a little is an error the MSE measures, not a blow-up; one a tenth
/// of its scale below zero is unphysical.
pub const UNDERSHOOT: f64 = 0.1;

impl PhysicalRange {
    /// From the training split's extremes: `[-UNDERSHOOT * max, factor * max]` for a state
    /// never negative in training, else `[-factor * max|x|, factor * max|x|]`. `None` when
    /// the normalisation has no extremes (runs saved before they were recorded).
    pub fn new(normalisation: &Normalisation, factor: f64) -> Option<PhysicalRange> {
        Self::from_extremes(&normalisation.state_min, &normalisation.state_max, factor)
    }

    /// [`PhysicalRange::new`]'s rule on the smallest and largest value of each state.
    pub fn from_extremes(min: &[f64], max: &[f64], factor: f64) -> Option<PhysicalRange> {
        if min.is_empty() || min.len() != max.len() {
            return None;
        }
        let nonnegative_floor = (min.iter().zip(max))
            .map(|(&lo, &hi)| {
                let largest = lo.abs().max(hi.abs());
                if lo <= hi && largest.is_finite() {
                    -UNDERSHOOT * largest
                } else {
                    f64::NEG_INFINITY
                }
            })
            .collect();
        let (lower, upper) = (min.iter().zip(max))
            .map(|(&lo, &hi)| {
                let largest = lo.abs().max(hi.abs());
                if !(lo <= hi && largest.is_finite()) {
                    // A state without a measured cell in training: no bound but finiteness.
                    (f64::NEG_INFINITY, f64::INFINITY)
                } else if lo >= 0.0 {
                    (-UNDERSHOOT * hi, factor * hi)
                } else {
                    (-factor * largest, factor * largest)
                }
            })
            .unzip();
        Some(PhysicalRange {
            lower,
            upper,
            nonnegative_floor,
        })
    }

    /// The range of `model`'s free runs: a state the model declares `nonnegative` gets
    /// its floor `-UNDERSHOOT * max|x|` even where noisy measurements of it dip below
    /// zero in training (the model says what the data cannot: that the state itself is
    /// never negative).
    pub fn declared(&self, model: &ir::Model) -> PhysicalRange {
        let mut range = self.clone();
        for (i, state) in model.states.iter().enumerate() {
            let floor = self.nonnegative_floor.get(i).copied();
            if let (true, Some(floor), Some(lower)) =
                (state.nonnegative, floor, range.lower.get_mut(i))
            {
                *lower = lower.max(floor);
            }
        }
        range
    }

    /// No bounds for `states` states: only a value that is not finite leaves it.
    pub fn unbounded(states: usize) -> PhysicalRange {
        PhysicalRange {
            lower: vec![f64::NEG_INFINITY; states],
            upper: vec![f64::INFINITY; states],
            nonnegative_floor: vec![f64::NEG_INFINITY; states],
        }
    }

    /// The first measured state of `state` outside the range or not finite.
    fn violation(&self, state: &[f64]) -> Option<usize> {
        (0..self.lower.len()).find(|&i| {
            let value = state.get(i).copied().unwrap_or(f64::NAN);
            let (lo, hi) = (self.lower[i], self.upper[i]);
            let slack = 1e-9
                * [lo, hi]
                    .iter()
                    .filter(|b| b.is_finite())
                    .fold(0.0, |m, b| b.abs().max(m));
            !value.is_finite() || value < lo - slack || value > hi + slack
        })
    }

    /// The divergence of `state` (measured states named by `names`) at knot `row` and
    /// `time` of `experiment`, if one of its values leaves the range or is not finite.
    pub fn check(
        &self,
        names: &[String],
        (experiment, row, time): (&str, usize, f64),
        state: &[f64],
    ) -> Option<Divergence> {
        let index = self.violation(state)?;
        Some(Divergence {
            experiment: experiment.to_string(),
            row,
            time,
            state: names.get(index).cloned().unwrap_or_default(),
            value: state.get(index).copied().unwrap_or(f64::NAN),
            range: (self.lower[index], self.upper[index]),
        })
    }

    /// The first row of a run (`columns[i][row]`: state `i` at `times[row]`) that leaves
    /// the range ([`PhysicalRange::check`]).
    pub fn first_exit(
        &self,
        names: &[String],
        experiment: &str,
        (times, columns): (&[f64], &[Vec<f64>]),
    ) -> Option<Divergence> {
        (0..times.len()).find_map(|row| {
            let state: Vec<f64> = columns.iter().map(|c| c[row]).collect();
            self.check(names, (experiment, row, times[row]), &state)
        })
    }
}

/// Where and why a free run stopped.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Divergence {
    /// The experiment.
    #[serde(default)]
    pub experiment: String,
    /// Knot of the offending state.
    pub row: usize,
    /// Its time.
    #[serde(with = "crate::json")]
    pub time: f64,
    /// The measured state.
    pub state: String,
    /// Its predicted value (a non-finite one is written by name, see [`crate::json`]).
    #[serde(with = "crate::json")]
    pub value: f64,
    /// The range it had to stay in.
    #[serde(with = "crate::json")]
    pub range: (f64, f64),
}

impl Divergence {
    /// Why, in words: "below its floor -0.1", "above its ceiling 12", "not finite".
    pub fn why(&self) -> String {
        let (lo, hi) = self.range;
        if !self.value.is_finite() {
            "not finite".into()
        } else if self.value < lo {
            format!("below its floor {}", short(lo))
        } else {
            format!("above its ceiling {}", short(hi))
        }
    }
}

/// A bound or value with about 4 significant digits.
fn short(value: f64) -> String {
    crate::train::analysis::compact(value)
}

impl fmt::Display for Divergence {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        let run = match self.experiment.as_str() {
            "" => "the free run".to_string(),
            name => format!("the free run of `{name}`"),
        };
        let value = if self.value.is_finite() {
            short(self.value)
        } else {
            self.value.to_string()
        };
        write!(
            formatter,
            "{run} diverged: {} = {value} at t = {}, {}",
            self.state,
            self.time,
            self.why()
        )
    }
}
