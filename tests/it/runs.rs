//! Issue 24, "nothing lost": a run whose epoch goes non-finite first recovers by itself
//! (back to the last finite epoch at half the learning rate) and, when it cannot, keeps its
//! run directory with the last finite weights and a run.json that says it failed, with or
//! without `-o DIR`; `--cv` keeps every fold.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::cli::{gbc, scratch};

// Eight epochs of GB1: one-step warm-up in epochs 1 to 4, rollouts from epoch 5 on.
use crate::safety::{GB1, SHORT, STEPS};

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).to_string()
}

fn run_json(run: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(run.join("run.json"))
        .unwrap_or_else(|e| panic!("{}: {e}", run.display()));
    serde_json::from_str(&text).unwrap()
}

/// `gbc train` of GB1 in `cwd` with [`SHORT`] and `extra`, model and data by absolute path.
fn train_in(cwd: &Path, extra: &[&str]) -> Output {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let (model, data) = (root.join(GB1), root.join(STEPS));
    Command::new(env!("CARGO_BIN_EXE_gbc"))
        .arg("train")
        .args([&model, &data])
        .args(SHORT)
        .args(extra)
        .current_dir(cwd)
        .env("NO_COLOR", "1")
        .output()
        .expect("gbc runs")
}

/// The loss of epoch 5, the first rollout epoch, reads NaN once: training goes back to
/// epoch 4's weights at half the learning rate, finishes, and says so on stderr and in
/// run.json.
#[test]
fn a_nan_at_the_switch_to_rollouts_is_recovered_and_reported() {
    let dir = scratch("runs-recover");
    let run = dir.join("run");
    let output = train_in(
        &dir,
        &["-o", run.to_str().unwrap(), "--poison-epoch", "5:1"],
    );
    let message = stderr(&output);
    assert!(output.status.success(), "{message}");
    assert!(
        message.contains("warning: epoch 5 (rollouts of 2 steps) went non-finite"),
        "{message}"
    );
    let info = run_json(&run);
    assert_eq!(info["status"], "finished");
    assert!(info.get("diverged").is_none(), "{info}");
    let recoveries = info["recoveries"].as_array().unwrap();
    assert_eq!(recoveries.len(), 1);
    assert_eq!(recoveries[0]["epoch"], 5);
    assert_eq!(recoveries[0]["back_to"], 4);
    assert_eq!(recoveries[0]["phase"], "rollouts of 2 steps");
    let rate = recoveries[0]["learning_rate"].as_f64().unwrap();
    let asked = info["training"]["learning_rate"].as_f64().unwrap();
    assert!((rate - asked / 2.0).abs() < 1e-15, "{rate} vs {asked}");
}

/// The loss of epoch 5 reads NaN on every try: after the recoveries the run fails with
/// E0415 naming the epoch and the phase, and its directory (here the default one under
/// runs/, no `-o`) keeps epoch 4's weights and a run.json that says it failed and why.
#[test]
fn a_run_that_cannot_recover_keeps_its_directory_and_says_why() {
    let dir = scratch("runs-failed");
    let output = train_in(&dir, &["--poison-epoch", "5:100", "--recoveries", "2"]);
    let message = stderr(&output);
    assert_eq!(output.status.code(), Some(1), "{message}");
    assert!(message.contains("E0415"), "{message}");
    assert!(message.contains("epoch 5"), "{message}");
    assert!(message.contains("rollouts of 2 steps"), "{message}");
    assert!(message.contains("--horizon"), "the advice: {message}");
    let runs: Vec<PathBuf> = std::fs::read_dir(dir.join("runs"))
        .expect("the default run directory")
        .map(|entry| entry.unwrap().path())
        .collect();
    assert_eq!(runs.len(), 1, "{runs:?}");
    let run = &runs[0];
    assert!(run.join("weights.safetensors").is_file());
    let info = run_json(run);
    assert_eq!(info["status"], "failed");
    assert_eq!(info["diverged"]["epoch"], 5);
    assert_eq!(info["diverged"]["kept_epoch"], 4);
    assert_eq!(info["diverged"]["phase"], "rollouts of 2 steps");
    assert!(info["diverged"]["what"].as_str().unwrap().contains("NaN"));
    assert!(info["diverged"]["advice"]
        .as_str()
        .unwrap()
        .contains("--lr"));
    assert_eq!(info["recoveries"].as_array().unwrap().len(), 2);
    let output = gbc(&[
        "predict",
        GB1,
        STEPS,
        "--weights",
        run.to_str().unwrap(),
        "-o",
        dir.join("predicted.csv").to_str().unwrap(),
    ]);
    assert!(output.status.success(), "{}", stderr(&output));
}

/// A decay, S = 2 exp(-t / 100): below 1 from t = 69.3 h on.
const DECAY: &str = "model decay\ntime h\nstate S [g/L] = 2\nder S = -0.01 * S\n";

/// `gbc simulate --range` judges a plain simulation by the rule every free run is judged
/// by: it stops before the first sample outside, saying the time, the state and why.
#[test]
fn a_simulation_that_leaves_its_range_stops_there_saying_why() {
    let dir = scratch("runs-simulate-range");
    let model = dir.join("decay.gbm");
    std::fs::write(&model, DECAY).unwrap();
    let out = dir.join("decay.csv");
    let (model, out_text) = (model.to_str().unwrap(), out.to_str().unwrap());
    let base = [
        "simulate", model, "--t-end", "200", "--dt", "1", "-o", out_text,
    ];
    let run = gbc(&[&base[..], &["--range", "S=1.."]].concat());
    let message = stderr(&run);
    assert_eq!(run.status.code(), Some(0), "{message}");
    assert!(
        message.contains("S = 0.9932 at t = 70, below its floor 1"),
        "{message}"
    );
    let rows = std::fs::read_to_string(&out).unwrap().lines().count();
    assert_eq!(rows, 1 + 70, "the header and t = 0 to 69");
    // Unbounded by default: the whole run, no warning.
    let run = gbc(&base);
    assert_eq!(run.status.code(), Some(0), "{}", stderr(&run));
    assert!(!stderr(&run).contains("diverged"), "{}", stderr(&run));
    assert_eq!(std::fs::read_to_string(&out).unwrap().lines().count(), 202);
    let run = gbc(&[&base[..], &["--range", "Q=0..1"]].concat());
    assert_eq!(run.status.code(), Some(1), "{}", stderr(&run));
    assert!(stderr(&run).contains("E0718"), "{}", stderr(&run));
}
