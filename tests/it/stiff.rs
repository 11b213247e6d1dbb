//! `gbc simulate` on a stiff model: the automatic integrator finishes and matches the
//! published values; the explicit method alone spends its budget and names the balance.

use super::cli::{gbc, scratch};

const ROBERTSON: &str = "model robertson \"Robertson's kinetics\"
state y1 = 1, y2 = 0, y3 = 0
const k1 = 0.04, k2 = 3e7, k3 = 1e4
der y1 = -k1 * y1 + k3 * y2 * y3
der y2 = k1 * y1 - k3 * y2 * y3 - k2 * y2^2
der y3 = k2 * y2^2
";

fn setup(name: &str) -> (std::path::PathBuf, String) {
    let dir = scratch(name);
    let model = dir.join("robertson.gbm");
    std::fs::write(&model, ROBERTSON).unwrap();
    (dir, model.display().to_string())
}

#[test]
fn a_stiff_model_simulates_to_its_published_values() {
    let (dir, model) = setup("stiff-robertson");
    let out = dir.join("r.csv").display().to_string();
    let args = [
        "simulate", &model, "--t-end", "40", "--dt", "40", "-o", &out,
    ];
    let output = gbc(&[&args[..], &["--rtol", "1e-10", "--atol", "1e-16"]].concat());
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = std::fs::read_to_string(&out).unwrap();
    let last: Vec<f64> = (text.lines().last().unwrap().split(','))
        .map(|v| v.parse().unwrap())
        .collect();
    // Hairer and Wanner II, section IV.1: y(40), 7 digits.
    let want = [0.715_827_1, 0.918_553_5e-5, 0.284_163_7];
    for (got, want) in last[1..].iter().zip(want) {
        assert!((got - want).abs() < 2e-7 * want, "{last:?}");
    }
}

#[test]
fn a_spent_step_budget_names_the_fast_balance() {
    let (dir, model) = setup("stiff-budget");
    let out = dir.join("r.csv").display().to_string();
    let args = [
        "simulate", &model, "--t-end", "4e5", "--dt", "4e4", "-o", &out,
    ];
    let budget = ["--integrator", "explicit", "--max-steps", "5000"];
    let output = gbc(&[&args[..], &budget].concat());
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("E0707") && stderr.contains("balance of `y2`"),
        "{stderr}"
    );
    assert!(!std::path::Path::new(&out).exists(), "nothing written");
}
