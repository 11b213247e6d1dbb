//! `gbc compare` on the command line: bad input ends before any training, with a code and
//! exit code 1 (the comparison itself is tested in `src/compare/tests.rs`).

use super::cli::gbc;

const DATA: &str = "models/diagnose/overflow/data/overflow.csv";

fn stderr(output: &std::process::Output) -> String {
    String::from_utf8_lossy(&output.stderr).to_string()
}

#[test]
fn a_model_without_closures_needs_a_grey_box_or_a_mechanism() {
    let out = gbc(&[
        "compare",
        "models/diagnose/overflow/monod.gbm",
        DATA,
        "--holdout",
        "B4",
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("E1201"), "{}", stderr(&out));
    assert!(stderr(&out).contains("--mechanism"), "{}", stderr(&out));
}

#[test]
fn an_unknown_held_out_experiment_is_named_with_the_nearest() {
    let grey_box = "bench/training/overflow_greybox.gbm";
    let out = gbc(&["compare", grey_box, DATA, "--holdout", "B1,B9"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let message = stderr(&out);
    assert!(
        message.contains("E0419") && message.contains("B9"),
        "{message}"
    );
    assert!(message.contains("--holdout"), "{message}");
    let out = gbc(&["compare", grey_box, DATA, "--seeds", "0"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("E1204"), "{}", stderr(&out));
}
