//! `gbc train MODEL DATA.csv`: fit a grey-box (or black-box) model's networks and params to
//! a record with Adam, report the validation errors and trained params, and write the run.
//!
//! Stiffness warnings and a progress bar (epoch, loss, ETA) go to stderr; the summary goes
//! to stdout. `-o DIR` writes `weights.safetensors` and `run.json`; `--json FILE` writes the
//! same metadata (metrics, params, warnings, normalisation, ...) to FILE.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::{CommandError, CommandResult};
use crate::backend::Precision;
use crate::data::MinRows;
use crate::ir::Model;
use crate::train::{self, artifacts, Event, TrainError, TrainOptions, Trained};

/// Element type of training.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PrecisionArg {
    /// 32-bit floats (faster).
    F32,
    /// 64-bit floats.
    F64,
}

impl From<PrecisionArg> for Precision {
    fn from(precision: PrecisionArg) -> Self {
        match precision {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::F64 => Precision::F64,
        }
    }
}

/// Arguments of `gbc train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// The model file (with closures or params).
    pub model: PathBuf,
    /// The training record (CSV with `t`, the inputs and the measured states).
    pub data: PathBuf,
    /// A separate validation record (default: the pairs after --train-points).
    #[arg(long)]
    pub val: Option<PathBuf>,
    /// Passes over the training pairs.
    #[arg(long, default_value_t = 100)]
    pub epochs: usize,
    /// Pairs per Adam step.
    #[arg(long, default_value_t = 50)]
    pub batch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Train on the first N pairs (default: all with --val, else the first 70 %).
    #[arg(long, value_name = "N")]
    pub train_points: Option<usize>,
    /// Seed of the initialisation and the shuffling (same seed, same result).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Element type.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
    /// RK4 sub-steps per sample (for stiff balances).
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub substeps: usize,
    /// Length (model time) of the online free run (default: to the end of the validation data).
    #[arg(long, value_name = "T")]
    pub online_horizon: Option<f64>,
    /// Directory to write the weights and run.json into.
    #[arg(short, long, value_name = "DIR")]
    pub output: Option<PathBuf>,
    /// Also write the run's metadata and metrics as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// Trains the model and reports.
pub fn run(args: &TrainArgs) -> CommandResult {
    let model = super::load_model(&args.model)?;
    let source = read_source(&args.model)?;
    let data = read_data(&model, &args.data)?;
    let validation = args
        .val
        .as_deref()
        .map(|path| read_data(&model, path))
        .transpose()?;
    let options = TrainOptions {
        epochs: args.epochs,
        batch_size: args.batch,
        learning_rate: args.lr,
        train_points: args.train_points,
        seed: args.seed,
        precision: args.precision.into(),
        substeps: args.substeps,
        online_horizon: args.online_horizon,
    };
    let started = Instant::now();
    let mut progress = Progress::default();
    let outcome = train::train(&model, &data, validation.as_ref(), &options, &mut |event| {
        progress.observe(event, options.epochs)
    });
    progress.finish();
    let trained = outcome.map_err(train_error)?;
    let model_path = args.model.display().to_string();
    let data_path = args.data.display().to_string();
    let info = artifacts::run_info(
        &model,
        (&model_path, &source),
        &data_path,
        &options,
        &trained,
    );
    if let Some(directory) = &args.output {
        artifacts::save(directory, &info, &trained.network).map_err(train_error)?;
    }
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&info)
            .map_err(|error| CommandError::Internal(format!("cannot encode metrics: {error}")))?;
        crate::io::write_atomic(path, json.as_bytes()).map_err(CommandError::user)?;
    }
    print_summary(&model, &trained, started.elapsed().as_secs_f64(), args);
    Ok(())
}

/// Reads a model file's text (for its hash).
pub fn read_source(path: &Path) -> Result<String, CommandError> {
    std::fs::read_to_string(path).map_err(|error| {
        train_error(TrainError::Unreadable {
            path: path.display().to_string(),
            reason: crate::io::describe(&error),
        })
    })
}

/// Reads a record with the model's inputs and measured states.
pub fn read_data(model: &Model, path: &Path) -> Result<crate::data::Dataset, CommandError> {
    let required: Vec<&str> = (model.inputs.iter().map(|i| i.name.as_str()))
        .chain(model.states.iter().map(|s| s.name.as_str()))
        .collect();
    crate::data::read(path, &required, MinRows::new(2, "one step needs two rows"))
        .map_err(CommandError::user)
}

/// A training or prediction error as a command error.
pub fn train_error(error: TrainError) -> CommandError {
    if error.is_internal() {
        CommandError::Internal(error.to_string())
    } else {
        CommandError::user(error)
    }
}

/// The progress bar and warnings on stderr.
#[derive(Default)]
struct Progress {
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    fn observe(&mut self, event: Event, epochs: usize) {
        match event {
            Event::Warning(warning) => eprintln!("warning: {warning}"),
            Event::Started {
                train_pairs,
                validation_pairs,
                ..
            } => {
                let bar = indicatif::ProgressBar::new(epochs as u64);
                let template = "epoch {pos}/{len} [{bar:30}] loss {msg} ETA {eta}";
                if let Ok(style) = indicatif::ProgressStyle::with_template(template) {
                    bar.set_style(style.progress_chars("=> "));
                }
                bar.println(format!(
                    "training on {train_pairs} pairs, validating on {validation_pairs}"
                ));
                self.bar = Some(bar);
            }
            Event::Epoch { epoch, loss } => {
                if let Some(bar) = &self.bar {
                    bar.set_message(format!("{loss:.3e}"));
                    bar.set_position(epoch as u64);
                }
            }
        }
    }

    fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}

fn print_summary(model: &Model, trained: &Trained, seconds: f64, args: &TrainArgs) {
    let report = &trained.report;
    println!(
        "trained `{}` on {} pairs for {} epochs in {seconds:.1} s (final loss {})",
        model.name,
        report.train_pairs,
        args.epochs,
        report
            .losses
            .last()
            .map_or("-".into(), |l| format!("{l:.4e}"))
    );
    let metrics = &report.metrics;
    match (&metrics.offline, &metrics.online) {
        (Some(offline), Some(online)) => {
            println!(
                "validation error on {} pairs (MSE of z-scored states):",
                report.validation_pairs
            );
            println!("  {:<16} {:>12} {:>12}", "state", "offline", "online");
            for ((name, off), (_, on)) in offline.per_state.iter().zip(&online.per_state) {
                println!("  {name:<16} {:>12} {:>12}", error(*off), error(*on));
            }
            let overall = (error(offline.overall), error(online.overall));
            println!("  {:<16} {:>12} {:>12}", "overall", overall.0, overall.1);
            if !online.overall.is_finite() {
                println!("the free run diverged (see the stiffness warnings, or train longer)");
            }
        }
        _ => println!("no validation pairs: pass --val FILE or a smaller --train-points"),
    }
    if !report.params.is_empty() {
        println!("params:");
        for (name, value) in &report.params {
            println!("  {name} = {value:.6}");
        }
    }
    if let Some(directory) = &args.output {
        println!("weights written to {}", directory.display());
    }
}

/// An error value for the summary: scientific notation, or `diverged`.
fn error(value: f64) -> String {
    if value.is_finite() {
        format!("{value:.4e}")
    } else {
        "diverged".to_string()
    }
}
