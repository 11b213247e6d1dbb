//! `gbc check FILE...`: parse and check model files, reporting every problem at once.

use super::{CommandError, CommandResult};
use gbc::api::{self, MessageFormat};
use std::path::PathBuf;

/// Arguments of `gbc check`.
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// Model files to check.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
}

/// Checks each file (and lowers it, so effect patches are validated too); prints a summary
/// line per clean file in human format.
pub fn run(args: &CheckArgs, format: MessageFormat) -> CommandResult {
    let mut reports = Vec::new();
    for path in &args.files {
        match api::check_file(path) {
            Ok(compiled) => {
                if format == MessageFormat::Human {
                    let model = compiled.ir();
                    let outputs: usize = model.closures.iter().map(|c| c.outputs.len()).sum();
                    println!(
                        "ok: {} (model {}: {} states, {} hidden, {} closure outputs, {} params, {} effects)",
                        path.display(),
                        model.name,
                        model.states.len(),
                        model.hidden.len(),
                        outputs,
                        model.params.len(),
                        model.effects.len()
                    );
                }
            }
            Err(mut errors) => reports.append(&mut errors),
        }
    }
    if reports.is_empty() {
        Ok(())
    } else {
        Err(CommandError::User(reports))
    }
}
