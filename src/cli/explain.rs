//! `gbc explain E0xxx`: print the catalogue entry of a diagnostic code.

use super::{CommandError, CommandResult};

/// Arguments of `gbc explain`.
#[derive(Debug, clap::Args)]
pub struct ExplainArgs {
    /// The code, e.g. `E0152` or `gbm::E0152`.
    pub code: String,
}

/// Prints the entry.
pub fn run(args: &ExplainArgs) -> CommandResult {
    let text = gbc::api::explain(&args.code).map_err(CommandError::user)?;
    print!("{text}");
    Ok(())
}
