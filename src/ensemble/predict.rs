//! Predictions of an ensemble run (`gbc predict` on a directory with `ensemble.json`): every
//! used member predicts each experiment (members on `jobs` threads), and the tables are
//! combined row by row into the members' median of every column, with the calibrated band
//! of each measured state beside it (`X_lo`, `X_hi`) and its coverage of the data's measured
//! cells.
//!
//! A member whose free run leaves the physical range stops there; the median and the band
//! are then taken over the members still running, and the table ends at the first row
//! where fewer than half of them are. A cell no member reaches counts outside the band.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use super::calibrate::{count, CellCount};
use super::error::EnsembleError;
use super::info::{EnsembleInfo, ENSEMBLE_FILE};
use super::noise::StateNoise;
use super::run::{row_at, Run};
use crate::error::Bug;
use crate::experiment::execute::run_jobs;
use crate::ir;
use crate::numeric::median;
use crate::record::Record;
use crate::train::{History, PhysicalRange};
use crate::trained::artifacts;
use crate::trained::predict::whatif::{what_if, WhatIf};
use crate::trained::predict::{predict_in_range, Mode, PredictionTable};

/// Whether `directory` holds an ensemble run.
pub fn is_ensemble(directory: &Path) -> bool {
    directory.join(ENSEMBLE_FILE).is_file()
}

/// An ensemble run read back: its description, and the directory of each used member.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// `ensemble.json`.
    pub info: EnsembleInfo,
    /// Each used member's run directory.
    pub members: Vec<PathBuf>,
    /// How the model differs from the one trained, outside its structure (for stderr).
    pub notes: Vec<String>,
    /// The first used member's sampling step (what-if runs default to it).
    pub step: f64,
}

/// Reads the ensemble in `directory` for `model` (file text `source`): `ensemble.json`, and
/// each used member's run checked against the model as [`artifacts::restore_with_notes`]
/// checks a run.
pub fn load(model: &ir::Model, source: &str, directory: &Path) -> Result<Loaded, EnsembleError> {
    let path = directory.join(ENSEMBLE_FILE);
    let bad = |reason: String| EnsembleError::BadEnsemble {
        path: path.display().to_string(),
        reason,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| bad(crate::io::describe(&e)))?;
    let info: EnsembleInfo = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let members: Vec<PathBuf> = info.used().map(|m| directory.join(&m.run)).collect();
    if members.is_empty() {
        return Err(bad("expected used members, found none".into()));
    }
    let mut notes = Vec::new();
    let mut step = f64::NAN;
    for member in &members {
        let restored = artifacts::restore_with_notes(model, source, member)?;
        if notes.is_empty() {
            notes = restored.notes;
        }
        if step.is_nan() {
            step = restored.setup.step;
        }
    }
    Ok(Loaded {
        info,
        members,
        notes,
        step,
    })
}

/// What is done with one restored member and its physical range.
type MemberWork<'a, T> =
    dyn Fn(&artifacts::Restored, Option<PhysicalRange>) -> Result<T, EnsembleError> + Sync + 'a;

/// `each(restored, range)` for every used member (members on `jobs` threads), in member
/// order; `on_member(k)` hears when member `k` (0-based among the used) is done.
fn for_each_member<T: Send>(
    model: &ir::Model,
    (source, loaded): (&str, &Loaded),
    jobs: usize,
    each: &MemberWork<'_, T>,
    on_member: &(dyn Fn(usize) + Sync),
) -> Result<Vec<T>, EnsembleError> {
    let slots: Mutex<Vec<Option<T>>> =
        Mutex::new((0..loaded.members.len()).map(|_| None).collect());
    let work = |member: usize| -> Result<(), EnsembleError> {
        let restored = artifacts::restore_with_notes(model, source, &loaded.members[member])?;
        let range = restored.info.physical_range();
        let result = each(&restored, range)?;
        slots.lock().unwrap_or_else(|p| p.into_inner())[member] = Some(result);
        on_member(member);
        Ok(())
    };
    run_jobs(
        jobs,
        loaded.members.len(),
        &work,
        EnsembleError::cannot_start,
    )?;
    Ok((slots.into_inner())
        .unwrap_or_else(|p| p.into_inner())
        .into_iter()
        .flatten()
        .collect())
}

