//! What-if runs (`gbc simulate --weights`), weights matched to models by structure, and
//! mechanistic runs with fitted params, an effect and initial values, through the built
//! `gbc`.

use std::path::{Path, PathBuf};

use crate::cli::{gbc, scratch};

const GB1: &str = "models/bioreactor/gb1.gbm";
const STEPS: &str = "models/bioreactor/data/steps.csv";

/// Header and columns of a CSV file.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut reader = csv::Reader::from_path(path).expect("csv");
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    let mut columns = vec![Vec::new(); header.len()];
    for row in reader.records() {
        for (column, cell) in columns.iter_mut().zip(row.unwrap().iter()) {
            column.push(cell.parse().unwrap());
        }
    }
    (header, columns)
}

fn run_ok(args: &[&str]) -> String {
    let output = gbc(args);
    let stderr = String::from_utf8_lossy(&output.stderr).to_string();
    assert!(output.status.success(), "gbc {args:?} failed:\n{stderr}");
    stderr
}

/// GB1 trained briefly in f64 on the shipped record.
fn trained_gb1(dir: &Path) -> PathBuf {
    let run = dir.join("run");
    let run_text = run.display().to_string();
    run_ok(&[
        "train",
        GB1,
        STEPS,
        "--precision",
        "f64",
        "--epochs",
        "1",
        "--objective",
        "one-step",
        "--train-points",
        "200",
        "-o",
        &run_text,
    ]);
    run
}

/// A copy of GB1 with `from` replaced by `to`.
fn edited_gb1(dir: &Path, name: &str, from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(GB1).unwrap();
    assert!(text.contains(from), "{from}");
    let path = dir.join(name);
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
    path.display().to_string()
}

#[test]
fn a_what_if_run_along_the_records_own_light_reproduces_the_online_prediction() {
    let dir = scratch("whatif-gb1");
    let run = trained_gb1(&dir);
    let run = run.display().to_string();
    assert!(
        dir.join("run/model.gbm").exists(),
        "the run keeps the model source"
    );
    let online = dir.join("online.csv").display().to_string();
    run_ok(&[
        "predict",
        GB1,
        STEPS,
        "--weights",
        &run,
        "--mode",
        "online",
        "--history",
        "measured",
        "-o",
        &online,
    ]);
    let whatif = dir.join("whatif.csv").display().to_string();
    let light = format!("u=csv({STEPS})");
    let simulate = |model: &str, output: &str| {
        gbc(&[
            "simulate",
            model,
            "--weights",
            &run,
            "--input",
            &light,
            "--history",
            STEPS,
            "--t-start",
            "45",
            "--t-end",
            "2999",
            "-o",
            output,
        ])
    };
    let output = simulate(GB1, &whatif);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let (online_header, online) = read_csv(Path::new(&online));
    let (header, ours) = read_csv(Path::new(&whatif));
    assert_eq!(header[0], "t");
    assert_eq!(header[1], "u");
    assert_eq!(&header[2..], &online_header[1..]);
    assert_eq!(ours[0].len(), 2955);
    assert_eq!(ours[0], online[0]);
    for (name, (a, b)) in header[2..].iter().zip(ours[2..].iter().zip(&online[1..])) {
        for (x, y) in a.iter().zip(b) {
            assert!(
                (x - y).abs() <= 1e-9 * y.abs().max(1e-12),
                "{name}: {x} vs {y}"
            );
        }
    }
    // Another comment: accepted, and said so.
    let commented = edited_gb1(
        &dir,
        "commented.gbm",
        "## Biomass balance",
        "# tried again\n## Biomass balance",
    );
    let output = simulate(&commented, &dir.join("commented.csv").display().to_string());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("structure is the same"), "{stderr}");
    assert_eq!(read_csv(&dir.join("commented.csv")).1, ours, "the same run");
    // Another dilution rate: a what-if on the physics, named in a note.
    let diluted = edited_gb1(&dir, "diluted.gbm", "const D = 0.05", "const D = 0.06");
    let output = simulate(&diluted, &dir.join("diluted.csv").display().to_string());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("const D = 0.06 (trained with 0.05)"),
        "{stderr}"
    );
    assert_ne!(read_csv(&dir.join("diluted.csv")).1[2], ours[2]);
    // A wider network: refused, naming what changed.
    let wider = edited_gb1(
        &dir,
        "wider.gbm",
        "hidden [20, 20, 20]",
        "hidden [21, 20, 20]",
    );
    let never = dir.join("never.csv");
    let output = simulate(&wider, &never.display().to_string());
    // The diagnostic wraps at 100 columns: compare with its words joined by single spaces.
    let stderr: String = String::from_utf8_lossy(&output.stderr).replace('│', " ");
    let stderr = stderr.split_whitespace().collect::<Vec<_>>().join(" ");
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("E0416"), "{stderr}");
    for part in [
        "closure kinetics network",
        "`hidden [20, 20, 20] softplus`",
        "`hidden [21, 20, 20]",
    ] {
        assert!(stderr.contains(part), "{stderr}");
    }
    assert!(!never.exists());
}

