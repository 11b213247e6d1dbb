//! The TextMate grammar `editors/gbm.tmLanguage.json`: every pattern compiles (the
//! patterns stay in the syntax Oniguruma and Rust's `regex` share), and tokenising every
//! shipped model, template and golden case covers every character and gives the expected
//! scopes.

use regex::Regex;
use serde_json::Value;
use std::path::{Path, PathBuf};

struct Rule {
    regex: Regex,
    name: Option<String>,
    captures: Vec<(usize, String)>,
}

fn grammar() -> Vec<Rule> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("editors/gbm.tmLanguage.json");
    let text = std::fs::read_to_string(path).expect("grammar file");
    let json: Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(json["scopeName"], "source.gbm");
    let repository = json["repository"].as_object().expect("repository");
    let patterns = json["patterns"].as_array().expect("patterns");
    patterns
        .iter()
        .map(|pattern| {
            let include = pattern["include"]
                .as_str()
                .expect("top-level patterns are includes");
            let rule = &repository[include.trim_start_matches('#')];
            let source = rule["match"]
                .as_str()
                .unwrap_or_else(|| panic!("{include} has a match"));
            let regex = Regex::new(source).unwrap_or_else(|e| panic!("{include}: {e}"));
            let captures = rule["captures"]
                .as_object()
                .map(|c| {
                    c.iter()
                        .map(|(k, v)| {
                            (
                                k.parse().expect("group"),
                                v["name"].as_str().unwrap_or_default().to_string(),
                            )
                        })
                        .collect()
                })
                .unwrap_or_default();
            Rule {
                regex,
                name: rule["name"].as_str().map(str::to_string),
                captures,
            }
        })
        .collect()
}

/// Tokens of one line as (text, scope); panics on text no pattern covers.
fn tokenise<'a>(rules: &[Rule], line: &'a str, file: &str) -> Vec<(&'a str, String)> {
    let mut tokens = Vec::new();
    let mut position = 0;
    while position < line.len() {
        let best = rules
            .iter()
            .filter_map(|rule| {
                let found = rule.regex.captures_at(line, position)?;
                let whole = found.get(0)?;
                (!whole.is_empty()).then_some((whole.start(), rule, found))
            })
            .min_by_key(|(start, _, _)| *start);
        let Some((start, rule, found)) = best else {
            assert!(
                line[position..].trim().is_empty(),
                "{file}: uncovered `{}`",
                &line[position..]
            );
            break;
        };
        assert!(
            line[position..start].trim().is_empty(),
            "{file}: uncovered `{}` in `{line}`",
            &line[position..start]
        );
        let whole = found.get(0).expect("match");
        if rule.captures.is_empty() {
            tokens.push((
                &line[whole.start()..whole.end()],
                rule.name.clone().unwrap_or_default(),
            ));
        } else {
            for (group, scope) in &rule.captures {
                if let Some(part) = found.get(*group) {
                    tokens.push((&line[part.start()..part.end()], scope.clone()));
                }
            }
        }
        position = whole.end();
    }
    tokens
}

fn sources() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut out = Vec::new();
    let mut stack = vec![
        root.join("models"),
        root.join("src/init/templates"),
        root.join("tests/golden"),
    ];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "gbm") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

#[test]
fn grammar_covers_every_shipped_model() {
    let rules = grammar();
    let files = sources();
    assert!(files.len() > 40, "{}", files.len());
    let mut tokens = 0;
    for path in files {
        let text = std::fs::read_to_string(&path).expect("read");
        if text.len() > 100_000 {
            continue; // generated stress cases
        }
        for line in text.lines() {
            tokens += tokenise(&rules, line, &path.display().to_string()).len();
        }
    }
    assert!(tokens > 5000, "{tokens}");
}

#[test]
fn grammar_gives_the_expected_scopes() {
    let rules = grammar();
    let scope_of = |line: &str, text: &str| -> String {
        tokenise(&rules, line, "case")
            .into_iter()
            .find(|(t, _)| *t == text)
            .map(|(_, s)| s)
            .unwrap_or_else(|| panic!("`{text}` is a token of `{line}`"))
    };
    let cases = [
        (
            "## Biomass [g/L].",
            "## Biomass [g/L].",
            "comment.line.documentation.gbm",
        ),
        (
            "state X [g/L] = 0.1 # note",
            "[g/L]",
            "constant.other.unit.gbm",
        ),
        (
            "state X [g/L] = 0.1 # note",
            "# note",
            "comment.line.number-sign.gbm",
        ),
        ("state X [g/L] = 0.1 # note", "state", "keyword.other.gbm"),
        ("state X [g/L] = 0.1 # note", "0.1", "constant.numeric.gbm"),
        ("input u [-] in [0, 1]", "[-]", "constant.other.unit.gbm"),
        ("state DO [%] = 30", "[%]", "constant.other.unit.gbm"),
        ("const c = 2 [ppm/h]", "[ppm/h]", "constant.other.unit.gbm"),
        ("input u [-] in [0, 1]", "[", "punctuation.separator.gbm"),
        (
            "param Y = 0.5 [g/g] positive",
            "positive",
            "keyword.other.gbm",
        ),
        (
            "state S [g/L] = 8 nonnegative",
            "nonnegative",
            "keyword.other.gbm",
        ),
        ("closure kinetics {", "kinetics", "entity.name.type.gbm"),
        (
            "  embed delay 5 dim 10",
            "delay",
            "keyword.other.closure.gbm",
        ),
        (
            "  network hidden [20, 20] relu",
            "relu",
            "support.constant.activation.gbm",
        ),
        ("  prior mu *= exp(-A / 7)", "exp", "support.function.gbm"),
        ("  prior mu *= exp(-A / 7)", "*=", "keyword.operator.gbm"),
        ("  prior mu *= exp(-A / 7)", "mu", "variable.other.gbm"),
        (
            "effect e \"desc\" {",
            "\"desc\"",
            "string.quoted.double.gbm",
        ),
        ("const k = 1.5e-2 [1/h]", "1.5e-2", "constant.numeric.gbm"),
        ("noise X = 4 % + 0.01 [g/L]", "noise", "keyword.other.gbm"),
        ("noise X = 4 % + 0.01 [g/L]", "%", "keyword.operator.gbm"),
        (
            "noise X = 4 % + 0.01 [g/L]",
            "[g/L]",
            "constant.other.unit.gbm",
        ),
        ("noise X = 4 % + 0.01 [g/L]", "0.01", "constant.numeric.gbm"),
    ];
    for (line, text, scope) in cases {
        assert_eq!(scope_of(line, text), scope, "`{text}` in `{line}`");
    }
}
