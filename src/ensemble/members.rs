//! Training the members of an ensemble in parallel, and what comes of them: the noise of
//! each state, the band's calibration, its coverage of the held-out experiments and the
//! errors, written to `ensemble.json`.

use std::path::Path;
use std::sync::Mutex;

use crate::trained::status::TrainingStatus;
use std::time::Instant;

use super::calibrate::{self, MemberRuns};
use super::error::EnsembleError;
use super::info::{BandRule, EnsembleInfo, MemberInfo, ENSEMBLE_FILE, MEMBERS_DIR, RULE};
use super::noise::{self, StateNoise};
use super::resample::{self, Resample};
use super::run::Run;
use crate::experiment::execute::run_jobs;
use crate::ir;
use crate::record::{Normalisation, Record};
use crate::train::{
    self, train_run, Event, History, Part, PhysicalRange, Recipe, RunControl, TrainError,
    TrainOptions, TrainingData,
};
use crate::trained::artifacts;
use crate::trained::keep::Keep;
use crate::trained::predict::{predict_in_range, Mode};

/// How many members, on what, on how many threads, and the level reported.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Members to train (at least 2).
    pub members: usize,
    /// What each member trains on.
    pub resample: Resample,
    /// Members trained at once.
    pub jobs: usize,
    /// The band level the coverage is counted at.
    pub level: f64,
}

/// What a member is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MemberEvent<'a> {
    /// A member starts training.
    Started {
        /// 1-based.
        member: usize,
        /// Members in all.
        members: usize,
        /// Its seed.
        seed: u64,
        /// The experiments it drew.
        trained_on: &'a [String],
    },
    /// A member enters a phase: [`crate::train::Event::Phase`]'s, or [`RUNNING_FREE`].
    Phase {
        /// 1-based.
        member: usize,
        /// The phase, in words.
        phase: &'static str,
    },
    /// A member finished an epoch.
    Epoch {
        /// 1-based.
        member: usize,
        /// 1-based epoch.
        epoch: usize,
        /// Epochs planned.
        epochs: usize,
    },
    /// `--toward-mechanism auto`'s folds, once for every member: `done` of `total` fold
    /// epochs ([`crate::train::settle`]).
    Choosing {
        /// Fold epochs done.
        done: usize,
        /// Fold epochs in all.
        total: usize,
    },
    /// The stop every member ends at (0: each member is the mechanism).
    Chosen {
        /// The chosen epoch.
        stop: usize,
        /// Epochs asked for.
        epochs: usize,
    },
    /// A member is done (trained, saved and run free along every experiment, or failed).
    Finished {
        /// 1-based.
        member: usize,
        /// `finished`, `diverged: ...`, `failed: ...`.
        status: &'a str,
        /// Wall-clock seconds.
        seconds: f64,
    },
}

/// A trained ensemble: its description (written to `ensemble.json`) and the free runs of
/// the members it uses.
#[derive(Debug, Clone)]
pub struct Trained {
    /// What `ensemble.json` holds.
    pub info: EnsembleInfo,
    /// The used members' free runs: the training experiments, then the held-out ones.
    pub members: Vec<MemberRuns>,
}

/// The phase after training: the member runs free along every experiment.
pub const RUNNING_FREE: &str = "running free along every experiment";

/// One member's outcome.
struct Outcome {
    info: MemberInfo,
    runs: Vec<Run>,
}

