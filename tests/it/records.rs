//! `gbc train` and `gbc predict` on data sets: several experiments, irregular times, missing
//! cells, and every bad data set a clear coded error with exit code 1; `gbc simulate
//! --input u=csv(...)` reading a lab record's input the same way.

use crate::cli::{gbc, scratch};
use std::path::Path;

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).to_string()
}

fn write(dir: &Path, name: &str, contents: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, contents).expect("write");
    path.display().to_string()
}

/// A small irregular chemostat-like experiment (the grey box's columns).
fn experiment(rows: usize, offset: f64) -> String {
    let mut text = String::from("t [s],E0 [mol/L],S [mol/L]\n");
    let mut time = 0.0;
    for row in 0..rows {
        let e0 = if (row / 7) % 2 == 0 { 0.005 } else { 0.015 };
        let s = 0.015 + 0.004 * ((time + offset) / 13.0_f64).sin();
        let cell = if row % 5 == 3 {
            String::new()
        } else {
            format!("{s}")
        };
        text.push_str(&format!("{time},{e0},{cell}\n"));
        time += 1.0 + 0.5 * ((row % 3) as f64);
    }
    text
}

/// The command fails with exit code 1 and stderr holding every one of `expected`.
fn refused(args: &[&str], expected: &[&str]) {
    let out = gbc(args);
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{args:?}\n{stderr}");
    for part in expected {
        assert!(stderr.contains(part), "missing `{part}` in:\n{stderr}");
    }
}

const MODEL: &str = "models/mm_chemostat/greybox.gbm";

