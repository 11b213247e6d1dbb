//! The command-line edge: argument parsing, dispatch over subcommands, and rendering of
//! diagnostics. The only part of gbc that prints or chooses colours. A module of the binary:
//! it reaches the library through `gbc::api` alone, and the flags a binding shares with it
//! are the API's ([`gbc::api::flags`]).
//!
//! Exit codes: 0 success, 1 user error (a coded diagnostic was printed), 2 internal error
//! (a bug in gbc, including any panic).

mod bench;
mod check;
mod compare;
mod compile;
mod completions;
mod demo;
mod diagnose;
mod experiment;
mod explain;
mod export;
mod fmt;
mod init;
mod lsp;
mod predict;
mod progress;
mod simulate;
#[cfg(test)]
mod tests_scratch;
mod train;

use clap::{Parser, Subcommand};
use gbc::api::flags::MessageFormatArg;
use gbc::api::{self, ApiError, MessageFormat};
use std::io::IsTerminal;

/// Why a command failed.
#[derive(Debug)]
pub enum CommandError {
    /// Bad input from the user (model, data, arguments): each report carries its source
    /// code where it has one. Exit code 1.
    User(Vec<miette::Report>),
    /// A bug in gbc. Exit code 2.
    Internal(String),
}

impl CommandError {
    /// The error of one diagnostic: a user error, or an internal one (exit code 2) when it
    /// is a bug in gbc ([`ApiError::user`] tells the two apart).
    pub fn user(diagnostic: impl miette::Diagnostic + Send + Sync + 'static) -> Self {
        CommandError::from(ApiError::user(diagnostic))
    }
}

impl From<Vec<miette::Report>> for CommandError {
    fn from(reports: Vec<miette::Report>) -> Self {
        CommandError::from(ApiError::from(reports))
    }
}

impl From<ApiError> for CommandError {
    fn from(error: ApiError) -> Self {
        match error {
            ApiError::User(reports) => CommandError::User(reports),
            ApiError::Internal(message) => CommandError::Internal(message),
        }
    }
}

/// What a command returns.
pub type CommandResult = Result<(), CommandError>;

/// gbc: compile, simulate and train grey-box models written in the .gbm language.
#[derive(Debug, Parser)]
#[command(name = "gbc", version, about, propagate_version = true)]
pub struct Cli {
    /// How diagnostics are printed.
    #[arg(long, global = true, value_enum, default_value_t = MessageFormatArg::Human)]
    pub message_format: MessageFormatArg,
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Check model files and report every problem.
    Check(check::CheckArgs),
    /// Compile a model and print a stage of it (AST or IR).
    Compile(compile::CompileArgs),
    /// Simulate a model without closures (adaptive Dormand–Prince, Radau IIA where stiff), or a trained one
    /// (`--weights`: a what-if run), writing a CSV record.
    Simulate(gbc::api::flags::SimulateArgs),
    /// Train a grey-box (or black-box) model on a data record.
    Train(Box<gbc::api::flags::TrainArgs>),
    /// Predict with trained weights: states and every closure output over time.
    Predict(predict::PredictArgs),
    /// Diagnose the gap between a mechanistic model and data: where, which effect, how much.
    Diagnose(gbc::api::flags::DiagnoseArgs),
    /// Compare a grey box with its fitted mechanism and the naive forecast on held-out
    /// experiments (seeds, table, verdict, report).
    Compare(Box<gbc::api::flags::CompareArgs>),
    /// Export a trained model's one-step map (ONNX) for other runtimes.
    Export(export::ExportArgs),
    /// Train models over a grid of training sizes and seeds, with results and figures.
    Experiment(experiment::ExperimentArgs),
    /// The main job: both paper studies, scaled down, with an HTML report.
    Demo(demo::DemoArgs),
    /// Time training steps, epochs and simulation of the shipped models on this machine.
    Bench(bench::BenchArgs),
    /// Rewrite model files in the canonical layout (`--check`: only report).
    Fmt(fmt::FmtArgs),
    /// Start a new model from a template, with a README of the commands to run.
    Init(init::InitArgs),
    /// Print the catalogue entry of a diagnostic code (e.g. `gbc explain E0152`).
    Explain(explain::ExplainArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(completions::CompletionsArgs),
    /// Run the language server on stdin/stdout (diagnostics, definition, hover, format).
    Lsp(lsp::LspArgs),
}

/// What a long command does when Ctrl-C or SIGTERM asks it to stop (`None`: a short
/// command keeps the default handling).
fn on_stop(command: &Command) -> Option<&'static str> {
    match command {
        Command::Train(_) => {
            Some("training ends before its next batch, with a checkpoint of its last whole epoch")
        }
        Command::Diagnose(_) => {
            Some("the fits end at their best so far; the report written is marked partial")
        }
        Command::Compare(_) | Command::Experiment(_) | Command::Demo(_) | Command::Bench(_) => {
            Some("the running training ends before its next batch; nothing more starts")
        }
        _ => None,
    }
}