/// Trains the ensemble of `plan` on `data` (members in parallel), calibrates its band on
/// the training experiments, counts its coverage of the held-out ones and writes every
/// member's run and `ensemble.json` under `keep.directory`.
pub fn train_ensemble(
    model: &ir::Model,
    data: &TrainingData,
    (options, recipe): (&TrainOptions, &Recipe),
    plan: &Plan,
    keep: &Keep,
    on_event: &(dyn Fn(MemberEvent) + Sync),
) -> Result<Trained, EnsembleError> {
    check_plan(plan, data)?;
    // The stop is chosen once, on the training experiments themselves: a member's bag may
    // draw one experiment twice, and no fold of it could hold that one out.
    let settled = settle_once(model, data, (options, recipe), on_event)?;
    let (options, recipe) = (&settled.options, &settled.recipe);
    let last_epoch = settled.last_epoch;
    let slots: Mutex<Vec<Option<Outcome>>> = Mutex::new((0..plan.members).map(|_| None).collect());
    let work = |member: usize| -> Result<(), EnsembleError> {
        let outcome = train_member(
            model,
            data,
            (options, recipe, last_epoch),
            (plan, member),
            keep,
            on_event,
        )?;
        let status = outcome.info.status.to_string();
        on_event(MemberEvent::Finished {
            member: member + 1,
            status: &status,
            seconds: outcome.info.seconds,
        });
        lock(&slots)[member] = Some(outcome);
        Ok(())
    };
    run_jobs(plan.jobs, plan.members, &work, EnsembleError::cannot_start)?;
    let outcomes: Vec<Outcome> = (slots.into_inner())
        .unwrap_or_else(|poisoned| poisoned.into_inner())
        .into_iter()
        .flatten()
        .collect();
    let trained = assemble(model, data, (options, plan, keep), outcomes);
    write_info(&keep.directory, &trained.info)?;
    let used = trained.members.len();
    if used < 2 {
        let why = (trained.info.members.iter())
            .find(|m| !m.used)
            .map_or("none finished".into(), |m| {
                format!("member {}: {}", m.index, m.status)
            });
        return Err(EnsembleError::MembersFailed {
            finished: used,
            members: plan.members,
            why,
        });
    }
    Ok(trained)
}

/// [`crate::train::settle`] for every member, its folds' progress told as
/// [`MemberEvent::Choosing`].
fn settle_once(
    model: &ir::Model,
    data: &TrainingData,
    how: (&TrainOptions, &Recipe),
    on_event: &(dyn Fn(MemberEvent) + Sync),
) -> Result<crate::train::Settled, EnsembleError> {
    use crate::train::toward::ChoiceEvent;
    let mut folds: Vec<usize> = Vec::new();
    let mut per_fold = 0;
    let mut listen = |event: Event| match event {
        Event::Strength(ChoiceEvent::Started { folds: n, epochs }) => {
            (folds, per_fold) = (vec![0; n], epochs);
        }
        Event::Strength(ChoiceEvent::Epoch { fold, epoch }) => {
            folds[fold] = epoch;
            let done = folds.iter().sum();
            on_event(MemberEvent::Choosing {
                done,
                total: per_fold * folds.len(),
            });
        }
        Event::Strength(ChoiceEvent::Chosen(choice)) => on_event(MemberEvent::Chosen {
            stop: choice.chosen,
            epochs: choice.epochs,
        }),
        _ => {}
    };
    let control = RunControl::default();
    Ok(crate::train::settle(
        model,
        data,
        how,
        &control,
        &mut listen,
    )?)
}

/// Refuses fewer than two members, and resampling where whole experiments cannot be.
fn check_plan(plan: &Plan, data: &TrainingData) -> Result<(), EnsembleError> {
    if plan.members < 2 {
        return Err(EnsembleError::TooFewMembers {
            found: plan.members,
        });
    }
    super::error::check_level(plan.level)?;
    if plan.resample == Resample::Experiments {
        let whole = matches!(data.part, Part::All);
        if !whole || data.train.len() < 2 {
            return Err(EnsembleError::CannotResample {
                expected: "at least two whole training experiments".into(),
                found: if whole {
                    format!("{} training experiment", data.train.len())
                } else {
                    "experiments split by rows (--val-fraction, --train-points)".into()
                },
            });
        }
    }
    Ok(())
}

