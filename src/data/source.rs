//! A data file's text: decoding, row numbers, and the spans and locations that let each
//! diagnostic point at a cell (the byte span of every field comes from [`super::scan`]).

use super::error::{ColumnRef, DataError, DataSource, Location};
use super::scan::{clean, scan_record, skip_line_breaks, BOM};
use super::sniff::sniff;
use miette::{NamedSource, SourceSpan};
use std::ops::Range;
use std::path::PathBuf;
use std::sync::Arc;

/// One data file's text, with what is needed to name rows.
#[derive(Debug, Clone)]
pub(super) struct Source {
    /// The file as the user named it (for messages).
    pub file: String,
    /// Where it was read from.
    pub path: PathBuf,
    /// The text, shared by every diagnostic about it.
    pub src: DataSource,
    /// Byte offset where the content starts (after a byte-order mark).
    pub body: usize,
    /// Byte offset of the start of every line.
    line_starts: Vec<usize>,
}

impl Source {
    /// The source of `text`, named `file` in messages and read from `path`.
    pub fn new(file: &str, path: PathBuf, text: String) -> Self {
        let body = if text.starts_with(BOM) { BOM.len() } else { 0 };
        let line_starts = std::iter::once(0)
            .chain(text.match_indices('\n').map(|(at, _)| at + 1))
            .collect();
        Source {
            file: file.to_string(),
            path,
            src: Arc::new(NamedSource::new(file, text)),
            body,
            line_starts,
        }
    }

    /// Decodes `bytes` as UTF-8; a file that is not UTF-8 is an error at its first bad byte.
    pub fn from_bytes(file: &str, path: PathBuf, bytes: Vec<u8>) -> Result<Self, DataError> {
        match String::from_utf8(bytes) {
            Ok(text) => Ok(Source::new(file, path, text)),
            Err(error) => Err(not_text(file, error)),
        }
    }

    /// The whole text.
    pub fn text(&self) -> &str {
        self.src.inner()
    }

    /// The 1-based row (line) holding byte `offset`.
    pub fn row_of(&self, offset: usize) -> usize {
        self.line_starts.partition_point(|&start| start <= offset)
    }

    /// A location in this file.
    pub fn at(&self, row: usize, column: Option<ColumnRef>) -> Box<Location> {
        Box::new(Location {
            file: self.file.clone(),
            row,
            column,
        })
    }
}

/// A span from a byte range.
pub(super) fn span(range: Range<usize>) -> SourceSpan {
    SourceSpan::new(range.start.into(), range.end - range.start)
}

/// A column reference from a 0-based position and its header text.
pub(super) fn column(position: usize, header: &str) -> Option<ColumnRef> {
    Some(ColumnRef {
        index: position + 1,
        name: header.to_string(),
    })
}

/// A delimiter in words, for messages.
pub(super) fn delimiter_name(delimiter: u8) -> &'static str {
    match delimiter {
        b';' => "`;`",
        b'\t' => "tabs",
        _ => "`,`",
    }
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
    let text = String::from_utf8_lossy(bytes).into_owned();
    let source = Source::new(file, PathBuf::from(file), text);
    let delimiter = sniff(source.text(), source.body);
    let index = 1 + bytes[line_start..offset]
        .iter()
        .filter(|&&b| b == delimiter)
        .count();
    let name = if row > 1 {
        header_field(&source, delimiter, index - 1)
    } else {
        String::new()
    };
    DataError::NotText {
        src: source.src.clone(),
        span: SourceSpan::new(offset.into(), '\u{FFFD}'.len_utf8()),
        at: source.at(row, Some(ColumnRef { index, name })),
    }
}

/// The cleaned text of field `index` of the file's first record (for naming columns).
fn header_field(source: &Source, delimiter: u8, index: usize) -> String {
    let text = source.text();
    let mut fields = Vec::new();
    scan_record(
        text,
        skip_line_breaks(text, source.body),
        delimiter,
        &mut fields,
    );
    fields
        .get(index)
        .map(|raw| clean(&text[raw.clone()]).to_string())
        .unwrap_or_default()
}
