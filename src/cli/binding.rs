//! The flags of `gbc train`, `gbc diagnose`, `gbc simulate`, `gbc compare` and
//! `gbc experiment` as the specs
//! of the library API, for a
//! binding whose keywords are these flags (`train_points=300` is `--train-points 300`): the
//! same names, the same defaults, the same checks, by construction.

use std::path::{Path, PathBuf};

use clap::Parser;

use super::compare::CompareArgs;
use super::diagnose::DiagnoseArgs;
use super::experiment::RunArgs;
use super::simulate::SimulateArgs;
use super::train::TrainArgs;
use super::CommandError;
use crate::api;

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
fn parse<P: Parser>(flags: &[String], command: &'static str) -> Result<P, CommandError> {
    parse_with::<P>(&["<model>", "<data>"], flags, command)
}

/// What `flags` mean to a command after the positional arguments `given` (the names that
/// stand for the objects the binding passes).
fn parse_with<P: Parser>(
    given: &[&str],
    flags: &[String],
    command: &'static str,
) -> Result<P, CommandError> {
    let argv = given.iter().map(|text| text.to_string());
    P::try_parse_from(argv.chain(flags.iter().cloned())).map_err(|error| {
        let message = error.render().to_string();
        let message = message.lines().next().unwrap_or_default();
        let message = message.trim_start_matches("error: ").to_string();
        CommandError::user(KeywordError { message, command })
    })
}

/// The training run `gbc train`'s `flags` ask for, and its run directory: `resumed`, the
/// stopped run it continues, else `-o DIR` or a new `runs/<model>-<time>`, checked as the
/// CLI checks it.
pub fn train_spec(
    flags: &[String],
    model: &api::Model,
    resumed: Option<&Path>,
) -> Result<(api::TrainSpec, PathBuf), CommandError> {
    let Train { mut args } = parse(flags, "train")?;
    args.model = (model.path.clone()).or_else(|| Some(PathBuf::from(model.stem())));
    args.data.clear();
    let spec = super::train::spec_of(&args)?;
    let directory = match resumed {
        Some(directory) => directory.to_path_buf(),
        None => super::train::run_directory(&args)?,
    };
    Ok((api::TrainSpec { data: None, ..spec }, directory))
}

/// The diagnosis `gbc diagnose`'s `flags` ask for.
pub fn diagnose_spec(flags: &[String]) -> Result<api::DiagnoseSpec, CommandError> {
    let Diagnose { args } = parse(flags, "diagnose")?;
    super::diagnose::spec_of(&args)
}

/// The simulation `gbc simulate`'s `flags` ask for (no output file: the caller keeps the
/// table) and the effects they apply (`--effect`).
pub fn simulate_spec(flags: &[String]) -> Result<(api::SimulateSpec, Vec<String>), CommandError> {
    let Simulate { args } = parse_with(&["<model>", "-o", "<output>"], flags, "simulate")?;
    Ok((args.spec(), args.effects.clone()))
}

/// The comparison `gbc compare`'s `flags` ask for.
pub fn compare_spec(flags: &[String]) -> Result<api::CompareSpec, CommandError> {
    let Compare { args } = parse(flags, "compare")?;
    super::compare::spec_of(&args)
}

/// The study `gbc experiment`'s `flags` ask for (`preset`, `config`, or `model`, `data`,
/// `sizes`, ...), with its shard, directory and threads.
pub fn experiment_plan(flags: &[String]) -> Result<api::experiment::StudyPlan, CommandError> {
    let Experiment { args } = parse_with(&[], flags, "experiment")?;
    if args.print_study {
        return Err(CommandError::user(KeywordError {
            message: "`print_study` prints a study file and runs nothing: use \
                      `gbc experiment --print-study` with the same flags"
                .into(),
            command: "experiment",
        }));
    }
    super::experiment::plan_of(&args)
}

/// The ensemble `gbc train`'s `flags` ask for (`ensemble=N` with `resample`, `jobs`,
/// `band`), if any.
pub fn ensemble_plan(flags: &[String]) -> Result<Option<crate::ensemble::Plan>, CommandError> {
    let Train { args } = parse(flags, "train")?;
    Ok(super::train::ensemble::plan_of(&args))
}
