//! The model's dependency graph as the locus search needs it (from the checked syntax
//! tree, where `let`s are still names): which lets use which, how far upstream each sits,
//! and the *groups* of lets that share an input and a form.
//!
//! - **Depth.** A let used by no other let has depth 1; a let used by others has one more
//!   than the deepest of them. Balances have depth 0. Larger is more upstream.
//! - **Forms.** A let's forms are its maximal sub-expressions that read an input (directly,
//!   or through a let that reads inputs and no state) and no state, stripped of constant
//!   factors: in `k * (u^n / (K + u^n)) * S / (K_S + S)` the form is `u^n / (K + u^n)`, and
//!   in `k * E_ss * X` (with `let E_ss = ...` of the input alone) it is `E_ss`. Two lets
//!   *share a form* when they have one written the same (spans aside).
//! - **Groups.** The lets with a common form, at least two, none using another: a missing
//!   mechanism acting on that input reaches every one of them, so their corrections (one
//!   each) are fitted jointly.

use crate::ast::{BinOp, Expr, ItemKind, SExpr};
use crate::check::Checked;
use std::collections::{BTreeMap, BTreeSet};

/// What a name is, as far as forms care.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Input,
    State,
    Let,
}

/// The lets of a model and their relations.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Graph {
    /// Let names in declaration order.
    pub lets: Vec<String>,
    /// Per let: the lets it uses directly.
    pub uses: BTreeMap<String, BTreeSet<String>>,
    /// Per let: its forms (canonical text).
    pub forms: BTreeMap<String, BTreeSet<String>>,
    /// Names the balances (`der`, `next`) use directly.
    pub balance_uses: BTreeSet<String>,
    /// Per balanced state: the names its balance uses directly.
    pub balances: BTreeMap<String, BTreeSet<String>>,
}

impl Graph {
    /// The graph of the model's top-level lets.
    pub fn of(checked: &Checked) -> Graph {
        let mut kinds: BTreeMap<String, Kind> = BTreeMap::new();
        let mut definitions: Vec<(String, &SExpr)> = Vec::new();
        let mut balances: Vec<(String, &SExpr)> = Vec::new();
        for item in &checked.ast.items {
            match &item.kind {
                ItemKind::Input(inputs) => {
                    for input in inputs {
                        kinds.insert(input.name.node.clone(), Kind::Input);
                    }
                }
                ItemKind::State(states) | ItemKind::Hidden(states) => {
                    for state in states {
                        kinds.insert(state.name.node.clone(), Kind::State);
                    }
                }
                ItemKind::Let(equation) => {
                    kinds.insert(equation.name.node.clone(), Kind::Let);
                    definitions.push((equation.name.node.clone(), &equation.expr));
                }
                ItemKind::Der(equation) | ItemKind::Next(equation) => {
                    balances.push((equation.name.node.clone(), &equation.expr));
                }
                _ => {}
            }
        }
        let expressions: BTreeMap<&str, &SExpr> =
            definitions.iter().map(|(n, e)| (n.as_str(), *e)).collect();
        let mut reads = Reads {
            kinds: &kinds,
            expressions: &expressions,
            memo: BTreeMap::new(),
        };
        let mut graph = Graph::default();
        for (state, expr) in balances {
            let mut used = BTreeSet::new();
            names_in(expr, &mut |n| {
                used.insert(n.to_string());
            });
            graph.balance_uses.extend(used.iter().cloned());
            graph.balances.entry(state).or_default().extend(used);
        }
        for (name, expr) in &definitions {
            let mut used = BTreeSet::new();
            names_in(expr, &mut |n| {
                if kinds.get(n) == Some(&Kind::Let) {
                    used.insert(n.to_string());
                }
            });
            let mut forms = BTreeSet::new();
            reads.forms(expr, &mut forms);
            graph.lets.push(name.clone());
            graph.uses.insert(name.clone(), used);
            graph.forms.insert(name.clone(), forms);
        }
        graph
    }

