//! The strict CSV scanner behind [`read_str`](super::read_str): header, cells, numbers and
//! the time grid, with a byte span for every defect.

use super::error::{ColumnRef, DataError, DataSource, Location};
use super::{Column, Dataset, MinRows};
use crate::suggest::did_you_mean;
use miette::{NamedSource, SourceSpan};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

/// Relative tolerance on the time step: a step is uniform when it differs from the typical
/// step by at most this fraction of it.
pub const STEP_TOLERANCE: f64 = 1e-6;

/// Decodes `bytes` as UTF-8 and reads them as a data file named `file`.
pub(super) fn read_bytes(
    file: &str,
    bytes: Vec<u8>,
    required: &[&str],
    min_rows: &MinRows,
) -> Result<Dataset, DataError> {
    match String::from_utf8(bytes) {
        Ok(text) => Scanner::new(file, text).dataset(required, min_rows),
        Err(error) => Err(not_text(file, error)),
    }
}

/// Reads `text` as a data file named `file`.
pub(super) fn read_text(
    file: &str,
    text: String,
    required: &[&str],
    min_rows: &MinRows,
) -> Result<Dataset, DataError> {
    Scanner::new(file, text).dataset(required, min_rows)
}

/// The error for a file that is not UTF-8, pointing at its first invalid byte.
fn not_text(file: &str, error: std::string::FromUtf8Error) -> DataError {
    let offset = error.utf8_error().valid_up_to();
    let bytes = error.as_bytes();
    let line_start = bytes[..offset]
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |p| p + 1);
    let row = 1 + bytes[..offset].iter().filter(|&&b| b == b'\n').count();
    let index = 1 + bytes[line_start..offset]
        .iter()
        .filter(|&&b| b == b',')
        .count();
    let text = String::from_utf8_lossy(bytes).into_owned();
    let name = first_line_cells(&text)
        .nth(index - 1)
        .filter(|_| row > 1)
        .unwrap_or_default();
    DataError::NotText {
        src: Arc::new(NamedSource::new(file, text)),
        span: SourceSpan::new(offset.into(), '\u{FFFD}'.len_utf8()),
        at: Box::new(Location {
            file: file.to_string(),
            row,
            column: Some(ColumnRef { index, name }),
        }),
    }
}

/// The cells of the first line of `text`, cleaned (for naming columns in messages).
fn first_line_cells(text: &str) -> impl Iterator<Item = String> + '_ {
    let line = text.lines().next().unwrap_or_default();
    line.split(',').map(|cell| clean(cell).to_string())
}

/// A cell's text without surrounding whitespace, a UTF-8 BOM or double quotes.
fn clean(cell: &str) -> &str {
    let trimmed = cell.trim().trim_start_matches('\u{FEFF}').trim();
    trimmed
        .strip_prefix('"')
        .and_then(|rest| rest.strip_suffix('"'))
        .map_or(trimmed, str::trim)
}

/// One line of the file.
#[derive(Debug, Clone, Copy)]
struct Line<'a> {
    /// 1-based row number.
    row: usize,
    /// Byte offset of its first character.
    start: usize,
    /// Its text, without the line ending.
    text: &'a str,
}

/// A cell of a line.
#[derive(Debug, Clone, Copy)]
struct Cell<'a> {
    /// Byte range of the cleaned text in the file.
    span: (usize, usize),
    /// The cleaned text.
    text: &'a str,
}

impl Cell<'_> {
    fn span(&self) -> SourceSpan {
        SourceSpan::new(self.span.0.into(), self.span.1 - self.span.0)
    }
}

/// Splits a line into cleaned cells, writing them into `cells`.
fn split_cells<'a>(line: Line<'a>, cells: &mut Vec<Cell<'a>>) {
    cells.clear();
    let mut offset = line.start;
    for raw in line.text.split(',') {
        let text = clean(raw);
        let inner = if text.is_empty() {
            offset + raw.len() - raw.trim_start().len()
        } else {
            offset + (text.as_ptr() as usize - raw.as_ptr() as usize)
        };
        cells.push(Cell {
            span: (inner, inner + text.len()),
            text,
        });
        offset += raw.len() + 1;
    }
}

