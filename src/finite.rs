//! The rule that gbc writes no NaN or infinite number as a result: every weight, param and
//! predicted value is checked before it is written, and a value that is not finite stops
//! the write with [`IoError::NotFinite`] (E0253) saying which value and where.
//!
//! Metrics are another matter: a validation error of a free run that diverged is infinite
//! by definition and is written by name (`"inf"`, see [`crate::json`]), with the
//! divergence beside it. What this module guards is a number presented as a result.

use std::path::Path;

use crate::io::IoError;
use crate::numeric::NamedTensor;

/// The first value of `values` that is not finite: its index and the value.
pub fn first_non_finite(values: &[f64]) -> Option<(usize, f64)> {
    (values.iter().copied().enumerate()).find(|(_, value)| !value.is_finite())
}

/// The first value of named tensors that is not finite, in words:
/// "`closure.r.layer0.weight`[12] = NaN" (the params tensor by param name where `params`
/// names them).
pub fn in_tensors(tensors: &[NamedTensor], params: &[String]) -> Option<String> {
    tensors.iter().find_map(|tensor| {
        let (index, value) = first_non_finite(&tensor.values)?;
        Some(
            match params
                .get(index)
                .filter(|_| tensor.name == crate::vocabulary::PARAMS_TENSOR)
            {
                Some(param) => format!("param `{param}` = {value}"),
                None => format!("weight `{}`[{index}] = {value}", tensor.name),
            },
        )
    })
}

/// The first named value that is not finite, in words: "`kcat` = NaN".
pub fn in_named<'a>(values: impl IntoIterator<Item = (&'a str, f64)>) -> Option<String> {
    (values.into_iter())
        .find(|(_, value)| !value.is_finite())
        .map(|(name, value)| format!("`{name}` = {value}"))
}

/// The earliest row of a table holding a value that is not finite, in words:
/// "`S` = NaN at t = 3.5 (row 12)". `columns` pair each name with its values; the time
/// column `t`, when named so, gives the time.
pub fn in_table<'c>(columns: &[(&'c str, &'c [f64])]) -> Option<String> {
    let rows = columns.first().map_or(0, |(_, values)| values.len());
    let times = (columns.iter()).find_map(|(name, values)| (*name == "t").then_some(*values));
    (0..rows).find_map(|row| {
        let (name, values) = columns
            .iter()
            .find(|(_, values)| values.get(row).is_some_and(|v| !v.is_finite()))?;
        let at = match times.and_then(|t| t.get(row)).filter(|t| t.is_finite()) {
            Some(time) => format!(" at t = {time} (row {})", row + 1),
            None => format!(" in row {}", row + 1),
        };
        Some(format!("`{name}` = {}{at}", values[row]))
    })
}

/// `Ok` when `found` is `None`; else [`IoError::NotFinite`] for `path` with `help`.
pub fn refuse(path: &Path, found: Option<String>, help: &str) -> Result<(), IoError> {
    match found {
        None => Ok(()),
        Some(what) => Err(IoError::NotFinite {
            path: path.display().to_string(),
            what,
            help: help.to_string(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_non_finite_value_is_named_with_where_it_sits() {
        assert_eq!(first_non_finite(&[1.0, 2.0]), None);
        let found = first_non_finite(&[1.0, f64::INFINITY, f64::NAN]);
        assert_eq!(found.map(|(i, _)| i), Some(1));
        let tensors = [
            NamedTensor {
                name: "closure.r.layer0.weight".into(),
                shape: vec![2],
                values: vec![0.5, 1.0],
            },
            NamedTensor {
                name: "params".into(),
                shape: vec![2],
                values: vec![0.1, f64::NAN],
            },
        ];
        let params = ["a".to_string(), "kcat".to_string()];
        assert_eq!(
            in_tensors(&tensors, &params).as_deref(),
            Some("param `kcat` = NaN")
        );
        assert_eq!(
            in_tensors(&tensors[1..], &[]).as_deref(),
            Some("weight `params`[1] = NaN")
        );
        assert_eq!(in_tensors(&tensors[..1], &[]), None);
        let named = [("a", 1.0), ("b", f64::NEG_INFINITY)];
        assert_eq!(in_named(named).as_deref(), Some("`b` = -inf"));
    }

    #[test]
    fn a_table_names_the_earliest_row_and_its_time() {
        let t = [0.0, 0.5, 1.0];
        let s = [1.0, 2.0, f64::NAN];
        let p = [1.0, f64::INFINITY, 3.0];
        let columns = [("t", &t[..]), ("S", &s[..]), ("P", &p[..])];
        assert_eq!(
            in_table(&columns).as_deref(),
            Some("`P` = inf at t = 0.5 (row 2)")
        );
        assert_eq!(
            in_table(&columns[..2]).as_deref(),
            Some("`S` = NaN at t = 1 (row 3)")
        );
        assert_eq!(
            in_table(&columns[1..2]).as_deref(),
            Some("`S` = NaN in row 3")
        );
        assert_eq!(in_table(&[("t", &t[..])]), None);
        let error = refuse(Path::new("out.csv"), in_table(&columns), "try again").unwrap_err();
        let message = error.to_string();
        assert!(
            message.contains("out.csv") && message.contains("`P` = inf"),
            "{message}"
        );
        use miette::Diagnostic;
        assert_eq!(
            error.code().map(|c| c.to_string()).as_deref(),
            Some("gbm::E0253")
        );
        assert!(refuse(Path::new("out.csv"), None, "").is_ok());
    }
}
