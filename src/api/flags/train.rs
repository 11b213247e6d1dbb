//! The flags of `gbc train` ([`TrainArgs`]) and what they ask for: the training run
//! ([`TrainArgs::spec`]), its directory ([`TrainArgs::run_directory`]) and, with
//! `--ensemble N`, the ensemble ([`TrainArgs::ensemble_plan`]).

use std::path::PathBuf;

use super::data::{ColumnArgs, HistoryArg};
use super::training::TrainingFlags;
use crate::api::{ApiError, TrainSpec, Validation};
use crate::ensemble::{Plan, Resample};
use crate::train::recipe::{
    DEFAULT_HORIZON, DEFAULT_RAMP_SHARE, DEFAULT_RANGE_FACTOR, DEFAULT_WARMUP_SHARE,
};
use crate::train::{Objective, ParamSource, Recipe, TrainError, TrainOptions};

/// The loss training minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ObjectiveArg {
    /// The paper's: one-step predictions, every epoch (with `--polish off` by default).
    OneStep,
    /// Free-run rollouts growing to --horizon steps after one-step warm-up epochs.
    MultiStep,
}

/// Whether the params are polished after training.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PolishArg {
    /// On for the multi-step objective, off for one-step.
    Auto,
    /// Always.
    On,
    /// Never.
    Off,
}

/// Where the params come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ParamsArg {
    /// From the balances where they determine the params, else trained with the network.
    Auto,
    /// Estimated from the balances alone before training and held fixed.
    Balances,
    /// Trained with the network by Adam, then polished (the paper's way).
    Train,
}