/// A column the reader parses: `t` or a required one.
#[derive(Debug, Clone)]
struct Wanted {
    /// 0-based position in the row.
    position: usize,
    /// Where its values go: `None` for the time column, else the index in `columns`.
    slot: Option<usize>,
}

/// Reads one file's text.
struct Scanner {
    file: String,
    src: DataSource,
}

/// The parsed header.
struct Header {
    /// Every column's name.
    names: Vec<String>,
    /// 0-based position of `t`.
    time: usize,
    /// 0-based positions of the required columns, in the order asked for.
    required: Vec<usize>,
}

impl Header {
    /// The columns to parse, `t` included, in the order they appear in a row.
    fn wanted(&self) -> Vec<Wanted> {
        let time = Wanted {
            position: self.time,
            slot: None,
        };
        let required = self
            .required
            .iter()
            .enumerate()
            .map(|(slot, &position)| Wanted {
                position,
                slot: Some(slot),
            });
        let mut wanted: Vec<Wanted> = std::iter::once(time).chain(required).collect();
        wanted.sort_by_key(|column| column.position);
        wanted
    }
}

/// The parsed values of the data rows.
struct Samples {
    /// The time column.
    times: Vec<f64>,
    /// Where each time cell lies.
    time_spans: Vec<SourceSpan>,
    /// The required columns, in the order asked for.
    columns: Vec<Vec<f64>>,
}

impl Scanner {
    fn new(file: &str, text: String) -> Self {
        Scanner {
            file: file.to_string(),
            src: Arc::new(NamedSource::new(file, text)),
        }
    }

    fn text(&self) -> &str {
        self.src.inner()
    }

    fn at(&self, row: usize, column: Option<(usize, &str)>) -> Box<Location> {
        Box::new(Location {
            file: self.file.clone(),
            row,
            column: column.map(|(position, name)| ColumnRef {
                index: position + 1,
                name: name.to_string(),
            }),
        })
    }

