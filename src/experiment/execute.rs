//! Running a study: [`prepare`] loads and checks every model and record once, [`execute`]
//! trains the pending runs of a grid on `jobs` threads, each training single-threaded, and writes each run's result atomically as it finishes.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use sha2::{Digest, Sha256};

use super::grid::RunSpec;
use super::reference::{free_run, free_run_error, free_run_errors, mean_error};
use super::results::{self, Fingerprint, Measure, RunResult, RunStatus, StudyRecord};
use super::set::{self, SetSplit};
use super::{ExperimentError, ExperimentFailure, Study, Validation};
use crate::data::{Column, Dataset, MinRows};
use crate::ir;
use crate::numeric::mean_std;
use crate::train::pairs::first_pair_row;
use crate::train::{self, artifacts, Event, TrainOptions, Trained};

/// A model of a study, compiled, with its validation record.
#[derive(Debug, Clone)]
pub struct LoadedModel {
    /// Its label.
    pub label: String,
    /// The model file.
    pub path: PathBuf,
    /// The compiled model.
    pub model: ir::Model,
    /// The file's text (for the weights' hash).
    pub source: String,
    /// Its validation record: the embedding history, then the validation window.
    pub validation: Dataset,
    /// Training pairs available before the validation window.
    pub available: usize,
    /// The row of [`Prepared::validation_source`] its validation record starts at.
    pub offset: usize,
    /// On a data set: its training and held-out experiments (then `validation` is empty).
    pub set: Option<SetSplit>,
}

/// A study with everything loaded and checked.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// The study.
    pub study: Study,
    /// Its record (with the files' hashes).
    pub record: StudyRecord,
    /// The models, in study order.
    pub models: Vec<LoadedModel>,
    /// The rows that may train.
    pub training: Dataset,
    /// The whole record validation rows come from (the training file, or `--val FILE`).
    pub validation_source: Dataset,
    /// Standard deviation of each measured state over the validation window, by name: the
    /// common scale of every error.
    pub reference_scale: Vec<(String, f64)>,
    /// The generalisation records.
    pub generalisation: Vec<Dataset>,
    /// The truth model, if the study names one.
    pub truth: Option<ir::Model>,
}

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

/// Loads the study's models and records and checks that every size fits the data.
pub fn prepare(study: &Study) -> Result<Prepared, ExperimentFailure> {
    study.check()?;
    let mut reports = Vec::new();
    let mut compiled = Vec::new();
    for spec in &study.models {
        match crate::driver::compile_file(&spec.path, &[]) {
            Ok(result) => compiled.push(result.model),
            Err(errors) => reports.extend(errors),
        }
    }
    let truth = match &study.truth {
        Some(path) => match crate::driver::compile_file(path, &[]) {
            Ok(result) => Some(result.model),
            Err(errors) => {
                reports.extend(errors);
                None
            }
        },
        None => None,
    };
    if !reports.is_empty() {
        return Err(ExperimentFailure::User(reports));
    }
    if study.on_data_set() {
        return prepare_set(study, compiled, truth);
    }
    let required = required_columns(&compiled, truth.as_ref());
    let data = read_record(study.data.paths()[0], &required)?;
    let split = Split::new(study, &data, &required)?;
    let mut models = Vec::new();
    for (spec, model) in study.models.iter().zip(compiled) {
        let history = first_pair_row(&model, data.step);
        let (validation, available, offset) = split.for_model(&spec.label, history)?;
        check_sizes(
            study,
            &spec.label,
            available,
            "before the validation window",
        )?;
        models.push(LoadedModel {
            label: spec.label.clone(),
            path: spec.path.clone(),
            source: std::fs::read_to_string(&spec.path).unwrap_or_default(),
            model,
            validation,
            available,
            offset,
            set: None,
        });
    }
    let generalisation = (study.generalisation.iter())
        .map(|path| read_record(path, &required))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Prepared {
        record: study_record(study)?,
        study: study.clone(),
        reference_scale: split.reference_scale(&models),
        training: split.training,
        validation_source: split.source,
        models,
        generalisation,
        truth,
    })
}

