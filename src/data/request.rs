//! What a reader is asked for: the columns the model reads with their roles, the
//! `--column` mappings, and how many rows an experiment needs.

/// What a command needs from the data: the columns the model reads, with their roles, the
/// `--column` mappings, and how many rows an experiment needs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request {
    /// The columns, in the order the model wants them.
    pub columns: Vec<Wanted>,
    /// `--column NAME=HEADER` mappings, in the order given: NAME is a requested column,
    /// `t` or `experiment`.
    pub mapping: Vec<(String, String)>,
    /// How many rows each experiment needs.
    pub min_rows: MinRows,
}

impl Request {
    /// A request for `columns`, with no mapping and no need beyond one row.
    pub fn new(columns: Vec<Wanted>) -> Self {
        Request {
            columns,
            mapping: Vec::new(),
            min_rows: MinRows::new(1, "an experiment has at least one row"),
        }
    }
    /// The same request with `--column` mappings.
    pub fn with_mapping(mut self, mapping: Vec<(String, String)>) -> Self {
        self.mapping = mapping;
        self
    }
    /// The same request, needing `min_rows` rows per experiment.
    pub fn with_min_rows(mut self, min_rows: impl Into<MinRows>) -> Self {
        self.min_rows = min_rows.into();
        self
    }
}

/// Parses the argument of `--column`, `NAME=HEADER` (split at the first `=`, both sides
/// trimmed, neither empty); the error says what was expected.
pub fn parse_mapping(argument: &str) -> Result<(String, String), String> {
    match argument.split_once('=') {
        Some((name, header)) if !name.trim().is_empty() && !header.trim().is_empty() => {
            Ok((name.trim().to_string(), header.trim().to_string()))
        }
        _ => Err(format!(
            "expected NAME=HEADER (e.g. `X=Biomass`), found `{argument}`"
        )),
    }
}

/// A column the model reads, and what it is to the model.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Wanted {
    /// The model's name for it (a header, or the NAME of a `--column` mapping).
    pub name: String,
    /// What it is.
    pub role: Role,
}

impl Wanted {
    /// An input column.
    pub fn input(name: impl Into<String>) -> Self {
        Wanted {
            name: name.into(),
            role: Role::Input,
        }
    }
    /// A measured-state column.
    pub fn state(name: impl Into<String>) -> Self {
        Wanted {
            name: name.into(),
            role: Role::State,
        }
    }
    /// An optional column.
    pub fn optional(name: impl Into<String>) -> Self {
        Wanted {
            name: name.into(),
            role: Role::Optional,
        }
    }
}

/// What a requested column is to the model, which decides what the reader demands of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// An input: a required column with a value at each experiment's first row. It holds
    /// its last value until the next one (zero-order hold, applied by the consumer).
    Input,
    /// A measured state: a required column with at least one value in each experiment.
    State,
    /// Read if present (e.g. an observable that may be measured); absent or empty is fine.
    Optional,
}

/// How many data rows a model needs, and why (for the message when an experiment has
/// fewer).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MinRows {
    /// The least number of data rows (header excluded).
    pub rows: usize,
    /// Why, in words completing "expected at least N data rows (...)", e.g. "the embedding
    /// needs 46 rows of history".
    pub reason: String,
}

impl MinRows {
    /// A requirement of `rows` data rows for `reason`.
    pub fn new(rows: usize, reason: impl Into<String>) -> Self {
        MinRows {
            rows,
            reason: reason.into(),
        }
    }
}

impl From<usize> for MinRows {
    fn from(rows: usize) -> Self {
        MinRows::new(rows, format!("the model needs {rows}"))
    }
}
