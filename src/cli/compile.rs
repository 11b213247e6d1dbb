//! `gbc compile FILE --emit ast|ir`: print a stage of the compiled model.

use super::CommandResult;
use gbc::api;
use std::path::PathBuf;

/// Which stage `gbc compile` prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Emit {
    /// The syntax tree, with byte spans.
    Ast,
    /// The canonical text of the compiled model.
    Ir,
}

/// Arguments of `gbc compile`.
#[derive(Debug, clap::Args)]
pub struct CompileArgs {
    /// The model file.
    pub file: PathBuf,
    /// What to print.
    #[arg(long, value_enum, default_value_t = Emit::Ir)]
    pub emit: Emit,
    /// Apply this effect before lowering (repeatable; applied in order).
    #[arg(long = "effect", value_name = "NAME")]
    pub effects: Vec<String>,
}

/// Compiles the file and prints the requested stage on stdout.
pub fn run(args: &CompileArgs) -> CommandResult {
    let text = match args.emit {
        Emit::Ast => api::syntax_tree_text(&args.file)?,
        Emit::Ir => api::Model::from_file_with_effects(&args.file, &args.effects)?.ir_text(),
    };
    print!("{text}");
    Ok(())
}