    /// How far upstream a let sits (see the module documentation); 0 for a name that is
    /// not a let.
    pub fn depth(&self, name: &str) -> usize {
        if !self.uses.contains_key(name) {
            return 0;
        }
        let users = (self.uses.iter())
            .filter(|(_, used)| used.contains(name))
            .map(|(user, _)| self.depth(user));
        1 + users.max().unwrap_or(0)
    }

    /// Whether let `name` reaches a balance (used there, or by a let that does).
    pub fn reaches_balance(&self, name: &str) -> bool {
        self.balance_uses.contains(name)
            || (self.uses.iter())
                .any(|(user, used)| used.contains(name) && self.reaches_balance(user))
    }

    /// Whether let `name` feeds `downstream`: a let that uses it (directly or through other
    /// lets), or a state whose balance does.
    pub fn feeds(&self, name: &str, downstream: &str) -> bool {
        match self.balances.get(downstream) {
            Some(used) => used.contains(name) || used.iter().any(|u| self.reaches(u, name)),
            None => self.reaches(downstream, name),
        }
    }

    /// Whether let `a` uses let `b`, directly or through other lets.
    pub fn reaches(&self, a: &str, b: &str) -> bool {
        let Some(used) = self.uses.get(a) else {
            return false;
        };
        used.contains(b) || used.iter().any(|u| self.reaches(u, b))
    }

    /// The groups among `candidates` (lets that reach a balance), each sorted by declaration
    /// order, without duplicates.
    pub fn groups(&self, candidates: &[String]) -> Vec<Vec<String>> {
        let mut by_form: BTreeMap<&str, Vec<String>> = BTreeMap::new();
        for name in &self.lets {
            if !candidates.contains(name) {
                continue;
            }
            for form in &self.forms[name] {
                by_form.entry(form.as_str()).or_default().push(name.clone());
            }
        }
        let mut groups: Vec<Vec<String>> = Vec::new();
        for members in by_form.into_values() {
            let independent = members.iter().all(|a| {
                members
                    .iter()
                    .all(|b| a == b || !(self.reaches(a, b) || self.reaches(b, a)))
            });
            if members.len() >= 2 && independent && !groups.contains(&members) {
                groups.push(members);
            }
        }
        groups
    }
}

/// Which names an expression reads, with memoised answers for lets.
struct Reads<'a> {
    kinds: &'a BTreeMap<String, Kind>,
    expressions: &'a BTreeMap<&'a str, &'a SExpr>,
    memo: BTreeMap<String, (bool, bool)>,
}

impl Reads<'_> {
    /// Whether `expr` reads an input, and whether it reads a state (through lets too).
    fn reads(&mut self, expr: &SExpr) -> (bool, bool) {
        match &expr.node {
            Expr::Num(_) => (false, false),
            Expr::Name(name) => self.name(name),
            Expr::Neg(inner) => self.reads(inner),
            Expr::Binary(_, a, b) => {
                let (x, y) = (self.reads(a), self.reads(b));
                (x.0 || y.0, x.1 || y.1)
            }
            Expr::Call(_, args) => args.iter().fold((false, false), |acc, a| {
                let r = self.reads(a);
                (acc.0 || r.0, acc.1 || r.1)
            }),
        }
    }

    fn name(&mut self, name: &str) -> (bool, bool) {
        match self.kinds.get(name) {
            Some(Kind::Input) => (true, false),
            Some(Kind::State) => (false, true),
            Some(Kind::Let) => {
                if let Some(&known) = self.memo.get(name) {
                    return known;
                }
                let answer = match self.expressions.get(name) {
                    Some(expr) => self.reads(expr),
                    None => (false, false),
                };
                self.memo.insert(name.to_string(), answer);
                answer
            }
            None => (false, false),
        }
    }

    /// Collects the maximal sub-expressions of `expr` that read an input and no state.
    fn forms(&mut self, expr: &SExpr, out: &mut BTreeSet<String>) {
        let (input, state) = self.reads(expr);
        if !input {
            return;
        }
        if !state {
            match &expr.node {
                Expr::Neg(inner) => self.forms(inner, out),
                Expr::Binary(BinOp::Mul | BinOp::Div, a, b) if !self.reads(a).0 => {
                    self.forms(b, out)
                }
                Expr::Binary(BinOp::Mul | BinOp::Div, a, b) if !self.reads(b).0 => {
                    self.forms(a, out)
                }
                _ => {
                    out.insert(canonical(expr));
                }
            }
            return;
        }
        match &expr.node {
            Expr::Neg(inner) => self.forms(inner, out),
            Expr::Binary(_, a, b) => {
                self.forms(a, out);
                self.forms(b, out);
            }
            Expr::Call(_, args) => args.iter().for_each(|a| self.forms(a, out)),
            Expr::Num(_) | Expr::Name(_) => {}
        }
    }
}

