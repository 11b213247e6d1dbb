//! `gbc init NAME [--template chemostat|bioreactor|batch|fedbatch]`: a new project
//! directory (see `gbc::api::new_project`).

use super::{CommandError, CommandResult};
use gbc::api::flags::TemplateArg;
use gbc::api::{new_project, write_atomic, InitError};
use std::path::PathBuf;

/// Arguments of `gbc init`.
#[derive(Debug, clap::Args)]
pub struct InitArgs {
    /// The new directory; its last part names the model.
    pub name: PathBuf,
    /// What to start from.
    #[arg(long, value_enum, default_value_t = TemplateArg::Chemostat)]
    pub template: TemplateArg,
}

/// Writes the project's files, never over existing ones.
pub fn run(args: &InitArgs) -> CommandResult {
    let occupied = std::fs::read_dir(&args.name).is_ok_and(|mut entries| entries.next().is_some())
        || args.name.is_file();
    if occupied {
        return Err(CommandError::user(InitError::Exists {
            path: args.name.display().to_string(),
        }));
    }
    let files = new_project(&args.name, args.template.into()).map_err(CommandError::user)?;
    for (path, contents) in &files {
        write_atomic(path, contents.as_bytes()).map_err(CommandError::user)?;
        println!("created {}", path.display());
    }
    println!("next: read {}", args.name.join("README.md").display());
    Ok(())
}
