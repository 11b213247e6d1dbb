//! How every command that reads data names its columns (`--column NAME=HEADER`), and where
//! free runs start (`--history`).

use crate::data::parse_mapping;

/// How data columns are named, shared by every command that reads data.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ColumnArgs {
    /// Map a model name to a header: `--column X=Biomass`, `--column t=time_h`,
    /// `--column experiment=batch` (repeatable).
    #[arg(long = "column", value_name = "NAME=HEADER", value_parser = parse_mapping)]
    pub columns: Vec<(String, String)>,
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