#[test]
fn a_what_if_run_from_a_held_start_follows_a_new_light_programme() {
    let dir = scratch("whatif-held");
    let run = trained_gb1(&dir).display().to_string();
    let out = dir.join("held.csv").display().to_string();
    let args = [
        "simulate",
        GB1,
        "--weights",
        &run,
        "--input",
        "u=steps(hold=10..20, seed=4)",
        "--t-end",
        "100",
        "--init",
        "X=0.1",
        "--init",
        "A=2",
        "--init",
        "B=0.45",
        "--init",
        "S=15",
        "-o",
        &out,
    ];
    run_ok(&args);
    let (header, columns) = read_csv(Path::new(&out));
    assert_eq!(header, ["t", "u", "X", "A", "B", "S", "mu", "mu_A", "mu_B"]);
    assert_eq!(columns[0].len(), 101, "dt defaults to the run's step");
    assert_eq!(
        (columns[2][0], columns[3][0], columns[4][0], columns[5][0]),
        (0.1, 2.0, 0.45, 15.0)
    );
    assert!(
        columns[1].windows(2).any(|w| w[0] != w[1]),
        "the light switches"
    );
    // Without an initial value for a state the run cannot start.
    let missing = gbc(&[
        "simulate",
        GB1,
        "--weights",
        &run,
        "--input",
        "u=const(0.5)",
        "--t-end",
        "10",
        "-o",
        &out,
    ]);
    let stderr = String::from_utf8_lossy(&missing.stderr);
    assert!(
        stderr.contains("E0714") && stderr.contains("--init X="),
        "{stderr}"
    );
    let unknown = gbc(&[
        "simulate",
        GB1,
        "--weights",
        &run,
        "--input",
        "u=const(0.5)",
        "--t-end",
        "10",
        "--init",
        "Q=1",
        "-o",
        &out,
    ]);
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("E0715"));
}

/// The chemostat diagnosis model with `edit` applied (`from` -> `to`), written to `dir`.
fn chemostat_copy(dir: &Path, name: &str, edits: &[(&str, &str)]) -> String {
    let mut text = std::fs::read_to_string("models/diagnose/chemostat/model.gbm").unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{from}");
        text = text.replacen(from, to, 1);
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

#[test]
fn a_mechanistic_run_takes_fitted_params_an_effect_and_initial_values() {
    let dir = scratch("whatif-params");
    let fit = dir.join("diagnosis.json");
    std::fs::write(
        &fit,
        r#"{"fitted_params": {"kcat": 0.14},
            "effects": [{"name": "product_inhibition", "params": {"kcat": 0.15, "K_P": 1e300}}]}"#,
    )
    .unwrap();
    let fit = fit.display().to_string();
    let simulate = |model: &str, name: &str, extra: &[&str]| {
        let out = dir.join(name);
        let mut args = vec![
            "simulate",
            model,
            "--t-end",
            "200",
            "--dt",
            "1",
            "--input",
            "E0=steps(hold=20..40, seed=2)",
        ];
        args.extend(extra);
        let out_text = out.display().to_string();
        args.extend(["-o", &out_text]);
        run_ok(&args);
        read_csv(&out).1
    };
    let model = "models/diagnose/chemostat/model.gbm";
    let fitted = simulate(model, "fitted.csv", &["--params", &fit, "--init", "S=0.02"]);
    let by_hand = chemostat_copy(
        &dir,
        "by_hand.gbm",
        &[
            ("kcat = 0.1", "kcat = 0.14"),
            ("state S [mol/L] = 0.0147", "state S [mol/L] = 0.02"),
        ],
    );
    assert_eq!(fitted, simulate(&by_hand, "by_hand.csv", &[]));
    // With the effect: its refitted params (an inhibition constant too large to act).
    let effect = simulate(
        model,
        "effect.csv",
        &["--params", &fit, "--effect", "product_inhibition"],
    );
    let no_effect = chemostat_copy(&dir, "kcat.gbm", &[("kcat = 0.1", "kcat = 0.15")]);
    assert_eq!(effect, simulate(&no_effect, "kcat.csv", &[]));
    assert_ne!(effect, simulate(model, "plain.csv", &[]));
    // A train run's params read the same way; a file without params is refused.
    std::fs::write(
        dir.join("run.json"),
        r#"{"params": [{"name": "kcat", "value": 0.14}]}"#,
    )
    .unwrap();
    let run_json = dir.join("run.json").display().to_string();
    let from_run = simulate(
        model,
        "run.csv",
        &["--params", &run_json, "--init", "S=0.02"],
    );
    assert_eq!(from_run, fitted);
    std::fs::write(dir.join("empty.json"), "{}").unwrap();
    let empty = dir.join("empty.json").display().to_string();
    let out = dir.join("never.csv").display().to_string();
    let refused = gbc(&[
        "simulate",
        model,
        "--t-end",
        "10",
        "--dt",
        "1",
        "--input",
        "E0=const(0.01)",
        "--params",
        &empty,
        "-o",
        &out,
    ]);
    assert!(String::from_utf8_lossy(&refused.stderr).contains("E0716"));
}
