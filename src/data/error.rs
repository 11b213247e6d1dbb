//! Defects of a data set: of a data file (each naming the file, the row and the column),
//! of an experiment (naming it), or of the `--column` mapping.

use miette::{Diagnostic, NamedSource, SourceSpan};
use std::fmt;
use std::sync::Arc;
use thiserror::Error;

/// The text of a data file, shared by every diagnostic about it.
pub type DataSource = Arc<NamedSource<String>>;

/// Where in a data file a defect lies. Rows count lines from 1, the header being row 1;
/// columns count cells from 1.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The file as the user named it.
    pub file: String,
    /// 1-based row (line) number; the header is row 1.
    pub row: usize,
    /// The column, where the defect lies in one.
    pub column: Option<ColumnRef>,
}

/// A column of a data file, by position and header name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ColumnRef {
    /// 1-based position in the row.
    pub index: usize,
    /// Its header name (empty when the header has no cell there).
    pub name: String,
}

impl fmt::Display for Location {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(formatter, "`{}` row {}", self.file, self.row)?;
        match &self.column {
            Some(column) if column.name.is_empty() => {
                write!(formatter, ", column {}", column.index)
            }
            Some(column) => write!(formatter, ", column {} `{}`", column.index, column.name),
            None => Ok(()),
        }
    }
}