/// Arguments of `gbc train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// The model file (with closures or params).
    #[arg(required_unless_present = "resume")]
    pub model: Option<PathBuf>,
    /// The data set: one or more CSV files, each an experiment (or several, with an
    /// `experiment` column); `t`, the inputs and the measured states, cells may be empty.
    #[arg(required_unless_present = "resume", num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// Files of whole experiments that validate (repeatable).
    #[arg(long, value_name = "FILE", num_args = 1..)]
    pub val: Vec<PathBuf>,
    /// Experiments of the data set that validate instead of training (repeatable).
    #[arg(long, value_name = "NAME", num_args = 1..)]
    pub holdout: Vec<String>,
    /// Hold out the last share of each experiment's rows (the free run still starts at the
    /// experiment's first row and is scored on the held-out tail).
    #[arg(long, value_name = "SHARE", conflicts_with = "train_points")]
    pub val_fraction: Option<f64>,
    /// Leave-one-experiment-out cross-validation: one model per experiment trained on the
    /// others and scored on it, each fold and the median reported; the saved model is then
    /// trained on every experiment.
    #[arg(long)]
    pub cv: bool,
    /// Longest integration step (default: the median spacing of the densest measured
    /// column, at most the shortest embedding delay).
    #[arg(long, value_name = "H")]
    pub dt: Option<f64>,
    /// Loss weight of a measured state's cells: `--weight X=2` (repeatable; others 1).
    #[arg(long, value_name = "NAME=W", value_parser = parse_weight)]
    pub weight: Vec<(String, f64)>,
    /// Where free runs of whole experiments and training windows start.
    #[arg(long, value_enum, default_value_t = HistoryArg::Held)]
    pub history: HistoryArg,
    /// How data columns are named.
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// Epochs, batch, learning rate, precision, sub-steps, engine (shared with
    /// `gbc experiment` and `gbc bench`).
    #[command(flatten)]
    pub settings: TrainingFlags,
    /// The paper's protocol: train on the first N one-step pairs after the embedding's
    /// history (experiments in order); with one experiment and nothing else validating,
    /// the pairs after them validate (default then: the first 70 %).
    #[arg(long, value_name = "N")]
    pub train_points: Option<usize>,
    /// Seed of the initialisation and the shuffling (same seed, same result).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Length (model time) of the online free run (default: to the end of the validation data).
    #[arg(long, value_name = "T")]
    pub online_horizon: Option<f64>,
    /// Training loss: free-run rollouts (multi-step) or the paper's one-step loss.
    #[arg(long, value_enum, default_value_t = ObjectiveArg::MultiStep)]
    pub objective: ObjectiveArg,
    /// Longest rollout of the multi-step objective, in sampling steps.
    #[arg(long, default_value_t = DEFAULT_HORIZON, value_name = "K")]
    pub horizon: usize,
    /// Share of the epochs trained one-step before rollouts start.
    #[arg(long, default_value_t = DEFAULT_WARMUP_SHARE, value_name = "SHARE")]
    pub warmup_share: f64,
    /// Deprecated spelling of --warmup-share (`gbc simulate --warmup` is a time).
    #[arg(
        long,
        value_name = "SHARE",
        hide = true,
        conflicts_with = "warmup_share"
    )]
    pub warmup: Option<f64>,
    /// Share of the epochs over which rollouts grow from 2 steps to --horizon.
    #[arg(long, default_value_t = DEFAULT_RAMP_SHARE, value_name = "SHARE")]
    pub ramp: f64,
    /// Rollout windows per Adam step (default: --batch).
    #[arg(long, value_name = "N")]
    pub windows: Option<usize>,
    /// Adam learning rate of the params (default: --lr).
    #[arg(long, value_name = "LR")]
    pub param_lr: Option<f64>,
    /// Clip each gradient to this Euclidean norm.
    #[arg(long, value_name = "NORM")]
    pub clip: Option<f64>,
    /// Fit the params by Levenberg-Marquardt with the network frozen after training.
    #[arg(long, value_enum, default_value_t = PolishArg::Auto)]
    pub polish: PolishArg,
    /// Where the params come from: `balances` estimates them from the balances alone
    /// (closure outputs free per interval) before training and holds them fixed; `auto`
    /// does so where the balances determine them (more measured states than closure
    /// outputs, no hidden states) and for the multi-step objective; `train` trains them.
    #[arg(long, value_enum, default_value_t = ParamsArg::Auto)]
    pub params: ParamsArg,
    /// A free run stops when a state leaves [-0.1 x max, F x max] of the training data
    /// ([-F x max|x|, F x max|x|] for a state that was negative).
    #[arg(long, default_value_t = DEFAULT_RANGE_FACTOR, value_name = "F")]
    pub range_factor: f64,
    /// The run directory (weights, run.json, log.csv); default: a new timestamped
    /// directory under runs/, announced on stderr.
    #[arg(short, long, value_name = "DIR")]
    pub output: Option<PathBuf>,
    /// Replace the run in an existing, non-empty `-o` directory.
    #[arg(long)]
    pub force: bool,
    /// Also write the run's metadata and metrics as JSON to this file (`-`: standard
    /// output; the summary then goes to standard error).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Continue the stopped run in DIR (Ctrl-C or SIGTERM end training after the current
    /// epoch with a checkpoint): the same command line, from the checkpoint on; with the
    /// same seed the run ends bit for bit where an uninterrupted one ends. The run resumes
    /// with the flags it was started with: any other flag given with --resume is refused
    /// (E0434; only the global --message-format goes with it), start a new run to change
    /// them.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["model", "data"])]
    pub resume: Option<PathBuf>,
    /// Also write a checkpoint into the run directory after every N epochs.
    #[arg(long, value_name = "N")]
    pub checkpoint_every: Option<usize>,
    /// Stop when the validation loss (the pooled online error, else the offline one,
    /// computed after every epoch) has not improved for PATIENCE epochs, counted from the
    /// full rollout (after the warm-up); the weights of the best epoch are kept.
    #[arg(long, value_name = "PATIENCE")]
    pub early_stop: Option<usize>,
    /// Stop after this epoch as if interrupted (tests of --resume).
    #[arg(long, value_name = "N", hide = true)]
    pub stop_after_epochs: Option<usize>,
    /// How many times an epoch that goes non-finite sends training back to the last finite
    /// epoch, at half the learning rate (and half the rollout length), before the run ends
    /// with E0415 (each time a warning; 0: end at the first).
    #[arg(long, value_name = "N", default_value_t = crate::train::recovery::DEFAULT_RECOVERIES)]
    pub recoveries: usize,
    /// The loss of epoch E reads NaN on its first T tries, `E:T` (tests of E0415).
    #[arg(long, value_name = "E:T", hide = true, value_parser = parse_poison)]
    pub poison_epoch: Option<(usize, usize)>,
    /// Train an ensemble of N members (member k with seed --seed + k - 1), saved under
    /// DIR/members/, and calibrate their prediction band on the training experiments
    /// (DIR/ensemble.json; see docs/uncertainty.md).
    #[arg(
        long,
        value_name = "N",
        conflicts_with_all = ["cv", "resume", "early_stop", "checkpoint_every", "stop_after_epochs"]
    )]
    pub ensemble: Option<usize>,
    /// What each member of --ensemble trains on: a bootstrap of whole training experiments
    /// (the experiments it did not draw calibrate the band), or every experiment (the band
    /// is then not calibrated and not written).
    #[arg(long, value_enum, requires = "ensemble")]
    pub resample: Option<ResampleArg>,
    /// Trainings run at once (default: the number of cores).
    #[arg(short, long, value_name = "N", requires = "ensemble")]
    pub jobs: Option<usize>,
    /// The level of the prediction band reported and drawn (--ensemble).
    #[arg(long, value_name = "LEVEL", default_value_t = crate::ensemble::DEFAULT_LEVEL)]
    pub band: f64,
    /// The flags given on `gbc`'s command line (`--epochs`, ...; filled in by the command
    /// line, empty where the arguments were parsed otherwise).
    #[arg(skip)]
    pub given: Vec<String>,
}

/// What the members of an ensemble train on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ResampleArg {
    /// A bootstrap of whole training experiments per member (the default).
    Experiments,
    /// Every training experiment, the members differing by seed alone.
    None,
}

