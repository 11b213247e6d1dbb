//! The symbol table: every declared name, its kind, where it is declared and in which scope.

use super::error::CheckError;
use super::sink::Sink;
use crate::ast::{self, Item, ItemKind, Span};
use std::collections::HashMap;

/// What a name denotes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    /// An actuator.
    Input,
    /// A measured state.
    State,
    /// A hidden state.
    Hidden,
    /// A known constant.
    Const,
    /// A trainable constant.
    Param,
    /// A `let`.
    Let,
    /// An `output`.
    Output,
    /// An output of closure number `.0`.
    ClosureOutput(usize),
}

impl Kind {
    /// The kind in words, with an article.
    pub fn describe(self) -> &'static str {
        match self {
            Kind::Input => "an input",
            Kind::State => "a measured state",
            Kind::Hidden => "a hidden state",
            Kind::Const => "a const",
            Kind::Param => "a param",
            Kind::Let => "a `let`",
            Kind::Output => "an `output`",
            Kind::ClosureOutput(_) => "a closure output",
        }
    }
    /// Whether it is a state (measured or hidden).
    pub fn is_state(self) -> bool {
        matches!(self, Kind::State | Kind::Hidden)
    }
}

/// A declared name.
#[derive(Debug, Clone, PartialEq)]
pub struct Symbol {
    /// What it is.
    pub kind: Kind,
    /// Where it is declared.
    pub span: Span,
}

/// Where a lookup happens: the model, or inside effect number `.0`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Scope {
    /// Top level.
    Model,
    /// Inside an effect (its own declarations shadow nothing: duplicates are errors).
    Effect(usize),
}

/// All names of a model: the top level and each effect's own declarations.
#[derive(Debug, Clone, Default)]
pub struct Symbols {
    /// Top-level names.
    pub model: HashMap<String, Symbol>,
    /// Names declared inside each effect, in effect order.
    pub effects: Vec<HashMap<String, Symbol>>,
    /// Closure names with their declaration spans.
    pub closures: HashMap<String, Span>,
}

impl Symbols {
    /// Looks a name up from `scope`.
    pub fn get(&self, scope: Scope, name: &str) -> Option<&Symbol> {
        if let Scope::Effect(index) = scope {
            if let Some(symbol) = self.effects.get(index).and_then(|e| e.get(name)) {
                return Some(symbol);
            }
        }
        self.model.get(name)
    }
    /// Every name visible from `scope` (for suggestions).
    pub fn visible(&self, scope: Scope) -> Vec<&str> {
        let mut names: Vec<&str> = self.model.keys().map(String::as_str).collect();
        if let Scope::Effect(index) = scope {
            if let Some(effect) = self.effects.get(index) {
                names.extend(effect.keys().map(String::as_str));
            }
        }
        names.sort_unstable();
        names
    }
}

/// Builds the symbol table, reporting duplicates. Top-level names first (their order in the
/// file does not matter), then each effect's own declarations, which may not reuse them.
pub fn collect(model: &ast::Model, sink: &mut Sink) -> Symbols {
    let mut symbols = Symbols::default();
    let mut closure_index = 0;
    for item in &model.items {
        match &item.kind {
            ItemKind::Effect(_) => continue,
            ItemKind::Closure(closure) => claim(&mut symbols.closures, &closure.name, sink),
            _ => {}
        }
        for (name, kind) in declared(item, closure_index) {
            insert(&mut symbols.model, name, kind, sink);
        }
        if matches!(item.kind, ItemKind::Closure(_)) {
            closure_index += 1;
        }
    }
    let mut effect_names: HashMap<String, Span> = HashMap::new();
    for effect in effect_items(model) {
        claim(&mut effect_names, &effect.name, sink);
        let mut scope = HashMap::new();
        for inner in &effect.items {
            for (name, kind) in declared(inner, usize::MAX) {
                match symbols.model.get(&name.node) {
                    Some(first) => sink.push(duplicate(name, first.span)),
                    None => insert(&mut scope, name, kind, sink),
                }
            }
        }
        symbols.effects.push(scope);
    }
    symbols
}

/// The effect declarations of a model, in order.
pub fn effect_items(model: &ast::Model) -> impl Iterator<Item = &ast::EffectDecl> {
    model.items.iter().filter_map(|item| match &item.kind {
        ItemKind::Effect(effect) => Some(effect),
        _ => None,
    })
}

fn duplicate(name: &ast::Ident, first: Span) -> CheckError {
    CheckError::Duplicate {
        name: name.node.clone(),
        span: name.span.into(),
        first: first.into(),
    }
}

fn claim(names: &mut HashMap<String, Span>, name: &ast::Ident, sink: &mut Sink) {
    if let Some(first) = names.get(&name.node) {
        sink.push(duplicate(name, *first));
    } else {
        names.insert(name.node.clone(), name.span);
    }
}

fn insert(map: &mut HashMap<String, Symbol>, name: &ast::Ident, kind: Kind, sink: &mut Sink) {
    if let Some(first) = map.get(&name.node) {
        sink.push(duplicate(name, first.span));
        return;
    }
    map.insert(
        name.node.clone(),
        Symbol {
            kind,
            span: name.span,
        },
    );
}

/// The names an item declares, with their kinds.
fn declared(item: &Item, closure_index: usize) -> Vec<(&ast::Ident, Kind)> {
    match &item.kind {
        ItemKind::Input(inputs) => inputs.iter().map(|i| (&i.name, Kind::Input)).collect(),
        ItemKind::State(states) => states.iter().map(|b| (&b.name, Kind::State)).collect(),
        ItemKind::Hidden(states) => states.iter().map(|b| (&b.name, Kind::Hidden)).collect(),
        ItemKind::Const(consts) => consts.iter().map(|b| (&b.name, Kind::Const)).collect(),
        ItemKind::Param(params) => params.iter().map(|p| (&p.name, Kind::Param)).collect(),
        ItemKind::Let(eq) => vec![(&eq.name, Kind::Let)],
        ItemKind::Output(eq) => vec![(&eq.name, Kind::Output)],
        ItemKind::Closure(closure) => closure
            .items
            .iter()
            .filter_map(|line| match &line.node {
                ast::ClosureItem::Outputs(outputs) => Some(outputs),
                _ => None,
            })
            .flatten()
            .map(|o| (&o.name, Kind::ClosureOutput(closure_index)))
            .collect(),
        _ => Vec::new(),
    }
}

/// A name as its declaring scope sees it.
pub type Key = (Scope, String);

/// The scope that declares `name` as seen from `scope`.
pub fn owner(symbols: &Symbols, scope: Scope, name: &str) -> Scope {
    match scope {
        Scope::Effect(i) if symbols.effects.get(i).is_some_and(|e| e.contains_key(name)) => scope,
        _ => Scope::Model,
    }
}
