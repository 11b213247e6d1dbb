//! Editor services for `gbc lsp`, as plain functions over a document's text: diagnostics,
//! go to definition, hover (kind, unit and doc comment of a name). Positions are byte
//! offsets here; [`LineIndex`] converts them to the editor's lines and UTF-16 columns.

mod index;

pub use index::LineIndex;

use crate::ast::{self, ItemKind, Span};
use crate::check::Scope;

/// A diagnostic located in the document.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// Where (the first label, or the start of the file).
    pub span: Span,
    /// `gbm::E0xxx`.
    pub code: Option<String>,
    /// The message, with the help line after it.
    pub message: String,
    /// The other labels, with their text.
    pub related: Vec<(Span, String)>,
}

/// Every diagnostic of the document, as `gbc check` reports them.
pub fn diagnostics(name: &str, source: &str) -> Vec<Problem> {
    let reports = match crate::driver::compile(name, source, &[]) {
        Ok(_) => return Vec::new(),
        Err(reports) => reports,
    };
    reports
        .iter()
        .map(|report| {
            let diagnostic: &dyn miette::Diagnostic = report.as_ref();
            let mut labels: Vec<(Span, String)> = diagnostic
                .labels()
                .map(|labels| {
                    labels
                        .map(|l| {
                            let span = Span::new(l.offset(), l.offset() + l.len());
                            (span, l.label().unwrap_or_default().to_string())
                        })
                        .collect()
                })
                .unwrap_or_default();
            let first = if labels.is_empty() {
                Span::new(0, 0)
            } else {
                labels.remove(0).0
            };
            let mut message = diagnostic.to_string();
            if let Some(help) = diagnostic.help() {
                message.push_str(&format!("\nhelp: {help}"));
            }
            Problem {
                span: first,
                code: diagnostic.code().map(|c| c.to_string()),
                message,
                related: labels,
            }
        })
        .collect()
}

/// A declared name.
#[derive(Debug, Clone, PartialEq)]
struct Declaration {
    scope: Scope,
    name: String,
    span: Span,
    /// `state`, `const`, `closure output`...
    kind: &'static str,
    doc: Option<String>,
    unit: Option<String>,
    /// A state declared `nonnegative`.
    nonnegative: bool,
}

/// Where the name at `offset` is declared.
pub fn definition(source: &str, offset: usize) -> Option<Span> {
    let model = crate::syntax::parse(source).ok()?;
    let (name, scope) = name_at(source, &model, offset)?;
    lookup(&declarations(&model), scope, &name).map(|d| d.span)
}

/// What the name at `offset` is: its declaration, unit (declared or inferred) and doc
/// comment, in Markdown.
pub fn hover(source: &str, offset: usize) -> Option<String> {
    let model = crate::syntax::parse(source).ok()?;
    let (name, scope) = name_at(source, &model, offset)?;
    let declarations = declarations(&model);
    let declaration = lookup(&declarations, scope, &name)?;
    let checked = crate::check::check(model.clone()).ok();
    let inferred = checked.as_ref().and_then(|c| {
        let entry = c.units.get(&c.symbols, declaration.scope, &name)?;
        Some((entry.text.clone(), entry.inferred))
    });
    let unit = match (&declaration.unit, inferred) {
        (Some(unit), _) => Some(format!("unit: `{unit}`")),
        (None, Some((unit, true))) => Some(format!("unit: `{unit}` (inferred)")),
        _ => None,
    };
    let noise = (declaration.scope == Scope::Model)
        .then(|| noise_of(&model, &name))
        .flatten();
    let sign = if declaration.nonnegative {
        " nonnegative"
    } else {
        ""
    };
    let mut text = format!(
        "```gbm\n{} {}{sign}\n```",
        declaration.kind, declaration.name
    );
    for part in [unit, noise, declaration.doc.clone()].into_iter().flatten() {
        text.push_str("\n\n");
        text.push_str(&part);
    }
    Some(text)
}

