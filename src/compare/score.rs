//! From runs to scores: the grey box's median error over seeds with its min–max range and
//! its diverged free runs, the mechanism's and the naive forecast's error, and the verdict
//! (`docs/compare.md`): the grey box is *better* than the mechanism when its worst seed
//! beats it, *worse* when its best seed loses to it, and *tied within its replicate spread*
//! otherwise, each by more than the comparison's numerical resolution: how far the
//! untrained grey box (the mechanism itself, run through the grey box's free run, in its
//! precision and steps) scores from the mechanism run by the exact integrator.

use crate::train::ErrorSet;

/// One model's error on one held-out experiment (or over all), reduced over its runs.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Score {
    /// The median over the runs that scored (one run: its error; none: NaN). Infinite when
    /// at least half the runs diverged.
    #[serde(with = "crate::json")]
    pub error: f64,
    /// The smallest and largest error over those runs.
    #[serde(with = "crate::json")]
    pub range: (f64, f64),
    /// Per state, the median over the runs of its NMSE.
    #[serde(with = "crate::json")]
    pub per_state: Vec<(String, f64)>,
    /// The runs that scored.
    pub runs: usize,
    /// The runs that failed to train or scored no cell.
    pub failed: usize,
    /// Each free run that left the physical range: which run, where and why.
    pub diverged: Vec<String>,
}

impl Score {
    /// The score of `runs` (label, error or none), per state over `states`.
    pub fn of(runs: &[(String, Option<&ErrorSet>)], states: &[String]) -> Score {
        let scored: Vec<(&String, &ErrorSet)> = (runs.iter())
            .filter_map(|(label, set)| set.map(|s| (label, s)))
            .collect();
        let overall: Vec<f64> = scored.iter().map(|(_, s)| s.overall).collect();
        let median = |values: &[f64]| crate::numeric::median(values).unwrap_or(f64::NAN);
        let per_state = (states.iter())
            .filter_map(|name| {
                let values: Vec<f64> = (scored.iter())
                    .filter_map(|(_, s)| s.per_state.iter().find(|(n, _)| n == name))
                    .map(|(_, v)| *v)
                    .collect();
                (!values.is_empty()).then(|| (name.clone(), median(&values)))
            })
            .collect();
        let lowest = overall.iter().copied().fold(f64::NAN, f64::min);
        let highest = overall.iter().copied().fold(f64::NAN, f64::max);
        Score {
            error: median(&overall),
            range: (lowest, highest),
            per_state,
            runs: scored.len(),
            failed: runs.len() - scored.len(),
            diverged: (scored.iter())
                .filter_map(|(label, s)| {
                    let divergence = s.divergence.as_ref()?;
                    Some(format!("{label}: {divergence}"))
                })
                .collect(),
        }
    }
}

/// Where the grey box stands against the fitted mechanism.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Standing {
    /// Every seed's error below the mechanism's, by more than the resolution.
    Better,
    /// Every seed's error above the mechanism's, by more than the resolution.
    Worse,
    /// The mechanism's error inside the grey box's min–max range widened by the
    /// resolution.
    Tied,
    /// No grey-box run, or no mechanism error, to compare.
    Undecided,
}

/// The grey box against the mechanism and the naive forecast.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Verdict {
    /// Against the mechanism, within the grey box's replicate spread.
    pub standing: Standing,
    /// The mechanism's error over the grey box's median (above 1: the grey box is lower).
    #[serde(with = "crate::json")]
    pub ratio_to_mechanism: f64,
    /// The naive forecast's error over the grey box's median.
    #[serde(with = "crate::json")]
    pub ratio_to_naive: f64,
    /// The numerical resolution: the untrained grey box's error minus the mechanism's, in
    /// absolute value (0 without an untrained run).
    #[serde(default, with = "crate::json")]
    pub resolution: f64,
    /// The verdict in one sentence.
    pub sentence: String,
}

