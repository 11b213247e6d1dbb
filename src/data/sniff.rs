//! The delimiter of a data file: `,`, `;` or tab, decided from the header and the first
//! data rows.
//!
//! Each candidate splits the header into some number of fields (quotes respected). A
//! candidate is *consistent* when the header has at least two fields with it and each of
//! the first [`ROWS_LOOKED_AT`] data rows has as many. The delimiter is the consistent
//! candidate with the most header fields; when none is consistent (a file that mixes
//! delimiters), the candidate with the most header fields; a header of one field is read
//! with `,`. Ties go to tab, then `;`, then `,`: where `;` splits as well as `,` does, the
//! commas are decimal commas or text.

use super::scan::{clean, scan_record, skip_line_breaks};

/// The candidates, in order of preference on a tie.
const CANDIDATES: [u8; 3] = [b'\t', b';', b','];

/// How many data rows after the header take part in the decision.
const ROWS_LOOKED_AT: usize = 5;

/// The delimiter of the file `text` whose content starts at byte `body`.
pub(super) fn sniff(text: &str, body: usize) -> u8 {
    let records = first_records(text, body);
    let Some((header, rows)) = records.split_first() else {
        return b',';
    };
    let mut best: Option<(bool, usize, u8)> = None;
    for delimiter in CANDIDATES {
        let fields = count_fields(text, *header, delimiter);
        let consistent = fields >= 2
            && rows
                .iter()
                .all(|&row| count_fields(text, row, delimiter) == fields);
        let better = best.is_none_or(|(best_consistent, best_fields, _)| {
            (consistent, fields) > (best_consistent, best_fields)
        });
        if better {
            best = Some((consistent, fields, delimiter));
        }
    }
    match best {
        Some((_, fields, delimiter)) if fields >= 2 => delimiter,
        _ => b',',
    }
}

/// How many fields the record starting at `start` has when split by `delimiter`.
pub(super) fn count_fields(text: &str, start: usize, delimiter: u8) -> usize {
    let mut fields = Vec::new();
    scan_record(text, start, delimiter, &mut fields);
    fields.len()
}

/// The start of the header and of the first data rows, blank lines skipped.
fn first_records(text: &str, body: usize) -> Vec<usize> {
    let mut starts = Vec::new();
    let mut fields = Vec::new();
    let mut at = skip_line_breaks(text, body);
    while at < text.len() && starts.len() <= ROWS_LOOKED_AT {
        // Any delimiter finds the same record ends: quotes do not depend on it.
        let end = scan_record(text, at, b',', &mut fields);
        if !clean(&text[at..end]).is_empty() {
            starts.push(at);
        }
        at = skip_line_breaks(text, end);
    }
    starts
}

#[cfg(test)]
mod tests {
    use super::sniff;

    /// Asserts that `text` is read with `delimiter`.
    fn check(text: &str, delimiter: u8) {
        assert_eq!(
            char::from(sniff(text, 0)),
            char::from(delimiter),
            "{text:?}"
        );
    }

    #[test]
    fn picks_the_delimiter_that_splits_header_and_rows_alike() {
        check("t,u,X\n0,1,2\n", b',');
        check("t;u;X\n0;1,5;2\n", b';');
        check("t\tu\tX\n0\t1,5\t2\n", b'\t');
        check("t;X [g/L, dry]\n0;1,5\n", b';');
        check("\"a;b\",c\n0,1\n", b',');
        check("t\n0\n", b',');
        check("", b',');
        check("\n\nt;u\n\n0;1\n", b';');
    }

    #[test]
    fn a_file_mixing_delimiters_keeps_the_header_s() {
        check("t;u;X;a;b;c\n0,1,2,3,4,5\n", b';');
        check("t,u,X\n0;1;2\n", b',');
    }
}
