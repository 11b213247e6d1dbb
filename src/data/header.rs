//! A data file's header: column names with their units, and which column is time, which
//! names experiments, and which holds each requested column (`--column` mappings applied).

use super::error::DataError;
use super::request::{Request, Role};
use super::scan::{clean, clean_range};
use super::source::{column, span, Source};
use crate::suggest::closest;
use std::collections::HashMap;
use std::ops::Range;

/// The header of the time column when nothing names another.
pub(super) const TIME: &str = "t";
/// The header of the experiment column when nothing names another.
pub(super) const EXPERIMENT: &str = "experiment";

/// One header cell.
#[derive(Debug, Clone)]
pub(super) struct HeaderCell {
    /// The text as written (cleaned of spaces and quotes), e.g. `X [g/L]`.
    pub text: String,
    /// The column's name: the text without its unit, e.g. `X`.
    pub name: String,
    /// The unit in brackets, if any, e.g. `g/L`.
    pub unit: Option<String>,
    /// Where the text lies.
    pub range: Range<usize>,
}

/// A parsed header line.
#[derive(Debug, Clone)]
pub(super) struct Header {
    /// The cells, in file order.
    pub cells: Vec<HeaderCell>,
    /// The byte range of the whole line.
    pub line: Range<usize>,
    /// The 1-based row of the header.
    pub row: usize,
}

/// Where each column a request reads lies in one file (0-based positions).
#[derive(Debug, Clone)]
pub(super) struct Layout {
    /// The time column.
    pub time: usize,
    /// The experiment column, if the file has one.
    pub experiment: Option<usize>,
    /// One entry per requested column: its position, or `None` where it is absent.
    pub columns: Vec<Option<usize>>,
}

/// Splits `text` into a column name and a unit: `X [g/L]` is `X` with unit `g/L`. A text
/// without a bracketed suffix (or with nothing before it) is all name.
pub(super) fn split_unit(text: &str) -> (&str, Option<&str>) {
    let Some(inner) = text.strip_suffix(']') else {
        return (text, None);
    };
    match inner.rfind('[') {
        Some(open) if !inner[..open].trim().is_empty() => {
            let unit = inner[open + 1..].trim();
            (inner[..open].trim(), (!unit.is_empty()).then_some(unit))
        }
        _ => (text, None),
    }
}

impl Header {
    /// Parses the header record whose raw fields are `fields`: every cell is named, and no
    /// two cells name the same column (units aside).
    pub fn parse(
        source: &Source,
        fields: &[Range<usize>],
        line: Range<usize>,
    ) -> Result<Header, DataError> {
        let text = source.text();
        let row = source.row_of(line.start);
        let mut cells: Vec<HeaderCell> = Vec::with_capacity(fields.len());
        let mut seen: HashMap<String, usize> = HashMap::new();
        for (position, raw) in fields.iter().enumerate() {
            let range = clean_range(text, raw.clone());
            let written = clean(&text[raw.clone()]);
            if written.is_empty() {
                return Err(DataError::UnnamedColumn {
                    src: source.src.clone(),
                    span: span(range),
                    at: source.at(row, column(position, "")),
                });
            }
            let (name, unit) = split_unit(written);
            if let Some(&first) = seen.get(name) {
                return Err(DataError::DuplicateColumn {
                    src: source.src.clone(),
                    span: span(range),
                    first_span: span(cells[first].range.clone()),
                    name: name.to_string(),
                    first_index: first + 1,
                    at: source.at(row, column(position, written)),
                });
            }
            seen.insert(name.to_string(), position);
            cells.push(HeaderCell {
                text: written.to_string(),
                name: name.to_string(),
                unit: unit.map(str::to_string),
                range,
            });
        }
        Ok(Header { cells, line, row })
    }

    /// The position of the column named `name` (units aside).
    pub fn named(&self, name: &str) -> Option<usize> {
        self.cells.iter().position(|cell| cell.name == name)
    }

    /// The position of the column a `--column NAME=HEADER` points at: the header as written,
    /// or its name without the unit.
    pub fn matching(&self, header: &str) -> Option<usize> {
        let header = header.trim();
        self.cells
            .iter()
            .position(|cell| cell.text == header)
            .or_else(|| self.named(split_unit(header).0))
    }

    /// The header texts, for listing in a help line.
    fn texts(&self) -> Vec<&str> {
        self.cells.iter().map(|cell| cell.text.as_str()).collect()
    }

