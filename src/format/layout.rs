//! The layout: blocks of entries (the file, a closure, an effect) with the comments and
//! blank lines between them, and each entry printed in canonical form.

use super::expr::{list, pieces, push_expr, text, wrap, Piece};
use crate::ast::{self, ClosureItem, Constraint, ItemKind, SExpr, SUnit, Span, Spanned};
use crate::syntax::comment_start;

/// Lines are wrapped beyond this many columns.
pub const WIDTH: usize = 100;

/// Prints `model` (parsed from `source`) in the canonical layout.
pub fn print(source: &str, model: &ast::Model) -> String {
    let mut printer = Printer {
        source,
        lines: Vec::new(),
    };
    let mut entries = vec![Entry::Header(model)];
    entries.extend(model.items.iter().map(Entry::Item));
    printer.block(&entries, 0, source.len(), 0);
    let mut out = printer.lines.join("\n");
    out.push('\n');
    out
}

/// One thing a block holds.
#[derive(Clone, Copy)]
enum Entry<'a> {
    Header(&'a ast::Model),
    Item(&'a ast::Item),
    Line(&'a Spanned<ClosureItem>),
}

impl Entry<'_> {
    fn span(&self, source: &str) -> Span {
        match self {
            Entry::Header(model) => header_span(source, model),
            Entry::Item(item) => item.span,
            Entry::Line(line) => line.span,
        }
    }
}

/// From `model` to the end of the name or of the description string.
fn header_span(source: &str, model: &ast::Model) -> Span {
    let name = model.name.span;
    let start = source[..name.start].rfind("model").unwrap_or(name.start);
    let mut end = name.end;
    if model.description.is_some() {
        let quotes: Vec<usize> = (source[end..].match_indices('"'))
            .take(2)
            .map(|(i, _)| end + i)
            .collect();
        end = quotes.get(1).map_or(end, |q| q + 1);
    }
    Span::new(start, end)
}

/// The text after the model name in the header: ` "description"` or nothing.
fn model_header_tail(model: &ast::Model) -> String {
    match &model.description {
        Some(text) => format!("\"{text}\""),
        None => String::new(),
    }
}

/// An entry printed as a head and a tail (`const D` and ` = 0.05 [1/h]`), so that runs of
/// one kind can be aligned on what follows the head.
struct Rendered {
    head: String,
    tail: Vec<Piece>,
    /// Whether it may be aligned with its neighbours.
    alignable: bool,
}

struct Printer<'a> {
    source: &'a str,
    lines: Vec<String>,
}

