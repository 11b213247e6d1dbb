//! The band's calibration on the training experiments, and its coverage of others.
//!
//! **Calibration** ([`calibrate`]) touches the training experiments only: each one is
//! predicted by the members that did not draw it (out of bag), their base band
//! ([`BaseBand`]) laid around those members' median, and each measured cell after the free
//! run's start scored by how many base half-widths it lies out ([`BaseBand::score`]). A
//! cell no out-of-bag member reached (every one stopped before it) scores infinity. A state
//! with at least [`MIN_CELLS`] scores is calibrated on its own; the others share the scores
//! of every state. The factor of a level is their split-conformal quantile
//! ([`calibrated_factor`]).
//!
//! **Coverage** ([`count`]) is the share of an experiment's measured cells after the start
//! inside the band of every member at a level; a cell no member reached counts as outside.

use super::band::{calibrated_factor, BaseBand};
use super::noise::StateNoise;
use super::run::Run;
use crate::numeric::median;
use crate::record::measure::{cell_error, mean_over_states, StateErrors};
use crate::record::Record;

/// Fewest scores that calibrate a state on its own (fewer: the scores of every state).
pub const MIN_CELLS: usize = 20;

/// What calibrates the band: per state, the scores of its out-of-bag cells.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Calibration {
    /// Whether any out-of-bag cell was scored (without one no band is claimed).
    pub calibrated: bool,
    /// Where the scores come from, in words.
    pub source: String,
    /// Why the band is not calibrated, when it is not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Each training experiment with the members (1-based) that predicted it out of bag.
    pub experiments: Vec<(String, Vec<usize>)>,
    /// Per measured state, the scores its factor is taken from.
    pub states: Vec<StateScores>,
}

/// The calibration scores of one measured state.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StateScores {
    /// The state.
    pub state: String,
    /// Its own out-of-bag cells.
    pub cells: usize,
    /// Whether it takes the scores of every state (its own were fewer than [`MIN_CELLS`]).
    pub pooled: bool,
    /// The scores its factor is the quantile of, ascending.
    #[serde(with = "crate::json")]
    pub scores: Vec<f64>,
}

impl Calibration {
    /// The factor that stretches state `state`'s base band to `level`; `None` where the
    /// band is not calibrated there (no scores, or too few for the level).
    pub fn factor(&self, state: usize, level: f64) -> Option<f64> {
        if !self.calibrated {
            return None;
        }
        calibrated_factor(&self.states.get(state)?.scores, level)
    }
}

/// One member's free runs of every experiment, with the training experiments it did not
/// draw.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberRuns {
    /// 1-based member index.
    pub index: usize,
    /// Training experiments (indices) it did not draw.
    pub out_of_bag: Vec<usize>,
    /// Its runs: the training experiments, then the held-out ones.
    pub runs: Vec<Run>,
}

/// Calibrates the band of `states` on the training experiments `training` (the first runs
/// of each member), from the out-of-bag members of each.
pub fn calibrate(
    states: &[String],
    training: &[Record],
    members: &[MemberRuns],
    noise: &[StateNoise],
) -> Calibration {
    let mut own: Vec<Vec<f64>> = vec![Vec::new(); states.len()];
    let mut experiments = Vec::new();
    for (index, record) in training.iter().enumerate() {
        let out: Vec<&MemberRuns> = (members.iter())
            .filter(|m| m.out_of_bag.contains(&index))
            .collect();
        experiments.push((record.name.clone(), out.iter().map(|m| m.index).collect()));
        let runs: Vec<&Run> = out.iter().filter_map(|m| m.runs.get(index)).collect();
        if runs.is_empty() {
            continue;
        }
        for cell in cells(record, &runs, noise) {
            own[cell.state].push(cell.base.map_or(f64::INFINITY, |b| b.score(cell.measured)));
        }
    }
    let mut pooled: Vec<f64> = own.iter().flatten().copied().collect();
    pooled.sort_by(f64::total_cmp);
    let scored = !pooled.is_empty();
    let states = (states.iter().zip(own))
        .map(|(state, mut scores)| {
            let cells = scores.len();
            scores.sort_by(f64::total_cmp);
            let pooled_here = cells < MIN_CELLS;
            StateScores {
                state: state.clone(),
                cells,
                pooled: pooled_here,
                scores: if pooled_here { pooled.clone() } else { scores },
            }
        })
        .collect();
    Calibration {
        calibrated: scored,
        source: "out-of-bag free runs of the training experiments: each predicted by the \
                 members that did not draw it"
            .into(),
        reason: (!scored).then(|| {
            "no training experiment was left out of a member's draws (resample whole \
             experiments, with at least two training experiments)"
                .to_string()
        }),
        experiments,
        states,
    }
}