    /// Finds the time column, the experiment column and each requested column.
    /// `elsewhere(header)` says whether another file of the set has a column matching
    /// `header`: a mapping of an optional column or of the experiment column may miss in
    /// some files, not in all.
    pub fn layout(
        &self,
        source: &Source,
        request: &Request,
        elsewhere: &dyn Fn(&str) -> bool,
    ) -> Result<Layout, DataError> {
        let mapped = |name: &str| {
            request
                .mapping
                .iter()
                .find(|(mapped, _)| mapped == name)
                .map(|(_, header)| header.as_str())
        };
        let time = match mapped(TIME) {
            Some(header) => self.mapped(source, TIME, header, true, elsewhere)?,
            None => Some(self.time(source)?),
        };
        let experiment = match mapped(EXPERIMENT) {
            Some(header) => self.mapped(source, EXPERIMENT, header, false, elsewhere)?,
            None => self.named(EXPERIMENT),
        };
        let columns = request
            .columns
            .iter()
            .map(|wanted| {
                let required = wanted.role != Role::Optional;
                match mapped(&wanted.name) {
                    Some(header) => self.mapped(source, &wanted.name, header, required, elsewhere),
                    None => match self.named(&wanted.name) {
                        None if required => Err(self.missing(source, &wanted.name)),
                        found => Ok(found),
                    },
                }
            })
            .collect::<Result<_, _>>()?;
        Ok(Layout {
            time: time.unwrap_or_default(),
            experiment,
            columns,
        })
    }

    /// The column of a mapping `name=header`; where the file lacks it, an error if the
    /// column is `required` or no other file has it, else `None`.
    fn mapped(
        &self,
        source: &Source,
        name: &str,
        header: &str,
        required: bool,
        elsewhere: &dyn Fn(&str) -> bool,
    ) -> Result<Option<usize>, DataError> {
        match self.matching(header) {
            Some(position) => Ok(Some(position)),
            None if !required && elsewhere(header) => Ok(None),
            None => Err(DataError::MissingMappedColumn {
                src: source.src.clone(),
                span: span(self.line.clone()),
                name: name.to_string(),
                header: header.to_string(),
                at: source.at(self.row, None),
                help: self.suggest(header),
            }),
        }
    }

    /// A help line for a mapped header that is missing: the closest header (by its text or
    /// its name without unit), then every header.
    fn suggest(&self, header: &str) -> String {
        let texts = self.texts();
        let close = closest(header, texts.iter().copied()).or_else(|| {
            let name = closest(
                split_unit(header).0,
                self.cells.iter().map(|c| c.name.as_str()),
            );
            name.and_then(|name| self.named(name))
                .map(|position| texts[position])
        });
        match close {
            Some(close) => format!(
                "did you mean `{close}`? columns present: {}",
                quoted_list(&texts)
            ),
            None => format!("columns present: {}", quoted_list(&texts)),
        }
    }

    /// The time column when no mapping names it: `t`, else a single `time` (any case).
    fn time(&self, source: &Source) -> Result<usize, DataError> {
        if let Some(position) = self.named(TIME) {
            return Ok(position);
        }
        let candidates: Vec<usize> = (0..self.cells.len())
            .filter(|&position| self.cells[position].name.eq_ignore_ascii_case("time"))
            .collect();
        if let [position] = candidates[..] {
            return Ok(position);
        }
        let texts = self.texts();
        let (found, help) = if candidates.is_empty() {
            let help = match closest(TIME, texts.iter().copied()) {
                Some(close) => format!(
                    "did you mean `{close}`? map it with `--column t={close}`; columns present: {}",
                    quoted_list(&texts)
                ),
                None => format!(
                    "name the time column `t`, or map it with `--column t=HEADER`; columns \
                     present: {}",
                    quoted_list(&texts)
                ),
            };
            ("none".to_string(), help)
        } else {
            let both: Vec<&str> = candidates.iter().map(|&position| texts[position]).collect();
            (
                format!(
                    "{}, each could be time",
                    quoted_list(&both).replace(", ", " and ")
                ),
                format!(
                    "name the time column with `--column t=HEADER`, e.g. `--column t={}`",
                    both[0]
                ),
            )
        };
        Err(DataError::MissingTime {
            src: source.src.clone(),
            span: span(self.line.clone()),
            found,
            at: source.at(self.row, None),
            help,
        })
    }

    /// The error for a required column that the file lacks.
    fn missing(&self, source: &Source, name: &str) -> DataError {
        let texts = self.texts();
        let help = match closest(name, self.cells.iter().map(|cell| cell.name.as_str())) {
            Some(close) => {
                let header = self.named(close).map_or(close, |position| texts[position]);
                format!(
                    "did you mean `{header}`? map it with `--column {name}={header}`; columns \
                     present: {}",
                    quoted_list(&texts)
                )
            }
            None => format!(
                "columns present: {}; map one with `--column {name}=HEADER`",
                quoted_list(&texts)
            ),
        };
        DataError::MissingColumn {
            src: source.src.clone(),
            span: span(self.line.clone()),
            name: name.to_string(),
            at: source.at(self.row, None),
            help,
        }
    }
}

/// Names in backquotes, separated by commas.
fn quoted_list(names: &[&str]) -> String {
    names
        .iter()
        .map(|name| format!("`{name}`"))
        .collect::<Vec<_>>()
        .join(", ")
}
