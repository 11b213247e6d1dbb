//! Defects of a data file, each naming the file, the row and the column.

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

/// A defect of a data file (spec section 4). Every variant but [`DataError::Unreadable`]
/// carries the file's text and a label on the offending cell or line.
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
    /// The header has no time column `t`.
    #[error("expected a time column `t` in the header at {at}, found none")]
    #[diagnostic(code(gbm::E0207))]
    MissingTime {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The header line.
        #[label("no `t` here")]
        span: SourceSpan,
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
    #[diagnostic(
        code(gbm::E0209),
        help("every row needs one cell per header column, separated by commas")
    )]
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
    },
    /// A cell the model reads is empty.
    #[error("expected a number at {at}, found an empty cell")]
    #[diagnostic(
        code(gbm::E0210),
        help("fill in the missing value; gaps in a record are not interpolated")
    )]
    EmptyCell {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The empty cell.
        #[label("empty")]
        span: SourceSpan,
        /// Where.
        at: Box<Location>,
    },
    /// A cell the model reads is not a number.
    #[error("expected a number at {at}, found `{found}`")]
    #[diagnostic(
        code(gbm::E0211),
        help("numbers are written like `20`, `0.05` or `1.5e-2`, with `.` as decimal point")
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
    /// A cell is NaN or infinite (or overflows a 64-bit float).
    #[error("expected a finite number at {at}, found `{found}`")]
    #[diagnostic(
        code(gbm::E0212),
        help("remove the row or replace the value; NaN and infinity cannot be fitted")
    )]
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
    },
    /// Time goes backwards.
    #[error("expected time to increase at {at}, found {found} after {previous}")]
    #[diagnostic(code(gbm::E0213), help("sort the rows by the time column `t`"))]
    UnsortedTime {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The time cell.
        #[label("earlier than the row above")]
        span: SourceSpan,
        /// The time of the row above.
        previous: f64,
        /// The time of this row.
        found: f64,
        /// Where.
        at: Box<Location>,
    },
    /// Two rows at the same time.
    #[error("expected time to increase at {at}, found {time} again")]
    #[diagnostic(code(gbm::E0214), help("remove or merge the repeated row"))]
    RepeatedTime {
        /// The file's text.
        #[source_code]
        src: DataSource,
        /// The time cell.
        #[label("same time as the row above")]
        span: SourceSpan,
        /// The repeated time.
        time: f64,
        /// Where.
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
    /// Fewer data rows than the model needs.
    #[error("expected at least {needed} data rows ({reason}), found {found}: {at} is the last")]
    #[diagnostic(
        code(gbm::E0216),
        help("use a longer record, or a model needing less history (smaller `delay` or `dim`)")
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
        /// The last row.
        at: Box<Location>,
    },
}

impl DataError {
    /// Where the defect lies, for every variant but [`DataError::Unreadable`].
    pub fn location(&self) -> Option<&Location> {
        match self {
            DataError::Unreadable { .. } => None,
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
            | DataError::TooFewRows { at, .. } => Some(at),
        }
    }
}