/// A measured cell after the start of every run, with the base band of the runs there.
pub struct Cell {
    /// The measured state.
    pub state: usize,
    /// The measured value.
    pub measured: f64,
    /// The runs' base band (`None`: no run reached the cell).
    pub base: Option<BaseBand>,
}

/// Every measured cell of `record` after the start of each of `runs`, with its base band.
pub fn cells(record: &Record, runs: &[&Run], noise: &[StateNoise]) -> Vec<Cell> {
    let start = latest_start(record, runs);
    let mut found = Vec::new();
    for (state, column) in record.states.iter().enumerate().take(noise.len()) {
        for (row, cell) in column.iter().enumerate().skip(start + 1) {
            let Some(measured) = *cell else { continue };
            let predictions = (runs.iter()).filter_map(|r| r.states.get(state).map(|v| v[row]));
            found.push(Cell {
                state,
                measured,
                base: noise[state].base_band(predictions),
            });
        }
    }
    found
}

/// The latest start of the runs that reached a row (the record's length without one).
fn latest_start(record: &Record, runs: &[&Run]) -> usize {
    (runs.iter().map(|r| r.start))
        .filter(|&start| start < record.len())
        .max()
        .unwrap_or(record.len())
}

/// Measured cells of one state inside a band.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CellCount {
    /// The state (`all` for every state together).
    pub state: String,
    /// Measured cells counted.
    pub cells: usize,
    /// Of them inside the band.
    pub inside: usize,
    /// Of them reached by no member's free run (counted outside).
    pub unreached: usize,
}

impl CellCount {
    /// No cells yet.
    pub fn new(state: &str) -> Self {
        CellCount {
            state: state.to_string(),
            cells: 0,
            inside: 0,
            unreached: 0,
        }
    }

    /// The share inside (NaN without cells).
    pub fn share(&self) -> f64 {
        self.inside as f64 / self.cells as f64
    }

    /// Adds another count's cells.
    pub fn add(&mut self, other: &CellCount) {
        self.cells += other.cells;
        self.inside += other.inside;
        self.unreached += other.unreached;
    }
}

/// The coverage of the band on held-out experiments.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Coverage {
    /// The band's level.
    #[serde(with = "crate::json")]
    pub level: f64,
    /// The experiments counted.
    pub experiments: Vec<String>,
    /// Per calibrated measured state.
    pub states: Vec<CellCount>,
    /// Every calibrated state together.
    pub overall: CellCount,
    /// The base band, not calibrated (the members' spread with the noise at
    /// [`super::band::BASE_LEVEL`]), over every state: what the calibration changed.
    pub uncalibrated: CellCount,
}

/// Counts, per measured state of `noise`, the measured cells of `record` inside the band at
/// `level` of `runs`; a state the calibration gives no factor at `level` is not counted.
/// The second count is the uncalibrated base band's, over every state.
pub fn count(
    record: &Record,
    runs: &[&Run],
    (noise, calibration): (&[StateNoise], &Calibration),
    level: f64,
) -> (Vec<CellCount>, CellCount) {
    let mut counts: Vec<CellCount> = noise.iter().map(|n| CellCount::new(&n.state)).collect();
    let mut base = CellCount::new("all");
    for cell in cells(record, runs, noise) {
        let band = cell.base.as_ref();
        base.cells += 1;
        base.inside += usize::from(band.is_some_and(|b| b.covers(1.0, cell.measured)));
        let Some(factor) = calibration.factor(cell.state, level) else {
            continue;
        };
        let count = &mut counts[cell.state];
        count.cells += 1;
        match band {
            Some(b) => count.inside += usize::from(b.covers(factor, cell.measured)),
            None => count.unreached += 1,
        }
    }
    (counts, base)
}