    /// The non-blank part of the file as lines: trailing blank lines are dropped.
    fn lines(&self) -> Vec<Line<'_>> {
        let text = self.text();
        let body_start = if text.starts_with('\u{FEFF}') { 3 } else { 0 };
        let mut lines = Vec::new();
        let mut start = body_start;
        for (row, raw) in text[body_start..].split('\n').enumerate() {
            let content = raw.strip_suffix('\r').unwrap_or(raw);
            lines.push(Line {
                row: row + 1,
                start,
                text: content,
            });
            start += raw.len() + 1;
        }
        while lines.last().is_some_and(|line| line.text.trim().is_empty()) {
            lines.pop();
        }
        lines
    }

    fn dataset(&self, required: &[&str], min_rows: &MinRows) -> Result<Dataset, DataError> {
        let lines = self.lines();
        let Some((&header_line, rows)) = lines.split_first() else {
            return Err(DataError::Empty {
                src: self.src.clone(),
                span: SourceSpan::new(0.into(), 0),
                at: self.at(1, None),
            });
        };
        let header = self.header(header_line, required)?;
        if rows.is_empty() {
            return Err(DataError::NoRows {
                src: self.src.clone(),
                span: line_span(header_line),
                at: self.at(1, None),
            });
        }
        let samples = self.rows(&header, rows)?;
        let step = self.uniform_step(&samples.times, &samples.time_spans, &header)?;
        self.enough_rows(&samples.times, rows, min_rows)?;
        Ok(Dataset {
            path: PathBuf::from(&self.file),
            times: samples.times,
            step,
            columns: required
                .iter()
                .zip(samples.columns)
                .map(|(name, values)| Column {
                    name: name.to_string(),
                    values,
                })
                .collect(),
        })
    }

    /// Checks the header's names and finds `t` and the required columns.
    fn header(&self, line: Line<'_>, required: &[&str]) -> Result<Header, DataError> {
        let mut cells = Vec::new();
        split_cells(line, &mut cells);
        let mut seen: HashMap<&str, usize> = HashMap::new();
        for (position, cell) in cells.iter().enumerate() {
            if cell.text.is_empty() {
                return Err(DataError::UnnamedColumn {
                    src: self.src.clone(),
                    span: cell.span(),
                    at: self.at(1, Some((position, ""))),
                });
            }
            if let Some(&first) = seen.get(cell.text) {
                return Err(DataError::DuplicateColumn {
                    src: self.src.clone(),
                    span: cell.span(),
                    first_span: cells[first].span(),
                    name: cell.text.to_string(),
                    first_index: first + 1,
                    at: self.at(1, Some((position, cell.text))),
                });
            }
            seen.insert(cell.text, position);
        }
        let names: Vec<&str> = cells.iter().map(|cell| cell.text).collect();
        let time = seen
            .get("t")
            .copied()
            .ok_or_else(|| self.missing_time(line, &names))?;
        let required = required
            .iter()
            .map(|name| {
                seen.get(name)
                    .copied()
                    .ok_or_else(|| DataError::MissingColumn {
                        src: self.src.clone(),
                        span: line_span(line),
                        name: name.to_string(),
                        at: self.at(1, None),
                        help: did_you_mean(name, &names, "columns present"),
                    })
            })
            .collect::<Result<_, _>>()?;
        Ok(Header {
            names: names.iter().map(|name| name.to_string()).collect(),
            time,
            required,
        })
    }

    fn missing_time(&self, line: Line<'_>, names: &[&str]) -> DataError {
        let time_like = names
            .iter()
            .find(|name| ["time", "t_s", "t_h", "times"].contains(&name.to_lowercase().as_str()));
        let help = match time_like {
            Some(name) => {
                format!("rename column `{name}` to `t`: the time column must be named `t`")
            }
            None => did_you_mean(
                "t",
                names,
                "the time column must be named `t`; columns present",
            ),
        };
        DataError::MissingTime {
            src: self.src.clone(),
            span: line_span(line),
            at: self.at(1, None),
            help,
        }
    }

    /// Parses every data row: cell count, numbers, and time increasing.
    fn rows(&self, header: &Header, rows: &[Line<'_>]) -> Result<Samples, DataError> {
        let wanted = header.wanted();
        let mut samples = Samples {
            times: Vec::with_capacity(rows.len()),
            time_spans: Vec::with_capacity(rows.len()),
            columns: vec![Vec::with_capacity(rows.len()); header.required.len()],
        };
        let mut cells = Vec::with_capacity(header.names.len());
        for &line in rows {
            self.row_shape(line, header, &mut cells)?;
            for column in &wanted {
                let cell = cells[column.position];
                let value = self.number(line.row, cell, column.position, header)?;
                match column.slot {
                    Some(slot) => samples.columns[slot].push(value),
                    None => {
                        let previous = samples.times.last().copied();
                        self.time_increases(previous, value, line.row, cell, header)?;
                        samples.times.push(value);
                        samples.time_spans.push(cell.span());
                    }
                }
            }
        }
        Ok(samples)
    }

    /// Splits a row and checks it has one cell per header column.
    fn row_shape<'a>(
        &self,
        line: Line<'a>,
        header: &Header,
        cells: &mut Vec<Cell<'a>>,
    ) -> Result<(), DataError> {
        let expected = header.names.len();
        if line.text.trim().is_empty() {
            return Err(self.ragged(
                line,
                line_span(line),
                expected,
                0,
                Some((0, &header.names[0])),
            ));
        }
        split_cells(line, cells);
        let found = cells.len();
        if found > expected {
            let surplus = cells[expected].span.0;
            let end = line.start + line.text.len();
            let span = SourceSpan::new(surplus.into(), end - surplus);
            return Err(self.ragged(line, span, expected, found, Some((expected, ""))));
        }
        if found < expected {
            let end = line.start + line.text.len();
            let column = Some((found, header.names[found].as_str()));
            return Err(self.ragged(
                line,
                SourceSpan::new(end.into(), 0),
                expected,
                found,
                column,
            ));
        }
        Ok(())
    }

    fn ragged(
        &self,
        line: Line<'_>,
        span: SourceSpan,
        expected: usize,
        found: usize,
        column: Option<(usize, &str)>,
    ) -> DataError {
        DataError::RaggedRow {
            src: self.src.clone(),
            span,
            expected,
            found,
            at: self.at(line.row, column),
        }
    }

    /// Parses a cell as a finite number.
    fn number(
        &self,
        row: usize,
        cell: Cell<'_>,
        position: usize,
        header: &Header,
    ) -> Result<f64, DataError> {
        let at = || self.at(row, Some((position, &header.names[position])));
        if cell.text.is_empty() {
            return Err(DataError::EmptyCell {
                src: self.src.clone(),
                span: cell.span(),
                at: at(),
            });
        }
        match cell.text.parse::<f64>() {
            Ok(value) if value.is_finite() => Ok(value),
            Ok(_) => Err(DataError::NotFinite {
                src: self.src.clone(),
                span: cell.span(),
                found: cell.text.to_string(),
                at: at(),
            }),
            Err(_) => Err(DataError::NotANumber {
                src: self.src.clone(),
                span: cell.span(),
                found: shorten(cell.text),
                at: at(),
            }),
        }
    }

    /// Checks that time strictly increases from the row above.
    fn time_increases(
        &self,
        previous: Option<f64>,
        time: f64,
        row: usize,
        cell: Cell<'_>,
        header: &Header,
    ) -> Result<(), DataError> {
        let Some(previous) = previous else {
            return Ok(());
        };
        let at = || self.at(row, Some((header.time, "t")));
        if time < previous {
            return Err(DataError::UnsortedTime {
                src: self.src.clone(),
                span: cell.span(),
                previous,
                found: time,
                at: at(),
            });
        }
        if time == previous {
            return Err(DataError::RepeatedTime {
                src: self.src.clone(),
                span: cell.span(),
                time,
                at: at(),
            });
        }
        Ok(())
    }

    /// Checks that the time step is uniform and returns it (the mean step, which is the
    /// most accurate estimate once every step agrees).
    fn uniform_step(
        &self,
        times: &[f64],
        spans: &[SourceSpan],
        header: &Header,
    ) -> Result<f64, DataError> {
        let steps: Vec<f64> = times.windows(2).map(|pair| pair[1] - pair[0]).collect();
        let Some(typical) = median(&steps) else {
            return Ok(0.0);
        };
        let magnitude = times
            .iter()
            .fold(0.0_f64, |largest, t| largest.max(t.abs()));
        let tolerance = STEP_TOLERANCE * typical + 8.0 * f64::EPSILON * magnitude;
        for (index, &step) in steps.iter().enumerate() {
            if (step - typical).abs() > tolerance {
                return Err(DataError::UnevenStep {
                    src: self.src.clone(),
                    span: spans[index + 1],
                    expected: typical,
                    found: step,
                    previous: times[index],
                    at: self.at(index + 3, Some((header.time, "t"))),
                });
            }
        }
        Ok((times[times.len() - 1] - times[0]) / steps.len() as f64)
    }

    /// Checks the number of data rows against the model's need (and the two rows a step
    /// needs).
    fn enough_rows(
        &self,
        times: &[f64],
        rows: &[Line<'_>],
        min_rows: &MinRows,
    ) -> Result<(), DataError> {
        let (needed, reason) = if min_rows.rows >= 2 {
            (min_rows.rows, min_rows.reason.clone())
        } else {
            (
                2,
                "two rows are needed to define the sampling step".to_string(),
            )
        };
        if times.len() >= needed {
            return Ok(());
        }
        let last = rows[rows.len() - 1];
        Err(DataError::TooFewRows {
            src: self.src.clone(),
            span: line_span(last),
            needed,
            found: times.len(),
            reason,
            at: self.at(last.row, None),
        })
    }
}

/// The span of a whole line.
fn line_span(line: Line<'_>) -> SourceSpan {
    SourceSpan::new(line.start.into(), line.text.len())
}

/// The median of `values` (the upper one of an even count), if any.
fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    let middle = sorted.len() / 2;
    let (_, value, _) = sorted.select_nth_unstable_by(middle, f64::total_cmp);
    Some(*value)
}

/// A cell's text cut to a readable length for messages.
fn shorten(text: &str) -> String {
    const LIMIT: usize = 40;
    match text.char_indices().nth(LIMIT) {
        Some((cut, _)) => format!("{}...", &text[..cut]),
        None => text.to_string(),
    }
}
