//! `gbc predict MODEL --weights DIR DATA... --mode offline|online -o PRED.csv`: predicted
//! states and every closure and model output over time, from a trained run, one run per
//! experiment of the data set.
//!
//! Columns: `experiment` (when the data set has several), `t`, the states (measured, then
//! hidden), the closure outputs, the model's outputs; one row per data row. Offline rows are one-step predictions from the true history; online rows come
//! from one free run driven by the data's inputs (see `gbc::api::SavedRun::predict`). A free run
//! that leaves the physical range of the training data (the run's `--range-factor`) stops:
//! the file ends before the offending row and a warning on stderr says where and why. No
//! value that is not finite is ever written: a table holding one is refused (E0253).

use std::path::PathBuf;

use super::progress::{Announce, Count, Reporter};
use super::{CommandError, CommandResult};
use gbc::api::flags::{ColumnArgs, HistoryArg};
use gbc::api::{self, PredictEvent, PredictMode, PredictSpec, SavedRun};

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
    #[arg(long, value_name = "LEVEL", default_value_t = api::DEFAULT_BAND_LEVEL)]
    pub band: f64,
    /// Members of an ensemble run predicting at once (default: the number of cores).
    #[arg(short, long, value_name = "N")]
    pub jobs: Option<usize>,
}

/// Predicts and writes the table (an ensemble's coverage on stdout).
pub fn run(args: &PredictArgs) -> CommandResult {
    let mut inputs: Vec<&std::path::Path> = vec![&args.model];
    inputs.extend(args.data.iter().map(|p| p.as_path()));
    api::ensure_not_input(&args.output, &inputs).map_err(CommandError::user)?;
    let model = api::Model::from_file(&args.model)?;
    let saved = SavedRun::load(&model, &args.weights)?;
    for note in saved.notes() {
        eprintln!("note: {note}");
    }
    let records = api::read_records(model.ir(), &args.data, &args.columns.columns)?;
    let spec = PredictSpec {
        mode: mode_of(args.mode),
        history: args.history.into(),
        band: args.band,
        jobs: args.jobs,
    };
    let reporter = Reporter::new();
    let predictions = saved.predict(&records, &spec, &|event| show(&reporter, event));
    reporter.finish();
    let predictions = predictions?;
    predictions.write_csv(&args.output)?;
    print!("{}", predictions.coverage_text());
    Ok(())
}

/// Prints a prediction's event on stderr: notes, warnings, progress.
fn show(reporter: &Reporter, event: PredictEvent) {
    match event {
        PredictEvent::Note(note) => eprintln!("note: {note}"),
        PredictEvent::Warning(warning) => reporter.println(&format!("warning: {warning}")),
        PredictEvent::Started { experiments } => reporter.stage(
            "predicting",
            experiments as u64,
            Count::Items("experiments"),
            Announce::IfSlow,
        ),
        PredictEvent::Experiment { name } => reporter.advance(1, name),
        PredictEvent::Members { members, jobs } => {
            eprintln!("predicting with {members} members ({jobs} at once)")
        }
        PredictEvent::MemberDone { done, members } => {
            eprintln!("predicting: {done}/{members} members")
        }
        PredictEvent::Finished => reporter.finish(),
    }
}

/// The library's mode of a `--mode`.
fn mode_of(mode: ModeArg) -> PredictMode {
    match mode {
        ModeArg::Offline => PredictMode::Offline,
        ModeArg::Online => PredictMode::Online,
        ModeArg::OnlineTrainedStep => PredictMode::OnlineTrainedStep,
    }
}
