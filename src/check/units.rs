//! Units of measure: declared units are resolved, undeclared ones are inferred where an
//! equation fixes them, and every place where two units must agree is checked.
//!
//! Rules (docs/language.md, "Units"): `+ - min max` need equal units; `der X` has the unit of
//! `X` per time unit and `next X` the unit of `X`; the arguments of `exp log tanh sigmoid
//! softplus`, exponents and `*=` factors are dimensionless; `sqrt` halves powers; a prior,
//! a `~` magnitude, bounds and initial values have the unit of their name; an embedding
//! delay has the time unit. A number has no unit of its own: it takes the one its place
//! needs, so anything multiplied by a number is unchecked. A model that declares no unit is
//! not checked at all.
//!
//! The check runs in two phases over the same sites: inference fills the unit of every
//! undeclared name an equation determines (source order, repeated until nothing changes),
//! then verification reports each disagreement once.

use super::error::CheckError;
use super::exprs::Evaluator;
use super::sink::Sink;
use super::symbols::{effect_items, owner, Key, Scope, Symbols};
use crate::ast::{self, ItemKind, Span};
use crate::suggest::closest;
use crate::units::{conversion, resolve, Comparison, Symbol, Unit, SYMBOL_NAMES};
use std::collections::HashMap;

/// The unit of one name, declared or inferred.
#[derive(Debug, Clone, PartialEq)]
pub struct UnitEntry {
    /// The unit.
    pub unit: Unit,
    /// How it is shown: as written for a declared unit, canonical for an inferred one.
    pub text: String,
    /// Whether it was inferred (not written in the model).
    pub inferred: bool,
    /// The annotation, or the expression it was inferred from.
    pub origin: Span,
}

/// Every unit the check knows: the time unit and each name's.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct UnitTable {
    /// The time unit (`time h`), when the model uses units.
    pub time: Option<Unit>,
    /// Units by declaring scope and name.
    pub names: HashMap<Key, UnitEntry>,
}

impl UnitTable {
    /// The entry of `name` as seen from `scope`.
    pub fn get(&self, symbols: &Symbols, scope: Scope, name: &str) -> Option<&UnitEntry> {
        self.names
            .get(&(owner(symbols, scope, name), name.to_string()))
    }
}

/// Checks the units of `model` (after the name checks) and returns every unit found.
pub fn check_units(
    model: &ast::Model,
    symbols: &Symbols,
    values: &HashMap<Key, f64>,
    sink: &mut Sink,
) -> UnitTable {
    if !uses_units(model) {
        return UnitTable::default();
    }
    let exprs = HashMap::new();
    let mut checker = Checker {
        symbols,
        evaluator: Evaluator::new(symbols, &exprs, values.clone()),
        table: UnitTable::default(),
        errors: Vec::new(),
        changed: false,
    };
    checker.declare(model);
    let sites = sites(model, symbols);
    for _ in 0..=checker.symbols_count() {
        checker.changed = false;
        for site in &sites {
            checker.infer_site(site);
        }
        if !checker.changed {
            break;
        }
    }
    for site in &sites {
        checker.verify_site(site);
    }
    sink.errors.append(&mut checker.errors);
    checker.table
}

/// Whether any declaration of the model carries a unit.
fn uses_units(model: &ast::Model) -> bool {
    let items = model
        .items
        .iter()
        .chain(effect_items(model).flat_map(|e| &e.items));
    let mut any = false;
    for item in items {
        declared_units(item, &mut |_, _| any = true);
    }
    any
}

/// Calls `visit` with each declared name of `item` that carries a unit.
fn declared_units<'a>(item: &'a ast::Item, visit: &mut impl FnMut(&'a ast::Ident, &'a ast::SUnit)) {
    let mut each = |name: &'a ast::Ident, unit: &'a Option<ast::SUnit>| {
        if let Some(unit) = unit {
            visit(name, unit);
        }
    };
    match &item.kind {
        ItemKind::Input(list) => list.iter().for_each(|i| each(&i.name, &i.unit)),
        ItemKind::State(list) | ItemKind::Hidden(list) | ItemKind::Const(list) => {
            list.iter().for_each(|b| each(&b.name, &b.unit))
        }
        ItemKind::Param(list) => list.iter().for_each(|p| each(&p.name, &p.unit)),
        ItemKind::Let(eq) | ItemKind::Output(eq) => each(&eq.name, &eq.unit),
        ItemKind::Closure(closure) => {
            for line in &closure.items {
                if let ast::ClosureItem::Outputs(outputs) = &line.node {
                    outputs.iter().for_each(|o| each(&o.name, &o.unit));
                }
            }
        }
        _ => {}
    }
}

