//! In-memory data: a table of named columns (a DataFrame's), read by the one data reader.

use super::ApiError;
use crate::data::format_number;

/// One column of a [`Table`].
#[derive(Debug, Clone, PartialEq)]
pub enum Column {
    /// Numbers; `NaN` is a missing cell.
    Numbers(Vec<f64>),
    /// Text, e.g. an experiment column; an empty string is a missing cell.
    Labels(Vec<String>),
}

impl Column {
    fn len(&self) -> usize {
        match self {
            Column::Numbers(values) => values.len(),
            Column::Labels(values) => values.len(),
        }
    }

    fn cell(&self, row: usize) -> String {
        match self {
            Column::Numbers(values) if values[row].is_nan() => String::new(),
            Column::Numbers(values) => format_number(values[row]),
            Column::Labels(values) => quote(&values[row]),
        }
    }
}

/// A table of named columns, as a DataFrame holds them: headers as a CSV file would have
/// them (`t [h]`, `X [g/L]`, `experiment`), one column each, all of one length.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// The name diagnostics give the table (as a file's path).
    pub name: String,
    /// The column headers.
    pub headers: Vec<String>,
    /// The columns, in the headers' order.
    pub columns: Vec<Column>,
}

/// The table as CSV text: its headers, then one line per row (numbers written so that
/// they read back exactly).
pub(super) fn table_text(table: &Table) -> Result<String, ApiError> {
    let rows = table.columns.first().map_or(0, Column::len);
    let uneven = (table.headers.len() != table.columns.len())
        || table.columns.iter().any(|c| c.len() != rows);
    if uneven {
        return Err(ApiError::Internal(format!(
            "the table `{}` has {} headers and columns of lengths {:?}",
            table.name,
            table.headers.len(),
            table.columns.iter().map(Column::len).collect::<Vec<_>>()
        )));
    }
    let mut text = (table.headers.iter())
        .map(|h| quote(h))
        .collect::<Vec<_>>()
        .join(",");
    text.push('\n');
    for row in 0..rows {
        let cells: Vec<String> = table.columns.iter().map(|c| c.cell(row)).collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    Ok(text)
}

/// A CSV field, quoted where it must be.
fn quote(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_is_written_as_the_csv_a_file_would_hold() -> Result<(), ApiError> {
        let table = Table {
            name: "frame".into(),
            headers: vec!["experiment".into(), "t [h]".into(), "X, dry [g/L]".into()],
            columns: vec![
                Column::Labels(vec!["B1".into(), "B1".into()]),
                Column::Numbers(vec![0.0, 0.1 + 0.2]),
                Column::Numbers(vec![f64::NAN, 1e-7]),
            ],
        };
        let text = table_text(&table)?;
        assert_eq!(
            text,
            "experiment,t [h],\"X, dry [g/L]\"\nB1,0,\nB1,0.30000000000000004,1e-7\n"
        );
        let uneven = Table {
            columns: vec![Column::Numbers(vec![1.0])],
            ..table
        };
        assert!(table_text(&uneven).is_err());
        Ok(())
    }
}
