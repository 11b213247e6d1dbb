//! `gbc predict MODEL --weights DIR DATA... --mode offline|online -o PRED.csv`: predicted
//! states and every closure and model output over time, from a trained run, one run per
//! experiment of the data set.
//!
//! Columns: `experiment` (when the data set has several), `t`, the states (measured, then
//! hidden), the closure outputs, the model's outputs; one row per data row. Offline rows are one-step predictions from the true history; online rows come
//! from one free run driven by the data's inputs (see `gbc::train::predict`). A free run
//! that leaves the physical range of the training data (the run's `--range-factor`) stops:
//! the file ends before the offending row and a warning on stderr says where and why. No
//! value that is not finite is ever written: a table holding one is refused (E0253).

use std::path::PathBuf;

use super::data::{load_records, ColumnArgs, HistoryArg};
use super::progress::{Announce, Count, Reporter};
use super::train::{read_source, train_error};
use super::{CommandError, CommandResult};
use crate::train::{artifacts, predict, PhysicalRange};

mod ensemble;

/// How predictions are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// One step from the true history.
    Offline,
    /// A free run from the initial history, driven by the inputs alone; each step cut
    /// into as many sub-steps as the model's stiffness needs there.
    Online,
    /// A free run at the trained step alone: what the exported ONNX map gives when
    /// iterated.
    OnlineTrainedStep,
}

/// Arguments of `gbc predict`.
#[derive(Debug, clap::Args)]
pub struct PredictArgs {
    /// The model file the weights were trained with.
    pub model: PathBuf,
    /// The data set to predict along: one or more CSV files (each an experiment, or several
    /// with an `experiment` column).
    #[arg(required = true, num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// The run directory written by `gbc train -o DIR`.
    #[arg(long, value_name = "DIR")]
    pub weights: PathBuf,
    /// Offline (one step) or online (free run) predictions.
    #[arg(long, value_enum, default_value_t = ModeArg::Offline)]
    pub mode: ModeArg,
    /// The CSV file to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Where each experiment's run starts: its first row (history held before it) or the
    /// first row with a full embedding history inside the data.
    #[arg(long, value_enum, default_value_t = HistoryArg::Held)]
    pub history: HistoryArg,
    /// How data columns are named.
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// The level of the prediction band of an ensemble run (`gbc train --ensemble N`): each
    /// measured state gets `X_lo` and `X_hi` columns (online mode), and its coverage of the
    /// data's measured cells is printed.
    #[arg(long, value_name = "LEVEL", default_value_t = crate::ensemble::DEFAULT_LEVEL)]
    pub band: f64,
    /// Members of an ensemble run predicting at once (default: the number of cores).
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
}

/// Predicts and writes the table.
pub fn run(args: &PredictArgs) -> CommandResult {
    let mut inputs: Vec<&std::path::Path> = vec![&args.model];
    inputs.extend(args.data.iter().map(|p| p.as_path()));
    crate::io::ensure_not_input(&args.output, &inputs).map_err(CommandError::user)?;
    let model = super::load_model(&args.model)?;
    let source = read_source(&args.model)?;
    if crate::ensemble::is_ensemble(&args.weights) {
        return ensemble::run(args, &model, &source);
    }
    let (network, setup, info) =
        artifacts::restore(&model, &source, &args.weights).map_err(train_error)?;
    let records = load_records(&model, &args.data, &args.columns)?;
    let mode = mode_of(args.mode);
    let range = PhysicalRange::of_run(&info);
    let mut header = Vec::new();
    let mut columns: Vec<Vec<f64>> = Vec::new();
    let mut labels = Vec::new();
    let reporter = Reporter::new();
    let count = Count::Items("experiments");
    reporter.stage("predicting", records.len() as u64, count, Announce::IfSlow);
    for record in &records {
        let how = (mode, args.history.into(), range.as_ref());
        let mut table = predict::predict_in_range(&model, &network, &setup, record, how)
            .map_err(train_error)?;
        if let Some(divergence) = &table.divergence {
            reporter.println(&format!(
                "warning: {divergence}; the predictions stop before it"
            ));
        }
        table.cut_at_divergence();
        reporter.advance(1, record.name.clone());
        let rows = table.columns.first().map_or(0, Vec::len);
        labels.extend(std::iter::repeat_n(record.name.clone(), rows));
        if columns.is_empty() {
            header = table.header;
            columns = table.columns;
        } else {
            for (all, part) in columns.iter_mut().zip(table.columns) {
                all.extend(part);
            }
        }
    }
    reporter.finish();
    let labels = (records.len() > 1).then_some(("experiment", labels.as_slice()));
    crate::data::write_table(&args.output, labels, &header, &columns)
        .map_err(CommandError::user)?;
    Ok(())
}

/// The library's mode of a `--mode`.
fn mode_of(mode: ModeArg) -> predict::Mode {
    match mode {
        ModeArg::Offline => predict::Mode::Offline,
        ModeArg::Online => predict::Mode::Online,
        ModeArg::OnlineTrainedStep => predict::Mode::OnlineTrainedStep,
    }
}
