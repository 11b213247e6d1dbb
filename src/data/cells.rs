//! The value of one cell: a finite number, or not measured.

use std::borrow::Cow;

/// What a cell holds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Cell {
    /// A finite number.
    Number(f64),
    /// Not measured: empty, `NA`, `N/A` or `NaN` (any case).
    Missing,
    /// A number too large for a 64-bit float, or infinity.
    NotFinite,
    /// Text that is not a number.
    NotANumber,
}

/// Whether `text` (cleaned) is a spelling of "not measured": empty, `NA`, `N/A` or `NaN`,
/// in any case.
pub(super) fn is_missing(text: &str) -> bool {
    text.is_empty()
        || ["na", "n/a", "nan"]
            .iter()
            .any(|spelling| text.eq_ignore_ascii_case(spelling))
}

/// Reads the cleaned text of a cell. With `decimal_comma` (files separated by `;` or tabs),
/// a comma in a number without a `.` is its decimal point: `1,5` is 1.5.
pub(super) fn parse(text: &str, decimal_comma: bool) -> Cell {
    if is_missing(text) {
        return Cell::Missing;
    }
    let number: Cow<str> = if decimal_comma && text.contains(',') && !text.contains('.') {
        Cow::Owned(text.replacen(',', ".", 1))
    } else {
        Cow::Borrowed(text)
    };
    match number.parse::<f64>() {
        Ok(value) if value.is_finite() => Cell::Number(value),
        // `+nan` and `-nan` parse, and mean NaN as much as `nan` does.
        Ok(value) if value.is_nan() => Cell::Missing,
        Ok(_) => Cell::NotFinite,
        Err(_) => Cell::NotANumber,
    }
}

#[cfg(test)]
mod tests {
    use super::{parse, Cell};

    /// Asserts that `text` reads as `expected`, with and without decimal commas as given.
    fn check(text: &str, decimal_comma: bool, expected: Cell) {
        assert_eq!(parse(text, decimal_comma), expected, "{text:?}");
    }

    #[test]
    fn numbers() {
        check("20", false, Cell::Number(20.0));
        check("-0.5", false, Cell::Number(-0.5));
        check("1.5e-2", false, Cell::Number(0.015));
        check("+3", false, Cell::Number(3.0));
        check("1,5", true, Cell::Number(1.5));
        check("-1,5e3", true, Cell::Number(-1500.0));
    }

    #[test]
    fn every_spelling_of_not_measured() {
        for text in [
            "", "NA", "na", "N/A", "n/a", "NaN", "nan", "NAN", "-nan", "+NaN",
        ] {
            check(text, false, Cell::Missing);
            check(text, true, Cell::Missing);
        }
    }

    #[test]
    fn infinities_and_overflow() {
        for text in ["inf", "-inf", "Infinity", "-INFINITY", "1e999", "-1e400"] {
            check(text, false, Cell::NotFinite);
        }
    }

    #[test]
    fn text_and_misplaced_commas() {
        for text in ["abc", "1.2.3", "1,5", "x1", "1 000", "--1"] {
            check(text, false, Cell::NotANumber);
        }
        check("1.000,5", true, Cell::NotANumber);
        check("1,000,5", true, Cell::NotANumber);
    }
}