/// A study on a data set: each model binds the experiments to its own columns.
fn prepare_set(
    study: &Study,
    compiled: Vec<ir::Model>,
    truth: Option<ir::Model>,
) -> Result<Prepared, ExperimentFailure> {
    let first = study.data.paths()[0].to_path_buf();
    let empty = Dataset {
        path: first,
        times: Vec::new(),
        step: 0.0,
        columns: Vec::new(),
    };
    let mut models = Vec::new();
    for (spec, model) in study.models.iter().zip(compiled) {
        let split = set::load(study, &model)?;
        let available = set::available_pairs(&model, &split, &study_options(study))?;
        check_sizes(study, &spec.label, available, "in the training experiments")?;
        models.push(LoadedModel {
            label: spec.label.clone(),
            path: spec.path.clone(),
            source: std::fs::read_to_string(&spec.path).unwrap_or_default(),
            model,
            validation: empty.clone(),
            available,
            offset: 0,
            set: Some(split),
        });
    }
    Ok(Prepared {
        record: study_record(study)?,
        study: study.clone(),
        reference_scale: set::reference_scale(&models),
        training: empty.clone(),
        validation_source: empty,
        models,
        generalisation: Vec::new(),
        truth,
    })
}

/// Refuses a size above the `available` training pairs of model `label` (`where_`: where
/// they come from).
fn check_sizes(
    study: &Study,
    label: &str,
    available: usize,
    where_: &str,
) -> Result<(), ExperimentFailure> {
    match study.sizes.iter().copied().find(|s| *s > available) {
        Some(size) => Err(ExperimentError::BadOption {
            option: "--sizes".into(),
            expected: format!(
                "sizes of at most {available} (the training pairs of `{label}` {where_})"
            ),
            found: size.to_string(),
        }
        .into()),
        None => Ok(()),
    }
}

/// Every column the models (and the truth's inputs) read.
fn required_columns(models: &[ir::Model], truth: Option<&ir::Model>) -> Vec<String> {
    let mut required: Vec<String> = Vec::new();
    let names = (models.iter())
        .flat_map(|m| {
            m.inputs
                .iter()
                .map(|i| &i.name)
                .chain(m.states.iter().map(|s| &s.name))
        })
        .chain(truth.into_iter().flat_map(|t| {
            (t.inputs.iter().map(|i| &i.name)).chain(t.states.iter().map(|s| &s.name))
        }));
    for name in names {
        if !required.contains(name) {
            required.push(name.clone());
        }
    }
    required
}

fn read_record(path: &Path, required: &[String]) -> Result<Dataset, ExperimentFailure> {
    let names: Vec<&str> = required.iter().map(String::as_str).collect();
    Ok(crate::data::read(
        path,
        &names,
        MinRows::new(2, "one step needs two rows"),
    )?)
}

/// The training rows and where validation comes from.
struct Split {
    training: Dataset,
    /// The record validation rows are taken from.
    source: Dataset,
    /// First validated row of `source` (a step starts there).
    start: usize,
    /// Whether `source` is a separate file (its own history) or the training record.
    separate: bool,
}

impl Split {
    fn new(study: &Study, data: &Dataset, required: &[String]) -> Result<Split, ExperimentFailure> {
        match &study.validation {
            Validation::FromRow(row) => {
                if *row + 2 > data.len() {
                    return Err(ExperimentError::BadOption {
                        option: "--val-from".into(),
                        expected: format!(
                            "a row below {} (the record's rows less one)",
                            data.len() - 1
                        ),
                        found: row.to_string(),
                    }
                    .into());
                }
                Ok(Split {
                    training: slice(data, 0..*row),
                    source: data.clone(),
                    start: *row,
                    separate: false,
                })
            }
            Validation::File(path) => Ok(Split {
                training: data.clone(),
                source: read_record(path, required)?,
                start: 0,
                separate: true,
            }),
            Validation::Holdout(_) => Err(ExperimentFailure::Internal(
                "a uniform split asked of a study on a data set".into(),
            )),
        }
    }