/// Trains member `member` (0-based) on its draws, saves its run and runs it free along
/// every experiment. A member whose training fails is an outcome with that status; an I/O
/// or network failure is an error.
fn train_member(
    model: &ir::Model,
    data: &TrainingData,
    (options, recipe, last_epoch): (&TrainOptions, &Recipe, Option<usize>),
    (plan, member): (&Plan, usize),
    keep: &Keep,
    on_event: &(dyn Fn(MemberEvent) + Sync),
) -> Result<Outcome, EnsembleError> {
    let started = Instant::now();
    let seed = options.seed.wrapping_add(member as u64);
    let draws = resample::draws(plan.resample, data.train.len(), seed);
    let bag = drawn_records(data.train, &draws);
    let mut info = member_info(data.train, &draws, member, seed);
    on_event(MemberEvent::Started {
        member: member + 1,
        members: plan.members,
        seed,
        trained_on: &info.trained_on,
    });
    let member_options = TrainOptions {
        seed,
        ..options.clone()
    };
    let member_data = TrainingData {
        train: &bag,
        ..*data
    };
    let control = RunControl {
        keep_last_finite: true,
        recoveries: keep.recoveries,
        last_epoch,
        ..RunControl::default()
    };
    let how = (&member_options, recipe);
    let trained = match train_one(model, &member_data, how, &control, (member, on_event)) {
        Ok(trained) => trained,
        Err(error @ (TrainError::Io(_) | TrainError::Backend(_))) => return Err(error.into()),
        Err(error) => {
            info.status = TrainingStatus::Failed(Some(error.to_string()));
            info.seconds = started.elapsed().as_secs_f64();
            return Ok(Outcome {
                info,
                runs: Vec::new(),
            });
        }
    };
    let run_info = artifacts::run_info(model, keep.model, keep.data, &member_options, &trained);
    artifacts::save(&keep.directory.join(&info.run), &run_info, &trained.network)?;
    if let Some(diverged) = &trained.report.diverged {
        info.status = TrainingStatus::Diverged {
            epoch: diverged.epoch,
            what: diverged.what.clone(),
        };
    }
    on_event(MemberEvent::Phase {
        member: member + 1,
        phase: RUNNING_FREE,
    });
    let runs = free_runs(model, data, &trained, options.history);
    info.used = trained.report.diverged.is_none();
    info.seconds = started.elapsed().as_secs_f64();
    Ok(Outcome { info, runs })
}

/// Member `member`'s (0-based) description before it trains: its seed, its run directory
/// and the experiments it drew from `train` and left out of its bag.
fn member_info(train: &[Record], draws: &[usize], member: usize, seed: u64) -> MemberInfo {
    let names = |indices: &[usize]| -> Vec<String> {
        (indices.iter()).map(|&i| train[i].name.clone()).collect()
    };
    MemberInfo {
        index: member + 1,
        seed,
        run: member_directory(member),
        trained_on: names(draws),
        out_of_bag: names(&resample::out_of_bag(draws, train.len())),
        status: TrainingStatus::Finished,
        used: false,
        validation_error: None,
        seconds: 0.0,
    }
}

/// One member's training run, its epochs and phases told as [`MemberEvent`]s of member
/// `member` (0-based).
fn train_one(
    model: &ir::Model,
    data: &TrainingData,
    (options, recipe): (&TrainOptions, &Recipe),
    control: &RunControl,
    (member, on_event): (usize, &(dyn Fn(MemberEvent) + Sync)),
) -> Result<train::Trained, TrainError> {
    let mut forward = |event: Event| match event {
        Event::Epoch { epoch, .. } => on_event(MemberEvent::Epoch {
            member: member + 1,
            epoch,
            epochs: options.epochs,
        }),
        Event::Phase(phase) => on_event(MemberEvent::Phase {
            member: member + 1,
            phase,
        }),
        _ => {}
    };
    train_run(model, data, (options, recipe), control, &mut forward)
}

/// A trained member's free runs along every experiment (the training ones, then the
/// held-out ones), each cut where it diverges; an experiment it cannot run is an empty run.
fn free_runs(
    model: &ir::Model,
    data: &TrainingData,
    trained: &train::Trained,
    history: History,
) -> Vec<Run> {
    let range = PhysicalRange::new(
        &trained.setup.normalisation,
        trained.report.recipe.range_factor,
    );
    let how = (Mode::Online, history, range.as_ref());
    (data.train.iter().chain(data.validation))
        .map(|record| {
            let table = predict_in_range(model, &trained.network, &trained.setup, record, how);
            table.map_or_else(
                |_| Run::none(record, model.states.len()),
                |mut table| {
                    table.cut_at_divergence();
                    Run::of_table(&table, record, model.states.len())
                },
            )
        })
        .collect()
}

/// The records of `draws`, in draw order; a repeated experiment is renamed `NAME (draw K)`.
pub fn drawn_records(records: &[Record], draws: &[usize]) -> Vec<Record> {
    let mut seen = vec![0usize; records.len()];
    (draws.iter())
        .map(|&index| {
            seen[index] += 1;
            let mut record = records[index].clone();
            if seen[index] > 1 {
                record.name = format!("{} (draw {})", record.name, seen[index]);
            }
            record
        })
        .collect()
}

/// Member `member`'s (0-based) run directory, relative to the ensemble's.
pub fn member_directory(member: usize) -> String {
    format!("{MEMBERS_DIR}/member-{:02}", member + 1)
}

