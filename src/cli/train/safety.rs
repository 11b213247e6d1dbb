//! `gbc train`'s run safety at the edge: the command line kept in the run directory for
//! `--resume` (Ctrl-C and SIGTERM are [`gbc::api::stop`]'s).
//!
//! Every checkpoint keeps the command line (its `command`): the arguments after `train`,
//! the working directory they were given in, and the sha256 of every model and data file.
//! `gbc train --resume DIR` parses those arguments again, checks that no file changed
//! (E0432), enters that working directory (so that relative paths read, and are recorded,
//! as they were) and hands the checkpoint to training. A flag given with `--resume` is
//! refused (E0434) rather than dropped.

use std::path::{Path, PathBuf};

use clap::Parser;
use sha2::{Digest, Sha256};

use super::train_error;
use crate::cli::{Cli, Command, CommandError};
use gbc::api::flags::TrainArgs;
use gbc::api::{Checkpoint, TrainError};

/// The command line a checkpoint keeps.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct SavedArgs {
    /// The working directory the arguments were given in.
    directory: PathBuf,
    /// The arguments after `train`.
    args: Vec<String>,
    /// Each model and data file with the sha256 of its bytes.
    files: Vec<(PathBuf, String)>,
}

/// The command line of this training, for its checkpoints.
pub fn command(args: &TrainArgs) -> Result<serde_json::Value, CommandError> {
    let argv: Vec<String> = std::env::args().collect();
    let after = argv
        .iter()
        .position(|a| a == "train")
        .map_or(argv.len(), |i| i + 1);
    let saved = SavedArgs {
        directory: std::env::current_dir().unwrap_or_default(),
        args: argv[after..].to_vec(),
        files: input_files(args)
            .into_iter()
            .map(|path| {
                let hash = file_hash(&path);
                (path, hash)
            })
            .collect(),
    };
    serde_json::to_value(&saved)
        .map_err(|error| CommandError::Internal(format!("cannot encode arguments: {error}")))
}

/// Refuses flags given with `--resume` (E0434): the run resumes with the flags it was
/// started with, and a flag given now would be dropped without a word.
pub fn alone(args: &TrainArgs) -> Result<(), CommandError> {
    match args.given.is_empty() {
        true => Ok(()),
        false => Err(train_error(TrainError::ResumeFlags {
            flags: args.given.clone(),
        })),
    }
}

/// The arguments and the checkpoint of the stopped run in `directory`.
pub fn resumed(directory: &Path) -> Result<(TrainArgs, Checkpoint), CommandError> {
    let no_checkpoint = |found: String| {
        train_error(TrainError::NoCheckpoint {
            directory: directory.display().to_string(),
            found,
        })
    };
    let checkpoint = Checkpoint::load(directory).map_err(train_error)?;
    let saved: SavedArgs = serde_json::from_value(checkpoint.command.clone())
        .map_err(|error| no_checkpoint(format!("a checkpoint without its command ({error})")))?;
    let argv = ["gbc".to_string(), "train".to_string()]
        .into_iter()
        .chain(saved.args.iter().cloned());
    let cli = Cli::try_parse_from(argv)
        .map_err(|error| no_checkpoint(format!("arguments that no longer parse ({error})")))?;
    let Command::Train(args) = cli.command else {
        return Err(no_checkpoint("another command's arguments".into()));
    };
    let mut args = *args;
    let base = &saved.directory;
    for (path, hash) in &saved.files {
        let path = base.join(path);
        if file_hash(&path) != *hash {
            return Err(train_error(TrainError::ResumeChanged {
                what: format!("`{}` changed since the run started", path.display()),
            }));
        }
    }
    args.output = Some(enter(base, directory)?);
    args.force = true;
    args.resume = None;
    args.stop_after_epochs = None;
    Ok((args, checkpoint))
}

/// Makes `base`, the working directory the run started in, the current one, so that the
/// saved arguments read as they did (and `run.json` records the paths as given then);
/// returns the run directory `directory` (given here) as an absolute path.
fn enter(base: &Path, directory: &Path) -> Result<PathBuf, CommandError> {
    let gone = |error: std::io::Error| {
        train_error(TrainError::ResumeChanged {
            what: format!(
                "the directory the run started in, `{}`, cannot be entered ({error})",
                base.display()
            ),
        })
    };
    let directory = std::path::absolute(directory).map_err(gone)?;
    std::env::set_current_dir(base).map_err(gone)?;
    Ok(directory)
}

/// The model and data files of a training.
fn input_files(args: &TrainArgs) -> Vec<PathBuf> {
    (args.model.iter())
        .chain(&args.data)
        .chain(&args.val)
        .cloned()
        .collect()
}

/// sha256 of a file's bytes (empty when it cannot be read).
fn file_hash(path: &Path) -> String {
    std::fs::read(path).map_or(String::new(), |bytes| {
        Sha256::digest(&bytes)
            .iter()
            .map(|byte| format!("{byte:02x}"))
            .collect()
    })
}
