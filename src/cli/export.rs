//! `gbc export MODEL --weights RUN_DIR --format onnx -o model.onnx`: the one-step map of a
//! trained model as a file other runtimes read (see `docs/export.md` and
//! `gbc::export`). The layout (window, step, tensors and their columns) goes to stderr.

use std::path::PathBuf;

use crate::backend::Precision;

use super::train::{read_source, train_error};
use super::{CommandError, CommandResult};
use crate::train::artifacts;

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
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    pub precision: Precision,
    /// The file to write.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Exports the trained model and describes the file on stderr.
pub fn run(args: &ExportArgs) -> CommandResult {
    crate::io::ensure_not_input(&args.output, &[&args.model]).map_err(CommandError::user)?;
    let model = super::load_model(&args.model)?;
    let source = read_source(&args.model)?;
    if crate::ensemble::is_ensemble(&args.weights) {
        return ensemble(args, &model, &source);
    }
    let restored =
        artifacts::restore_with_notes(&model, &source, &args.weights).map_err(train_error)?;
    for note in &restored.notes {
        eprintln!("note: {note}");
    }
    let exported = match args.format {
        FormatArg::Onnx => {
            crate::export::onnx(&model, &restored.network, &restored.setup, args.precision)
        }
    }
    .map_err(|error| match error {
        crate::export::ExportError::Internal(message) => CommandError::Internal(message),
        not_finite => CommandError::user(not_finite),
    })?;
    crate::io::write_atomic(&args.output, &exported.bytes).map_err(CommandError::user)?;
    let layout = &exported.layout;
    let columns = |names: &[String]| names.join(", ");
    eprintln!(
        "wrote {}: one step of {} ({} RK4 sub-steps) from a window of {} knots",
        args.output.display(),
        layout.step,
        layout.substeps,
        layout.window
    );
    eprintln!(
        "  state_window [batch, {}, {}]: {}",
        layout.window,
        layout.states.len(),
        columns(&layout.states)
    );
    if !layout.inputs.is_empty() {
        eprintln!(
            "  input_window [batch, {}, {}]: {}",
            layout.window,
            layout.inputs.len(),
            columns(&layout.inputs)
        );
    }
    if !layout.hidden.is_empty() {
        eprintln!(
            "  hidden [batch, {}]: {}",
            layout.hidden.len(),
            columns(&layout.hidden)
        );
    }
    eprintln!("  -> next_state [batch, {}]", layout.states.len());
    for (name, list) in [
        ("next_hidden", &layout.hidden),
        ("closure_outputs", &layout.closure_outputs),
        ("outputs", &layout.outputs),
    ] {
        if !list.is_empty() {
            eprintln!("  -> {name} [batch, {}]: {}", list.len(), columns(list));
        }
    }
    Ok(())
}

/// An ensemble run: every used member's map and the band's facts (`gbc::export::ensemble`).
fn ensemble(args: &ExportArgs, model: &crate::ir::Model, source: &str) -> CommandResult {
    let exported =
        crate::export::ensemble::export(model, source, &args.weights, args.precision, &args.output)
            .map_err(CommandError::user)?;
    for (path, _) in &exported.members {
        crate::io::ensure_not_input(path, &[&args.model]).map_err(CommandError::user)?;
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