struct Checker<'a> {
    symbols: &'a Symbols,
    evaluator: Evaluator<'a>,
    table: UnitTable,
    errors: Vec<CheckError>,
    changed: bool,
}

impl Checker<'_> {
    fn symbols_count(&self) -> usize {
        self.symbols.model.len() + self.symbols.effects.iter().map(|e| e.len()).sum::<usize>()
    }

    /// Resolves every annotation and the time unit, reporting unknown symbols.
    fn declare(&mut self, model: &ast::Model) {
        let mut scoped: Vec<(Scope, &ast::Item)> = (model.items.iter())
            .map(|item| (Scope::Model, item))
            .collect();
        for (index, effect) in effect_items(model).enumerate() {
            scoped.extend(effect.items.iter().map(|item| (Scope::Effect(index), item)));
        }
        for (scope, item) in scoped {
            if let ItemKind::Time(unit) = &item.kind {
                match Symbol::parse(&unit.node) {
                    Some(symbol) => self.table.time = Some(Unit::symbol(symbol)),
                    None => self.unknown_unit(&unit.node, unit.span),
                }
            }
            let mut found = Vec::new();
            declared_units(item, &mut |name, unit| found.push((name, unit)));
            for (name, annotation) in found {
                match resolve(annotation) {
                    Ok(unit) => {
                        let entry = UnitEntry {
                            unit,
                            text: annotation.node.to_string(),
                            inferred: false,
                            origin: annotation.span,
                        };
                        self.table.names.insert((scope, name.node.clone()), entry);
                    }
                    Err(unknown) => {
                        for (span, symbol) in unknown {
                            self.unknown_unit(&symbol, span);
                        }
                    }
                }
            }
        }
    }

    fn unknown_unit(&mut self, symbol: &str, span: Span) {
        self.errors.push(unknown_unit(symbol, span));
    }

    fn key(&self, scope: Scope, name: &str) -> Key {
        (owner(self.symbols, scope, name), name.to_string())
    }

    fn unit_of(&self, key: &Key) -> Option<Unit> {
        self.table.names.get(key).map(|entry| entry.unit.clone())
    }

    /// Records an inferred unit for a name that has none yet.
    fn infer(&mut self, key: Key, unit: Unit, origin: Span) {
        let declared = match key.0 {
            Scope::Model => self.symbols.model.contains_key(&key.1),
            Scope::Effect(i) => self
                .symbols
                .effects
                .get(i)
                .is_some_and(|e| e.contains_key(&key.1)),
        };
        if !declared || self.table.names.contains_key(&key) {
            return;
        }
        let entry = UnitEntry {
            text: unit.to_string(),
            unit,
            inferred: true,
            origin,
        };
        self.table.names.insert(key, entry);
        self.changed = true;
    }

    /// The unit a site's expression must have, if known.
    fn expected(&self, target: &Target) -> Option<Unit> {
        match target {
            Target::Name(key) => self.unit_of(key),
            Target::Rate(key) => Some(self.unit_of(key)?.div(self.table.time.as_ref()?)),
            Target::Dimensionless => Some(Unit::dimensionless()),
            Target::Time => self.table.time.clone(),
        }
    }

    fn infer_site(&mut self, site: &Site) {
        let expected = self.expected(&site.target);
        self.push(site.expr, site.scope, expected.as_ref());
        if expected.is_some() {
            return;
        }
        let Some(found) = self.eval(site.expr, site.scope, false) else {
            return;
        };
        match &site.target {
            Target::Name(key) => self.infer(key.clone(), found, site.expr.span),
            Target::Rate(key) => {
                if let Some(time) = self.table.time.clone() {
                    self.infer(key.clone(), found.mul(&time), site.expr.span);
                }
            }
            Target::Dimensionless | Target::Time => {}
        }
    }

    fn verify_site(&mut self, site: &Site) {
        let found = self.eval(site.expr, site.scope, true);
        let (Some(found), Some(expected)) = (found, self.expected(&site.target)) else {
            return;
        };
        let origin = match &site.target {
            Target::Name(key) => self.table.names.get(key).map(|entry| entry.origin),
            Target::Rate(_) | Target::Dimensionless | Target::Time => None,
        };
        if matches!(site.target, Target::Dimensionless) {
            self.dimensionless(&site.context, site.expr.span, &found);
            return;
        }
        let before = self.errors.len();
        self.mismatch(&site.context, &expected, origin, &found, site.expr.span);
        if let (Target::Rate(key), Some(time)) = (&site.target, &self.table.time) {
            let note = match self.table.names.get(key) {
                Some(state) => format!(
                    "a balance has the unit of its state ({}: {}) per time unit ({time}); ",
                    key.1, state.text
                ),
                None => String::new(),
            };
            if let Some(error) = self.errors.get_mut(before) {
                prepend_help(error, &note);
            }
        }
    }

    /// Reports `found` at `span` where `expected` was needed, if they differ.
    fn mismatch(
        &mut self,
        context: &str,
        expected: &Unit,
        origin: Option<Span>,
        found: &Unit,
        span: Span,
    ) -> bool {
        let (expected_text, found_text) = (shown(expected), shown(found));
        let error = match found.compare(expected) {
            Comparison::Equal => return false,
            Comparison::Scale(_) => {
                let (sentence, factor) = conversion(found, expected);
                CheckError::UnitScale {
                    context: context.to_string(),
                    expected: expected_text.clone(),
                    found: found_text.clone(),
                    factor: factor.clone(),
                    span: span.into(),
                    origin: origin.map(Into::into),
                    help: format!(
                        "{found_text} and {expected_text} differ by a factor of {factor} \
                         ({sentence}): use one unit for both, or convert with that factor"
                    ),
                }
            }
            Comparison::Incompatible => CheckError::UnitMismatch {
                context: context.to_string(),
                expected: expected_text.clone(),
                found: found_text.clone(),
                span: span.into(),
                origin: origin.map(Into::into),
                help: format!(
                    "{found_text} ({}) and {expected_text} ({}) are different dimensions; \
                     check the units declared for the names involved",
                    found.dimension_words(),
                    expected.dimension_words()
                ),
            },
        };
        self.errors.push(error);
        true
    }

    /// Reports a unit that should be dimensionless.
    fn dimensionless(&mut self, context: &str, span: Span, found: &Unit) {
        if found.is_dimensionless() {
            let context = format!("{context} (dimensionless)");
            self.mismatch(&context, &Unit::dimensionless(), None, found, span);
            return;
        }
        self.errors.push(CheckError::NotDimensionless {
            context: context.to_string(),
            found: shown(found),
            span: span.into(),
            help: format!(
                "divide by a quantity in {found} (a constant such as `K [{found}]`) to make it \
                 a pure number"
            ),
        });
    }
}

