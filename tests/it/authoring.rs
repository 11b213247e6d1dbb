//! Authoring commands through the built `gbc`: `init` (the README's commands run on every
//! template), `fmt`, `explain` and `completions`.

use crate::cli::scratch;
use std::path::Path;
use std::process::{Command, Output};

fn gbc_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gbc"))
        .args(args)
        .current_dir(dir)
        .env("NO_COLOR", "1")
        .output()
        .expect("gbc runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).to_string()
}

/// Splits a README command line into arguments (single quotes group, as in sh).
fn shell_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut current = String::new();
    let mut quoted = false;
    for c in line.chars() {
        match c {
            '\'' => quoted = !quoted,
            ' ' if !quoted => {
                if !current.is_empty() {
                    words.push(std::mem::take(&mut current));
                }
            }
            _ => current.push(c),
        }
    }
    if !current.is_empty() {
        words.push(current);
    }
    words
}

/// The `gbc ...` command lines of a README.
fn readme_commands(readme: &str) -> Vec<Vec<String>> {
    readme
        .lines()
        .filter(|l| l.starts_with("gbc "))
        .map(|l| shell_words(&l["gbc ".len()..]))
        .collect()
}

fn run_ok(dir: &Path, args: &[String]) -> String {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = gbc_in(dir, &refs);
    assert_eq!(
        out.status.code(),
        Some(0),
        "gbc {args:?}: {}",
        text(&out.stderr)
    );
    text(&out.stdout)
}

#[test]
fn init_makes_models_whose_readme_commands_run() {
    let dir = scratch("init");
    for template in ["chemostat", "bioreactor", "batch", "fedbatch"] {
        let name = format!("my-{template}");
        let out = gbc_in(&dir, &["init", &name, "--template", template]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let readme = std::fs::read_to_string(dir.join(&name).join("README.md")).expect("README");
        let commands = readme_commands(&readme);
        let verbs: Vec<&str> = commands.iter().map(|c| c[0].as_str()).collect();
        assert_eq!(
            verbs,
            ["check", "simulate", "diagnose", "train", "predict", "fmt"]
        );
        let checked = run_ok(&dir, &commands[0]);
        assert_eq!(
            checked.lines().filter(|l| l.starts_with("ok: ")).count(),
            2,
            "{checked}"
        );
        run_ok(&dir, &commands[1]);
        let data = std::fs::read_to_string(dir.join(&name).join("data.csv")).expect("simulated");
        assert!(
            data.lines().count() > 100,
            "{template}: {} rows",
            data.lines().count()
        );
        let formatted = run_ok(&dir, &commands[5]);
        assert!(
            formatted.is_empty(),
            "generated files are formatted: {formatted}"
        );
        if template == "batch" {
            let diagnosis = run_ok(&dir, &commands[2]);
            assert!(diagnosis.contains("credited"), "{diagnosis}");
            let mut train = commands[3].clone();
            train.extend(["--epochs".to_string(), "2".to_string()]);
            let trained = run_ok(&dir, &train);
            assert!(trained.contains("run written to"), "{trained}");
            run_ok(&dir, &commands[4]);
            assert!(dir.join(&name).join("prediction.csv").exists());
        }
    }
    let again = gbc_in(&dir, &["init", "my-batch"]);
    assert_eq!(again.status.code(), Some(1));
    assert!(
        text(&again.stderr).contains("gbm::E1003"),
        "{}",
        text(&again.stderr)
    );
    let bad = gbc_in(&dir, &["init", "9lives"]);
    assert!(
        text(&bad.stderr).contains("gbm::E1004"),
        "{}",
        text(&bad.stderr)
    );
}

#[test]
fn fmt_rewrites_checks_and_reads_stdin() {
    let dir = scratch("fmt");
    let messy = "model  m\nstate X=1 [g/L];der X=-X\n";
    let file = dir.join("m.gbm");
    std::fs::write(&file, messy).expect("write");
    let check = gbc_in(&dir, &["fmt", "--check", "m.gbm"]);
    assert_eq!(check.status.code(), Some(1));
    assert!(
        text(&check.stderr).contains("gbm::E1001"),
        "{}",
        text(&check.stderr)
    );
    assert_eq!(
        std::fs::read_to_string(&file).expect("read"),
        messy,
        "--check changes nothing"
    );
    let out = gbc_in(&dir, &["fmt", "."]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let expected = "model m\nstate X [g/L] = 1\nder X = -X\n";
    assert_eq!(std::fs::read_to_string(&file).expect("read"), expected);
    assert_eq!(
        gbc_in(&dir, &["fmt", "--check", "m.gbm"]).status.code(),
        Some(0)
    );
    let mut child = Command::new(env!("CARGO_BIN_EXE_gbc"))
        .args(["fmt", "-"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("spawn");
    use std::io::Write;
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(messy.as_bytes())
        .expect("write");
    let piped = child.wait_with_output().expect("output");
    assert_eq!(text(&piped.stdout), expected);
    let broken = gbc_in(&dir, &["fmt", "-"]);
    assert_eq!(
        broken.status.code(),
        Some(1),
        "empty input is a syntax error"
    );
    std::fs::create_dir_all(dir.join("empty")).expect("dir");
    let empty = gbc_in(&dir, &["fmt", "empty"]);
    assert!(
        text(&empty.stderr).contains("gbm::E1002"),
        "{}",
        text(&empty.stderr)
    );
}

#[test]
fn explain_prints_the_catalogue_entry() {
    let dir = scratch("explain");
    let out = gbc_in(&dir, &["explain", "E0152"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let entry = text(&out.stdout);
    assert!(entry.starts_with("## E0152 (units)"), "{entry}");
    assert!(entry.contains("1 g/L = 1000 mg/L"), "{entry}");
    let table = text(&gbc_in(&dir, &["explain", "gbm::E0215"]).stdout);
    assert!(table.contains("E0215: uneven time step"), "{table}");
    let unknown = gbc_in(&dir, &["explain", "E0125"]);
    assert_eq!(unknown.status.code(), Some(1));
    assert!(
        text(&unknown.stderr).contains("did you mean E01"),
        "{}",
        text(&unknown.stderr)
    );
}

#[test]
fn completions_cover_every_subcommand() {
    let dir = scratch("completions");
    let markers = [
        ("bash", "complete -F _gbc"),
        ("zsh", "#compdef gbc"),
        ("fish", "complete -c gbc"),
    ];
    for (shell, marker) in markers {
        let out = gbc_in(&dir, &["completions", shell]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let script = text(&out.stdout);
        assert!(script.contains(marker), "{shell}: {marker}");
        for command in [
            "check", "simulate", "train", "diagnose", "fmt", "init", "explain", "lsp",
        ] {
            assert!(script.contains(command), "{shell} script lacks `{command}`");
        }
        assert!(script.contains("template"), "{shell}: subcommand options");
        assert!(script.contains("fedbatch"), "{shell}: option values");
    }
}
