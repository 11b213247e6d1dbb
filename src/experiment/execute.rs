//! Running a prepared study ([`super::prepare`]): [`execute`] trains the pending runs of a
//! grid on `jobs` threads, each training single-threaded, and writes each run's result
//! atomically as it finishes.

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use super::grid::RunSpec;
use super::prepare::{study_options, LoadedModel, Prepared};
use super::reference::{free_run, free_run_error, free_run_errors, mean_error};
use super::results::{self, Measure, RunResult, RunStatus, StudyRecord};
use super::{ExperimentError, ExperimentFailure, Study};
use crate::numeric::mean_std;
use crate::train::{self, Event, TrainOptions, Trained};
use crate::trained::artifacts;

/// Something worth showing while runs go on.
#[derive(Debug, Clone, Copy)]
pub enum Progress<'a> {
    /// A run was finished before (its result was read back).
    Skipped(&'a RunSpec),
    /// A run starts training.
    Started(&'a RunSpec),
    /// A run finished an epoch (1-based).
    Epoch(&'a RunSpec, usize),
    /// A run finished.
    Finished(&'a RunSpec, &'a RunResult),
}

/// Records the study in `dir`, refusing a directory that holds runs of another study.
pub fn claim_directory(dir: &Path, record: &StudyRecord) -> Result<(), ExperimentFailure> {
    if let Some(existing) = results::read_study_record(dir)? {
        if !existing.same_identity(record) {
            let what = if existing.files != record.files {
                "set of files or file contents"
            } else {
                "study (models, data, split or training settings)"
            };
            return Err(ExperimentError::StudyChanged {
                dir: dir.display().to_string(),
                what: what.to_string(),
            }
            .into());
        }
    }
    let json = serde_json::to_string_pretty(record)
        .map_err(|error| ExperimentFailure::Internal(format!("cannot encode study: {error}")))?;
    crate::io::write_atomic(&dir.join(results::STUDY_FILE), json.as_bytes())?;
    Ok(())
}

/// Trains the runs of `runs` not finished in `dir` on `jobs` threads and returns every
/// run's result (read back or new), in the order of `runs`. A run that fails to train is a
/// result with status `failed`; failing to write a result stops the experiment.
#[cfg(test)]
pub fn execute(
    prepared: &Prepared,
    runs: &[&RunSpec],
    dir: &Path,
    jobs: usize,
    on_progress: &(dyn Fn(Progress) + Sync),
) -> Result<Vec<RunResult>, ExperimentFailure> {
    execute_until(
        prepared,
        runs,
        dir,
        (jobs, &AtomicBool::new(false)),
        on_progress,
    )
}

/// [`execute`] that starts no further run once `stop` is set (runs under way finish and
/// are written): the results are those of the runs finished, in the order of `runs`, and
/// a later call reuses them.
pub fn execute_until(
    prepared: &Prepared,
    runs: &[&RunSpec],
    dir: &Path,
    (jobs, stop): (usize, &AtomicBool),
    on_progress: &(dyn Fn(Progress) + Sync),
) -> Result<Vec<RunResult>, ExperimentFailure> {
    claim_directory(dir, &prepared.record)?;
    let mut finished: Vec<Option<RunResult>> = Vec::with_capacity(runs.len());
    for spec in runs {
        let done = results::read_result(dir, &spec.id);
        if done.is_some() {
            on_progress(Progress::Skipped(spec));
        }
        finished.push(done);
    }
    let pending: Vec<usize> = (0..runs.len()).filter(|i| finished[*i].is_none()).collect();
    let slots = Mutex::new(finished);
    run_queue(jobs, pending.len(), &|position| {
        if stop.load(Ordering::Relaxed) {
            return Ok(());
        }
        let index = pending[position];
        let spec = runs[index];
        on_progress(Progress::Started(spec));
        let result = run_one(prepared, spec, dir, on_progress)?;
        on_progress(Progress::Finished(spec, &result));
        lock(&slots)[index] = Some(result);
        Ok(())
    })?;
    let slots = slots
        .into_inner()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    Ok(slots.into_iter().flatten().collect())
}

/// Calls `work(0..count)` on `jobs` threads, each taking the next item in order; the first
/// failure stops the queue (items under way finish) and is returned ([`run_jobs`] with the
/// study's failure type).
pub(super) fn run_queue(
    jobs: usize,
    count: usize,
    work: &(dyn Fn(usize) -> Result<(), ExperimentFailure> + Sync),
) -> Result<(), ExperimentFailure> {
    run_jobs(jobs, count, work, ExperimentFailure::Internal)
}

/// Calls `work(0..count)` on `jobs` threads, each taking the next item in order; the first
/// failure stops the queue (items under way finish) and is returned; `unstarted` makes the
/// failure of a thread that cannot start.
///
/// Each job is a plain thread that runs its items on a rayon pool of one thread of its own:
/// dfdx's matrix products use the current rayon pool, so every training stays
/// single-threaded. The job threads must not be rayon workers themselves: a rayon worker
/// waiting for another pool runs queued tasks of its own pool meanwhile, so it would take
/// up a sibling job's whole loop nested inside its wait and hold its own loop until that
/// one had drained the queue, leaving one job doing all the work.
pub(crate) fn run_jobs<E: Send>(
    jobs: usize,
    count: usize,
    work: &(dyn Fn(usize) -> Result<(), E> + Sync),
    unstarted: fn(String) -> E,
) -> Result<(), E> {
    let jobs = jobs.clamp(1, count.max(1));
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let failures = Mutex::new(Vec::new());
    let job = || {
        let single = rayon::ThreadPoolBuilder::new().num_threads(1).build().ok();
        while !stop.load(Ordering::Relaxed) {
            let item = next.fetch_add(1, Ordering::Relaxed);
            if item >= count {
                break;
            }
            let outcome = match &single {
                Some(single) => single.install(|| work(item)),
                None => work(item),
            };
            if let Err(failure) = outcome {
                stop.store(true, Ordering::Relaxed);
                lock(&failures).push(failure);
            }
        }
    };
    std::thread::scope(|scope| {
        for index in 0..jobs {
            let started = std::thread::Builder::new()
                .name(format!("gbc-job-{index}"))
                .spawn_scoped(scope, job);
            if let Err(error) = started {
                stop.store(true, Ordering::Relaxed);
                lock(&failures).push(unstarted(format!("cannot start a job thread: {error}")));
                break;
            }
        }
    });
    let first = lock(&failures).drain(..).next();
    first.map_or(Ok(()), Err)
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The training options of a run.
pub fn options_of(study: &Study, spec: &RunSpec) -> TrainOptions {
    TrainOptions {
        train_points: Some(spec.size),
        seed: spec.seed,
        ..study_options(study)
    }
}

/// Trains and evaluates one run, saves its weights and writes its result.
fn run_one(
    prepared: &Prepared,
    spec: &RunSpec,
    dir: &Path,
    on_progress: &(dyn Fn(Progress) + Sync),
) -> Result<RunResult, ExperimentFailure> {
    let loaded = &prepared.models[spec.model];
    let options = options_of(&prepared.study, spec);
    let started = Instant::now();
    let train_on = |data: &train::TrainingData| {
        train::train_with(
            &loaded.model,
            data,
            &options,
            &prepared.study.training.recipe(),
            &mut |event| {
                if let Event::Epoch { epoch, .. } = event {
                    on_progress(Progress::Epoch(spec, epoch));
                }
            },
        )
    };
    let trained = match &loaded.set {
        Some(set) => train_on(&set.training_data()),
        None => train::record_of(&loaded.model, &prepared.training).and_then(|training| {
            let validation = train::record_of(&loaded.model, &loaded.validation)?;
            train_on(&train::TrainingData {
                train: std::slice::from_ref(&training),
                validation: std::slice::from_ref(&validation),
                part: train::Part::All,
            })
        }),
    };
    let result = match trained.and_then(|trained| {
        let result = evaluate(prepared, loaded, spec, &trained, started)?;
        save_weights(
            prepared,
            loaded,
            &options,
            &trained,
            &results::weights_dir(dir, &spec.id),
        )?;
        Ok(result)
    }) {
        Ok(result) => result,
        Err(error) => {
            let message = if crate::error::is_bug(&error) {
                format!("internal error (a bug in gbc): {error}")
            } else {
                error.to_string()
            };
            let seconds = started.elapsed().as_secs_f64();
            RunResult::failed(spec, &loaded.label, options.epochs, message, seconds)
        }
    };
    results::write_result(dir, &result)?;
    Ok(result)
}

/// The result of a trained run: errors on the common scale, generalisation, params.
fn evaluate(
    prepared: &Prepared,
    loaded: &LoadedModel,
    spec: &RunSpec,
    trained: &Trained,
    started: Instant,
) -> Result<RunResult, train::TrainError> {
    let report = &trained.report;
    let rescale = |set: &Option<train::ErrorSet>| -> (Option<f64>, Vec<Measure>) {
        let Some(set) = set else {
            return (None, Vec::new());
        };
        let per_state: Vec<Measure> = (set.per_state.iter().enumerate())
            .map(|(index, (name, mse))| {
                let own = trained
                    .setup
                    .normalisation
                    .state_std
                    .get(index)
                    .copied()
                    .unwrap_or(1.0);
                let reference = (prepared.reference_scale.iter())
                    .find(|(n, _)| n == name)
                    .map_or(own, |(_, s)| *s);
                Measure::new(name, mse * (own / reference).powi(2))
            })
            .collect();
        let values: Vec<f64> = per_state
            .iter()
            .map(|m| m.value.unwrap_or(f64::INFINITY))
            .collect();
        let mean = values.iter().sum::<f64>() / values.len().max(1) as f64;
        (results::finite(mean), per_state)
    };
    let (offline_mse, offline_per_state) = rescale(&report.metrics.offline);
    let left_range = (report.metrics.online.as_ref())
        .and_then(|set| set.divergence.as_ref())
        .map(ToString::to_string);
    // On a data set the held-out experiments' free runs are training's own online error.
    let (online_mse, online_per_state) = if loaded.set.is_some() {
        rescale(&report.metrics.online)
    } else {
        uniform_online(prepared, loaded, trained)?
    };
    let mut generalisation = Vec::new();
    for data in &prepared.generalisation {
        let error = free_run_error(&loaded.model, &trained.network, &trained.setup, data)?;
        generalisation.push(Measure::new(&data.path.display().to_string(), error));
    }
    Ok(RunResult {
        id: spec.id.clone(),
        model: loaded.label.clone(),
        size: spec.size,
        replicate: spec.replicate,
        seed: spec.seed,
        epochs: prepared.study.settings.epochs,
        status: RunStatus::Ok,
        error: None,
        offline_mse,
        online_mse,
        offline_per_state,
        online_per_state,
        generalisation,
        params: report
            .params
            .iter()
            .map(|(name, value)| Measure::new(name, *value))
            .collect(),
        final_loss: report.losses.last().copied().and_then(results::finite),
        train_pairs: report.train_pairs,
        validation_pairs: report.validation_pairs,
        wall_seconds: started.elapsed().as_secs_f64(),
        warnings: report.warnings.iter().map(ToString::to_string).collect(),
        left_range,
    })
}

/// The online error of a run on the paper's protocol: one free run over the validation
/// window, on the study's common scale.
fn uniform_online(
    prepared: &Prepared,
    loaded: &LoadedModel,
    trained: &Trained,
) -> Result<(Option<f64>, Vec<Measure>), train::TrainError> {
    let run = free_run(
        &loaded.model,
        &trained.network,
        &trained.setup,
        &loaded.validation,
    )?;
    let reference = |name: &str, column: &[f64]| {
        (prepared.reference_scale.iter())
            .find(|(n, _)| n == name)
            .map_or_else(|| mean_std(column).1, |(_, s)| *s)
    };
    let online = free_run_errors(&loaded.model, &run, &loaded.validation, &reference);
    let online_mse = results::finite(mean_error(&online));
    let online_per_state = online.iter().map(|(n, e)| Measure::new(n, *e)).collect();
    Ok((online_mse, online_per_state))
}

fn save_weights(
    prepared: &Prepared,
    loaded: &LoadedModel,
    options: &TrainOptions,
    trained: &Trained,
    directory: &Path,
) -> Result<(), train::TrainError> {
    let model_path = loaded.path.display().to_string();
    let data_path = prepared.study.data.describe();
    let info = artifacts::run_info(
        &loaded.model,
        (&model_path, &loaded.source),
        &data_path,
        options,
        trained,
    );
    artifacts::save(directory, &info, &trained.network)
}
