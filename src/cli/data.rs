//! Reading data sets on the command line: one reader for every command (records spec,
//! section 1), `--column NAME=HEADER` mappings, and the choice of held-out experiments.

use std::path::PathBuf;

use super::CommandError;
use crate::data::{parse_mapping, MinRows};
use crate::ir::Model;
use crate::record::Record;

/// How data columns are named, shared by every command that reads data.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ColumnArgs {
    /// Map a model name to a header: `--column X=Biomass`, `--column t=time_h`,
    /// `--column experiment=batch` (repeatable).
    #[arg(long = "column", value_name = "NAME=HEADER", value_parser = parse_mapping)]
    pub columns: Vec<(String, String)>,
}

/// Reads `files` as one data set and binds it to `model`: every experiment of every file,
/// in order.
pub fn load_records(
    model: &Model,
    files: &[PathBuf],
    columns: &ColumnArgs,
) -> Result<Vec<Record>, CommandError> {
    if files.is_empty() {
        return Ok(Vec::new());
    }
    let request = crate::record::request(
        model,
        &columns.columns,
        MinRows::new(2, "one step needs two rows"),
    );
    let data = crate::data::read_set(files, &request).map_err(CommandError::user)?;
    crate::record::bind(model, &data).map_err(CommandError::user)
}

/// Splits `records` into the experiments that train and those named in `holdout`; an
/// unknown name is an error that lists the experiments, and holding out every experiment
/// leaves none to train.
pub fn hold_out(
    records: Vec<Record>,
    holdout: &[String],
) -> Result<(Vec<Record>, Vec<Record>), CommandError> {
    let names: Vec<&str> = records.iter().map(|r| r.name.as_str()).collect();
    for name in holdout {
        if !names.contains(&name.as_str()) {
            return Err(CommandError::user(crate::train::TrainError::BadOption {
                option: "--holdout".into(),
                expected: format!(
                    "the name of an experiment ({})",
                    crate::suggest::did_you_mean(name, &names, "experiments")
                ),
                found: name.clone(),
            }));
        }
    }
    let (held, kept): (Vec<Record>, Vec<Record>) =
        records.into_iter().partition(|r| holdout.contains(&r.name));
    if kept.is_empty() {
        return Err(CommandError::user(
            crate::train::TrainError::NoTrainingExperiment,
        ));
    }
    Ok((kept, held))
}

/// Where whole-experiment free runs and training windows start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum HistoryArg {
    /// At each experiment's first row, the history before it held at the first values.
    Held,
    /// At the first row whose whole embedding lies inside the experiment (the paper's).
    Measured,
}

impl From<HistoryArg> for crate::train::History {
    fn from(history: HistoryArg) -> Self {
        match history {
            HistoryArg::Held => crate::train::History::Held,
            HistoryArg::Measured => crate::train::History::Measured,
        }
    }
}