/// The ensemble from its members' outcomes: noise, calibration, coverage and errors.
fn assemble(
    model: &ir::Model,
    data: &TrainingData,
    (options, plan, keep): (&TrainOptions, &Plan, &Keep),
    outcomes: Vec<Outcome>,
) -> Trained {
    let states: Vec<String> = model.states.iter().map(|s| s.name.clone()).collect();
    let train_count = data.train.len();
    let members: Vec<MemberRuns> = (outcomes.iter())
        .filter(|o| o.info.used)
        .map(|o| MemberRuns {
            index: o.info.index,
            out_of_bag: (0..train_count)
                .filter(|&e| o.info.out_of_bag.contains(&data.train[e].name))
                .collect(),
            runs: o.runs.clone(),
        })
        .collect();
    let noise = state_noise(model, data.train, &members);
    let calibration = calibrate::calibrate(&states, data.train, &members, &noise);
    let held: Vec<(&Record, Vec<&Run>)> = (data.validation.iter().enumerate())
        .map(|(v, record)| {
            let runs = members.iter().filter_map(|m| m.runs.get(train_count + v));
            (record, runs.collect())
        })
        .collect();
    let coverage = calibrate::coverage(&held, (&noise, &calibration), plan.level);
    let parts: Vec<crate::record::Part> = (data.train.iter()).map(|r| (r, 0..r.len())).collect();
    let std = Normalisation::over(&parts, states.len(), model.inputs.len()).state_std;
    let errors = (!held.is_empty()).then(|| calibrate::errors(&held, &states, &std));
    let mut member_infos: Vec<MemberInfo> = outcomes.iter().map(|o| o.info.clone()).collect();
    if let Some(errors) = &errors {
        for (info, error) in member_infos
            .iter_mut()
            .filter(|m| m.used)
            .zip(&errors.members)
        {
            info.validation_error = Some(*error);
        }
    }
    let info = EnsembleInfo {
        gbc_version: env!("CARGO_PKG_VERSION").to_string(),
        model: keep.model.0.to_string(),
        data: keep.data.to_string(),
        seed: options.seed,
        resample: plan.resample,
        training_experiments: data.train.iter().map(|r| r.name.clone()).collect(),
        validation_experiments: data.validation.iter().map(|r| r.name.clone()).collect(),
        members: member_infos,
        band: BandRule {
            rule: RULE.into(),
            base_level: super::band::BASE_LEVEL,
            noise,
        },
        calibration,
        coverage,
        errors,
    };
    Trained { info, members }
}

/// Each measured state's noise: declared, else estimated from the used members' free-run
/// residuals on the training experiments they drew.
fn state_noise(model: &ir::Model, training: &[Record], members: &[MemberRuns]) -> Vec<StateNoise> {
    (0..model.states.len())
        .map(|state| {
            noise::declared(model, state)
                .unwrap_or_else(|| {
                    let mut pairs = Vec::new();
                    for member in members {
                        for (index, record) in training.iter().enumerate() {
                            if member.out_of_bag.contains(&index) {
                                continue;
                            }
                            let Some(run) = member.runs.get(index) else {
                                continue;
                            };
                            pairs.extend(residuals(record, run, state));
                        }
                    }
                    noise::estimated(&model.states[state].name, &pairs)
                })
                .with_floor_of(model, state)
        })
        .collect()
}

/// `(prediction, measured - prediction)` at the measured cells of `state` after the run's
/// start where it predicted.
fn residuals(record: &Record, run: &Run, state: usize) -> Vec<(f64, f64)> {
    (record.states[state].iter().enumerate())
        .skip(run.start + 1)
        .filter_map(|(row, cell)| {
            let predicted = run.states[state][row];
            cell.filter(|_| predicted.is_finite())
                .map(|measured| (predicted, measured - predicted))
        })
        .collect()
}

/// Writes `ensemble.json` into `directory`.
pub fn write_info(directory: &Path, info: &EnsembleInfo) -> Result<(), EnsembleError> {
    let path = directory.join(ENSEMBLE_FILE);
    let json = serde_json::to_string_pretty(info).map_err(|error| EnsembleError::BadEnsemble {
        path: path.display().to_string(),
        reason: error.to_string(),
    })?;
    crate::io::write_atomic(&path, json.as_bytes()).map_err(TrainError::from)?;
    Ok(())
}

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}
