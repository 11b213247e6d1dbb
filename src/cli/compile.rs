//! `gbc compile FILE --emit ast|ir`: print a stage of the compiled model.

use super::CommandResult;
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
        Emit::Ast => {
            let source = crate::driver::read_source(&args.file).map_err(|r| vec![r])?;
            let model = crate::driver::parse(&args.file.display().to_string(), &source)?;
            format!("{model:#?}\n")
        }
        Emit::Ir => {
            let effects: Vec<&str> = args.effects.iter().map(String::as_str).collect();
            let compiled = crate::driver::compile_file(&args.file, &effects)?;
            crate::ir::print(&compiled.model)
        }
    };
    print!("{text}");
    Ok(())
}