/// A defect of a data set (records.md). Every variant but [`DataError::Unreadable`] and the
/// `--column` defects carries the file's text and a label on the offending cell or line.
#[derive(Debug, Clone, Error, Diagnostic)]
pub enum DataError {
    /// The file could not be opened or read.
    #[error("cannot read data file `{file}`: {reason}")]
    #[diagnostic(
        code(gbm::E0201),
        help("check the path, and that it names a readable file rather than a directory")
    )]
    Unreadable {
        /// The file as the user named it.
        file: String,
        /// What the operating system said.
        reason: String,
    },
    /// The file holds bytes that are not UTF-8 text (a binary file, or another encoding).
    #[error("expected UTF-8 text at {at}, found a byte sequence that is not UTF-8")]
    #[diagnostic(
        code(gbm::E0202),
        help("a data file is a CSV text file; is this the right file? (re-save it as UTF-8)")
    )]
    NotText {
        /// The file's text, invalid bytes replaced.
        #[source_code]
        src: DataSource,
        /// The first invalid byte.
        #[label("not UTF-8")]
        span: SourceSpan,
        /// Where.
        at: Box<Location>,
    },
    /// The file is empty (or only blank lines).
    #[error("expected a header row at {at}, found an empty file")]
    #[diagnostic(
        code(gbm::E0203),
        help("a data file starts with a header such as `t,u,X`, then one row per sample")
    )]
    Empty {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The start of the file.
        #[label("empty")]
        span: SourceSpan,
        /// Where.
        at: Box<Location>,
    },
    /// The file has a header but no data row.
    #[error("expected data rows after the header at {at}, found none")]
    #[diagnostic(code(gbm::E0204), help("add one row per sample below the header"))]
    NoRows {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The header line.
        #[label("only a header")]
        span: SourceSpan,
        /// Where.
        at: Box<Location>,
    },
    /// A header cell is empty.
    #[error("expected a column name at {at}, found an empty header cell")]
    #[diagnostic(
        code(gbm::E0205),
        help("give every column a name, or remove the column")
    )]
    UnnamedColumn {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The empty cell.
        #[label("no name")]
        span: SourceSpan,
        /// Where.
        at: Box<Location>,
    },
    /// Two header cells have the same name.
    #[error("duplicate column name at {at}: `{name}` is also column {first_index}")]
    #[diagnostic(code(gbm::E0206), help("rename or remove one of the two columns"))]
    DuplicateColumn {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The second occurrence.
        #[label("again here")]
        span: SourceSpan,
        /// The first occurrence.
        #[label("first here")]
        first_span: SourceSpan,
        /// The repeated name.
        name: String,
        /// 1-based position of the first occurrence.
        first_index: usize,
        /// Where (the second occurrence).
        at: Box<Location>,
    },
    /// The header has no time column: no `t`, no single `time`, no `--column t=HEADER`.
    #[error("expected a time column `t` in the header at {at}, found {found}")]
    #[diagnostic(code(gbm::E0207))]
    MissingTime {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The header line.
        #[label("no `t` here")]
        span: SourceSpan,
        /// `none`, or the candidates when several headers could be time.
        found: String,
        /// Where.
        at: Box<Location>,
        /// The columns present, with a suggestion.
        #[help]
        help: String,
    },
    /// The header lacks a column the model needs.
    #[error("expected a column `{name}` in the header at {at}, found none")]
    #[diagnostic(code(gbm::E0208))]
    MissingColumn {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The header line.
        #[label("no `{name}` here")]
        span: SourceSpan,
        /// The missing column.
        name: String,
        /// Where.
        at: Box<Location>,
        /// The columns present, with a suggestion.
        #[help]
        help: String,
    },
    /// A row with more or fewer cells than the header.
    #[error("expected {expected} cells (one per header column), found {found} at {at}")]
    #[diagnostic(code(gbm::E0209))]
    RaggedRow {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The row (or its first surplus cell).
        #[label("{found} cells")]
        span: SourceSpan,
        /// Number of header columns.
        expected: usize,
        /// Number of cells in the row.
        found: usize,
        /// Where.
        at: Box<Location>,
        /// What to do, naming the file's delimiter.
        #[help]
        help: String,
    },
    /// A cell that must hold a value holds none: a time, an experiment name, or (for a
    /// command that reads a complete record) a measured value.
    #[error("expected {expected} at {at}, found {found}")]
    #[diagnostic(code(gbm::E0210))]
    EmptyCell {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The empty cell.
        #[label("no value")]
        span: SourceSpan,
        /// What the cell must hold, e.g. "a number" or "a time".
        expected: &'static str,
        /// `an empty cell`, or the spelling of not measured (`NA`).
        found: String,
        /// Where.
        at: Box<Location>,
        /// What to do.
        #[help]
        help: String,
    },
    /// A cell the model reads is not a number.
    #[error("expected a number at {at}, found `{found}`")]
    #[diagnostic(
        code(gbm::E0211),
        help(
            "numbers are written like `20`, `0.05` or `1.5e-2` (a decimal comma such as `1,5` \
             only in a file separated by `;` or tabs); leave the cell empty or write `NA` where \
             nothing was measured"
        )
    )]
    NotANumber {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The cell.
        #[label("not a number")]
        span: SourceSpan,
        /// The cell's text.
        found: String,
        /// Where.
        at: Box<Location>,
    },
    /// A cell is infinite (or overflows a 64-bit float), or NaN where a command reads a
    /// complete record.
    #[error("expected a finite number at {at}, found `{found}`")]
    #[diagnostic(code(gbm::E0212))]
    NotFinite {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The cell.
        #[label("not finite")]
        span: SourceSpan,
        /// The cell's text.
        found: String,
        /// Where.
        at: Box<Location>,
        /// What to do.
        #[help]
        help: String,
    },
    /// Time goes backwards within an experiment.
    #[error(
        "expected time to increase in experiment `{experiment}` at {at}, found {found} after \
         {previous} (row {previous_row})"
    )]
    #[diagnostic(
        code(gbm::E0213),
        help("sort the rows of each experiment by time (file order is time order)")
    )]
    UnsortedTime {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The time cell.
        #[label("earlier than the experiment's row before")]
        span: SourceSpan,
        /// The time of the experiment's row before.
        previous: f64,
        /// The time of this row.
        found: f64,
        /// The experiment.
        experiment: String,
        /// The row of the earlier sample.
        previous_row: usize,
        /// Where.
        at: Box<Location>,
    },
    /// Two rows of one experiment at the same time.
    #[error(
        "two rows with time {time} in experiment `{experiment}`: {at} repeats row {first_row}"
    )]
    #[diagnostic(
        code(gbm::E0214),
        help(
            "remove or merge the repeated row (one row per time, with every value measured then)"
        )
    )]
    RepeatedTime {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The second time cell.
        #[label("same time again")]
        span: SourceSpan,
        /// The first time cell.
        #[label("first here")]
        first_span: SourceSpan,
        /// The repeated time.
        time: f64,
        /// The experiment.
        experiment: String,
        /// The row of the first sample at that time.
        first_row: usize,
        /// Where (the second row).
        at: Box<Location>,
    },
    /// The time step is not uniform (a gap, or irregular sampling).
    #[error("expected a time step of {expected} at {at}, found {found} (from t = {previous})")]
    #[diagnostic(
        code(gbm::E0215),
        help("data must be sampled uniformly; resample the record or split it at the gap")
    )]
    UnevenStep {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The time cell.
        #[label("step of {found}")]
        span: SourceSpan,
        /// The step of most rows.
        expected: f64,
        /// The step into this row.
        found: f64,
        /// The time of the row above.
        previous: f64,
        /// Where.
        at: Box<Location>,
    },
    /// An experiment with fewer data rows than the model needs.
    #[error(
        "expected at least {needed} data rows ({reason}), found {found} in experiment \
         `{experiment}`: {at} is its last"
    )]
    #[diagnostic(
        code(gbm::E0216),
        help(
            "use a longer record, drop the experiment, or a model needing less history \
             (smaller `delay` or `dim`)"
        )
    )]
    TooFewRows {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The last row.
        #[label("last row")]
        span: SourceSpan,
        /// How many data rows are needed.
        needed: usize,
        /// How many there are.
        found: usize,
        /// Why that many are needed.
        reason: String,
        /// The experiment.
        experiment: String,
        /// The last row.
        at: Box<Location>,
    },
    /// Rows that do not split into the header's fields with its delimiter but do with
    /// another one.
    #[error(
        "expected {expected} fields separated by {delimiter} at {at}, found {found}; the file \
         mixes delimiters: the header is separated by {delimiter}, this row by {other}"
    )]
    #[diagnostic(
        code(gbm::E0217),
        help("use one delimiter throughout the file (export it again, or fix the header)")
    )]
    MixedDelimiters {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The row.
        #[label("separated by {other}")]
        span: SourceSpan,
        /// Number of header columns.
        expected: usize,
        /// Number of fields with the header's delimiter.
        found: usize,
        /// The header's delimiter, in words.
        delimiter: &'static str,
        /// The row's delimiter, in words.
        other: &'static str,
        /// Where.
        at: Box<Location>,
    },
    /// A `--column NAME=HEADER` whose NAME the command does not read.
    #[error("unknown `--column` name `{name}`")]
    #[diagnostic(code(gbm::E0218))]
    UnknownMapping {
        /// The name given.
        name: String,
        /// The names that can be mapped, with a suggestion.
        #[help]
        help: String,
    },
    /// Two `--column` mappings for one name.
    #[error("expected one `--column {name}=HEADER`, found two: `{first}` and `{second}`")]
    #[diagnostic(code(gbm::E0219), help("keep one of the two mappings"))]
    RepeatedMapping {
        /// The mapped name.
        name: String,
        /// The first header.
        first: String,
        /// The second header.
        second: String,
    },
    /// The header named by `--column NAME=HEADER` is not in the file.
    #[error(
        "expected a column `{header}` (from `--column {name}={header}`) in the header at {at}, \
         found none"
    )]
    #[diagnostic(code(gbm::E0220))]
    MissingMappedColumn {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The header line.
        #[label("no `{header}` here")]
        span: SourceSpan,
        /// The mapped name.
        name: String,
        /// The header asked for.
        header: String,
        /// Where.
        at: Box<Location>,
        /// The headers present, with a suggestion.
        #[help]
        help: String,
    },
    /// Two experiments of a data set with the same name.
    #[error("two experiments named `{name}`: one in {first}, another at {at}")]
    #[diagnostic(
        code(gbm::E0221),
        help(
            "experiments are named by their file's stem or by their value in the experiment \
             column: rename a file or a value, or drop one of the two"
        )
    )]
    DuplicateExperiment {
        /// The second experiment's file.
        #[source_code]
        src: DataSource,
        /// Its first row, or its experiment cell.
        #[label("`{name}` again")]
        span: SourceSpan,
        /// The name.
        name: String,
        /// Where the first one is, in words.
        first: String,
        /// Where the second one starts.
        at: Box<Location>,
    },
    /// An input without a value at its experiment's first row.
    #[error(
        "expected a value of input `{input}` at the first row of experiment `{experiment}`, \
         found none at {at}"
    )]
    #[diagnostic(
        code(gbm::E0222),
        help("give the input's value at the experiment's first row (inputs hold their last value until the next one)")
    )]
    InputMissingAtStart {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The cell.
        #[label("no value")]
        span: SourceSpan,
        /// The input.
        input: String,
        /// The experiment.
        experiment: String,
        /// Where.
        at: Box<Location>,
    },
    /// A measured state with no value at all in an experiment.
    #[error(
        "expected at least one value of state `{state}` in experiment `{experiment}`, found \
         none in its {rows} rows from {at}"
    )]
    #[diagnostic(code(gbm::E0223))]
    StateNeverMeasured {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The cell at the experiment's first row.
        #[label("never measured")]
        span: SourceSpan,
        /// The state.
        state: String,
        /// The experiment.
        experiment: String,
        /// How many rows the experiment has.
        rows: usize,
        /// The experiment's first row, in that column.
        at: Box<Location>,
        /// What to do.
        #[help]
        help: String,
    },
    /// Several experiments where a command reads one record.
    #[error("expected one record, found {count} experiments ({names}); the second starts at {at}")]
    #[diagnostic(
        code(gbm::E0224),
        help("this command reads one record: give it one experiment (its own file)")
    )]
    SeveralExperiments {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The second experiment's first row.
        #[label("another experiment")]
        span: SourceSpan,
        /// How many experiments.
        count: usize,
        /// Their names, listed.
        names: String,
        /// Where the second one starts.
        at: Box<Location>,
    },
}

