//! The command-line edge: argument parsing, dispatch over subcommands, and rendering of
//! diagnostics. The only part of gbc that prints or chooses colours.

use clap::{Parser, Subcommand};

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
    /// A user error from one diagnostic.
    pub fn user(diagnostic: impl miette::Diagnostic + Send + Sync + 'static) -> Self {
        CommandError::User(vec![miette::Report::new(diagnostic)])
    }
}

/// What a command returns.
pub type CommandResult = Result<(), CommandError>;

/// gbc: compile and train grey-box models written in the .gbm language.
#[derive(Debug, Parser)]
#[command(name = "gbc", version, about)]
pub struct Cli {
    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {}

/// Parses the command line, runs the command and returns the process exit code.
pub fn main() -> i32 {
    let _cli = Cli::parse();
    0
}

/// Reads, parses, checks and lowers the model file at `path` (no effect applied); every
/// problem becomes a user error carrying the file's source.
pub fn load_model(path: &std::path::Path) -> Result<crate::ir::Model, CommandError> {
    Err(CommandError::Internal(format!(
        "front end not wired yet for {}",
        path.display()
    )))
}
