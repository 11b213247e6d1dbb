//! Model files as text: reading and checking them, printing their syntax tree, formatting
//! them (`gbc fmt`), the catalogue of diagnostic codes (`gbc explain`), rendering
//! diagnostics, the editor services of `gbc lsp` ([`ide`]) and new projects (`gbc init`).

use std::path::Path;

use super::{ApiError, Model};

pub use crate::ast::Span;
pub use crate::diagnostics::{render as render_diagnostic, MessageFormat};
pub use crate::driver::read_source;
pub use crate::explain::explain;
pub use crate::format::{format_source, FormatError};
pub use crate::init::{project as new_project, InitError, Template};

/// Editor services over a document's text, as plain functions: diagnostics, go to
/// definition, hover; positions are byte offsets, [`ide::LineIndex`] converts them to an
/// editor's lines and UTF-16 columns.
pub mod ide {
    pub use crate::ide::{definition, diagnostics, hover, LineIndex, Problem};
}

/// Reads, parses, checks and lowers the model file at `path` as `gbc check` does: every
/// problem of the file as a report carrying its source, an internal one included (an
/// [`ApiError`] tells those apart).
pub fn check_file(path: &Path) -> Result<Model, Vec<miette::Report>> {
    let source = read_source(path).map_err(|report| vec![report])?;
    let origin = path.display().to_string();
    let compiled = crate::driver::compile(&origin, &source, &[])?;
    Ok(Model {
        origin,
        path: Some(path.to_path_buf()),
        source,
        compiled,
        effects: Vec::new(),
    })
}

/// The syntax tree of the model file at `path`, with byte spans (what `gbc compile --emit
/// ast` prints).
pub fn syntax_tree_text(path: &Path) -> Result<String, ApiError> {
    let source = read_source(path).map_err(|report| vec![report])?;
    let model = crate::driver::parse(&path.display().to_string(), &source)?;
    Ok(format!("{model:#?}\n"))
}