impl Printer<'_> {
    /// Prints the entries of a block whose contents lie in `start..end`.
    fn block(&mut self, entries: &[Entry], start: usize, end: usize, depth: usize) {
        let indent = "  ".repeat(depth);
        let first_line = self.lines.len();
        let mut cursor = start;
        let mut previous: Option<usize> = None;
        let rendered: Vec<Option<Rendered>> = entries.iter().map(|e| self.render(e)).collect();
        let widths = self.alignment(entries, &rendered);
        for (index, entry) in entries.iter().enumerate() {
            let span = entry.span(self.source);
            let gap_end = span.start.max(cursor);
            self.gap(
                cursor,
                gap_end,
                &indent,
                first_line,
                previous.is_some() || depth > 0,
            );
            match (&rendered[index], entry) {
                (_, Entry::Item(item))
                    if matches!(item.kind, ItemKind::Closure(_) | ItemKind::Effect(_)) =>
                {
                    self.nested(item, depth);
                }
                (Some(rendered), _) => {
                    let mut all = vec![Piece::Text(pad(&rendered.head, widths[index]))];
                    all.extend(rendered.tail.iter().cloned());
                    self.lines.extend(wrap(&all, &indent, WIDTH));
                }
                (None, _) => self.verbatim(span, &indent),
            }
            previous = Some(index);
            cursor = span.end;
        }
        self.gap(cursor, end.max(cursor), &indent, first_line, true);
        while self.lines.len() > first_line && self.lines.last().is_some_and(|l| l.is_empty()) {
            self.lines.pop();
        }
    }

    /// The comments and blank lines in `start..end`. The text before the first newline ends
    /// the line above (its comment is kept there, as a trailing comment) when `attached`.
    fn gap(&mut self, start: usize, end: usize, indent: &str, first_line: usize, attached: bool) {
        let text = &self.source[start..end];
        let mut segments = text.split('\n');
        let Some(first) = segments.next() else { return };
        let rest: Vec<&str> = segments.collect();
        if attached {
            if let (Some(at), Some(last)) = (comment_start(first), self.lines.last_mut()) {
                last.push(' ');
                last.push_str(first[at..].trim_end());
            }
        } else if let Some(at) = comment_start(first) {
            self.lines
                .push(format!("{indent}{}", first[at..].trim_end()));
        }
        // The last segment is the start of the next entry's own line.
        let middle = rest.len().saturating_sub(1);
        for line in &rest[..middle] {
            let trimmed = line.trim();
            if trimmed.is_empty() {
                let at_start = self.lines.len() == first_line;
                if !at_start && self.lines.last().is_some_and(|l| !l.is_empty()) {
                    self.lines.push(String::new());
                }
            } else if let Some(at) = comment_start(line) {
                self.lines
                    .push(format!("{indent}{}", line[at..].trim_end()));
            }
        }
    }

    /// A closure or an effect: header, its block, closing brace.
    fn nested(&mut self, item: &ast::Item, depth: usize) {
        let indent = "  ".repeat(depth);
        let close = item.span.end.saturating_sub(1);
        let (header, after_name, entries): (String, usize, Vec<Entry>) = match &item.kind {
            ItemKind::Closure(closure) => (
                format!("closure {} {{", closure.name.node),
                closure.name.span.end,
                closure.items.iter().map(Entry::Line).collect(),
            ),
            ItemKind::Effect(effect) => {
                let description = match &effect.description {
                    Some(text) => format!(" \"{text}\""),
                    None => String::new(),
                };
                let mut after = effect.name.span.end;
                if effect.description.is_some() {
                    // Skip the description string (strings have no escapes).
                    let quotes: Vec<usize> = (self.source[after..close].match_indices('"'))
                        .take(2)
                        .map(|(i, _)| after + i)
                        .collect();
                    after = quotes.get(1).map_or(after, |q| q + 1);
                }
                (
                    format!("effect {}{description} {{", effect.name.node),
                    after,
                    effect.items.iter().map(Entry::Item).collect(),
                )
            }
            _ => return,
        };
        let open = self.source[after_name..close]
            .find('{')
            .map_or(after_name, |i| after_name + i + 1);
        self.lines.push(format!("{indent}{header}"));
        self.block(&entries, open, close, depth + 1);
        self.lines.push(format!("{indent}}}"));
    }

    /// An entry whose text holds a comment: kept as written (first line re-indented,
    /// trailing spaces removed).
    fn verbatim(&mut self, span: Span, indent: &str) {
        let text = &self.source[span.start..span.end];
        for (index, line) in text.split('\n').enumerate() {
            if index == 0 {
                self.lines.push(format!("{indent}{}", line.trim()));
            } else {
                self.lines.push(line.trim_end().to_string());
            }
        }
    }

    /// Head widths: the widest head of each run of alignable entries of one kind that
    /// follow each other on consecutive lines.
    fn alignment(&self, entries: &[Entry], rendered: &[Option<Rendered>]) -> Vec<usize> {
        let mut widths: Vec<usize> = (rendered.iter())
            .map(|r| r.as_ref().map_or(0, |r| r.head.chars().count()))
            .collect();
        let mut run_start = 0;
        for index in 0..=entries.len() {
            let continues = index < entries.len()
                && index > run_start
                && self.adjacent(entries, rendered, index - 1, index);
            if continues {
                continue;
            }
            let run = run_start..index;
            if run.len() > 1 {
                let widest = run.clone().map(|i| widths[i]).max().unwrap_or(0);
                run.for_each(|i| widths[i] = widest);
            }
            run_start = index;
        }
        widths
    }

    /// Whether entries `a` and `b` are alignable, of one kind, and printed on consecutive
    /// lines.
    fn adjacent(
        &self,
        entries: &[Entry],
        rendered: &[Option<Rendered>],
        a: usize,
        b: usize,
    ) -> bool {
        let (Some(first), Some(second)) = (&rendered[a], &rendered[b]) else {
            return false;
        };
        if !first.alignable || !second.alignable || keyword(&first.head) != keyword(&second.head) {
            return false;
        }
        let gap =
            &self.source[entries[a].span(self.source).end..entries[b].span(self.source).start];
        // Adjacent in the output: no blank or comment line between them (see `gap`).
        let segments: Vec<&str> = gap.split('\n').collect();
        let middle = &segments[1.min(segments.len())..segments.len().saturating_sub(1).max(1)];
        middle
            .iter()
            .all(|line| !line.trim().is_empty() && comment_start(line).is_none())
    }

    /// The canonical form of an entry, or `None` to keep it as written (it holds a comment,
    /// or it is a block, printed by [`Printer::nested`]).
    fn render(&self, entry: &Entry) -> Option<Rendered> {
        let span = entry.span(self.source);
        if comment_start(&self.source[span.start..span.end]).is_some() {
            return None;
        }
        let source = self.source;
        let mut tail = Vec::new();
        let (head, alignable) = match entry {
            Entry::Header(model) => {
                let description = model_header_tail(model);
                if !description.is_empty() {
                    text(&mut tail, format!(" {description}"));
                }
                (format!("model {}", model.name.node), false)
            }
            Entry::Item(item) => item_head(source, &item.kind, &mut tail)?,
            Entry::Line(line) => (closure_line(source, &line.node, &mut tail), false),
        };
        Some(Rendered {
            head,
            tail,
            alignable,
        })
    }
}

