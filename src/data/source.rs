//! A data file's text: decoding, row numbers, and the byte span of every field of a
//! record, so that each diagnostic can point at a cell.
//!
//! The `csv` crate reads the values; this module finds where they lie. Its scanner follows
//! the same grammar as `csv_core` with double-quote quoting: a field that starts with `"`
//! runs to the next lone `"` (a doubled `""` is a quote inside it), a record ends at an
//! unquoted `\r` or `\n`.

use super::error::{ColumnRef, DataError, DataSource, Location};
use miette::{NamedSource, SourceSpan};
use std::ops::Range;
use std::path::PathBuf;
use std::sync::Arc;

/// The byte-order mark some editors put at the start of a UTF-8 file.
const BOM: &str = "\u{FEFF}";

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

/// The raw byte range of each field of the record starting at byte `start`, written into
/// `fields`; returns where the record's content ends (its line break, or the end of text).
pub(super) fn scan_record(
    text: &str,
    start: usize,
    delimiter: u8,
    fields: &mut Vec<Range<usize>>,
) -> usize {
    fields.clear();
    let bytes = text.as_bytes();
    let mut at = start;
    let mut field_start = start;
    let mut quoted = bytes.get(at) == Some(&b'"');
    if quoted {
        at += 1;
    }
    while at < bytes.len() {
        let byte = bytes[at];
        if quoted {
            if byte == b'"' {
                if bytes.get(at + 1) == Some(&b'"') {
                    at += 1;
                } else {
                    quoted = false;
                }
            }
        } else if byte == delimiter {
            fields.push(field_start..at);
            field_start = at + 1;
            quoted = bytes.get(at + 1) == Some(&b'"');
            if quoted {
                at += 1;
            }
        } else if byte == b'\n' || byte == b'\r' {
            break;
        }
        at += 1;
    }
    let end = at.min(bytes.len());
    fields.push(field_start..end);
    end
}

/// The start of the next record at or after `at`: line breaks skipped.
pub(super) fn skip_line_breaks(text: &str, at: usize) -> usize {
    let rest = &text.as_bytes()[at.min(text.len())..];
    at + rest
        .iter()
        .take_while(|&&byte| byte == b'\n' || byte == b'\r')
        .count()
}

/// Where the first blank line between a record ending at `end` and the next one starting
/// at `next` begins, if any lies between them (one line break is the record's own).
pub(super) fn blank_line_between(text: &str, end: usize, next: usize) -> Option<usize> {
    let gap = text.get(end..next)?;
    let own = if gap.starts_with("\r\n") {
        2
    } else {
        usize::from(!gap.is_empty())
    };
    (gap.len() > own).then_some(end + own)
}

/// The byte range of a field's cleaned text (see [`clean`]) within its raw range.
pub(super) fn clean_range(text: &str, raw: Range<usize>) -> Range<usize> {
    let Some(field) = text.get(raw.clone()) else {
        return raw;
    };
    let cleaned = clean(field);
    if cleaned.is_empty() {
        let leading = field.len() - field.trim_start().len();
        return raw.start + leading..raw.start + leading;
    }
    let offset = cleaned.as_ptr() as usize - field.as_ptr() as usize;
    raw.start + offset..raw.start + offset + cleaned.len()
}

/// A field's text without surrounding whitespace, a byte-order mark or double quotes.
pub(super) fn clean(field: &str) -> &str {
    let trimmed = field.trim().trim_start_matches(BOM).trim();
    trimmed
        .strip_prefix('"')
        .and_then(|rest| rest.strip_suffix('"'))
        .map_or(trimmed, str::trim)
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
    let delimiter = super::sniff::sniff(source.text(), source.body);
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