/// Every used member's predictions along each of `records` (`[member][record]`), members on
/// `jobs` threads; each table as the member's own prediction, cut where its free run left
/// the physical range. `on_member(k)` hears when member `k` (0-based among the used) is
/// done.
pub fn member_tables(
    model: &ir::Model,
    (source, loaded): (&str, &Loaded),
    records: &[Record],
    (mode, history, jobs): (Mode, History, usize),
    on_member: &(dyn Fn(usize) + Sync),
) -> Result<Vec<Vec<PredictionTable>>, EnsembleError> {
    let each = |restored: &artifacts::Restored, range: Option<PhysicalRange>| {
        let mut tables = Vec::with_capacity(records.len());
        for record in records {
            let how = (mode, history, range.as_ref());
            let mut table =
                predict_in_range(model, &restored.network, &restored.setup, record, how)?;
            table.cut_at_divergence();
            tables.push(table);
        }
        Ok(tables)
    };
    for_each_member(model, (source, loaded), jobs, &each, on_member)
}

/// A what-if run of every used member (`gbc simulate --weights DIR`, members on `jobs`
/// threads), combined into the median and, at `level`, the band of each measured state.
pub fn what_if_band(
    model: &ir::Model,
    (source, loaded): (&str, &Loaded),
    what: &WhatIf,
    (level, jobs): (Option<f64>, usize),
) -> Result<BandTable, EnsembleError> {
    let each = |restored: &artifacts::Restored, range: Option<PhysicalRange>| {
        let network = (&restored.network, &restored.setup);
        let mut table = what_if(model, network, what, range.as_ref())?;
        table.cut_at_divergence();
        Ok(table)
    };
    let tables = for_each_member(model, (source, loaded), jobs, &each, &|_| {})?;
    let times = (tables.iter())
        .filter_map(|t| t.columns.first())
        .max_by_key(|c| c.len())
        .cloned()
        .unwrap_or_default();
    let record = Record {
        name: "what-if".into(),
        source: "what-if".into(),
        inputs: vec![Vec::new(); model.inputs.len()],
        states: vec![vec![None; times.len()]; model.states.len()],
        observables: Vec::new(),
        times,
    };
    predict_table(model, &loaded.info, (&record, &tables), level)
}

/// The ensemble's prediction along one experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct BandTable {
    /// The members' median of every column, then `X_lo`, `X_hi` per banded state.
    pub table: PredictionTable,
    /// The measured states with a band.
    pub banded: Vec<String>,
    /// Per banded state, the data's measured cells after the start inside the band (none
    /// without a band).
    pub coverage: Vec<CellCount>,
    /// Each member's divergence, in words (`member 3: ...`).
    pub stopped: Vec<String>,
    /// The time from which fewer than half the members ran (the table ends before it).
    pub ended: Option<f64>,
}

/// Combines the members' `tables` along `record` (one per used member, as
/// [`member_tables`] gives them) into the median and, at `level`, the band.
pub fn predict_table(
    model: &ir::Model,
    info: &EnsembleInfo,
    (record, tables): (&Record, &[PredictionTable]),
    level: Option<f64>,
) -> Result<BandTable, EnsembleError> {
    let header = common_header(tables)?;
    let banding = Banding {
        noise: &info.band.noise,
        factors: (0..model.states.len())
            .map(|s| level.and_then(|l| info.calibration.factor(s, l)))
            .collect(),
        state_columns: state_columns(model, &header)?,
    };
    let combined = combine(record, tables, header.len(), &banding);
    let mut banded = Vec::new();
    let mut full_header = header;
    let mut columns = combined.columns;
    for (state, (lo, hi)) in combined.bands.into_iter().enumerate() {
        if banding.factors[state].is_some() {
            let name = &model.states[state].name;
            full_header.extend([format!("{name}_lo"), format!("{name}_hi")]);
            columns.extend([lo, hi]);
            banded.push(name.clone());
        }
    }
    let coverage = match level.filter(|_| !banded.is_empty()) {
        Some(level) => band_coverage(model, info, (record, tables), level, &banded),
        None => Vec::new(),
    };
    Ok(BandTable {
        table: PredictionTable {
            header: full_header,
            columns,
            divergence: None,
        },
        banded,
        coverage,
        stopped: stopped_members(info, tables),
        ended: combined.ended,
    })
}

/// The header every member's table shares (an internal error where they differ or have
/// none).
fn common_header(tables: &[PredictionTable]) -> Result<Vec<String>, EnsembleError> {
    let header = (tables.first()).map_or_else(Vec::new, |t| t.header.clone());
    if header.is_empty() || tables.iter().any(|t| t.header != header) {
        return Err(Bug::new(
            "the ensemble's prediction",
            "member tables differ in columns",
        )
        .into());
    }
    Ok(header)
}