impl DataError {
    /// Where the defect lies in a file: for every variant but [`DataError::Unreadable`] and
    /// the `--column` defects ([`DataError::UnknownMapping`], [`DataError::RepeatedMapping`]).
    pub fn location(&self) -> Option<&Location> {
        match self {
            DataError::Unreadable { .. }
            | DataError::UnknownMapping { .. }
            | DataError::RepeatedMapping { .. } => None,
            DataError::NotText { at, .. }
            | DataError::Empty { at, .. }
            | DataError::NoRows { at, .. }
            | DataError::UnnamedColumn { at, .. }
            | DataError::DuplicateColumn { at, .. }
            | DataError::MissingTime { at, .. }
            | DataError::MissingColumn { at, .. }
            | DataError::RaggedRow { at, .. }
            | DataError::EmptyCell { at, .. }
            | DataError::NotANumber { at, .. }
            | DataError::NotFinite { at, .. }
            | DataError::UnsortedTime { at, .. }
            | DataError::RepeatedTime { at, .. }
            | DataError::UnevenStep { at, .. }
            | DataError::TooFewRows { at, .. }
            | DataError::MixedDelimiters { at, .. }
            | DataError::MissingMappedColumn { at, .. }
            | DataError::DuplicateExperiment { at, .. }
            | DataError::InputMissingAtStart { at, .. }
            | DataError::StateNeverMeasured { at, .. }
            | DataError::SeveralExperiments { at, .. } => Some(at),
        }
    }
}