    /// A model's validation record, its available training pairs, and the row of the
    /// source its record starts at.
    fn for_model(
        &self,
        label: &str,
        history: usize,
    ) -> Result<(Dataset, usize, usize), ExperimentFailure> {
        let too_short = |what: &str| ExperimentError::BadOption {
            option: "--val-from".into(),
            expected: format!(
                "room for the {history} rows of embedding history of `{label}` {what}"
            ),
            found: format!("{} rows", self.training.len()),
        };
        let available = (self.training.len())
            .checked_sub(history + 1)
            .filter(|a| *a > 0)
            .ok_or_else(|| too_short("and one training pair"))?;
        if self.separate {
            if self.source.len() < history + 2 {
                return Err(too_short("and one step in the validation file").into());
            }
            return Ok((self.source.clone(), available, 0));
        }
        let first = self
            .start
            .checked_sub(history)
            .ok_or_else(|| too_short("before it"))?;
        Ok((
            slice(&self.source, first..self.source.len()),
            available,
            first,
        ))
    }

    /// Std of each measured state over the validation window.
    fn reference_scale(&self, models: &[LoadedModel]) -> Vec<(String, f64)> {
        let history = (models.iter())
            .map(|m| first_pair_row(&m.model, self.source.step))
            .max()
            .unwrap_or(0);
        let start = if self.separate { history } else { self.start };
        let mut scale: Vec<(String, f64)> = Vec::new();
        for state in models.iter().flat_map(|m| &m.model.states) {
            if scale.iter().any(|(name, _)| name == &state.name) {
                continue;
            }
            if let Some(values) = self.source.column(&state.name) {
                let window = &values[start.min(values.len())..];
                scale.push((state.name.clone(), mean_std(window).1));
            }
        }
        scale
    }
}

/// Rows `rows` of a record.
pub fn slice(data: &Dataset, rows: Range<usize>) -> Dataset {
    Dataset {
        path: data.path.clone(),
        times: data.times[rows.clone()].to_vec(),
        step: data.step,
        columns: (data.columns.iter())
            .map(|c| Column {
                name: c.name.clone(),
                values: c.values[rows.clone()].to_vec(),
            })
            .collect(),
    }
}

/// The study with the hashes of its files.
fn study_record(study: &Study) -> Result<StudyRecord, ExperimentFailure> {
    let paths = study.files();
    let files = (paths.into_iter())
        .map(|path| {
            let bytes = std::fs::read(path).map_err(|error| ExperimentError::BadStudy {
                path: path.display().to_string(),
                reason: crate::io::describe(&error),
                source_code: None,
                span: None,
            })?;
            let sha256 = Sha256::digest(&bytes)
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect();
            Ok(Fingerprint {
                path: path.display().to_string(),
                sha256,
            })
        })
        .collect::<Result<Vec<_>, ExperimentError>>()?;
    Ok(StudyRecord {
        gbc_version: env!("CARGO_PKG_VERSION").to_string(),
        study: study.clone(),
        files,
    })
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
pub fn execute(
    prepared: &Prepared,
    runs: &[&RunSpec],
    dir: &Path,
    jobs: usize,
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
/// failure stops the queue (items under way finish) and is returned.
///
/// Each job is a plain thread that runs its items on a rayon pool of one thread of its own:
/// dfdx's matrix products use the current rayon pool, so every training stays
/// single-threaded. The job threads must not be rayon workers themselves: a rayon worker
/// waiting for another pool runs queued tasks of its own pool meanwhile, so it would take
/// up a sibling job's whole loop nested inside its wait and hold its own loop until that
/// one had drained the queue, leaving one job doing all the work.
pub(super) fn run_queue(
    jobs: usize,
    count: usize,
    work: &(dyn Fn(usize) -> Result<(), ExperimentFailure> + Sync),
) -> Result<(), ExperimentFailure> {
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
                let message = format!("cannot start a job thread: {error}");
                lock(&failures).push(ExperimentFailure::Internal(message));
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

/// The training options every run of `study` shares.
fn study_options(study: &Study) -> TrainOptions {
    TrainOptions {
        // The paper's protocol: validation runs start from measured history. On a data
        // set, each experiment starts at its first row (as `gbc train` does).
        history: if study.on_data_set() {
            train::History::Held
        } else {
            train::History::Measured
        },
        // The free run covers the whole validation window (the default).
        ..TrainOptions::with(&study.settings)
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
