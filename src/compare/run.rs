//! Running a comparison: the splits checked, every fit and training of every split on
//! `jobs` threads (each training single-threaded, as `gbc experiment` runs them), then the
//! naive forecast and the scores.

use std::sync::Mutex;
use std::time::Instant;

use crate::ir;
use crate::record::{Normalisation, Record};
use crate::train::{
    self, Part, PhysicalRange, RunControl, TrainError, TrainOptions, Trained, TrainingData,
};
use crate::trained::predict::{predict_in_range, Mode};

use super::comparison::{Comparison, Curve, HeldOutRun, MemberRun, SplitResult};
use super::error::CompareError;
use super::naive::Naive;
use super::options::{Event, Member, Options, Splits};
use super::scoring::{overall, split_scores};

/// Compares `grey_box` with `mechanism` (closure-free, the same states) and the naive
/// forecast on `options`' splits of `records` (bound to the grey box; `mechanism_records`
/// the same experiments bound to the mechanism). `on_event` hears from every job thread.
pub fn compare(
    (grey_box, mechanism): (&ir::Model, &ir::Model),
    (records, mechanism_records): (&[Record], &[Record]),
    options: &Options,
    on_event: &(dyn Fn(Event) + Sync),
) -> Result<Comparison, CompareError> {
    check(grey_box, mechanism, options)?;
    let splits = held_out_indices(records, &options.splits)?;
    let members: Vec<Member> = [Member::Mechanism, Member::Untrained]
        .into_iter()
        .chain(options.seeds.iter().map(|&s| Member::GreyBox(s)))
        .collect();
    let jobs = Jobs::new(
        (grey_box, mechanism),
        (records, mechanism_records),
        (&splits, &members),
        options,
    );
    let mut outcomes = jobs.run(on_event)?.into_iter();
    let states: Vec<String> = grey_box.states.iter().map(|s| s.name.clone()).collect();
    let mut results = Vec::with_capacity(splits.len());
    for held in &splits {
        let split: Vec<Option<Outcome>> = outcomes.by_ref().take(members.len()).collect();
        results.push(assemble(records, held, split, (options, &states))?);
    }
    Ok(Comparison {
        grey_box: grey_box.name.clone(),
        mechanism: mechanism.name.clone(),
        seeds: options.seeds.clone(),
        epochs: options.training.epochs,
        overall: overall(&results, &options.seeds, &states),
        labels: std::iter::once(grey_box.time_label())
            .chain(states.iter().map(|s| grey_box.axis_label(s)))
            .collect(),
        states,
        splits: results,
    })
}

/// Every training of a comparison: each member on each split, one job each.
struct Jobs<'a> {
    /// The grey box and the mechanism.
    models: (&'a ir::Model, &'a ir::Model),
    /// The experiments bound to the grey box, and bound to the mechanism.
    records: (&'a [Record], &'a [Record]),
    /// Each split's held-out experiments, by index.
    splits: &'a [Vec<usize>],
    /// Each split's held-out experiments, by name.
    names: Vec<Vec<String>>,
    /// Every job: a split and a member, split by split.
    items: Vec<(usize, Member)>,
    /// The comparison's options.
    options: &'a Options,
}

