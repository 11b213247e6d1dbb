//! Reading data sets on the command line: one reader for every command (records spec,
//! section 1), `--column NAME=HEADER` mappings, and the choice of held-out experiments.

use std::path::PathBuf;

use super::CommandError;
use crate::data::parse_mapping;
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

/// Reads `files` as one data set and binds it to `model` ([`crate::api::read_records`]).
pub fn load_records(
    model: &Model,
    files: &[PathBuf],
    columns: &ColumnArgs,
) -> Result<Vec<Record>, CommandError> {
    Ok(crate::api::read_records(model, files, &columns.columns)?)
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
