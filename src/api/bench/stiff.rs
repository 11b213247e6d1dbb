//! `gbc bench`'s stiff integrations: Robertson's kinetics to 4e5 s and the stiff fed-batch
//! of `models/stiff/` along every batch of its record (feed held from each row, start from
//! each batch's first row), at the model's declared params and with the Monod constant
//! lowered to 2.7e-6 g/L, where a fit's line search goes. The same runs as
//! `bench/stiff/compare.py`, timed in process (median of five) so that scipy's timings in
//! `bench/stiff/timing_scipy.json` compare without process start-up.

use std::path::Path;
use std::time::Instant;

use super::ApiError;
use crate::ir::Model;
use crate::numeric::median;
use crate::signal::Signal;
use crate::solve::ode::{SimOptions, Stats};

/// Repetitions of each case.
const REPEATS: usize = 5;

/// One timed case.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StiffRow {
    /// What is integrated.
    pub case: String,
    /// Integrations per repetition (batches).
    pub runs: usize,
    /// Median wall time of all of them together.
    pub median_seconds: f64,
    /// Accepted steps, all runs together.
    pub accepted: usize,
    /// Of which implicit.
    pub implicit: usize,
}

/// A simulation to time.
struct Job {
    model: Model,
    signals: Vec<Signal>,
    options: SimOptions,
}

/// Times every case.
pub fn time_stiff(root: &Path) -> Result<Vec<StiffRow>, ApiError> {
    let robertson = super::load_model(&root.join("models/stiff/robertson.gbm"))?;
    let options = SimOptions::new(4e5, 4e4);
    let mut rows = vec![time_case(
        "robertson to 4e5 s",
        &[Job {
            model: robertson,
            signals: Vec::new(),
            options,
        }],
    )?];
    let fedbatch = super::load_model(&root.join("models/stiff/fedbatch.gbm"))?;
    let data = root.join("models/stiff/data/fedbatch.csv");
    let declared = batches(&fedbatch, &data)?;
    rows.push(time_case(
        "fed-batch, 9 batches, declared params",
        &declared,
    )?);
    let mut lowered = fedbatch.clone();
    if let Some(k_s) = lowered.params.iter_mut().find(|p| p.name == "K_S") {
        k_s.init = 2.7e-6;
    }
    let lowered_jobs = batches(&lowered, &data)?;
    rows.push(time_case(
        "fed-batch, 9 batches, K_S = 2.7e-6 g/L",
        &lowered_jobs,
    )?);
    Ok(rows)
}

/// One simulation per experiment of the record at `data`: from its first row to its last,
/// sampled every 0.05 h (the record's clock), inputs held from each row.
fn batches(model: &Model, data: &Path) -> Result<Vec<Job>, ApiError> {
    let records = crate::api::read_records(model, &[data.to_path_buf()], &[])?;
    records
        .iter()
        .map(|record| {
            let signals = (record.inputs.iter())
                .map(|column| Signal::new(record.times.clone(), column.clone()))
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| ApiError::Internal(e.to_string()))?;
            let (first, last) = (record.times[0], record.times[record.len() - 1]);
            let options = SimOptions {
                t_start: first,
                initial: record.states.iter().map(|cells| cells[0]).collect(),
                ..SimOptions::new(last, 0.05)
            };
            Ok(Job {
                model: model.clone(),
                signals,
                options,
            })
        })
        .collect()
}

/// The median time of all `jobs` together over [`REPEATS`] repetitions.
fn time_case(case: &str, jobs: &[Job]) -> Result<StiffRow, ApiError> {
    let mut seconds = Vec::with_capacity(REPEATS);
    let mut stats = Stats::default();
    for _ in 0..REPEATS {
        stats = Stats::default();
        let started = Instant::now();
        for job in jobs {
            let run = crate::solve::ode::simulate(&job.model, &job.signals, &job.options)
                .map_err(ApiError::user)?;
            stats.add(&run.stats);
        }
        seconds.push(started.elapsed().as_secs_f64());
    }
    Ok(StiffRow {
        case: case.to_string(),
        runs: jobs.len(),
        median_seconds: median(&seconds).unwrap_or(f64::NAN),
        accepted: stats.accepted,
        implicit: stats.implicit,
    })
}