/// The error for a unit symbol gbc does not know, with the symbol meant or the known ones.
pub(super) fn unknown_unit(symbol: &str, span: Span) -> CheckError {
    let alias = ALIASES
        .iter()
        .find(|(word, _)| word.eq_ignore_ascii_case(symbol));
    let refused = Symbol::refused_prefix(symbol).map(|base| {
        format!(
            "`{}` takes no SI prefix: only `g mol L m K s` do (`mg`, `mmol`, `mL`, `ms`)",
            base.symbol()
        )
    });
    let suggestion = alias
        .map(|(_, unit)| *unit)
        .or(closest(symbol, SYMBOL_NAMES))
        .map(|best| format!("did you mean `{best}`?"));
    let help = refused.or(suggestion).unwrap_or_else(|| {
        format!(
            "units are products of {} with SI prefixes (`mg`, `mmol`, `mL`, `ms`), or `-`",
            SYMBOL_NAMES.map(|s| format!("`{s}`")).join(" ")
        )
    });
    CheckError::UnknownUnit {
        symbol: symbol.to_string(),
        span: span.into(),
        help,
    }
}

/// Words people write for units, and the symbol gbc reads.
const ALIASES: [(&str, &str); 18] = [
    ("gram", "g"),
    ("grams", "g"),
    ("hr", "h"),
    ("hrs", "h"),
    ("hour", "h"),
    ("hours", "h"),
    ("l", "L"),
    ("liter", "L"),
    ("litre", "L"),
    ("sec", "s"),
    ("second", "s"),
    ("minute", "min"),
    ("mole", "mol"),
    ("day", "d"),
    ("kelvin", "K"),
    ("M", "mol/L"),
    ("percent", "%"),
    ("pct", "%"),
];

/// Puts `note` in front of the help line of a unit mismatch.
fn prepend_help(error: &mut CheckError, note: &str) {
    if let CheckError::UnitMismatch { help, .. } | CheckError::UnitScale { help, .. } = error {
        help.insert_str(0, note);
    }
}

/// A unit for messages: its text, or `dimensionless` for `-`.
pub(super) fn shown(unit: &Unit) -> String {
    if unit.is_one() {
        "dimensionless".to_string()
    } else {
        unit.to_string()
    }
}

mod site;
#[cfg(test)]
mod tests;
mod walk;

use site::{sites, Site, Target};
