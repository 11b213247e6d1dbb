//! `gbc predict MODEL --weights DIR DATA.csv --mode offline|online -o PRED.csv`: predicted
//! states and every closure and model output over time, from a trained run.
//!
//! Columns: `t`, the states (measured, then hidden), the closure outputs, the model's
//! outputs. Offline rows are one-step predictions from the true history; online rows come
//! from one free run driven by the data's inputs (see `gbc::train::predict`). A free run
//! that leaves the physical range of the training data (the run's `--range-factor`) stops:
//! the file ends at the offending row and a warning on stderr says where and why.

use std::path::PathBuf;

use super::train::{read_data, read_source, train_error};
use super::{CommandError, CommandResult};
use crate::train::recipe::DEFAULT_RANGE_FACTOR;
use crate::train::{artifacts, predict, PhysicalRange};

/// How predictions are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// One step from the true history.
    Offline,
    /// A free run from the initial history, driven by the inputs alone.
    Online,
}

/// Arguments of `gbc predict`.
#[derive(Debug, clap::Args)]
pub struct PredictArgs {
    /// The model file the weights were trained with.
    pub model: PathBuf,
    /// The record to predict along (CSV with `t`, the inputs and the measured states).
    pub data: PathBuf,
    /// The run directory written by `gbc train -o DIR`.
    #[arg(long, value_name = "DIR")]
    pub weights: PathBuf,
    /// Offline (one step) or online (free run) predictions.
    #[arg(long, value_enum, default_value_t = ModeArg::Offline)]
    pub mode: ModeArg,
    /// The CSV file to write.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Predicts and writes the table.
pub fn run(args: &PredictArgs) -> CommandResult {
    crate::io::ensure_not_input(&args.output, &[&args.model, &args.data])
        .map_err(CommandError::user)?;
    let model = super::load_model(&args.model)?;
    let source = read_source(&args.model)?;
    let (network, setup, info) =
        artifacts::restore(&model, &source, &args.weights).map_err(train_error)?;
    let data = read_data(&model, &args.data)?;
    let record = crate::train::record_of(&model, &data).map_err(train_error)?;
    let mode = match args.mode {
        ModeArg::Offline => predict::Mode::Offline,
        ModeArg::Online => predict::Mode::Online,
    };
    let factor = info.recipe.map_or(DEFAULT_RANGE_FACTOR, |r| r.range_factor);
    let history = crate::train::History::Measured;
    let range = PhysicalRange::new(&setup.normalisation, factor);
    let mut table = predict::predict_in_range(
        &model,
        &network,
        &setup,
        &record,
        (mode, history, range.as_ref()),
    )
    .map_err(train_error)?;
    if let Some(divergence) = &table.divergence {
        eprintln!("warning: {divergence}; the predictions stop there");
        let rows = (table.columns.first()).map_or(0, |times| {
            times.iter().take_while(|t| **t <= divergence.time).count()
        });
        for column in &mut table.columns {
            column.truncate(rows);
        }
    }
    crate::data::write_csv(&args.output, &table.header, &table.columns)
        .map_err(CommandError::user)?;
    Ok(())
}