/// The keyword a head starts with.
fn keyword(head: &str) -> &str {
    head.split(' ').next().unwrap_or_default()
}

fn pad(head: &str, width: usize) -> String {
    format!("{head:<width$}")
}

fn unit_text(unit: &Option<SUnit>) -> String {
    match unit {
        Some(unit) => format!(" [{}]", unit.node),
        None => String::new(),
    }
}

fn push_constraint(pieces: &mut Vec<Piece>, source: &str, constraint: &Option<Constraint>) {
    match constraint {
        Some(Constraint::Positive(_)) => text(pieces, " positive"),
        Some(Constraint::Bounds(lo, hi)) => push_bounds(pieces, source, lo, hi),
        None => {}
    }
}

fn push_bounds(pieces: &mut Vec<Piece>, source: &str, lo: &SExpr, hi: &SExpr) {
    text(pieces, " in [");
    list(pieces, 1, &[lo, hi], |pieces, bound| {
        push_expr(pieces, source, bound, 0, 1)
    });
    text(pieces, "]");
}

/// The head of a declaration and the pieces of its tail; `None` for blocks.
fn item_head(source: &str, kind: &ItemKind, tail: &mut Vec<Piece>) -> Option<(String, bool)> {
    let equation = |keyword: &str, eq: &ast::Equation, op: &str, tail: &mut Vec<Piece>| {
        text(tail, format!(" {op} "));
        tail.extend(pieces(source, &eq.expr));
        (
            format!("{keyword} {}{}", eq.name.node, unit_text(&eq.unit)),
            true,
        )
    };
    Some(match kind {
        ItemKind::Time(unit) => (format!("time {}", unit.node), false),
        ItemKind::Input(inputs) => {
            list(tail, 0, inputs, |pieces, input| {
                text(
                    pieces,
                    format!("{}{}", input.name.node, unit_text(&input.unit)),
                );
                if let Some((lo, hi)) = &input.bounds {
                    push_bounds(pieces, source, lo, hi);
                }
            });
            ("input ".to_string(), false)
        }
        ItemKind::State(list_) | ItemKind::Hidden(list_) | ItemKind::Const(list_) => {
            let keyword = match kind {
                ItemKind::State(_) => "state",
                ItemKind::Hidden(_) => "hidden",
                _ => "const",
            };
            let unit_after_value = keyword == "const";
            bindings(source, keyword, list_, unit_after_value, tail)
        }
        ItemKind::Param(params) => {
            if let [param] = params.as_slice() {
                param_tail(source, param, tail);
                (format!("param {}", param.name.node), true)
            } else {
                list(tail, 0, params, |pieces, param| {
                    text(pieces, param.name.node.clone());
                    param_tail(source, param, pieces);
                });
                ("param ".to_string(), false)
            }
        }
        ItemKind::Let(eq) => equation("let", eq, "=", tail),
        ItemKind::Output(eq) => equation("output", eq, "=", tail),
        ItemKind::Der(eq) => equation("der", eq, "=", tail),
        ItemKind::DerPatch(eq) => equation("der", eq, "+=", tail),
        ItemKind::Next(eq) => equation("next", eq, "=", tail),
        ItemKind::Patch(patch) => {
            text(tail, format!(" {} ", patch.op.symbol()));
            tail.extend(pieces(source, &patch.expr));
            (patch.target.node.clone(), false)
        }
        ItemKind::Noise(noise) => noise_head(source, noise, tail),
        ItemKind::Closure(_) | ItemKind::Effect(_) => return None,
    })
}

