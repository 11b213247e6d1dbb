//! One data file: its delimiter and header, then its rows, grouped into experiments.

use super::cells::{self, Cell};
use super::error::{ColumnRef, DataError, Location};
use super::experiment::{Experiment, Origin, Series};
use super::header::{Header, Layout};
use super::request::Request;
use super::scan::{blank_line_between, clean, clean_range, scan_record, skip_line_breaks};
use super::sniff::{count_fields, sniff};
use super::source::{column, delimiter_name, span, Source};
use std::collections::HashMap;
use std::ops::Range;

/// The delimiters a file may use.
const DELIMITERS: [u8; 3] = [b',', b';', b'\t'];

/// A file whose delimiter and header are known.
#[derive(Debug)]
pub(super) struct Opened {
    /// Its text.
    pub source: Source,
    /// Its delimiter.
    pub delimiter: u8,
    /// Its header.
    pub header: Header,
}

/// Decides the delimiter and parses the header: the first record that is not blank.
pub(super) fn open(source: Source) -> Result<Opened, DataError> {
    let text = source.text();
    let delimiter = sniff(text, source.body);
    let mut fields = Vec::new();
    let mut start = skip_line_breaks(text, source.body);
    while start < text.len() {
        let end = scan_record(text, start, delimiter, &mut fields);
        if !clean(&text[start..end]).is_empty() {
            let header = Header::parse(&source, &fields, start..end)?;
            return Ok(Opened {
                source,
                delimiter,
                header,
            });
        }
        start = skip_line_breaks(text, end);
    }
    Err(DataError::Empty {
        src: source.src.clone(),
        span: span(0..0),
        at: source.at(1, None),
    })
}

/// An experiment being read.
struct Building {
    name: String,
    times: Vec<f64>,
    rows: Vec<usize>,
    starts: Vec<usize>,
    /// One list per present requested column, in `Reader::present` order.
    values: Vec<Vec<Option<f64>>>,
}

/// Reads the rows of one opened file.
struct Reader<'a> {
    opened: &'a Opened,
    layout: &'a Layout,
    /// The requested columns the file has: (index in the request, 0-based position).
    present: Vec<(usize, usize)>,
    /// Raw field ranges of the current record.
    fields: Vec<Range<usize>>,
    /// Its row.
    row: usize,
}

/// Reads the data rows of `opened`, whose columns `layout` locates, into experiments.
pub(super) fn read_rows(
    opened: &Opened,
    layout: &Layout,
    request: &Request,
) -> Result<Vec<Experiment>, DataError> {
    let source = &opened.source;
    let text = source.text();
    let body = &text.as_bytes()[source.body..];
    let mut csv = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .delimiter(opened.delimiter)
        .trim(csv::Trim::None)
        .from_reader(body);
    let present = (layout.columns.iter().enumerate())
        .filter_map(|(wanted, position)| position.map(|position| (wanted, position)))
        .collect();
    let mut reader = Reader {
        opened,
        layout,
        present,
        fields: Vec::new(),
        row: 0,
    };
    let mut building: Vec<Building> = Vec::new();
    let mut by_name: HashMap<String, usize> = HashMap::new();
    let mut record = csv::StringRecord::new();
    let mut previous_end = opened.header.line.end;
    while csv
        .read_record(&mut record)
        .map_err(|error| unreadable(source, &error))?
    {
        let offset = record.position().map_or(0, |p| p.byte() as usize);
        let start = skip_line_breaks(text, source.body + offset);
        let blank = record.len() == 1 && clean(&record[0]).is_empty();
        if start <= opened.header.line.start || blank {
            continue;
        }
        let end = scan_record(text, start, opened.delimiter, &mut reader.fields);
        reader.row = source.row_of(start);
        if let Some(blank) = blank_line_between(text, previous_end, start) {
            return Err(reader.blank_line(blank));
        }
        previous_end = end;
        reader.shape(&record, start..end)?;
        let name = reader.experiment(&record)?;
        let index = *by_name.entry(name.clone()).or_insert_with(|| {
            building.push(Building {
                name,
                times: Vec::new(),
                rows: Vec::new(),
                starts: Vec::new(),
                values: vec![Vec::new(); reader.present.len()],
            });
            building.len() - 1
        });
        let experiment = &mut building[index];
        experiment.times.push(reader.time(&record)?);
        experiment.rows.push(reader.row);
        experiment.starts.push(start);
        for (slot, &(_, position)) in reader.present.iter().enumerate() {
            experiment.values[slot].push(reader.value(&record, position)?);
        }
    }
    if building.is_empty() {
        return Err(DataError::NoRows {
            src: source.src.clone(),
            span: span(opened.header.line.clone()),
            at: source.at(opened.header.row, None),
        });
    }
    Ok(building
        .into_iter()
        .map(|experiment| reader.finish(experiment, request))
        .collect())
}