/// Calls `visit` with every name in `expr`.
fn names_in(expr: &SExpr, visit: &mut dyn FnMut(&str)) {
    match &expr.node {
        Expr::Num(_) => {}
        Expr::Name(name) => visit(name),
        Expr::Neg(inner) => names_in(inner, visit),
        Expr::Binary(_, a, b) => {
            names_in(a, visit);
            names_in(b, visit);
        }
        Expr::Call(_, args) => args.iter().for_each(|a| names_in(a, visit)),
    }
}

/// A fully parenthesised text of an expression (spans aside).
fn canonical(expr: &SExpr) -> String {
    match &expr.node {
        Expr::Num(value) => format!("{value:?}"),
        Expr::Name(name) => name.clone(),
        Expr::Neg(inner) => format!("(-{})", canonical(inner)),
        Expr::Binary(op, a, b) => format!("({} {} {})", canonical(a), op.symbol(), canonical(b)),
        Expr::Call(function, args) => {
            let args: Vec<String> = args.iter().map(canonical).collect();
            format!("{}({})", function.node, args.join(", "))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(source: &str) -> Graph {
        Graph::of(&crate::driver::check("m", source).unwrap())
    }

    const TWO_RATES: &str = "model m\ninput u\nstate X = 1\nstate P = 0\nconst K = 1\n\
        let E_ss = u^2 / (K + u^2)\n\
        let r_P = 2 * E_ss * X / (1 + X)\n\
        let r_Q = 3 * E_ss * P\n\
        let r_X = 0.1 * X\n\
        der X = r_X - r_P\nder P = r_P - r_Q\n";

    #[test]
    fn lets_sharing_an_input_through_a_let_form_a_group() {
        let graph = graph(TWO_RATES);
        let all: Vec<String> = graph.lets.clone();
        assert_eq!(
            graph.groups(&all),
            vec![vec!["r_P".to_string(), "r_Q".to_string()]]
        );
        // E_ss feeds both rates: it sits upstream of them.
        assert_eq!(graph.depth("E_ss"), 2);
        assert_eq!(graph.depth("r_P"), 1);
        assert_eq!(graph.depth("X"), 0);
        assert!(graph.reaches("r_P", "E_ss") && !graph.reaches("E_ss", "r_P"));
        assert!(graph.reaches_balance("E_ss") && graph.reaches_balance("r_X"));
        // What feeds what: lets through lets, balances through the lets they use.
        assert!(graph.feeds("E_ss", "r_P") && graph.feeds("E_ss", "P"));
        assert!(graph.feeds("r_X", "X") && !graph.feeds("r_X", "P"));
        assert!(!graph.feeds("r_P", "E_ss"));
    }

    #[test]
    fn the_same_form_written_inline_makes_a_group_and_other_forms_do_not() {
        let source = "model m\ninput u\nstate X = 1\nstate P = 0\nconst K = 1\n\
            let a = 2 * (u^2 / (K + u^2)) * X\n\
            let b = 3 * (u^2 / (K + u^2)) * P\n\
            let c = (1 - u) * X\n\
            der X = -a - c\nder P = a - b\n";
        let graph = graph(source);
        let all = graph.lets.clone();
        assert_eq!(
            graph.groups(&all),
            vec![vec!["a".to_string(), "b".to_string()]]
        );
        // Only candidates count.
        assert!(graph.groups(&["a".to_string(), "c".to_string()]).is_empty());
    }
}
