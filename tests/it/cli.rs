//! Command-line tests: run the built `gbc` and check exit codes and output.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs gbc with `args` from the crate root.
pub fn gbc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gbc"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("NO_COLOR", "1")
        .output()
        .expect("gbc runs")
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gbc-it-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).to_string()
}

fn write(dir: &Path, name: &str, contents: &[u8]) -> String {
    let path = dir.join(name);
    std::fs::write(&path, contents).expect("write");
    path.display().to_string()
}

#[test]
fn check_accepts_every_shipped_model() {
    let models = [
        "models/mm_chemostat/truth.gbm",
        "models/mm_chemostat/greybox.gbm",
        "models/mm_chemostat/greybox_positive.gbm",
        "models/mm_chemostat/blackbox.gbm",
        "models/bioreactor/truth.gbm",
        "models/bioreactor/gb1.gbm",
        "models/bioreactor/gb2.gbm",
        "models/bioreactor/blackbox.gbm",
    ];
    let out = gbc(&[&["check"], &models[..]].concat());
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        text(&out.stdout)
            .lines()
            .filter(|l| l.starts_with("ok: "))
            .count(),
        models.len()
    );
}

#[test]
fn bioreactor_gb2_has_fifty_inputs_and_three_outputs() {
    let out = gbc(&["compile", "models/bioreactor/gb2.gbm", "--emit", "ir"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let ir = text(&out.stdout);
    assert!(
        ir.contains("network 50 -> [20, 20, 20] softplus -> 3 linear"),
        "{ir}"
    );
    assert!(ir.contains("in 49: "), "{ir}");
    assert!(!ir.contains("in 50: "), "{ir}");
    assert_eq!(
        ir.matches(", 0) * (max(n").count(),
        3,
        "three multiplicative priors on positive outputs: {ir}"
    );
}

#[test]
fn check_reports_all_errors_with_exit_code_one() {
    let dir = scratch("errors");
    let file = write(
        &dir,
        "bad.gbm",
        b"model m\nstate X = 1, Y\nder X = -k * X + expp(X)\n",
    );
    let out = gbc(&["check", &file]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    for code in ["E0101", "E0113", "E0103"] {
        assert!(stderr.contains(code), "{code} missing in {stderr}");
    }
}

#[test]
fn json_message_format_gives_code_location_and_help() {
    let dir = scratch("json");
    let file = write(
        &dir,
        "bad.gbm",
        b"model m\nconst S0 = 1\nstate S = 1\nder S = SO - S\n",
    );
    let out = gbc(&["check", "--message-format", "json", &file]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    let record: serde_json::Value =
        serde_json::from_str(stderr.lines().next().unwrap_or("{}")).expect("json");
    assert_eq!(record["code"], "gbm::E0101");
    assert_eq!(record["line"], 4);
    assert_eq!(record["column"], 9);
    assert_eq!(record["file"], file.as_str());
    assert_eq!(record["help"], "did you mean `S0`?");
    let short = gbc(&["check", "--message-format", "short", &file]);
    let expected = format!("{file}:4:9: error[gbm::E0101]: unknown name `SO`");
    assert_eq!(text(&short.stderr).trim(), expected);
}

#[test]
fn unreadable_and_binary_files_are_user_errors() {
    let dir = scratch("binary");
    let binary = write(&dir, "garbage.gbm", &[0x6d, 0x6f, 0xff, 0xfe, 0x00, 0x80]);
    let out = gbc(&["check", &binary]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("E0006"), "{}", text(&out.stderr));
    let missing = dir.join("missing.gbm").display().to_string();
    let out = gbc(&["check", &missing]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("E0008"));
    let empty = write(&dir, "empty.gbm", b"");
    let out = gbc(&["check", &empty]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("E0001"));
}

#[test]
fn deep_nesting_from_a_file_is_a_diagnostic_not_a_crash() {
    let dir = scratch("deep");
    let source = format!(
        "model m\nstate X = 1\nder X = {}X{}\n",
        "(".repeat(100_000),
        ")".repeat(100_000)
    );
    let file = write(&dir, "deep.gbm", source.as_bytes());
    let out = gbc(&["check", &file]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("E0002"));
}

#[test]
fn effects_apply_by_name_and_unknown_effects_are_reported() {
    let dir = scratch("effects");
    let file = write(
        &dir,
        "fx.gbm",
        b"model m\nstate X = 1\nconst k = 1\nlet r = k * X\nder X = -r\neffect slow {\n  param K = 2 positive\n  r *= 1 / (1 + X / K)\n  der X += 0.5\n}\n",
    );
    let out = gbc(&["compile", &file, "--effect", "slow"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("der X = -(k * X * (1 / (1 + X / K))) + 0.5"),
        "{}",
        text(&out.stdout)
    );
    let out = gbc(&["compile", &file, "--effect", "slwo"]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("E0130") && stderr.contains("did you mean `slow`?"),
        "{stderr}"
    );
}

#[test]
fn usage_errors_exit_with_one() {
    let out = gbc(&["compile"]);
    assert_eq!(out.status.code(), Some(1));
    let out = gbc(&["frobnicate"]);
    assert_eq!(out.status.code(), Some(1));
}

/// Issues 4 and 24: on the stiff record (E0 up to 1 mol/L) the sampling step is unstable;
/// `gbc train` takes the sub-steps the stiffness estimate names by itself (the run equals
/// one with `--substeps 4` asked), and the first-order grey-box model free-runs stably and
/// close to the data.
#[test]
fn stiff_chemostat_takes_its_substeps_and_gives_a_stable_free_run() {
    let dir = scratch("stiff");
    let online = |substeps: &str| {
        let json = dir.join(format!("k{substeps}.json")).display().to_string();
        let out = gbc(&[
            "train",
            "models/mm_chemostat/greybox_positive.gbm",
            "models/mm_chemostat/data/stiff.csv",
            "--train-points",
            "1000",
            "--epochs",
            "100",
            "--objective",
            "one-step",
            "--seed",
            "4",
            "--substeps",
            substeps,
            "--json",
            &json,
            "-o",
            &dir.join(format!("run{substeps}")).display().to_string(),
        ]);
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
        let report: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("json");
        let stderr = text(&out.stderr);
        let warned = stderr.contains("use --substeps");
        let took = stderr.contains("training takes 4 RK4 sub-steps per step");
        let substeps = report["substeps"].as_u64();
        (
            warned,
            took,
            substeps,
            report["metrics"]["online"]["overall"].as_f64(),
        )
    };
    let (warned, took, substeps, default) = online("1");
    assert!(!warned && took, "sub-steps not taken by default");
    assert_eq!(substeps, Some(4));
    let (warned, took, _, asked) = online("4");
    assert!(
        !warned && !took,
        "a warning or a note with the sub-steps asked for"
    );
    let asked = asked.expect("the free run with sub-steps stays in range");
    assert!(asked < 0.3, "online MSE with sub-steps {asked}");
    assert_eq!(
        default,
        Some(asked),
        "the default run is the run with --substeps 4"
    );
}
