//! The byte span of every field of a data file's record.
//!
//! The `csv` crate reads the values; this module finds where they lie. Its scanner follows
//! the same grammar as `csv_core` with double-quote quoting: a field that starts with `"`
//! runs to the next lone `"` (a doubled `""` is a quote inside it), a record ends at an
//! unquoted `\r` or `\n`.

use std::ops::Range;

/// The byte-order mark some editors put at the start of a UTF-8 file.
pub(super) const BOM: &str = "\u{FEFF}";

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