impl Verdict {
    /// The verdict of `grey_box` against `mechanism` and `naive`, within the resolution
    /// that `untrained` (the untrained grey box's score) measures.
    pub fn of(
        grey_box: &Score,
        (mechanism, untrained): (&Score, Option<&Score>),
        naive: &Score,
    ) -> Verdict {
        let resolution = (untrained.map(|u| (u.error - mechanism.error).abs()))
            .filter(|r| r.is_finite())
            .unwrap_or(0.0);
        let (low, high) = grey_box.range;
        let standing = if grey_box.runs == 0 || mechanism.runs == 0 || mechanism.error.is_nan() {
            Standing::Undecided
        } else if high < mechanism.error - resolution {
            Standing::Better
        } else if low > mechanism.error + resolution {
            Standing::Worse
        } else {
            Standing::Tied
        };
        let ratio_to_mechanism = mechanism.error / grey_box.error;
        let ratio_to_naive = naive.error / grey_box.error;
        let sentence = sentence(standing, grey_box, (mechanism, naive), resolution);
        Verdict {
            standing,
            ratio_to_mechanism,
            ratio_to_naive,
            resolution,
            sentence,
        }
    }
}

/// The verdict in words.
fn sentence(
    standing: Standing,
    grey_box: &Score,
    (mechanism, naive): (&Score, &Score),
    resolution: f64,
) -> String {
    let spread = if grey_box.runs > 1 {
        format!(
            "median error {} ({}–{} over {} seeds)",
            number(grey_box.error),
            number(grey_box.range.0),
            number(grey_box.range.1),
            grey_box.runs
        )
    } else {
        format!("error {}", number(grey_box.error))
    };
    let against = format!("against the fitted mechanism's {}", number(mechanism.error));
    let head = match standing {
        Standing::Better => format!(
            "The grey box beats its fitted mechanism on every seed: {spread} {against}, {} lower",
            times(mechanism.error / grey_box.error)
        ),
        Standing::Worse => format!(
            "The grey box loses to its fitted mechanism on every seed: {spread} {against}, {} \
             higher",
            times(grey_box.error / mechanism.error)
        ),
        Standing::Tied => format!(
            "The grey box ties with its fitted mechanism within its replicate spread and the \
             numerical resolution ({}): {spread} {against}",
            number(resolution)
        ),
        Standing::Undecided => {
            return format!(
                "Undecided: {} grey-box runs and {} mechanism runs scored.",
                grey_box.runs, mechanism.runs
            )
        }
    };
    let against_naive = if naive.error < grey_box.error {
        format!(
            "the naive forecast ({}) is {} lower still",
            number(naive.error),
            times(grey_box.error / naive.error)
        )
    } else {
        format!(
            "{} below the naive forecast ({})",
            times(naive.error / grey_box.error),
            number(naive.error)
        )
    };
    let diverged = match grey_box.diverged.len() {
        0 => "no free run diverged".to_string(),
        n => format!("{n} of {} free runs diverged", grey_box.runs),
    };
    format!("{head}; {against_naive}; {diverged}.")
}

/// A ratio as `1.27x` (`infx`, `nanx` for the others).
pub fn times(ratio: f64) -> String {
    if ratio.is_finite() {
        format!("{ratio:.2}x")
    } else {
        format!("{}x", number(ratio))
    }
}

/// An error with four significant digits: `0.3902`, `4.981e-3`, `inf`.
pub fn number(value: f64) -> String {
    if !value.is_finite() {
        return crate::json::name_of(value).to_string();
    }
    if value == 0.0 {
        return "0".into();
    }
    let magnitude = value.abs();
    if (0.01..1e4).contains(&magnitude) {
        let decimals = (3 - magnitude.log10().floor() as i32).clamp(0, 5) as usize;
        format!("{value:.decimals$}")
    } else {
        format!("{value:.3e}")
    }
}