impl TrainArgs {
    /// The training run the flags ask for.
    pub fn spec(&self) -> Result<TrainSpec, ApiError> {
        let data = (self.data.iter())
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(" ");
        Ok(TrainSpec {
            options: TrainOptions {
                train_points: self.train_points,
                seed: self.seed,
                online_horizon: self.online_horizon,
                dt: self.dt,
                history: self.history.into(),
                column_weights: self.weight.clone(),
                ..TrainOptions::with(&self.settings.settings()?)
            },
            recipe: self.recipe(),
            validation: Validation {
                holdout: self.holdout.clone(),
                val_fraction: self.val_fraction,
                train_points: self.train_points,
                cv: self.cv,
            },
            early_stop: self.early_stop,
            recoveries: self.recoveries,
            checkpoint_every: self.checkpoint_every,
            data: Some(data),
        })
    }

    /// The recipe the flags ask for.
    pub fn recipe(&self) -> Recipe {
        Recipe {
            objective: match self.objective {
                ObjectiveArg::OneStep => Objective::OneStep,
                ObjectiveArg::MultiStep => Objective::MultiStep,
            },
            horizon: self.horizon,
            warmup_share: self.warmup.unwrap_or(self.warmup_share),
            ramp_share: self.ramp,
            windows_per_batch: self.windows,
            param_learning_rate: self.param_lr,
            max_gradient_norm: self.clip,
            polish: match self.polish {
                PolishArg::Auto => None,
                PolishArg::On => Some(true),
                PolishArg::Off => Some(false),
            },
            range_factor: self.range_factor,
            params: match self.params {
                ParamsArg::Auto => ParamSource::Auto,
                ParamsArg::Balances => ParamSource::Balances,
                ParamsArg::Train => ParamSource::Train,
            },
            sparse_budget: (!self.settings.gives_budget())
                .then_some(crate::train::recipe::SPARSE_BUDGET),
        }
    }

    /// Where the run goes: `-o DIR` (refused when it holds files, unless `--force`), else a
    /// new directory `runs/<model>-<UTC time>`, which `on_note` hears of. Checked before
    /// training, so that no run is lost to a directory that cannot take it.
    pub fn run_directory(&self, on_note: &mut dyn FnMut(String)) -> Result<PathBuf, ApiError> {
        if let Some(directory) = &self.output {
            let occupied =
                std::fs::read_dir(directory).is_ok_and(|mut entries| entries.next().is_some());
            let taken = (occupied && !self.force) || (directory.exists() && !directory.is_dir());
            if taken {
                return Err(ApiError::from(TrainError::RunExists {
                    directory: directory.display().to_string(),
                }));
            }
            return Ok(directory.clone());
        }
        let stem = (self.model.as_ref().and_then(|m| m.file_stem()))
            .map_or("run".to_string(), |s| s.to_string_lossy().to_string());
        let stamp = utc_stamp(std::time::SystemTime::now());
        let mut directory = PathBuf::from("runs").join(format!("{stem}-{stamp}"));
        let mut attempt = 1;
        while directory.exists() {
            attempt += 1;
            directory = PathBuf::from("runs").join(format!("{stem}-{stamp}-{attempt}"));
        }
        on_note(format!(
            "the run goes to {} (choose the directory with -o DIR)",
            directory.display()
        ));
        Ok(directory)
    }

    /// The ensemble the flags ask for (`--ensemble N`, `--resample`, `--jobs`, `--band`).
    pub fn ensemble_plan(&self) -> Option<Plan> {
        let members = self.ensemble?;
        Some(Plan {
            members,
            resample: match self.resample.unwrap_or(ResampleArg::Experiments) {
                ResampleArg::Experiments => Resample::Experiments,
                ResampleArg::None => Resample::None,
            },
            jobs: self
                .jobs
                .unwrap_or_else(crate::experiment::default_jobs)
                .max(1),
            level: self.band,
        })
    }
}

/// `E:T`, two counts.
fn parse_poison(argument: &str) -> Result<(usize, usize), String> {
    let (epoch, tries) = argument
        .split_once(':')
        .ok_or_else(|| format!("expected EPOCH:TRIES, found `{argument}`"))?;
    let count = |text: &str| {
        (text.trim().parse::<usize>()).map_err(|_| format!("expected a count, found `{text}`"))
    };
    Ok((count(epoch)?, count(tries)?))
}

/// `NAME=W` with a number.
fn parse_weight(argument: &str) -> Result<(String, f64), String> {
    let (name, weight) = argument
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=WEIGHT (e.g. `X=2`), found `{argument}`"))?;
    let weight: f64 = weight
        .trim()
        .parse()
        .map_err(|_| format!("expected a number after `=`, found `{}`", weight.trim()))?;
    Ok((name.trim().to_string(), weight))
}

/// `YYYYMMDD-HHMMSS` in UTC.
fn utc_stamp(time: std::time::SystemTime) -> String {
    let seconds = time
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rest) = (seconds / 86_400, seconds % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}{month:02}{day:02}-{:02}{:02}{:02}",
        rest / 3600,
        rest % 3600 / 60,
        rest % 60
    )
}
