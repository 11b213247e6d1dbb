//! `gbc fmt`: idempotent and meaning-preserving on every shipped model and on 1000
//! generated models with random layouts (spacing, `;`, continuation lines, `\`, comments,
//! doc comments, blank lines, extra parentheses, unit placement).

use crate::format::{comments, format_source};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};

fn compiled_ir(name: &str, source: &str) -> Result<String, String> {
    crate::driver::compile(name, source, &[])
        .map(|compiled| crate::ir::print(&compiled.model))
        .map_err(|reports| {
            reports
                .iter()
                .map(|r| format!("{r:?}"))
                .collect::<Vec<_>>()
                .join("\n")
        })
}

/// Formats `source` and checks the properties; returns the formatted text.
fn check_properties(name: &str, source: &str) -> String {
    let formatted = format_source(source).unwrap_or_else(|e| {
        let _ = std::fs::write(std::env::temp_dir().join("gbc-fmt-failure.gbm"), source);
        panic!("{name}: {e}\n{source}")
    });
    let again = format_source(&formatted).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(again, formatted, "{name}: not idempotent\n{source}");
    let before = compiled_ir(name, source).unwrap_or_else(|e| panic!("{name}: {e}\n{source}"));
    let after = compiled_ir(name, &formatted)
        .unwrap_or_else(|e| panic!("{name}: formatted text fails: {e}\n{formatted}"));
    assert_eq!(
        after, before,
        "{name}: IR changed\n{source}\n---\n{formatted}"
    );
    assert_eq!(
        comments(&formatted),
        comments(source),
        "{name}: comments changed"
    );
    formatted
}

fn shipped_models(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.is_dir() {
            shipped_models(&path, out);
        } else if path.extension().is_some_and(|e| e == "gbm") {
            out.push(path);
        }
    }
}

#[test]
fn shipped_models_are_formatted_and_keep_their_ir() {
    let mut models = Vec::new();
    shipped_models(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("models"),
        &mut models,
    );
    assert!(models.len() >= 19, "found {}", models.len());
    for path in models {
        let source = std::fs::read_to_string(&path).expect("read model");
        let name = path.display().to_string();
        let formatted = check_properties(&name, &source);
        assert_eq!(
            formatted, source,
            "{name} is not formatted: run `gbc fmt models/`"
        );
    }
}

#[test]
fn generated_models_format_idempotently_with_the_same_ir() {
    for seed in 0..1000u64 {
        let source = Generator::new(seed).model();
        let formatted = check_properties(&format!("seed {seed}"), &source);
        // The canonical layout is also a fixed point when produced from another layout.
        assert!(
            formatted.ends_with('\n') && !formatted.ends_with("\n\n"),
            "seed {seed}"
        );
    }
}

/// Random models that compile, written with random layout.
struct Generator {
    rng: ChaCha8Rng,
    comments: usize,
}

impl Generator {
    fn new(seed: u64) -> Self {
        Generator {
            rng: ChaCha8Rng::seed_from_u64(seed),
            comments: 0,
        }
    }

    fn chance(&mut self, p: f64) -> bool {
        self.rng.gen_bool(p)
    }

