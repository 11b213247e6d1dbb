//! The flags of `gbc experiment` that describe a study and how to run it ([`RunArgs`]):
//! `--preset`, `--config FILE` or the flags (`--model`, `--data`, ...), flags overriding a
//! preset or config.

use std::path::PathBuf;

use super::training::TrainingFlags;
use crate::api::experiment::StudyPlan;
use crate::api::ApiError;
use crate::experiment::study::{parse_model_argument, parse_sizes, Training};
use crate::experiment::{DataFiles, ExperimentError, Shard, Study, Validation};

/// How every run trains (the values of `gbc train --objective`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TrainingArg {
    /// The paper's: one-step loss every epoch, no polish of the params (also `paper`).
    #[value(alias = "paper")]
    OneStep,
    /// gbc's default: one-step epochs, then free-run rollouts of growing length, params polished.
    MultiStep,
}

impl From<TrainingArg> for Training {
    fn from(training: TrainingArg) -> Self {
        match training {
            TrainingArg::OneStep => Training::Paper,
            TrainingArg::MultiStep => Training::MultiStep,
        }
    }
}

/// The study and how to run it.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// A built-in study at the paper's scale.
    #[arg(long, value_parser = Study::PRESETS)]
    pub preset: Option<String>,
    /// A study file (JSON, like `experiments/*.json`).
    #[arg(long, value_name = "FILE", conflicts_with = "preset")]
    pub config: Option<PathBuf>,
    /// A model to train, as `LABEL=PATH` or `PATH` (labelled by its file stem); repeat.
    #[arg(long = "model", value_name = "[LABEL=]PATH")]
    pub models: Vec<String>,
    /// The training record; with --holdout, the files of a data set (repeat).
    #[arg(long, value_name = "CSV")]
    pub data: Vec<PathBuf>,
    /// Hold out the experiment NAME of the data set (a file stem or a value of its
    /// experiment column) and free-run it whole; every other experiment trains (repeat).
    #[arg(long, value_name = "NAME", conflicts_with_all = ["val", "val_from"])]
    pub holdout: Vec<String>,
    /// A separate validation record (every row of --data may then train).
    #[arg(long, value_name = "CSV", conflicts_with = "val_from")]
    pub val: Option<PathBuf>,
    /// Validate on the rows of --data from ROW on; the rows before it train.
    #[arg(long, value_name = "ROW")]
    pub val_from: Option<usize>,
    /// Training sizes (training pairs), comma-separated.
    #[arg(long, value_name = "N,N,...")]
    pub sizes: Option<String>,
    /// Replicates per model and size (seeds first-seed, first-seed + 1, ...).
    #[arg(long, value_name = "R")]
    pub replicates: Option<usize>,
    /// Seed of the first replicate.
    #[arg(long, value_name = "SEED")]
    pub first_seed: Option<u64>,
    /// Epochs, batch, learning rate, precision, sub-steps, engine (shared with `gbc train`
    /// and `gbc bench`; each given overrides the study's).
    #[command(flatten)]
    pub settings: TrainingFlags,
    /// Training loss, as in `gbc train`: the paper's one-step loss, or gbc's multi-step
    /// rollouts.
    #[arg(long, value_enum)]
    pub objective: Option<TrainingArg>,
    /// Deprecated spelling of --objective.
    #[arg(long, value_enum, hide = true, conflicts_with = "objective")]
    pub training: Option<TrainingArg>,
    /// The mechanistic model behind the data (true rates and params for the figures).
    #[arg(long, value_name = "GBM")]
    pub truth: Option<PathBuf>,
    /// A record never trained on, for free runs under other inputs; repeat.
    #[arg(long = "generalisation", value_name = "CSV")]
    pub generalisation: Vec<PathBuf>,
    /// Training size shown in the trajectory, closure and param figures.
    #[arg(long, value_name = "N")]
    pub representative_size: Option<usize>,
    /// Name of the study (default: the preset's, the config's, or `experiment`).
    #[arg(long)]
    pub name: Option<String>,
    /// Trainings run at once (default: the number of cores).
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Run only slice K of N of the grid (1 <= K <= N), e.g. as a job array task.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// Experiment directory (default: `experiment-<name>`; also `--out`, deprecated).
    #[arg(short, long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print the study as JSON (a config file) and exit.
    #[arg(long)]
    pub print_study: bool,
}

/// A study's error as the API's.
fn user(error: ExperimentError) -> ApiError {
    ApiError::user(error)
}

impl RunArgs {
    /// The study the flags describe; `on_note` hears of a deprecated flag.
    pub fn study(&self, on_note: &mut dyn FnMut(String)) -> Result<Study, ApiError> {
        let args = self;
        let mut study = match (&args.preset, &args.config) {
            (Some(name), _) => Study::preset(name).ok_or_else(|| {
                user(ExperimentError::BadOption {
                    option: "--preset".into(),
                    expected: format!("one of {}", Study::PRESETS.join(", ")),
                    found: name.clone(),
                })
            })?,
            (None, Some(path)) => Study::load(path).map_err(user)?,
            (None, None) => from_flags(args)?,
        };
        if !args.models.is_empty() {
            study.models = (args.models.iter())
                .map(|m| parse_model_argument(m))
                .collect::<Result<_, _>>()
                .map_err(user)?;
        }
        override_settings(&mut study, args, on_note)?;
        args.settings.check(&study.settings)?;
        study
            .check()
            .map_err(|error| user(named_as_given(error, args)))?;
        Ok(study)
    }