/// A failure of the `csv` crate on text that is already in memory and valid UTF-8 (it
/// cannot happen; reported rather than hidden).
fn unreadable(source: &Source, error: &csv::Error) -> DataError {
    DataError::Unreadable {
        file: source.file.clone(),
        reason: error.to_string(),
    }
}

impl Reader<'_> {
    fn source(&self) -> &Source {
        &self.opened.source
    }

    /// The header text of the column at 0-based `position` ("" past the header).
    fn header_text(&self, position: usize) -> &str {
        self.opened
            .header
            .cells
            .get(position)
            .map_or("", |cell| cell.text.as_str())
    }

    /// The span of the cleaned cell at `position` of the current record.
    fn cell_span(&self, position: usize) -> miette::SourceSpan {
        let text = self.source().text();
        match self.fields.get(position) {
            Some(raw) => span(clean_range(text, raw.clone())),
            None => span(0..0),
        }
    }

    /// The error for a blank line starting at byte `start` inside the data.
    fn blank_line(&self, start: usize) -> DataError {
        let source = self.source();
        let text = source.text();
        let length = text[start..]
            .find(['\n', '\r'])
            .unwrap_or(text.len() - start);
        DataError::RaggedRow {
            src: source.src.clone(),
            span: span(start..start + length),
            expected: self.opened.header.cells.len(),
            found: 0,
            at: source.at(source.row_of(start), column(0, self.header_text(0))),
            help: "remove the blank line: every row inside the data is one sample".to_string(),
        }
    }

    /// Checks that the record at `line` has one cell per header column.
    fn shape(&self, record: &csv::StringRecord, line: Range<usize>) -> Result<(), DataError> {
        let expected = self.opened.header.cells.len();
        let found = record.len();
        if found == expected {
            return Ok(());
        }
        let source = self.source();
        let delimiter = self.opened.delimiter;
        let other = DELIMITERS.into_iter().find(|&other| {
            other != delimiter
                && expected >= 2
                && count_fields(source.text(), line.start, other) == expected
        });
        if let Some(other) = other {
            return Err(DataError::MixedDelimiters {
                src: source.src.clone(),
                span: span(line),
                expected,
                found,
                delimiter: delimiter_name(delimiter),
                other: delimiter_name(other),
                at: source.at(self.row, None),
            });
        }
        let (span, position) = if found > expected {
            let surplus = self.cell_span(expected).offset();
            (span(surplus.max(line.start)..line.end), expected)
        } else {
            (span(line.end..line.end), found)
        };
        Err(DataError::RaggedRow {
            src: source.src.clone(),
            span,
            expected,
            found,
            at: source.at(self.row, column(position, self.header_text(position))),
            help: format!(
                "every row needs one cell per header column, separated by {}",
                delimiter_name(delimiter)
            ),
        })
    }

    /// The experiment of the current record: its value in the experiment column, or the
    /// file's stem.
    fn experiment(&self, record: &csv::StringRecord) -> Result<String, DataError> {
        let Some(position) = self.layout.experiment else {
            return Ok(stem(self.source()));
        };
        let name = clean(record.get(position).unwrap_or_default());
        if !name.is_empty() {
            return Ok(name.to_string());
        }
        Err(DataError::EmptyCell {
            src: self.source().src.clone(),
            span: self.cell_span(position),
            expected: "an experiment name",
            found: "an empty cell".to_string(),
            at: self.at(position),
            help: "give every row its experiment, or remove the row".to_string(),
        })
    }

    /// The time of the current record.
    fn time(&self, record: &csv::StringRecord) -> Result<f64, DataError> {
        let position = self.layout.time;
        if let Some(time) = self.value(record, position)? {
            return Ok(time);
        }
        let written = clean(record.get(position).unwrap_or_default());
        Err(DataError::EmptyCell {
            src: self.source().src.clone(),
            span: self.cell_span(position),
            expected: "a time",
            found: if written.is_empty() {
                "an empty cell".to_string()
            } else {
                format!("`{written}`")
            },
            at: self.at(position),
            help: "every row needs its time: fill it in, or remove the row".to_string(),
        })
    }

    /// The value of the cell at `position` of the current record.
    fn value(&self, record: &csv::StringRecord, position: usize) -> Result<Option<f64>, DataError> {
        let written = clean(record.get(position).unwrap_or_default());
        let src = || self.source().src.clone();
        match cells::parse(written, self.opened.delimiter != b',') {
            Cell::Number(value) => Ok(Some(value)),
            Cell::Missing => Ok(None),
            Cell::NotFinite => Err(DataError::NotFinite {
                src: src(),
                span: self.cell_span(position),
                found: shorten(written),
                at: self.at(position),
                help: "replace the value, or leave the cell empty (or write `NA`) where nothing \
                       was measured: infinity cannot be fitted"
                    .to_string(),
            }),
            Cell::NotANumber => Err(DataError::NotANumber {
                src: src(),
                span: self.cell_span(position),
                found: shorten(written),
                at: self.at(position),
            }),
        }
    }

    /// A location at the current row, in the column at `position`.
    fn at(&self, position: usize) -> Box<Location> {
        self.source()
            .at(self.row, column(position, self.header_text(position)))
    }

    /// The experiment read, with its requested columns in request order.
    fn finish(&self, building: Building, request: &Request) -> Experiment {
        let header = &self.opened.header;
        let columns = self
            .present
            .iter()
            .zip(building.values)
            .map(|(&(wanted, position), values)| Series {
                name: request.columns[wanted].name.clone(),
                header: header.cells[position].text.clone(),
                unit: header.cells[position].unit.clone(),
                index: position + 1,
                values,
            })
            .collect();
        let reference = |position: usize| ColumnRef {
            index: position + 1,
            name: header.cells[position].text.clone(),
        };
        Experiment {
            name: building.name,
            file: self.source().path.clone(),
            times: building.times,
            rows: building.rows,
            columns,
            #[cfg(test)]
            time_unit: header.cells[self.layout.time].unit.clone(),
            origin: Origin {
                file: self.source().file.clone(),
                source: self.source().src.clone(),
                delimiter: self.opened.delimiter,
                starts: building.starts,
                time: reference(self.layout.time),
                experiment: self.layout.experiment.map(reference),
            },
        }
    }
}

/// The name of a file's only experiment: its stem.
pub(super) fn stem(source: &Source) -> String {
    source.path.file_stem().map_or_else(
        || source.file.clone(),
        |stem| stem.to_string_lossy().into_owned(),
    )
}

/// A cell's text cut to a readable length for messages.
fn shorten(text: &str) -> String {
    const LIMIT: usize = 40;
    match text.char_indices().nth(LIMIT) {
        Some((cut, _)) => format!("{}...", &text[..cut]),
        None => text.to_string(),
    }
}