/// `noise: `4 % + 0.01 [g/L]`` for a quantity with a noise declaration.
fn noise_of(model: &ast::Model, name: &str) -> Option<String> {
    model.items.iter().find_map(|item| match &item.kind {
        ItemKind::Noise(noise) if noise.targets.iter().any(|t| t.node == name) => Some(format!(
            "noise: `{}` (standard deviation `sqrt(absolute^2 + (relative * {name})^2)`)",
            noise.terms_text()
        )),
        _ => None,
    })
}

fn lookup<'a>(
    declarations: &'a [Declaration],
    scope: Scope,
    name: &str,
) -> Option<&'a Declaration> {
    let find = |s: Scope| declarations.iter().find(|d| d.scope == s && d.name == name);
    find(scope).or_else(|| find(Scope::Model))
}

/// The identifier under `offset` and the scope it is written in.
fn name_at(source: &str, model: &ast::Model, offset: usize) -> Option<(String, Scope)> {
    let bytes = source.as_bytes();
    let is_ident = |b: u8| b.is_ascii_alphanumeric() || b == b'_';
    let offset = offset.min(bytes.len());
    let mut start = offset;
    while start > 0 && is_ident(bytes[start - 1]) {
        start -= 1;
    }
    let mut end = offset;
    while end < bytes.len() && is_ident(bytes[end]) {
        end += 1;
    }
    if start == end || bytes[start].is_ascii_digit() {
        return None;
    }
    let effect = crate::check::symbols::effect_items(model).position(|effect| {
        let first = effect.name.span.start;
        let last = effect.items.last().map_or(first, |i| i.span.end);
        (first..=last).contains(&start)
    });
    let scope = effect.map_or(Scope::Model, Scope::Effect);
    Some((source[start..end].to_string(), scope))
}

/// Every declaration of the model and of its effects.
fn declarations(model: &ast::Model) -> Vec<Declaration> {
    let mut out = Vec::new();
    for item in &model.items {
        item_declarations(item, Scope::Model, &mut out);
    }
    for (index, effect) in crate::check::symbols::effect_items(model).enumerate() {
        for item in &effect.items {
            item_declarations(item, Scope::Effect(index), &mut out);
        }
    }
    out
}

fn item_declarations(item: &ast::Item, scope: Scope, out: &mut Vec<Declaration>) {
    let mut push = |name: &ast::Ident, kind: &'static str, unit: &Option<ast::SUnit>, sign| {
        out.push(Declaration {
            scope,
            name: name.node.clone(),
            span: name.span,
            kind,
            doc: item.doc.clone(),
            unit: unit.as_ref().map(|u| u.node.to_string()),
            nonnegative: sign,
        })
    };
    match &item.kind {
        ItemKind::Input(list) => list
            .iter()
            .for_each(|i| push(&i.name, "input", &i.unit, false)),
        ItemKind::State(list) | ItemKind::Hidden(list) => {
            let kind = match item.kind {
                ItemKind::State(_) => "state",
                _ => "hidden",
            };
            for b in list {
                push(&b.name, kind, &b.unit, b.nonnegative.is_some());
            }
        }
        ItemKind::Const(list) => list
            .iter()
            .for_each(|b| push(&b.name, "const", &b.unit, false)),
        ItemKind::Param(list) => list
            .iter()
            .for_each(|p| push(&p.name, "param", &p.unit, false)),
        ItemKind::Let(eq) => push(&eq.name, "let", &eq.unit, false),
        ItemKind::Output(eq) => push(&eq.name, "output", &eq.unit, false),
        ItemKind::Closure(closure) => {
            for line in &closure.items {
                if let ast::ClosureItem::Outputs(outputs) = &line.node {
                    (outputs.iter()).for_each(|o| push(&o.name, "closure output", &o.unit, false));
                }
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests;
