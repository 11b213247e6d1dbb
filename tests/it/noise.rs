//! Measurement noise from the command line: `gbc simulate --noise` with the model's `noise`
//! declarations, the IR text, and every bad `--noise` spec a clear error with exit code 1.

use super::cli::{gbc, scratch};
use std::path::Path;

/// A decay with a measured state, an output and a hidden state; X and P declare noise.
const MODEL: &str = "model decay\ntime h\nstate X [g/L] = 1, S [g/L] = 2\nhidden E [-] = 1\n\
const k = 0.01 [1/h]\noutput P [g/L] = 3 - X\nder X = -k * E * X\nder S = -k * S\n\
der E = 0\nnoise X = 0.05 [g/L]\nnoise P = 10 %\n";

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).to_string()
}

/// The columns of a CSV file with a header, by name.
fn columns(path: &Path) -> Vec<(String, Vec<f64>)> {
    let content = std::fs::read_to_string(path).expect("written");
    let mut lines = content.lines();
    let header: Vec<String> = (lines.next().expect("header").split(','))
        .map(str::to_string)
        .collect();
    let mut values = vec![Vec::new(); header.len()];
    for line in lines {
        for (column, cell) in values.iter_mut().zip(line.split(',')) {
            column.push(cell.parse::<f64>().expect("a number"));
        }
    }
    header.into_iter().zip(values).collect()
}

fn column<'a>(table: &'a [(String, Vec<f64>)], name: &str) -> &'a [f64] {
    let found = table.iter().find(|(n, _)| n.starts_with(name));
    &found.unwrap_or_else(|| panic!("no column {name}")).1
}

/// The standard deviation of `noisy - clean` (population), optionally relative to `clean`.
fn spread(noisy: &[f64], clean: &[f64], relative: bool) -> f64 {
    let errors: Vec<f64> = (noisy.iter().zip(clean))
        .map(|(y, c)| if relative { y / c - 1.0 } else { y - c })
        .collect();
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt()
}

/// Simulates [`MODEL`] for 2000 h at 1 h with `extra` arguments; the table written.
fn simulate(dir: &Path, name: &str, extra: &[&str]) -> Vec<(String, Vec<f64>)> {
    let model = dir.join("decay.gbm");
    std::fs::write(&model, MODEL).expect("write model");
    let out_path = dir.join(name);
    let (model, out) = (model.display().to_string(), out_path.display().to_string());
    let mut args = vec![
        "simulate", &model, "--t-end", "2000", "--dt", "1", "--hidden", "-o", &out,
    ];
    args.extend(extra);
    let run = gbc(&args);
    assert_eq!(run.status.code(), Some(0), "{}", text(&run.stderr));
    columns(&out_path)
}

#[test]
fn simulate_adds_the_declared_noise_only_when_asked() {
    let dir = scratch("noise-declared");
    let clean = simulate(&dir, "clean.csv", &[]);
    let declared = simulate(
        &dir,
        "declared.csv",
        &["--noise", "declared", "--seed", "3"],
    );
    let x = spread(column(&declared, "X"), column(&clean, "X"), false);
    assert!((x / 0.05 - 1.0).abs() < 0.1, "X: std {x} for 0.05 g/L");
    let p = spread(column(&declared, "P"), column(&clean, "P"), true);
    assert!((p / 0.1 - 1.0).abs() < 0.1, "P: relative std {p} for 10 %");
    for exact in ["t", "S", "E"] {
        assert_eq!(column(&declared, exact), column(&clean, exact), "{exact}");
    }
    // A named spec replaces a declaration; `X=0` removes one; a bare level covers every
    // measured state and the outputs that declare noise.
    let laid_over = simulate(
        &dir,
        "over.csv",
        &[
            "--noise", "declared", "--noise", "X=0", "--noise", "S=2%", "--seed", "3",
        ],
    );
    assert_eq!(column(&laid_over, "X"), column(&clean, "X"));
    let s = spread(column(&laid_over, "S"), column(&clean, "S"), true);
    assert!((s / 0.02 - 1.0).abs() < 0.1, "S: relative std {s} for 2 %");
    let bare = simulate(&dir, "bare.csv", &["--noise", "0.01", "--seed", "3"]);
    for name in ["X", "S", "P"] {
        let relative = spread(column(&bare, name), column(&clean, name), true);
        assert!((relative / 0.01 - 1.0).abs() < 0.1, "{name}: {relative}");
    }
    assert_eq!(
        column(&bare, "E"),
        column(&clean, "E"),
        "hidden states stay exact"
    );
}

#[test]
fn the_ir_lists_the_declared_noise_in_the_quantity_unit() {
    let dir = scratch("noise-ir");
    let model = dir.join("decay.gbm");
    let source = MODEL.replace("noise X = 0.05 [g/L]", "noise X = 4 % + 20 [mg/L]");
    std::fs::write(&model, source).expect("write model");
    let out = gbc(&["compile", &model.display().to_string(), "--emit", "ir"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let ir = text(&out.stdout);
    assert!(
        ir.contains(
            "noise (sigma(y) = sqrt(absolute^2 + (relative * y)^2))\n\
             \x20 state X [g/L]: relative 0.04, absolute 0.02\n\
             \x20 output P [g/L]: relative 0.1, absolute 0\n"
        ),
        "{ir}"
    );
}

#[test]
fn bad_noise_specs_are_refused_with_exit_code_one() {
    let dir = scratch("noise-errors");
    let model = dir.join("decay.gbm");
    std::fs::write(&model, MODEL).expect("write model");
    let output = dir.join("never.csv");
    let (model, out) = (model.display().to_string(), output.display().to_string());
    let refused = |noise: &[&str], expected: &[&str]| {
        let mut args = vec!["simulate", &model, "--t-end", "5", "--dt", "1", "-o", &out];
        args.extend(noise);
        let run = gbc(&args);
        let stderr = text(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{noise:?}: {stderr}");
        for part in expected {
            assert!(stderr.contains(part), "{noise:?}: `{part}` not in {stderr}");
        }
    };
    refused(
        &["--noise", "Xx=1%"],
        &["gbm::E0134", "found `Xx`", "did you mean `X`?"],
    );
    refused(
        &["--noise", "E=1%"],
        &["gbm::E0134", "`E`, a hidden state (never measured)"],
    );
    refused(
        &["--noise", "S=1%", "--noise", "S=2%"],
        &[
            "gbm::E0135",
            "expected one `--noise` spec for `S`, found two",
        ],
    );
    refused(
        &["--noise", "-1"],
        &["expected a finite noise level >= 0, found `-1`"],
    );
    refused(
        &["--noise", "X=0.01[g/L]"],
        &["expected a number in the noise level"],
    );
    assert!(!output.exists(), "nothing written");
    // diagnose checks its specs against the model before it reads the data.
    let run = gbc(&["diagnose", &model, "missing.csv", "--noise", "E=1%"]);
    assert_eq!(run.status.code(), Some(1));
    assert!(
        text(&run.stderr).contains("gbm::E0134"),
        "{}",
        text(&run.stderr)
    );
}