/// The column of each of the model's states in `header`.
fn state_columns(model: &ir::Model, header: &[String]) -> Result<Vec<usize>, EnsembleError> {
    Ok((model.states.iter())
        .map(|s| header.iter().position(|h| *h == s.name))
        .collect::<Option<_>>()
        .ok_or_else(|| Bug::new("the ensemble's prediction", "a state without its column"))?)
}

/// How each state's band is made from the members' predictions.
struct Banding<'a> {
    /// The measurement noise of each state.
    noise: &'a [StateNoise],
    /// Each state's calibrated factor at the level asked for (`None`: no band).
    factors: Vec<Option<f64>>,
    /// The column of each state in the members' tables.
    state_columns: Vec<usize>,
}

/// The members combined row by row.
struct Combined {
    /// The members' median of every column.
    columns: Vec<Vec<f64>>,
    /// Each state's band, lower and upper edge (empty for a state without one).
    bands: Vec<(Vec<f64>, Vec<f64>)>,
    /// The time from which fewer than half the members ran.
    ended: Option<f64>,
}

/// The median of every column and each state's band, row by row from the first row any
/// member predicts, until fewer than half the members that started still run.
fn combine(
    record: &Record,
    tables: &[PredictionTable],
    width: usize,
    banding: &Banding,
) -> Combined {
    let rows = member_rows(record, tables);
    let starts: Vec<usize> = (rows.iter())
        .map(|m| m.iter().position(Option::is_some).unwrap_or(record.len()))
        .collect();
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); width];
    let mut bands: Vec<(Vec<f64>, Vec<f64>)> =
        vec![(Vec::new(), Vec::new()); banding.factors.len()];
    let mut ended = None;
    let first = starts.iter().copied().min().unwrap_or(record.len());
    for row in first..record.len() {
        let living: Vec<&Vec<f64>> = rows.iter().filter_map(|m| m[row].as_ref()).collect();
        let started = starts.iter().filter(|&&s| s <= row).count();
        if living.len() < started.div_ceil(2) || living.is_empty() {
            ended = Some(record.times[row]);
            break;
        }
        for (column, values) in columns.iter_mut().enumerate() {
            let at: Vec<f64> = living.iter().map(|v| v[column]).collect();
            values.push(median(&at).unwrap_or(f64::NAN));
        }
        banding.extend(&mut bands, &living);
    }
    Combined {
        columns,
        bands,
        ended,
    }
}

impl Banding<'_> {
    /// Extends each banded state's `bands` by the band of the `living` members' row.
    fn extend(&self, bands: &mut [(Vec<f64>, Vec<f64>)], living: &[&Vec<f64>]) {
        for (state, (lo, hi)) in bands.iter_mut().enumerate() {
            let Some(factor) = self.factors[state] else {
                continue;
            };
            let predictions = living.iter().map(|v| v[self.state_columns[state]]);
            let (l, h) = (self.noise[state].base_band(predictions))
                .map_or((f64::NAN, f64::NAN), |b| b.stretched(factor));
            lo.push(l);
            hi.push(h);
        }
    }
}

/// The data's measured cells inside the band at `level`, per `banded` state.
fn band_coverage(
    model: &ir::Model,
    info: &EnsembleInfo,
    (record, tables): (&Record, &[PredictionTable]),
    level: f64,
    banded: &[String],
) -> Vec<CellCount> {
    let runs: Vec<Run> = (tables.iter())
        .map(|t| Run::of_table(t, record, model.states.len()))
        .collect();
    let runs: Vec<&Run> = runs.iter().collect();
    let noise = &info.band.noise;
    let (counts, _) = count(record, &runs, (noise, &info.calibration), level);
    counts
        .into_iter()
        .filter(|c| banded.contains(&c.state))
        .collect()
}

/// Each member's divergence, in words (`member 3: ...`).
fn stopped_members(info: &EnsembleInfo, tables: &[PredictionTable]) -> Vec<String> {
    (tables.iter().zip(info.used()))
        .filter_map(|(t, m)| {
            t.divergence
                .as_ref()
                .map(|d| format!("member {}: {d}", m.index))
        })
        .collect()
}

/// Per member, per record row, the row of its table at that time (`None`: not predicted).
fn member_rows(record: &Record, tables: &[PredictionTable]) -> Vec<Vec<Option<Vec<f64>>>> {
    let tolerance = record.time_tolerance();
    (tables.iter())
        .map(|table| {
            let mut rows = vec![None; record.len()];
            let times = table.columns.first().map_or(&[][..], Vec::as_slice);
            for (position, time) in times.iter().enumerate() {
                if let Some(row) = row_at(record, *time, tolerance) {
                    rows[row] = Some(table.columns.iter().map(|c| c[position]).collect());
                }
            }
            rows
        })
        .collect()
}