    /// The study the flags describe with its shard (`--shard`), directory (`-o`, default
    /// `experiment-<name>`) and threads (`--jobs`, default every core); `on_note` hears of a
    /// deprecated flag.
    pub fn plan(&self, on_note: &mut dyn FnMut(String)) -> Result<StudyPlan, ApiError> {
        let args = self;
        let study = self.study(on_note)?;
        let shard = match &args.shard {
            Some(text) => text.parse::<Shard>().map_err(user)?,
            None => Shard::ALL,
        };
        let out = (args.out.clone())
            .unwrap_or_else(|| PathBuf::from(format!("experiment-{}", study.name)));
        let jobs = args
            .jobs
            .unwrap_or_else(crate::experiment::default_jobs)
            .max(1);
        Ok(StudyPlan {
            study,
            shard,
            out,
            jobs,
        })
    }
}

/// A bad study field the user gave by its flag named as that flag; one from a study file
/// keeps its field name.
fn named_as_given(error: ExperimentError, args: &RunArgs) -> ExperimentError {
    let ExperimentError::BadOption {
        option,
        expected,
        found,
    } = error
    else {
        return error;
    };
    let flag = match option.as_str() {
        "models" if !args.models.is_empty() || (args.preset.is_none() && args.config.is_none()) => {
            Some("--model")
        }
        "sizes" if args.sizes.is_some() => Some("--sizes"),
        "replicates" if args.replicates.is_some() => Some("--replicates"),
        "epochs" if args.settings.epochs.is_some() => Some("--epochs"),
        "validation" if args.val_from.is_some() => Some("--val-from"),
        _ => None,
    };
    ExperimentError::BadOption {
        option: flag.map_or(option, str::to_string),
        expected,
        found,
    }
}

/// The study of the flags alone (no preset, no config).
fn from_flags(args: &RunArgs) -> Result<Study, ApiError> {
    let missing = |option: &str, expected: &str| {
        user(ExperimentError::BadOption {
            option: option.into(),
            expected: expected.into(),
            found: "none (and no --preset or --config)".into(),
        })
    };
    if args.data.is_empty() {
        return Err(missing("--data", "a training record"));
    }
    let data = DataFiles::from_paths(args.data.clone());
    let validation = match (&args.val, args.val_from, args.holdout.is_empty()) {
        (_, _, false) => Validation::Holdout(args.holdout.clone()),
        (Some(path), _, _) => Validation::File(path.clone()),
        (None, Some(row), _) => Validation::FromRow(row),
        (None, None, true) => {
            let expected = "a validation record, row or held-out experiment";
            return Err(missing("--val/--val-from/--holdout", expected));
        }
    };
    let sizes = args
        .sizes
        .as_deref()
        .ok_or_else(|| missing("--sizes", "training sizes"))?;
    Ok(Study {
        name: "experiment".into(),
        title: String::new(),
        models: Vec::new(),
        data,
        validation,
        sizes: parse_sizes(sizes).map_err(user)?,
        replicates: 1,
        first_seed: 1,
        settings: crate::train::Settings::default(),
        training: Training::Paper,
        truth: None,
        generalisation: Vec::new(),
        representative_size: None,
    })
}

/// Overrides the study's fields with the flags given; `on_note` hears of a deprecated flag.
fn override_settings(
    study: &mut Study,
    args: &RunArgs,
    on_note: &mut dyn FnMut(String),
) -> Result<(), ApiError> {
    if !args.data.is_empty() {
        study.data = DataFiles::from_paths(args.data.clone());
    }
    match (&args.val, args.val_from, args.holdout.is_empty()) {
        (_, _, false) => study.validation = Validation::Holdout(args.holdout.clone()),
        (Some(path), _, _) => study.validation = Validation::File(path.clone()),
        (None, Some(row), _) => study.validation = Validation::FromRow(row),
        (None, None, true) => {}
    }
    if let Some(sizes) = &args.sizes {
        study.sizes = parse_sizes(sizes).map_err(user)?;
    }
    let set = |target: &mut usize, value: Option<usize>| *target = value.unwrap_or(*target);
    set(&mut study.replicates, args.replicates);
    study.first_seed = args.first_seed.unwrap_or(study.first_seed);
    args.settings.apply(&mut study.settings);
    if args.training.is_some() {
        on_note("warning: `gbc experiment --training` is deprecated: use --objective".into());
    }
    let objective = args.objective.or(args.training);
    study.training = objective.map_or(study.training, Into::into);
    if args.truth.is_some() {
        study.truth = args.truth.clone();
    }
    if !args.generalisation.is_empty() {
        study.generalisation = args.generalisation.clone();
    }
    study.representative_size = args.representative_size.or(study.representative_size);
    if let Some(name) = &args.name {
        study.name = name.clone();
    }
    Ok(())
}
