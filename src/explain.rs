//! `gbc explain E0xxx`: the catalogue entry of a diagnostic code, from `docs/errors.md`
//! (embedded at build time, so the binary explains without the repository).

use miette::Diagnostic;
use thiserror::Error;

/// The catalogue, as shipped.
pub const CATALOGUE: &str = include_str!("../docs/errors.md");

/// A code the catalogue does not list.
#[derive(Debug, Clone, Error, Diagnostic, PartialEq)]
pub enum ExplainError {
    /// Not a code, or a code no diagnostic has.
    #[error("expected a diagnostic code such as E0151, found `{code}`")]
    #[diagnostic(code(gbm::E1005))]
    UnknownCode {
        /// What was asked for.
        code: String,
        /// The nearest code, or where to look.
        #[help]
        help: String,
    },
}

/// The entry of `code` (`E0151`, `e0151` or `gbm::E0151`): its section of the catalogue,
/// or, for codes listed in a table, the table's section introduction and the code's row.
pub fn explain(code: &str) -> Result<String, ExplainError> {
    let wanted = normalise(code);
    if let Some(section) = section(&wanted) {
        return Ok(section);
    }
    if let Some(row) = table_row(&wanted) {
        return Ok(row);
    }
    let codes = codes();
    let help = match crate::suggest::closest(&wanted, codes.iter().map(String::as_str)) {
        Some(best) => format!(
            "did you mean {best}? `gbc explain` knows {} codes",
            codes.len()
        ),
        None => "docs/errors.md lists every code".to_string(),
    };
    Err(ExplainError::UnknownCode {
        code: code.to_string(),
        help,
    })
}

/// Every code the catalogue documents, in order.
pub fn codes() -> Vec<String> {
    let mut out = Vec::new();
    for line in CATALOGUE.lines() {
        let candidate = line
            .strip_prefix("## ")
            .or_else(|| line.strip_prefix("| "))
            .and_then(|rest| rest.get(..5));
        if let Some(code) = candidate.filter(|c| is_code(c)) {
            if !out.iter().any(|known: &String| known == code) {
                out.push(code.to_string());
            }
        }
    }
    out
}

fn is_code(text: &str) -> bool {
    text.len() == 5 && text.starts_with('E') && text[1..].bytes().all(|b| b.is_ascii_digit())
}

fn normalise(code: &str) -> String {
    let code = code.trim();
    let code = code.strip_prefix("gbm::").unwrap_or(code);
    code.to_ascii_uppercase()
}

/// `## E0151 (units)` up to the next heading or the end of the generated part.
fn section(code: &str) -> Option<String> {
    let heading = format!("## {code} ");
    let start = CATALOGUE.find(&heading)?;
    let body = &CATALOGUE[start..];
    let end = body[3..]
        .find("\n## ")
        .map(|i| i + 4)
        .into_iter()
        .chain(body.find("<!--"))
        .min()
        .unwrap_or(body.len());
    Some(format!("{}\n", body[..end].trim_end()))
}

/// `| E0203 | empty file |` with the heading and introduction of its table's section.
fn table_row(code: &str) -> Option<String> {
    let row_marker = format!("| {code} |");
    let row_at = CATALOGUE.find(&row_marker)?;
    let heading_at = CATALOGUE[..row_at].rfind("\n## ").map_or(0, |i| i + 1);
    let section = &CATALOGUE[heading_at..row_at];
    let introduction: Vec<&str> = section
        .lines()
        .take_while(|l| !l.starts_with('|'))
        .collect();
    let row = CATALOGUE[row_at..].lines().next()?;
    let description = row
        .trim_start_matches(&row_marker)
        .trim()
        .trim_end_matches('|')
        .trim();
    Some(format!(
        "{}\n\n{code}: {description}\n",
        introduction.join("\n").trim_end()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_front_end_code_prints_its_section_with_the_example() {
        let text = explain("E0152").expect("documented");
        assert!(text.starts_with("## E0152 (units)"), "{text}");
        assert!(text.contains("factor"), "{text}");
        assert!(text.contains("gbm::E0152"), "the golden example: {text}");
        assert!(!text.contains("## E0153"), "{text}");
        assert_eq!(explain("gbm::e0152"), Ok(text));
    }

    #[test]
    fn a_table_code_prints_its_row_and_section() {
        let text = explain("E0203").expect("documented");
        assert!(text.starts_with("## Data files (E02xx)"), "{text}");
        assert!(text.ends_with("E0203: empty file\n"), "{text}");
    }

    #[test]
    fn every_catalogued_code_explains_and_unknown_codes_suggest() {
        let codes = codes();
        assert!(codes.len() > 100, "{}", codes.len());
        for code in &codes {
            assert!(explain(code).is_ok(), "{code}");
        }
        match explain("E0125") {
            Err(ExplainError::UnknownCode { help, .. }) => {
                assert!(help.contains("did you mean"), "{help}")
            }
            other => panic!("{other:?}"),
        }
    }
}
