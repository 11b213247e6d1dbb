//! `gbc completions bash|zsh|fish|elvish|powershell`: a shell completion script on stdout,
//! generated from the command-line definition (so it always matches the commands).

use super::{Cli, CommandResult};
use clap::CommandFactory;

/// Arguments of `gbc completions`.
#[derive(Debug, clap::Args)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

/// Prints the script.
pub fn run(args: &CompletionsArgs) -> CommandResult {
    let mut command = Cli::command();
    clap_complete::generate(args.shell, &mut command, "gbc", &mut std::io::stdout());
    Ok(())
}
