//! The flags of the commands as clap structs, and what they ask for as the specs of the
//! API: the one definition of every flag's name, default and check, which the command line
//! parses and a binding whose keywords are these flags (`train_points=300` is
//! `--train-points 300`) parses too, so that both take the same names, the same defaults and
//! the same checks, by construction.
//!
//! - [`TrainArgs`] (`gbc train`), [`DiagnoseArgs`], [`SimulateArgs`], [`CompareArgs`] and
//!   [`RunArgs`] (the study of `gbc experiment`), each with its spec.
//! - [`TrainingFlags`]: the training settings `train`, `experiment`, `compare` and `bench`
//!   share; [`ColumnArgs`] and [`HistoryArg`], the data flags.
//! - The clap mirrors of the library's choices ([`PrecisionArg`], [`EngineArg`],
//!   [`TemplateArg`], [`MessageFormatArg`]).
//! - [`train_spec`], [`diagnose_spec`], [`simulate_spec`], [`compare_spec`],
//!   [`experiment_plan`] and [`ensemble_plan`]: a command's flags given as words (a
//!   binding's keywords), parsed and turned into the spec; a flag the command does not take
//!   is a [`KeywordError`] (E1006).
//!
//! Nothing here prints: what the command line says about its flags (a deprecated flag, the
//! run directory chosen) goes to an `on_note` callback.

mod compare;
mod data;
mod diagnose;
mod experiment;
mod simulate;
mod train;
mod training;

use std::path::{Path, PathBuf};

use clap::Parser;

use super::{ApiError, CompareSpec, DiagnoseSpec, EnsemblePlan, Model, SimulateSpec, TrainSpec};
pub use compare::CompareArgs;
pub use data::{ColumnArgs, HistoryArg};
pub use diagnose::DiagnoseArgs;
pub use experiment::{RunArgs, TrainingArg};
pub use simulate::SimulateArgs;
pub use train::{ObjectiveArg, ParamsArg, PolishArg, ResampleArg, TrainArgs};
pub use training::{EngineArg, MessageFormatArg, PrecisionArg, TemplateArg, TrainingFlags};

/// Flags a binding passed that `gbc` does not take.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
#[error("{message}")]
#[diagnostic(
    code(gbm::E1006),
    help("the keywords are the command's flags with `_` for `-`: see `gbc {command} --help`")
)]
pub struct KeywordError {
    /// What the flag parser said.
    pub message: String,
    /// The command whose flags they are.
    pub command: &'static str,
}

#[derive(Parser)]
#[command(name = "gbc", no_binary_name = true)]
struct Train {
    #[command(flatten)]
    args: TrainArgs,
}

#[derive(Parser)]
#[command(name = "gbc", no_binary_name = true)]
struct Diagnose {
    #[command(flatten)]
    args: DiagnoseArgs,
}

#[derive(Parser)]
#[command(name = "gbc", no_binary_name = true)]
struct Simulate {
    #[command(flatten)]
    args: SimulateArgs,
}

#[derive(Parser)]
#[command(name = "gbc", no_binary_name = true)]
struct Compare {
    #[command(flatten)]
    args: CompareArgs,
}

#[derive(Parser)]
#[command(name = "gbc", no_binary_name = true)]
struct Experiment {
    #[command(flatten)]
    args: RunArgs,
}

/// What `flags` mean to a command. The command line's two positional arguments (model and
/// data file) are given as the names `<model>` and `<data>`: the binding passes the model
/// and the data as objects, and `train_spec` replaces both before anything reads them.
fn parse<P: Parser>(flags: &[String], command: &'static str) -> Result<P, ApiError> {
    parse_with::<P>(&["<model>", "<data>"], flags, command)
}

/// What `flags` mean to a command after the positional arguments `given` (the names that
/// stand for the objects the binding passes).
fn parse_with<P: Parser>(
    given: &[&str],
    flags: &[String],
    command: &'static str,
) -> Result<P, ApiError> {
    let argv = given.iter().map(|text| text.to_string());
    P::try_parse_from(argv.chain(flags.iter().cloned())).map_err(|error| {
        let message = error.render().to_string();
        let message = message.lines().next().unwrap_or_default();
        let message = message.trim_start_matches("error: ").to_string();
        ApiError::user(KeywordError { message, command })
    })
}

/// The training run `gbc train`'s `flags` ask for, and its run directory: `resumed`, the
/// stopped run it continues, else `-o DIR` or a new `runs/<model>-<time>` (which `on_note`
/// hears of), checked as the CLI checks it.
pub fn train_spec(
    flags: &[String],
    model: &Model,
    resumed: Option<&Path>,
    on_note: &mut dyn FnMut(String),
) -> Result<(TrainSpec, PathBuf), ApiError> {
    let Train { mut args } = parse(flags, "train")?;
    args.model = (model.path.clone()).or_else(|| Some(PathBuf::from(model.stem())));
    args.data.clear();
    let spec = args.spec()?;
    let directory = match resumed {
        Some(directory) => directory.to_path_buf(),
        None => args.run_directory(on_note)?,
    };
    Ok((TrainSpec { data: None, ..spec }, directory))
}

/// The diagnosis `gbc diagnose`'s `flags` ask for.
pub fn diagnose_spec(flags: &[String]) -> Result<DiagnoseSpec, ApiError> {
    let Diagnose { args } = parse(flags, "diagnose")?;
    args.spec()
}

/// The simulation `gbc simulate`'s `flags` ask for (no output file: the caller keeps the
/// table) and the effects they apply (`--effect`).
pub fn simulate_spec(flags: &[String]) -> Result<(SimulateSpec, Vec<String>), ApiError> {
    let Simulate { args } = parse_with(&["<model>", "-o", "<output>"], flags, "simulate")?;
    Ok((args.spec(), args.effects.clone()))
}

/// The comparison `gbc compare`'s `flags` ask for.
pub fn compare_spec(flags: &[String]) -> Result<CompareSpec, ApiError> {
    let Compare { args } = parse(flags, "compare")?;
    args.spec()
}

/// The study `gbc experiment`'s `flags` ask for (`preset`, `config`, or `model`, `data`,
/// `sizes`, ...), with its shard, directory and threads; `on_note` hears of a deprecated
/// flag.
pub fn experiment_plan(
    flags: &[String],
    on_note: &mut dyn FnMut(String),
) -> Result<super::experiment::StudyPlan, ApiError> {
    let Experiment { args } = parse_with(&[], flags, "experiment")?;
    if args.print_study {
        return Err(ApiError::user(KeywordError {
            message: "`print_study` prints a study file and runs nothing: use \
                      `gbc experiment --print-study` with the same flags"
                .into(),
            command: "experiment",
        }));
    }
    args.plan(on_note)
}

/// The ensemble `gbc train`'s `flags` ask for (`ensemble=N` with `resample`, `jobs`,
/// `band`), if any.
pub fn ensemble_plan(flags: &[String]) -> Result<Option<EnsemblePlan>, ApiError> {
    let Train { args } = parse(flags, "train")?;
    Ok(args.ensemble_plan())
}
