//! `gbc export MODEL --weights RUN_DIR --format onnx -o model.onnx`: the one-step map of a
//! trained model as a file other runtimes read (see `docs/export.md` and
//! `gbc::api::SavedRun::export`). The layout (window, step, tensors and their columns) goes
//! to stderr.

use std::path::PathBuf;

use super::{CommandError, CommandResult};
use gbc::api::flags::PrecisionArg;
use gbc::api::{self, ExportFormat, SavedRun};

/// The file format written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FormatArg {
    /// ONNX (IR version 8, opset 17): onnxruntime, tract, MATLAB, CasADi, ...
    Onnx,
}

/// Arguments of `gbc export`.
#[derive(Debug, clap::Args)]
pub struct ExportArgs {
    /// The model file the weights were trained with.
    pub model: PathBuf,
    /// The run directory written by `gbc train -o DIR`.
    #[arg(long, value_name = "DIR")]
    pub weights: PathBuf,
    /// The file format.
    #[arg(long, value_enum, default_value_t = FormatArg::Onnx)]
    pub format: FormatArg,
    /// Element type of the exported tensors.
    #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
    pub precision: PrecisionArg,
    /// The file to write.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Exports the trained model and describes the file on stderr.
pub fn run(args: &ExportArgs) -> CommandResult {
    api::ensure_not_input(&args.output, &[&args.model]).map_err(CommandError::user)?;
    let model = api::Model::from_file(&args.model)?;
    if api::is_ensemble(&args.weights) {
        return ensemble(args, &model);
    }
    let saved = SavedRun::load_single(&model, &args.weights)?;
    for note in saved.notes() {
        eprintln!("note: {note}");
    }
    let format = match args.format {
        FormatArg::Onnx => ExportFormat::Onnx,
    };
    let export = saved.export(format, args.precision.into())?;
    export.write(&args.output)?;
    eprint!("{}", export.layout_text(&args.output));
    Ok(())
}

/// An ensemble run: every used member's map and the band's facts
/// ([`api::export_ensemble`]).
fn ensemble(args: &ExportArgs, model: &api::Model) -> CommandResult {
    let precision = args.precision.into();
    let exported = api::export_ensemble(model, &args.weights, precision, &args.output)?;
    for (path, _) in &exported.members {
        api::ensure_not_input(path, &[&args.model]).map_err(CommandError::user)?;
    }
    exported.write().map_err(CommandError::user)?;
    for (path, member) in &exported.members {
        let layout = &member.layout;
        eprintln!(
            "wrote {}: one step of {} ({} RK4 sub-steps) from a window of {} knots",
            path.display(),
            layout.step,
            layout.substeps,
            layout.window
        );
    }
    let band = &exported.band;
    eprintln!(
        "wrote {}: {} members, the noise, floor and calibrated factors of each state{}",
        exported.band_path.display(),
        band.members.len(),
        if band.calibrated {
            ""
        } else {
            " (not calibrated: the median alone)"
        }
    );
    eprintln!("  the tensors of each are a single run's export's; the band's recipe: docs/export.md, \"Ensembles\"");
    Ok(())
}