/// The coverage at `level` of the members' band on `records`, each with the members' runs.
pub fn coverage(
    records: &[(&Record, Vec<&Run>)],
    (noise, calibration): (&[StateNoise], &Calibration),
    level: f64,
) -> Option<Coverage> {
    let mut states: Vec<CellCount> = noise.iter().map(|n| CellCount::new(&n.state)).collect();
    let mut uncalibrated = CellCount::new("all");
    for (record, runs) in records {
        let (counts, base) = count(record, runs, (noise, calibration), level);
        for (total, part) in states.iter_mut().zip(&counts) {
            total.add(part);
        }
        uncalibrated.add(&base);
    }
    let mut overall = CellCount::new("all");
    states.retain(|s| s.cells > 0);
    states.iter().for_each(|s| overall.add(s));
    (uncalibrated.cells > 0).then(|| Coverage {
        level,
        experiments: records.iter().map(|(r, _)| r.name.clone()).collect(),
        states,
        overall,
        uncalibrated,
    })
}

/// The held-out errors of the members' pointwise median and of each member.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ErrorSummary {
    /// What is measured, in words.
    pub measure: String,
    /// The median's error per measured state.
    #[serde(with = "crate::json")]
    pub median_per_state: Vec<(String, f64)>,
    /// The median's error (the mean over states).
    #[serde(with = "crate::json")]
    pub median: f64,
    /// Each used member's error, in member order.
    #[serde(with = "crate::json")]
    pub members: Vec<f64>,
}

/// The errors of the median of `runs` and of each run on `records`' measured cells after
/// the start, z-scored by `std` (the training experiments' deviations); a cell a run did
/// not reach makes its error infinite.
pub fn errors(records: &[(&Record, Vec<&Run>)], states: &[String], std: &[f64]) -> ErrorSummary {
    let members = records.first().map_or(0, |(_, runs)| runs.len());
    let mut median_errors = StateErrors::new(states.len());
    let mut member_errors = vec![StateErrors::new(states.len()); members];
    for (record, runs) in records {
        let start = latest_start(record, runs);
        for (state, column) in record.states.iter().enumerate().take(states.len()) {
            let scale = std.get(state).copied().unwrap_or(1.0);
            for (row, cell) in column.iter().enumerate().skip(start + 1) {
                let Some(measured) = *cell else { continue };
                let values: Vec<f64> = runs.iter().map(|r| r.states[state][row]).collect();
                let centre = median(&values).unwrap_or(f64::INFINITY);
                median_errors.add(state, finite_error(centre, measured, scale));
                for (errors, value) in member_errors.iter_mut().zip(&values) {
                    errors.add(state, finite_error(*value, measured, scale));
                }
            }
        }
    }
    let per_state: Vec<(String, f64)> = (states.iter().zip(median_errors.nmse()))
        .filter_map(|(name, e)| e.map(|e| (name.clone(), e)))
        .collect();
    ErrorSummary {
        measure: "the mean over measured states of the NMSE of the free run at the held-out \
                  cells after its start (z-scored by the training experiments' deviations)"
            .into(),
        median: mean_over_states(per_state.iter().map(|(_, e)| *e)),
        median_per_state: per_state,
        members: (member_errors.iter())
            .map(|e| mean_over_states(e.nmse().into_iter().flatten()))
            .collect(),
    }
}

/// A cell's error; infinite where the prediction is not finite (a run that stopped).
fn finite_error(predicted: f64, measured: f64, scale: f64) -> f64 {
    if predicted.is_finite() {
        cell_error(predicted, measured, scale)
    } else {
        f64::INFINITY
    }
}