impl<'a> Jobs<'a> {
    /// The jobs of `members` on `splits`.
    fn new(
        models: (&'a ir::Model, &'a ir::Model),
        records: (&'a [Record], &'a [Record]),
        (splits, members): (&'a [Vec<usize>], &[Member]),
        options: &'a Options,
    ) -> Self {
        let items = (0..splits.len())
            .flat_map(|split| members.iter().map(move |&m| (split, m)))
            .collect();
        let names = (splits.iter())
            .map(|held| held.iter().map(|&i| records.0[i].name.clone()).collect())
            .collect();
        Jobs {
            models,
            records,
            splits,
            names,
            items,
            options,
        }
    }

    /// Runs every job on the options' threads; their outcomes, in job order.
    fn run(&self, on_event: &(dyn Fn(Event) + Sync)) -> Result<Vec<Option<Outcome>>, CompareError> {
        on_event(Event::Started {
            runs: self.items.len(),
            epochs: self.options.training.epochs,
        });
        let slots: Mutex<Vec<Option<Outcome>>> =
            Mutex::new((0..self.items.len()).map(|_| None).collect());
        let work = |item: usize| -> Result<(), CompareError> {
            let outcome = self.run_one(item, on_event)?;
            lock(&slots)[item] = Some(outcome);
            Ok(())
        };
        let unstarted = |message: String| CompareError::from(bug(message));
        crate::experiment::execute::run_jobs(
            self.options.jobs,
            self.items.len(),
            &work,
            unstarted,
        )?;
        Ok(slots.into_inner().unwrap_or_else(|p| p.into_inner()))
    }

    /// Trains and scores job `item`'s member on its split, telling `on_event` of its epochs
    /// and its end; an I/O, backend or internal failure is an error, any other a failed
    /// outcome.
    fn run_one(
        &self,
        item: usize,
        on_event: &(dyn Fn(Event) + Sync),
    ) -> Result<Outcome, CompareError> {
        let (split, member) = self.items[item];
        let (model, bound) = match member {
            Member::Mechanism => (self.models.1, self.records.1),
            Member::Untrained | Member::GreyBox(_) => (self.models.0, self.records.0),
        };
        let held_out = &self.names[split][..];
        let parts = parted(bound, &self.splits[split]);
        let mut on_epoch = |epoch| {
            on_event(Event::Epoch {
                member,
                held_out,
                epoch,
            })
        };
        let started = Instant::now();
        let parts = (&parts.0[..], &parts.1[..]);
        let outcome = match run_member(model, parts, self.options, member, &mut on_epoch) {
            Err(error @ (TrainError::Io(_) | TrainError::Backend(_))) => return Err(error.into()),
            Err(error) if crate::error::is_bug(&error) => return Err(error.into()),
            outcome => outcome,
        };
        let seconds = started.elapsed().as_secs_f64();
        let error = outcome.as_ref().ok().and_then(|(run, _)| mean_error(run));
        on_event(Event::Finished {
            member,
            held_out,
            seconds,
            error,
        });
        Ok(outcome.map(|(run, norm)| (MemberRun { seconds, ..run }, norm)))
    }
}

/// What one item left: its run and the normalisation it was scored with, or why it did not
/// train.
type Outcome = Result<(MemberRun, Normalisation), TrainError>;

fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

fn bug(message: String) -> crate::error::Bug {
    crate::error::Bug::new("the comparison", message)
}

/// The input checks: a grey box with a closure, a closure-free mechanism with its states,
/// at least one seed and one job.
fn check(
    grey_box: &ir::Model,
    mechanism: &ir::Model,
    options: &Options,
) -> Result<(), CompareError> {
    if grey_box.closures.is_empty() {
        return Err(CompareError::NoClosure {
            model: grey_box.name.clone(),
        });
    }
    if let Some(closure) = mechanism.closures.first() {
        return Err(CompareError::MechanismHasClosures {
            file: mechanism.name.clone(),
            closure: closure.name.clone(),
        });
    }
    let names = |model: &ir::Model| -> Vec<String> {
        model.states.iter().map(|s| s.name.clone()).collect()
    };
    if names(grey_box) != names(mechanism) {
        return Err(CompareError::DifferentStates {
            mechanism: mechanism.name.clone(),
            grey_box: names(grey_box).join(", "),
            found: names(mechanism).join(", "),
        });
    }
    let bad = |option: &str, expected: &str, help: &str| CompareError::BadOption {
        option: option.into(),
        expected: expected.into(),
        found: "0".into(),
        help: help.into(),
    };
    if options.seeds.is_empty() {
        return Err(bad(
            "--seeds",
            "at least one seed",
            "--seeds 3 trains three replicates",
        ));
    }
    if options.jobs == 0 {
        return Err(bad(
            "--jobs",
            "at least 1 thread",
            "--jobs 2 runs two trainings at a time",
        ));
    }
    Ok(())
}

/// The record indices each split holds out.
fn held_out_indices(records: &[Record], splits: &Splits) -> Result<Vec<Vec<usize>>, CompareError> {
    let names: Vec<&str> = records.iter().map(|r| r.name.as_str()).collect();
    match splits {
        Splits::LeaveOneOut if records.len() < 2 => Err(TrainError::BadOption {
            option: "--cv".into(),
            expected: "at least two experiments (each fold trains on the others)".into(),
            found: format!("{} experiment", records.len()),
        }
        .into()),
        Splits::LeaveOneOut => Ok((0..records.len()).map(|i| vec![i]).collect()),
        Splits::Holdout(held) if held.is_empty() => Err(CompareError::BadOption {
            option: "--holdout".into(),
            expected: "the experiments to hold out, or --cv".into(),
            found: "none".into(),
            help: format!("the experiments are {}", names.join(", ")),
        }),
        Splits::Holdout(held) => {
            let mut indices = Vec::new();
            for name in held {
                let index =
                    names
                        .iter()
                        .position(|n| n == name)
                        .ok_or_else(|| TrainError::BadOption {
                            option: "--holdout".into(),
                            expected: format!(
                                "the name of an experiment ({})",
                                crate::suggest::did_you_mean(name, &names, "experiments")
                            ),
                            found: name.clone(),
                        })?;
                if !indices.contains(&index) {
                    indices.push(index);
                }
            }
            if indices.len() == records.len() {
                return Err(TrainError::NoTrainingExperiment.into());
            }
            Ok(vec![indices])
        }
    }
}

/// The training and the held-out records of a split.
fn parted(records: &[Record], held: &[usize]) -> (Vec<Record>, Vec<Record>) {
    let train = (records.iter().enumerate())
        .filter(|(i, _)| !held.contains(i))
        .map(|(_, r)| r.clone())
        .collect();
    let held = held.iter().map(|&i| records[i].clone()).collect();
    (train, held)
}

/// Trains (or fits) one member on `train` and runs it free on each of `held`.
fn run_member(
    model: &ir::Model,
    (train, held): (&[Record], &[Record]),
    options: &Options,
    member: Member,
    on_epoch: &mut dyn FnMut(usize),
) -> Result<(MemberRun, Normalisation), TrainError> {
    let seed = match member {
        Member::Mechanism | Member::Untrained => options.seeds.first().copied().unwrap_or(0),
        Member::GreyBox(seed) => seed,
    };
    let untrained = member == Member::Untrained;
    let training = TrainOptions {
        seed,
        epochs: if untrained {
            0
        } else {
            options.training.epochs
        },
        ..options.training.clone()
    };
    let mut recipe = options.recipe.clone();
    if untrained {
        recipe.polish = Some(false);
    }
    let data = TrainingData {
        train,
        validation: held,
        part: Part::All,
    };
    let control = RunControl {
        keep_last_finite: true,
        recoveries: options.recoveries,
        ..RunControl::default()
    };
    let trained = train::train_run(model, &data, (&training, &recipe), &control, &mut |event| {
        if let train::Event::Epoch { epoch, .. } = event {
            on_epoch(epoch)
        }
    })?;
    let held_out = (held.iter().enumerate())
        .map(|(index, record)| held_out_run(model, &trained, (index, record), options))
        .collect();
    let run = MemberRun {
        seed,
        seconds: 0.0,
        failed: None,
        training_diverged: (trained.report.diverged.as_ref()).map(|d| {
            format!(
                "epoch {}: {} (kept epoch {})",
                d.epoch, d.what, d.kept_epoch
            )
        }),
        params: trained.report.params.clone(),
        epochs: trained.report.losses.len(),
        held_out,
    };
    Ok((run, trained.setup.normalisation.clone()))
}

/// The free run of a trained member on held-out experiment `index` and its error, as
/// training validated it.
fn held_out_run(
    model: &ir::Model,
    trained: &Trained,
    (index, record): (usize, &Record),
    options: &Options,
) -> HeldOutRun {
    let validations = &trained.report.metrics.validations;
    let error = (validations.iter().find(|v| v.name == record.name))
        .or_else(|| validations.get(index))
        .and_then(|v| v.online.clone());
    let range = PhysicalRange::new(&trained.setup.normalisation, options.recipe.range_factor);
    let how = (Mode::Online, options.training.history, range.as_ref());
    let curve = predict_in_range(model, &trained.network, &trained.setup, record, how)
        .ok()
        .map(|mut table| {
            table.cut_at_divergence();
            let mut columns = table.columns.into_iter();
            let times = columns.next().unwrap_or_default();
            Curve {
                times,
                states: columns.take(model.states.len()).collect(),
            }
        });
    HeldOutRun {
        experiment: record.name.clone(),
        error,
        curve,
    }
}

/// The mean of a run's errors over its held-out experiments (`None` where one has none).
fn mean_error(run: &MemberRun) -> Option<f64> {
    let errors: Vec<f64> = (run.held_out.iter())
        .map(|h| h.error.as_ref().map(|e| e.overall))
        .collect::<Option<_>>()?;
    (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
}

/// One split's result from its items' outcomes (the mechanism first, the untrained grey box,
/// then each seed): the mechanism must have run; the grey box needs one seed that trained
/// (else the first seed's failure is the error); an untrained grey box that failed is left
/// out (the verdict then has no numerical resolution).
fn assemble(
    records: &[Record],
    held: &[usize],
    outcomes: Vec<Option<Outcome>>,
    (options, states): (&Options, &[String]),
) -> Result<SplitResult, CompareError> {
    let missing = || CompareError::from(bug("a run left no result".into()));
    let mut outcomes = outcomes.into_iter();
    let (mechanism, normalisation) = outcomes.next().flatten().ok_or_else(missing)??;
    let untrained = outcomes.next().flatten().ok_or_else(missing)?;
    let untrained = untrained.ok().map(|(run, _)| run);
    let mut grey_box = Vec::with_capacity(options.seeds.len());
    let mut first_failure = None;
    for &seed in &options.seeds {
        match outcomes.next().flatten().ok_or_else(missing)? {
            Ok((run, _)) => grey_box.push(run),
            Err(error) => {
                grey_box.push(MemberRun {
                    seed,
                    seconds: 0.0,
                    failed: Some(error.to_string()),
                    training_diverged: None,
                    params: Vec::new(),
                    epochs: 0,
                    held_out: Vec::new(),
                });
                first_failure.get_or_insert(error);
            }
        }
    }
    if let Some(error) = first_failure.filter(|_| grey_box.iter().all(|r| r.failed.is_some())) {
        return Err(error.into());
    }
    let (train, held_records) = parted(records, held);
    let naive = Naive::new(&train);
    let naive_runs = (held_records.iter())
        .map(|record| HeldOutRun {
            experiment: record.name.clone(),
            error: naive.error(record, &normalisation, states),
            curve: Some(naive.curve(record)),
        })
        .collect();
    let mut split = SplitResult {
        held_out: held_records.iter().map(|r| r.name.clone()).collect(),
        training: train.iter().map(|r| r.name.clone()).collect(),
        mechanism,
        untrained,
        grey_box,
        naive: naive_runs,
        scores: Vec::new(),
    };
    split.scores = split_scores(&split, states);
    Ok(split)
}