/// Runs one parsed command line.
pub fn dispatch(cli: &Cli) -> CommandResult {
    match &cli.command {
        Command::Check(args) => check::run(args, cli.message_format.into()),
        Command::Compile(args) => compile::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Train(args) => train::run(args),
        Command::Predict(args) => predict::run(args),
        Command::Diagnose(args) => diagnose::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Experiment(args) => experiment::run(args),
        Command::Export(args) => export::run(args),
        Command::Demo(args) => demo::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Fmt(args) => fmt::run(args),
        Command::Init(args) => init::run(args),
        Command::Explain(args) => explain::run(args),
        Command::Completions(args) => completions::run(args),
        Command::Lsp(args) => lsp::run(args),
    }
}

/// Parses the command line, runs the command and returns the process exit code.
pub fn main() -> i32 {
    let cli = match parse() {
        Ok(cli) => cli,
        Err(error) => {
            let code = if error.use_stderr() { 1 } else { 0 };
            let _ = error.print();
            return code;
        }
    };
    let format: MessageFormat = cli.message_format.into();
    if let Some(what) = on_stop(&cli.command) {
        api::stop::on_signal(what);
    }
    // Deep but legal models recurse in the front end; a large stack keeps that safe.
    let worker = std::thread::Builder::new()
        .name("gbc".to_string())
        .stack_size(256 << 20)
        .spawn(move || dispatch(&cli));
    let outcome = match worker {
        Ok(handle) => handle.join(),
        Err(error) => Ok(Err(CommandError::Internal(format!(
            "cannot start worker thread: {error}"
        )))),
    };
    match outcome {
        Ok(Ok(())) => 0,
        Ok(Err(CommandError::User(reports))) => {
            print_reports(&reports, format);
            1
        }
        Ok(Err(CommandError::Internal(message))) => {
            eprintln!("internal error: {message}\nthis is a bug in gbc; please report it");
            2
        }
        Err(_) => {
            eprintln!(
                "internal error: gbc panicked (see above)\nthis is a bug in gbc; please report it"
            );
            2
        }
    }
}

/// The command line, parsed, with what `gbc train` needs to know of how it was given
/// (the flags given with `--resume`).
fn parse() -> Result<Cli, clap::Error> {
    use clap::{CommandFactory, FromArgMatches};
    let matches = Cli::command().try_get_matches()?;
    let mut cli = Cli::from_arg_matches(&matches)?;
    if let (Command::Train(args), Some(("train", given))) = (&mut cli.command, matches.subcommand())
    {
        args.given = train::given_flags(given);
    }
    Ok(cli)
}

/// Prints diagnostics to stderr in the chosen format.
pub fn print_reports(reports: &[miette::Report], format: MessageFormat) {
    let stderr = std::io::stderr();
    let color = stderr.is_terminal() && std::env::var_os("NO_COLOR").is_none();
    let width = 100;
    for report in reports {
        eprint!("{}", api::render_diagnostic(report, format, color, width));
    }
}
