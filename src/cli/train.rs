//! `gbc train MODEL DATA...`: fit a grey-box (or black-box) model's networks and params to
//! a data set (one or more experiments) with Adam, report the validation errors per
//! experiment and pooled, the trained params and each experiment's initial state, and write
//! the run.
//!
//! The default recipe is multi-step (free-run rollouts with a curriculum, then a polish of
//! the params); `--objective one-step` is the paper's (see `docs/training.md`). Stiffness
//! warnings and the progress (epoch, rollout length, loss, ETA: a bar on a terminal, else a
//! line every few seconds) go to stderr; the summary goes to stdout: errors per validation
//! set, where a free run left the physical range, and each param with its standard error.
//! `-o DIR` writes `weights.safetensors` and `run.json`; `--json FILE` writes the same
//! metadata (metrics, params, warnings, normalisation, ...) to FILE. An epoch that goes
//! non-finite sends training back to the last finite one at half the learning rate (up to
//! `--recoveries` times, each a warning); after that the run, in `-o DIR` or the default
//! directory alike, is saved with its last finite epoch's weights and a run.json saying it
//! failed, and fails with E0415. `--cv` keeps every fold under `DIR/cv/` ([`cv`]). The
//! flags are the API's ([`TrainArgs`]).

use std::path::Path;
use std::time::Instant;

mod cv;
mod ensemble;
mod progress;
mod safety;

use gbc::api::flags::TrainArgs;
use gbc::api::summary::summary;
use gbc::api::{self, ApiError, Checkpoint, EpochDivergence, Record, Run, TrainError, TrainSpec};
use progress::Progress;

use super::{CommandError, CommandResult};

/// Flags that may go with `--resume`: they change how gbc reports, not the run.
const WITH_RESUME: [&str; 2] = ["resume", "message_format"];

/// The flags of `gbc train` given on the command line (not defaults), as spelled there
/// (`--epochs`; a positional argument by its value name).
pub fn given_flags(matches: &clap::ArgMatches) -> Vec<String> {
    use clap::CommandFactory;
    let command = super::Cli::command();
    let Some(train) = command.find_subcommand("train") else {
        return Vec::new();
    };
    (train.get_arguments())
        .filter(|arg| !WITH_RESUME.contains(&arg.get_id().as_str()))
        .filter(|arg| {
            matches.value_source(arg.get_id().as_str())
                == Some(clap::parser::ValueSource::CommandLine)
        })
        .map(|arg| match arg.get_long() {
            Some(long) => format!("--{long}"),
            None => arg.get_id().to_string().to_uppercase(),
        })
        .collect()
}

/// Trains the model and reports.
pub fn run(args: &TrainArgs) -> CommandResult {
    let resumed;
    let (args, checkpoint) = match &args.resume {
        Some(directory) => {
            safety::alone(args)?;
            let (saved, checkpoint) = safety::resumed(directory)?;
            resumed = saved;
            (&resumed, Some(checkpoint))
        }
        None => (args, None),
    };
    let model_file = (args.model.clone()).ok_or_else(|| {
        CommandError::Internal("a training without a model file or --resume".into())
    })?;
    let model = api::Model::from_file(&model_file)?;
    let records = model.records_from_files(&args.data, &args.columns.columns)?;
    let val = model.records_from_files(&args.val, &args.columns.columns)?;
    let spec = args.spec()?;
    if args.warmup.is_some() {
        eprintln!(
            "warning: `gbc train --warmup` is deprecated: use --warmup-share (a share of the \
             epochs; `gbc simulate --warmup` is a time)"
        );
    }
    if let Some(plan) = args.ensemble_plan() {
        let directory = args.run_directory(&mut note)?;
        return ensemble::run(args, &model, (records, val), (&spec, &plan), &directory);
    }
    let directory = match &checkpoint {
        Some(_) => args.output.clone().unwrap_or_default(),
        None => args.run_directory(&mut note)?,
    };
    if checkpoint.is_none() && args.cv {
        cv::cross_validate(&model, records.clone(), &spec, &directory)?;
    }
    let run = Single {
        args,
        model: &model,
        spec: &spec,
        directory: &directory,
    };
    run.train((records, val), checkpoint)
}

/// Prints a note the flags give (the run directory chosen) on stderr.
fn note(text: String) {
    eprintln!("{text}");
}

/// One training run (not an ensemble): what it trains and where it goes.
struct Single<'a> {
    args: &'a TrainArgs,
    model: &'a api::Model,
    spec: &'a TrainSpec,
    directory: &'a Path,
}

