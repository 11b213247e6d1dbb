//! `gbc train --ensemble N` and `gbc predict` on the ensemble: the run directory, the band
//! columns around the median, the coverage on stdout, and the refusals.

use std::path::Path;
use std::process::Output;

use super::cli::{gbc, scratch};

const MODEL: &str = "models/mm_chemostat/greybox.gbm";

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).to_string()
}

/// The chemostat record's first 600 rows as four experiments `e1` to `e4` of 150 rows.
fn four_experiments(dir: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("models/mm_chemostat/data/steps.csv")).unwrap();
    let mut csv = String::from("experiment,t,E0,S\n");
    for (row, line) in text.lines().skip(1).take(600).enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        let t = (row % 150) as f64;
        csv.push_str(&format!(
            "e{},{t},{},{}\n",
            row / 150 + 1,
            fields[1],
            fields[2]
        ));
    }
    let path = dir.join("four.csv");
    std::fs::write(&path, csv).unwrap();
    path.display().to_string()
}

#[test]
fn an_ensemble_predicts_a_band_around_its_median_and_reports_its_coverage() {
    let dir = scratch("ensemble-band");
    let data = four_experiments(&dir);
    let run = dir.join("run");
    let run_text = run.display().to_string();
    let trained = gbc(&[
        "train",
        MODEL,
        &data,
        "--holdout",
        "e4",
        "--ensemble",
        "3",
        "--epochs",
        "2",
        "--objective",
        "one-step",
        "-j",
        "2",
        "-o",
        &run_text,
    ]);
    assert_eq!(trained.status.code(), Some(0), "{}", stderr(&trained));
    let summary = String::from_utf8_lossy(&trained.stdout);
    assert!(
        summary.contains("coverage of the 90 % band on held-out e4"),
        "{summary}"
    );
    assert!(
        stderr(&trained).contains("member 3/3: seed 2"),
        "{}",
        stderr(&trained)
    );
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("ensemble.json")).unwrap()).unwrap();
    assert_eq!(info["members"].as_array().unwrap().len(), 3);
    assert_eq!(info["coverage"]["experiments"], serde_json::json!(["e4"]));
    assert!(run.join("members/member-02/run.json").is_file());
    assert!(run.join("report.html").is_file());
    let predicted = dir.join("predicted.csv");
    let out = gbc(&[
        "predict",
        MODEL,
        &data,
        "--weights",
        &run_text,
        "--mode",
        "online",
        "-o",
        predicted.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(String::from_utf8_lossy(&out.stdout).contains("the 90 % band holds"));
    let table = std::fs::read_to_string(&predicted).unwrap();
    let mut lines = table.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (s, lo, hi) = (at("S"), at("S_lo"), at("S_hi"));
    let mut rows = 0;
    for line in lines {
        let fields: Vec<f64> = line
            .split(',')
            .skip(1)
            .map(|f| f.parse().unwrap())
            .collect();
        let (s, lo, hi) = (fields[s - 1], fields[lo - 1], fields[hi - 1]);
        assert!(lo <= s && s <= hi, "{line}");
        rows += 1;
    }
    assert!(rows >= 150, "{rows} rows");
    let wide = dir.join("wide.csv");
    let bad = gbc(&[
        "predict",
        MODEL,
        &data,
        "--weights",
        &run_text,
        "--band",
        "1.5",
        "-o",
        wide.to_str().unwrap(),
    ]);
    assert_eq!(bad.status.code(), Some(1));
    assert!(stderr(&bad).contains("E0454"), "{}", stderr(&bad));
}

#[test]
fn one_training_experiment_cannot_be_resampled() {
    let dir = scratch("ensemble-one");
    let data = four_experiments(&dir);
    let run = dir.join("run");
    let out = gbc(&[
        "train",
        MODEL,
        &data,
        "--holdout",
        "e2",
        "e3",
        "e4",
        "--ensemble",
        "3",
        "--epochs",
        "1",
        "-o",
        run.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("E0451"), "{}", stderr(&out));
}