    /// Spaces (maybe none) around a token.
    fn space(&mut self) -> &'static str {
        ["", " ", " ", "  "][self.rng.gen_range(0..4)]
    }

    /// A break after an operator or comma: nothing, a space, or a newline and an indent.
    fn soft_break(&mut self) -> String {
        match self.rng.gen_range(0..10) {
            0 => format!("\n{}", " ".repeat(self.rng.gen_range(0..7))),
            1 => format!(" # note {}\n  ", self.next_comment()),
            _ => self.space().to_string(),
        }
    }

    fn next_comment(&mut self) -> usize {
        self.comments += 1;
        self.comments
    }

    fn number(&mut self) -> String {
        let choices = ["1", "0.5", "2", "3e-2", ".25", "10", "1.5E1", "7."];
        choices[self.rng.gen_range(0..choices.len())].to_string()
    }

    fn expr(&mut self, names: &[String], depth: u32) -> String {
        if depth == 0 || self.chance(0.3) {
            return if names.is_empty() || self.chance(0.3) {
                self.number()
            } else {
                names[self.rng.gen_range(0..names.len())].clone()
            };
        }
        let text = match self.rng.gen_range(0..8) {
            0 => format!("-{}", self.atom(names, depth - 1)),
            1 => {
                let function = ["exp", "softplus", "tanh", "abs"][self.rng.gen_range(0..4)];
                format!(
                    "{function}({}{})",
                    self.space(),
                    self.expr(names, depth - 1)
                )
            }
            2 => {
                let function = ["max", "min"][self.rng.gen_range(0..2)];
                let (a, b) = (self.expr(names, depth - 1), self.expr(names, depth - 1));
                let brk = self.soft_break();
                format!("{function}({a},{brk}{b})")
            }
            3 => format!("{}^{}", self.atom(names, depth - 1), self.atom(names, 0)),
            _ => {
                let op = ["+", "-", "*", "/"][self.rng.gen_range(0..4)];
                let a = self.expr(names, depth - 1);
                let b = self.expr(names, depth - 1);
                let (s, brk) = (self.space(), self.soft_break());
                format!("{a}{s}{op}{brk}{b}")
            }
        };
        if self.chance(0.2) {
            format!("({text})")
        } else {
            text
        }
    }

    /// An operand that needs no parentheses around it.
    fn atom(&mut self, names: &[String], depth: u32) -> String {
        format!("({})", self.expr(names, depth))
    }

    fn unit(&mut self, with_units: bool) -> Option<String> {
        if !with_units || self.chance(0.4) {
            return None;
        }
        let units = ["-", "g/g", "g g^-1", "mol/mol", " - ", "1", "L/L"];
        Some(format!("[{}]", units[self.rng.gen_range(0..units.len())]))
    }

    fn doc(&mut self) -> String {
        match self.rng.gen_range(0..6) {
            0 => format!("## doc {}\n", self.next_comment()),
            1 => format!("# comment {}\n", self.next_comment()),
            2 => "\n".to_string(),
            3 => "\n\n\n".to_string(),
            _ => String::new(),
        }
    }

    fn model(&mut self) -> String {
        let with_units = self.chance(0.5);
        let mut lines: Vec<String> = Vec::new();
        lines.push(format!(
            "{}model{}m{}",
            self.doc(),
            " ",
            if self.chance(0.5) { " \"a model\"" } else { "" }
        ));
        if !with_units && self.chance(0.7) {
            lines.push("time h".to_string());
        }
        let states: Vec<String> = (0..self.rng.gen_range(1..4))
            .map(|i| format!("X{i}"))
            .collect();
        let consts: Vec<String> = (0..self.rng.gen_range(0..3))
            .map(|i| format!("c{i}"))
            .collect();
        let params: Vec<String> = (0..self.rng.gen_range(0..3))
            .map(|i| format!("p{i}"))
            .collect();
        if self.chance(0.5) {
            let unit = self
                .unit(with_units)
                .map(|u| format!(" {u}"))
                .unwrap_or_default();
            lines.push(format!("input{}u{unit} in [0,{}1]", " ", self.space()));
        }
        self.declare_states(&states, with_units, &mut lines);
        for name in &consts {
            let (value, unit) = (self.number(), self.unit(with_units));
            lines.push(match (unit, self.chance(0.5)) {
                (Some(unit), true) => {
                    format!("{}const {name} {unit} ={}{value}", self.doc(), self.space())
                }
                (Some(unit), false) => format!("{}const {name}={value} {unit}", self.doc()),
                (None, _) => format!("{}const {name} = {value}", self.doc()),
            });
        }
        for name in &params {
            let unit = self
                .unit(with_units)
                .map(|u| format!(" {u}"))
                .unwrap_or_default();
            let constraint = if self.chance(0.5) {
                " positive"
            } else {
                " in [0.1, 10]"
            };
            lines.push(format!("{}param {name} = 1{unit}{constraint}", self.doc()));
        }
        let mut names: Vec<String> = states
            .iter()
            .chain(&consts)
            .chain(&params)
            .cloned()
            .collect();
        let lets: Vec<String> = (0..self.rng.gen_range(0..3))
            .map(|i| format!("l{i}"))
            .collect();
        for name in &lets {
            let expr = self.expr(&names, 3);
            lines.push(format!(
                "{}let {name}{}={}{expr}",
                self.doc(),
                self.space(),
                self.space()
            ));
            names.push(name.clone());
        }
        let closure = self.chance(0.5);
        if closure {
            lines.push(self.closure(&states, with_units));
        }
        for (index, state) in states.iter().enumerate() {
            let mut expr = self.expr(&names, 3);
            if closure && index == 0 {
                expr = format!("r0 * ({expr})");
            }
            lines.push(format!("{}der {state} = {expr}", self.doc()));
        }
        if self.chance(0.5) {
            lines.push(self.noise(&states));
        }
        if self.chance(0.5) {
            lines.push(self.effect(&states, &names, &lets));
        }
        self.join(lines)
    }

    /// `noise X0, X1 = 4 % + 0.01 [-]` in a random layout: some states, one or two terms in
    /// either order, with or without a dimensionless unit.
    fn noise(&mut self, states: &[String]) -> String {
        let count = self.rng.gen_range(1..=states.len());
        let separator = format!(",{}", self.soft_break());
        let targets = states[..count].join(&separator);
        let relative = format!("{}{}%", self.number(), self.space());
        let unit = ["", " [-]", "[%]", " [ - ]"][self.rng.gen_range(0..4)];
        let absolute = format!("{}{unit}", self.number());
        let terms = match self.rng.gen_range(0..4) {
            0 => relative,
            1 => absolute,
            2 => format!("{relative}{}+{}{absolute}", self.space(), self.soft_break()),
            _ => format!("{absolute}{}+{}{relative}", self.space(), self.soft_break()),
        };
        format!(
            "{}noise {targets}{}={}{terms}",
            self.doc(),
            self.space(),
            self.space()
        )
    }

    fn declare_states(&mut self, states: &[String], with_units: bool, lines: &mut Vec<String>) {
        let entries: Vec<String> = states
            .iter()
            .map(|name| {
                let unit = self.unit(with_units);
                let value = self.number();
                match (unit, self.chance(0.5)) {
                    (Some(unit), true) => format!("{name} {unit} = {value}"),
                    (Some(unit), false) => format!("{name} = {value} {unit}"),
                    (None, _) => format!("{name} = {value}"),
                }
            })
            .collect();
        if self.chance(0.5) {
            let separator = format!(",{}", self.soft_break());
            lines.push(format!("{}state {}", self.doc(), entries.join(&separator)));
        } else {
            for entry in entries {
                lines.push(format!("{}state {entry}", self.doc()));
            }
        }
    }

    fn closure(&mut self, states: &[String], with_units: bool) -> String {
        let unit = self
            .unit(with_units)
            .map(|u| format!(" {u}"))
            .unwrap_or_default();
        let mut inner = vec![format!("outputs r0{unit} ~ 0.1 positive")];
        inner.push(format!("observe {}", states.join(", ")));
        if self.chance(0.5) {
            inner.push("embed dim 3 delay 2".to_string());
        }
        if self.chance(0.5) {
            inner.push("network hidden [4,4] tanh".to_string());
        }
        if self.chance(0.5) {
            inner.push(format!("prior r0 *= 1 + {}", states[0]));
        }
        inner.shuffle(&mut self.rng);
        let separator = if self.chance(0.3) { "; " } else { "\n    " };
        if self.chance(0.3) {
            // A comment runs to the end of its line: last when lines are joined with `;`.
            let at = if separator == "; " {
                inner.len()
            } else {
                self.rng.gen_range(0..=inner.len())
            };
            inner.insert(at, format!("# inside {}", self.next_comment()));
        }
        format!("closure kinetics {{\n    {}\n}}", inner.join(separator))
    }

    fn effect(&mut self, states: &[String], names: &[String], lets: &[String]) -> String {
        let mut inner = vec!["param k_e = 2 positive".to_string()];
        let term = self.expr(names, 2);
        inner.push(format!("der {} += k_e * ({term})", states[0]));
        if let Some(target) = lets.first() {
            inner.push(format!("{target} *= k_e"));
        }
        format!(
            "{}effect e \"an effect\" {{ {} }}",
            self.doc(),
            inner.join("\n  ")
        )
    }

    /// Joins declarations with newlines, some with `;`, some with trailing comments.
    fn join(&mut self, lines: Vec<String>) -> String {
        let mut out = String::new();
        for (index, line) in lines.iter().enumerate() {
            out.push_str(line);
            let last = index + 1 == lines.len();
            let next_starts_plain = lines.get(index + 1).is_some_and(|l| {
                !l.starts_with('#')
                    && !l.starts_with('\n')
                    && !l.contains('{')
                    && !line.contains('}')
            });
            if !last && next_starts_plain && index > 0 && self.chance(0.15) {
                out.push(';');
                out.push_str(self.space());
            } else {
                if self.chance(0.15) {
                    out.push_str(&format!(" # trailing {}", self.next_comment()));
                }
                out.push('\n');
            }
        }
        out
    }
}