/// `noise X = 4 % + 0.01 [g/L]`: one name is alignable (on `=`), a list of names is not.
fn noise_head(source: &str, noise: &ast::NoiseDecl, tail: &mut Vec<Piece>) -> (String, bool) {
    let head = match noise.targets.as_slice() {
        [target] => format!("noise {}", target.node),
        targets => {
            list(tail, 0, targets, |pieces, name| {
                text(pieces, name.node.clone())
            });
            "noise ".to_string()
        }
    };
    text(tail, " = ");
    for (index, term) in noise.terms.iter().enumerate() {
        if index > 0 {
            text(tail, " +");
            tail.push(Piece::Break(1));
            text(tail, " ");
        }
        text(tail, noise_term(source, term));
    }
    (head, noise.targets.len() == 1)
}

/// A noise term with its number as written: `4 %`, `-0.01`, `10 [mg/L]`.
fn noise_term(source: &str, term: &ast::NoiseTerm) -> String {
    let value = term.value.node;
    let written = source
        .get(term.value.span.start..term.value.span.end)
        .unwrap_or_default();
    let literal = written.trim_start_matches('-').trim();
    let magnitude = if literal.parse::<f64>().ok() == Some(value.abs()) {
        literal.to_string()
    } else {
        ast::format_number(value.abs())
    };
    let sign = if value.is_sign_negative() { "-" } else { "" };
    match &term.kind {
        ast::NoiseKind::Relative => format!("{sign}{magnitude} %"),
        ast::NoiseKind::Absolute(unit) => format!("{sign}{magnitude}{}", unit_text(unit)),
    }
}

fn param_tail(source: &str, param: &ast::ParamDecl, pieces: &mut Vec<Piece>) {
    text(pieces, " = ");
    push_expr(pieces, source, &param.init, 0, 0);
    text(pieces, unit_text(&param.unit));
    push_constraint(pieces, source, &param.constraint);
}

/// `state X [g/L] = 1, S` or `const D = 0.05 [1/h]`: one binding is alignable.
fn bindings(
    source: &str,
    keyword: &str,
    list_: &[ast::Binding],
    unit_after_value: bool,
    tail: &mut Vec<Piece>,
) -> (String, bool) {
    let value = |pieces: &mut Vec<Piece>, binding: &ast::Binding| {
        if let Some(value) = &binding.value {
            text(pieces, " = ");
            push_expr(pieces, source, value, 0, 0);
        }
        if unit_after_value {
            text(pieces, unit_text(&binding.unit));
        }
        if binding.nonnegative.is_some() {
            text(pieces, " nonnegative");
        }
    };
    let name = |binding: &ast::Binding| {
        if unit_after_value {
            binding.name.node.clone()
        } else {
            format!("{}{}", binding.name.node, unit_text(&binding.unit))
        }
    };
    if let [binding] = list_ {
        value(tail, binding);
        return (
            format!("{keyword} {}", name(binding)),
            binding.value.is_some(),
        );
    }
    list(tail, 0, list_, |pieces, binding| {
        text(pieces, name(binding));
        value(pieces, binding);
    });
    (format!("{keyword} "), false)
}

/// A closure line: its text as a head (`outputs` lists, `embed`, `network`) and the tail
/// of a prior.
fn closure_line(source: &str, line: &ClosureItem, tail: &mut Vec<Piece>) -> String {
    match line {
        ClosureItem::Outputs(outputs) => {
            list(tail, 0, outputs, |pieces, output| {
                text(
                    pieces,
                    format!("{}{}", output.name.node, unit_text(&output.unit)),
                );
                if let Some(scale) = &output.scale {
                    text(pieces, " ~ ");
                    push_expr(pieces, source, scale, 0, 0);
                }
                push_constraint(pieces, source, &output.constraint);
            });
            "outputs ".to_string()
        }
        ClosureItem::Observe(names) => {
            list(tail, 0, names, |pieces, name| {
                text(pieces, name.node.clone())
            });
            "observe ".to_string()
        }
        ClosureItem::Embed { delay, dim } => {
            if let Some(delay) = delay {
                text(tail, " delay ");
                push_expr(tail, source, delay, 0, 0);
            }
            if let Some(dim) = dim {
                text(tail, format!(" dim {}", dim.node));
            }
            "embed".to_string()
        }
        ClosureItem::Network { hidden, activation } => {
            if let Some(widths) = hidden {
                text(tail, " hidden [");
                list(tail, 1, widths, |pieces, width| {
                    text(pieces, width.node.to_string())
                });
                text(tail, "]");
            }
            if let Some(activation) = activation {
                text(tail, format!(" {}", activation.node));
            }
            "network".to_string()
        }
        ClosureItem::Prior(prior) => {
            text(tail, format!(" {} ", prior.op.symbol()));
            tail.extend(pieces(source, &prior.expr));
            format!("prior {}", prior.target.node)
        }
    }
}