impl Single<'_> {
    /// Trains on `data` (from `checkpoint`, when resumed) with the progress on stderr,
    /// keeps an interrupted run's log beside its checkpoint, and saves and reports the run.
    fn train(
        &self,
        data: (Vec<Record>, Vec<Record>),
        checkpoint: Option<Checkpoint>,
    ) -> CommandResult {
        let command = match &checkpoint {
            Some(checkpoint) => checkpoint.command.clone(),
            None => safety::command(self.args)?,
        };
        let started = Instant::now();
        let mut progress = Progress::default();
        if let Some(checkpoint) = &checkpoint {
            progress.resume_from(checkpoint);
            eprintln!(
                "resuming {} after epoch {} of {}",
                self.directory.display(),
                checkpoint.epoch,
                checkpoint.epochs
            );
        }
        let control = api::Control {
            directory: Some(self.directory.to_path_buf()),
            stop: Some(api::stop::flag()),
            resume: checkpoint,
            command,
            stop_after: self.args.stop_after_epochs,
            poison: self.args.poison_epoch,
        };
        let epochs = self.spec.options.epochs;
        let outcome = api::train(self.model, data, self.spec, control, &mut |event| {
            progress.observe(event, epochs)
        });
        progress.finish();
        if outcome.as_ref().is_err_and(|error| error.is_interrupted()) {
            // An interrupted run keeps its log beside its checkpoint.
            self.write_log(&progress, None)?;
        }
        self.report(&outcome?, &progress, started)
    }

    /// Saves the run with its log (and `--json`), fails a run that diverged, and prints the
    /// summary (on stderr when the JSON goes to stdout).
    fn report(&self, run: &Run, progress: &Progress, started: Instant) -> CommandResult {
        if let Some(note) = &run.split.note {
            eprintln!("{note}");
        }
        run.save(self.directory)?;
        self.write_log(progress, Some(run))?;
        let json_to_stdout =
            (self.args.json.as_ref()).is_some_and(|p| p.as_os_str() == api::STDOUT);
        if let Some(path) = &self.args.json {
            api::write_atomic(path, run.json()?.as_bytes()).map_err(CommandError::user)?;
        }
        if let Some(diverged) = &run.trained.report.diverged {
            return Err(diverged_run(diverged, self.directory));
        }
        let seconds = started.elapsed().as_secs_f64();
        let cv = self.args.cv;
        let text = summary(
            self.model.ir(),
            &run.trained,
            seconds,
            (Some(self.directory), cv),
        );
        if json_to_stdout {
            eprint!("{text}");
        } else {
            print!("{text}");
        }
        Ok(())
    }

    /// Writes the training log (`log.csv`) into the run directory, with the finished
    /// `run`'s validation errors when there is one.
    fn write_log(&self, progress: &Progress, run: Option<&Run>) -> CommandResult {
        let report = run.map(|run| &run.trained.report);
        let log = progress.log(report, self.spec.options.learning_rate);
        api::write_atomic(&self.directory.join(LOG_FILE), log.as_bytes())
            .map_err(CommandError::user)
    }
}

/// A run that went non-finite and was saved with its last finite weights: says which
/// epoch those are and what to try on stderr, and fails with E0415 naming the epoch and
/// phase that diverged.
fn diverged_run(diverged: &EpochDivergence, directory: &Path) -> CommandError {
    let kept = match diverged.kept_epoch {
        0 => "the initial weights (no epoch ended finite)".to_string(),
        epoch => format!("the weights of epoch {epoch}, the last finite one"),
    };
    eprintln!(
        "{} keeps {kept} and a run.json that says the run failed: `gbc predict --weights {}` \
         reads them",
        directory.display(),
        directory.display()
    );
    if !diverged.advice.is_empty() {
        eprintln!("try {}", diverged.advice);
    }
    let phase = diverged.phase.to_string();
    let what = match phase.as_str() {
        "" => diverged.what.clone(),
        phase => format!("{} ({phase})", diverged.what),
    };
    train_error(TrainError::Diverged {
        epoch: diverged.epoch,
        what,
    })
}

/// The training log of a run directory.
pub const LOG_FILE: &str = "log.csv";

/// A training or prediction error as a command error (its option named as the flag).
pub fn train_error(error: TrainError) -> CommandError {
    CommandError::from(ApiError::from(error))
}