#[test]
fn training_on_several_irregular_experiments_validates_the_held_out_one() {
    let dir = scratch("records-train");
    let a = write(&dir, "a.csv", &experiment(90, 0.0));
    let b = write(&dir, "b.csv", &experiment(80, 5.0));
    let c = write(&dir, "c.csv", &experiment(70, 9.0));
    let run = dir.join("run").display().to_string();
    let out = gbc(&[
        "train",
        MODEL,
        &a,
        &b,
        &c,
        "--holdout",
        "c",
        "--epochs",
        "2",
        "-o",
        &run,
    ]);
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(stdout.contains("validation on c ("), "{stdout}");
    // The run's report page: the fit of every experiment by role, and the figures.
    let page = std::fs::read_to_string(dir.join("run/report.html")).expect("report.html");
    assert!(page.contains("<h2>Fit per state</h2>"), "{page}");
    assert!(page.contains("<td>c</td><td>validation</td>"), "{page}");
    assert!(page.contains("<td>a</td><td>training</td>"), "{page}");
    assert!(
        page.matches("<svg").count() >= 4,
        "loss, states and closures drawn"
    );
    // Without a choice, the last experiment validates and the user is told.
    let second = dir.join("run2").display().to_string();
    let out = gbc(&["train", MODEL, &a, &b, &c, "--epochs", "1", "-o", &second]);
    assert!(text(&out.stderr).contains("validating on experiment `c`"));
    // Predictions of two experiments in one file, each row labelled.
    let predictions = dir.join("p.csv").display().to_string();
    let out = gbc(&[
        "predict",
        MODEL,
        "--weights",
        &run,
        &a,
        &b,
        "--mode",
        "online",
        "-o",
        &predictions,
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let table = std::fs::read_to_string(&predictions).unwrap();
    assert!(table.starts_with("experiment,t,S,r\n"), "{table}");
    assert_eq!(table.lines().filter(|l| l.starts_with("a,")).count(), 90);
    assert_eq!(table.lines().filter(|l| l.starts_with("b,")).count(), 80);
    // Cross-validation reports each fold and the median.
    let folds = dir.join("cv").display().to_string();
    let out = gbc(&[
        "train", MODEL, &a, &b, &c, "--cv", "--epochs", "1", "-o", &folds,
    ]);
    let stdout = text(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert!(stdout.contains("cross-validation (3 folds"), "{stdout}");
    assert!(stdout.contains("median"), "{stdout}");
    assert!(stdout.contains("pooled"), "{stdout}");
    assert!(!stdout.contains("nothing validates"), "{stdout}");
    // Every fold is kept: its run, its held-out free run, and the summary.
    let kept = dir.join("cv").join("cv");
    for (k, name) in ["a", "b", "c"].iter().enumerate() {
        let fold = kept.join(format!("fold-0{}-{name}", k + 1));
        assert!(
            fold.join("weights.safetensors").is_file(),
            "{}",
            fold.display()
        );
        assert!(fold.join("run.json").is_file());
        let predicted = std::fs::read_to_string(fold.join("predictions.csv")).unwrap();
        assert!(predicted.starts_with("t,S,r\n"), "{predicted}");
        assert!(predicted.lines().count() > 10, "{predicted}");
    }
    let summary = std::fs::read_to_string(kept.join("summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&summary).unwrap();
    assert_eq!(summary["folds"].as_array().unwrap().len(), 3);
    assert_eq!(summary["folds"][1]["run"], "cv/fold-02-b");
    assert!(
        summary["pooled_online"]["per_state"].is_array(),
        "{summary}"
    );
}

#[test]
fn bad_data_sets_are_refused_naming_file_row_and_column() {
    let dir = scratch("records-bad");
    let good = write(&dir, "good.csv", &experiment(60, 0.0));
    let duplicate = write(
        &dir,
        "dup.csv",
        "t,E0,S\n0,0.01,0.02\n1,0.01,0.02\n1,0.01,0.021\n",
    );
    refused(
        &["train", MODEL, &duplicate],
        &["E0214", "dup.csv", "row 4"],
    );
    let empty_state = write(&dir, "nos.csv", "t,E0,S\n0,0.01,\n1,0.01,\n2,0.01,NA\n");
    refused(&["train", MODEL, &empty_state], &["E0223", "`S`", "nos"]);
    let no_input = write(&dir, "noin.csv", "t,E0,S\n0,,0.02\n1,0.01,0.02\n");
    refused(&["train", MODEL, &no_input], &["E0222", "`E0`", "row 2"]);
    let infinite = write(&dir, "inf.csv", "t,E0,S\n0,0.01,0.02\n1,0.01,inf\n");
    refused(&["train", MODEL, &infinite], &["E0212", "inf.csv", "row 3"]);
    let mixed = write(&dir, "mixed.csv", "t;E0;S\n0,0.01,0.02\n1,0.01,0.02\n");
    refused(&["train", MODEL, &mixed], &["E0217", "mixed.csv"]);
    refused(
        &["train", MODEL, &good, "--column", "Q=S"],
        &["E0218", "unknown `--column` name `Q`"],
    );
    // Too short for the embedding's history (40 s) when runs start from measured history.
    let short = write(&dir, "short.csv", &experiment(20, 0.0));
    refused(
        &[
            "train",
            MODEL,
            &good,
            &short,
            "--holdout",
            "short",
            "--history",
            "measured",
        ],
        &["E0428", "`short`", "40"],
    );
    // Hold-outs that leave a part too small say what each part needs and got.
    refused(
        &["train", MODEL, &good, "--val-fraction", "0.01"],
        &["E0424", "at least 2 rows", "59 training and 1 held-out"],
    );
    refused(&["train", MODEL, &good, "--holdout", "good"], &["E0427"]);
    refused(
        &["train", MODEL, &good, "--holdout", "goood"],
        &["E0419", "--holdout", "did you mean `good`"],
    );
    // A discrete map on irregular times points to the continuous black box.
    refused(
        &["train", "models/mm_chemostat/blackbox.gbm", &good],
        &["E0425", "blackbox_ode.gbm"],
    );
}

/// A study on a data set: the held-out experiment free-runs whole, a size counts training
/// pairs over the training experiments, and each run trains exactly what `gbc train` trains
/// on the same experiments (the same final loss, bit for bit); bad splits are refused.
#[test]
fn experiment_on_a_data_set_holds_out_whole_experiments() {
    let dir = scratch("records-study");
    let a = write(&dir, "a.csv", &experiment(90, 0.0));
    let b = write(&dir, "b.csv", &experiment(80, 5.0));
    let c = write(&dir, "c.csv", &experiment(70, 9.0));
    let model = format!("gb={MODEL}");
    let study = |extra: &[&str], out: &str| {
        let mut args = vec![
            "experiment",
            "--model",
            &model,
            "--data",
            &a,
            "--data",
            &b,
            "--data",
            &c,
            "--replicates",
            "1",
            "--epochs",
            "2",
            "--training",
            "multi-step",
            "--jobs",
            "1",
            "--out",
            out,
        ];
        args.extend_from_slice(extra);
        gbc(&args)
    };
    let out_dir = dir.join("study").display().to_string();
    let out = study(&["--holdout", "c", "--sizes", "40"], &out_dir);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let results: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("study/results.json")).expect("results"),
    )
    .expect("json");
    let run = &results[0];
    assert_eq!(run["train_pairs"], 40, "{run}");
    assert!(
        run["online_mse"].as_f64().is_some_and(f64::is_finite),
        "{run}"
    );
    assert!(dir.join("study/figures/heldout_c_S.svg").exists());
    // The same training through `gbc train`.
    let json = dir.join("train.json").display().to_string();
    let run_dir = dir.join("train-run").display().to_string();
    let out = gbc(&[
        "train",
        MODEL,
        &a,
        &b,
        &c,
        "--holdout",
        "c",
        "--train-points",
        "40",
        "--epochs",
        "2",
        "--seed",
        "1",
        "--json",
        &json,
        "-o",
        &run_dir,
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    let trained: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("json");
    assert_eq!(trained["training"]["train_pairs"], 40);
    assert_eq!(
        trained["training"]["final_loss"].as_f64(),
        run["final_loss"].as_f64()
    );
    assert_eq!(
        trained["training"]["validation_pairs"],
        run["validation_pairs"]
    );
    // An unknown experiment, a size above the pairs there are, several files without
    // held-out experiments: each refused with exit code 1.
    let bad = |extra: &[&str], expected: &str| {
        let out = study(extra, &dir.join("bad").display().to_string());
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{extra:?}\n{stderr}");
        assert!(
            stderr.contains(expected),
            "missing `{expected}` in:\n{stderr}"
        );
    };
    bad(&["--holdout", "d", "--sizes", "40"], "experiments");
    bad(
        &["--holdout", "c", "--sizes", "100000"],
        "training pairs of `gb`",
    );
    bad(&["--val-from", "50", "--sizes", "40"], "--holdout NAME");
}

/// `gbc simulate` of `der X = u` (so `X` is the integral of the input) from 0 to 4 h at
/// 0.5 h, under the input programme `programme`; the output's text, or the failure.
fn integrate(dir: &Path, programme: &str, output: &str) -> Result<String, String> {
    let model = write(
        dir,
        "tank.gbm",
        "model tank\ntime h\ninput u [%] in [0, 100]\nstate X [% h] = 0\nder X = u\n",
    );
    let output = dir.join(output).display().to_string();
    let out = gbc(&[
        "simulate", &model, "--t-end", "4", "--dt", "0.5", "--input", programme, "-o", &output,
    ]);
    match out.status.code() {
        Some(0) => Ok(std::fs::read_to_string(&output).expect("written")),
        _ => Err(text(&out.stderr)),
    }
}

#[test]
fn simulate_reads_a_lab_record_input_like_any_record() {
    let dir = scratch("simulate-csv-input");
    let schedule = integrate(&dir, "u=schedule(0:20, 2.5:70)", "schedule.csv").expect("runs");
    let last = schedule.lines().last().unwrap_or_default().to_string();
    let x_end: f64 = last
        .split(',')
        .nth(2)
        .and_then(|x| x.parse().ok())
        .unwrap_or(f64::NAN);
    assert!((x_end - (20.0 * 2.5 + 70.0 * 1.5)).abs() < 1e-6, "{last}");
    let lab = write(
        &dir,
        "lab.csv",
        "experiment,t [h],DO [%],u [%]\nday1,0,95,10\nday2,0,96,20\nday2,0.7,,\n\
         day2,2.5,90,70\nday2,3.5,88,NA\n",
    );
    let record = integrate(&dir, &format!("u=csv({lab}, u, day2)"), "record.csv").expect("runs");
    assert_eq!(
        record, schedule,
        "held cells and an irregular grid give the schedule's run"
    );
    let error = integrate(&dir, &format!("u=csv({lab})"), "none.csv").expect_err("fails");
    assert!(error.contains("gbm::E0319"), "{error}");
    assert!(error.contains("experiment=day1"), "{error}");
    let error = integrate(&dir, "u=schedule(0:20, 3:70, 2:0)", "order.csv").expect_err("fails");
    assert!(error.contains("gbm::E0317"), "{error}");
    assert!(
        !error.contains("E0709"),
        "a defective programme is no missing one: {error}"
    );
}
