//! An ensemble's export: the members' ONNX files stepped in tract and the band recomputed
//! here from the companion file's facts alone (read as plain JSON, by the documented
//! names), against `gbc predict`'s median and `X_lo`/`X_hi` on the same run.

use std::path::Path;

use super::tests::free_run;
use super::Exported;
use crate::engine::graph::Precision;
use crate::ensemble::{self, Keep, Plan, Resample};
use crate::record::Record;
use crate::train::{History, Part, Recipe, TrainOptions, TrainingData};
use crate::trained::predict::{Mode, PredictionTable};
use serde_json::Value;

/// `Phi` from `erfc`, written here.
fn phi(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// The median as the recipe says: the middle one, or the mean of the two middle ones.
fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        0.5 * (sorted[n / 2 - 1] + sorted[n / 2])
    }
}

/// The recipe's band of one cell from the members' `predictions` and a state's entry of
/// the companion file: `(median, lo, hi)`.
fn recipe_band(predictions: &[f64], state: &Value, base_level: f64) -> (f64, f64, f64) {
    let noise = &state["noise"];
    let (absolute, relative) = (
        noise["absolute"].as_f64().unwrap(),
        noise["relative"].as_f64().unwrap(),
    );
    let floor = noise.get("floor").and_then(Value::as_f64);
    let draws: Vec<(f64, f64)> = (predictions.iter())
        .map(|&p| (p, absolute.hypot(relative * p)))
        .collect();
    let cdf = |y: f64| {
        if floor.is_some_and(|f| y < f) {
            return 0.0;
        }
        draws.iter().map(|(p, s)| phi((y - p) / s)).sum::<f64>() / draws.len() as f64
    };
    let quantile = |q: f64| {
        let (mut low, mut high) = (-1e3, 1e3);
        for _ in 0..300 {
            let middle = 0.5 * (low + high);
            if cdf(middle) >= q {
                high = middle;
            } else {
                low = middle;
            }
        }
        high
    };
    let m = median(predictions);
    let below = (m - quantile((1.0 - base_level) / 2.0)).max(0.0);
    let above = (quantile((1.0 + base_level) / 2.0) - m).max(0.0);
    // The factor at 0.9 from the scores, checked against the file's own.
    let scores: Vec<f64> = (state["scores"].as_array().unwrap().iter())
        .map(|s| s.as_f64().unwrap())
        .collect();
    let rank = ((scores.len() + 1) as f64 * 0.9).ceil() as usize;
    let c = scores[rank - 1];
    assert_eq!(state["factor"].as_f64(), Some(c));
    let raise = |v: f64| floor.map_or(v, |f| v.max(f));
    (m, raise(m - c * below), raise(m + c * above))
}

/// Four chemostat experiments (the grey box's `S` declared `nonnegative`), three to
/// train four members in `f64`, one held out.
fn chemostat() -> (crate::ir::Model, Vec<Record>) {
    use crate::train::fixtures::{chemostat, record};
    let mut model = chemostat::grey_box();
    model.states[0].nonnegative = true;
    let records = (1..=4)
        .map(|seed| {
            let mut r = record(&model, &chemostat::data(80, (0.002, 0.02), seed).0);
            r.name = format!("run{seed}");
            r
        })
        .collect();
    (model, records)
}

#[test]
fn the_band_recomputed_from_the_exported_files_is_gbc_predicts() {
    let (model, records) = chemostat();
    let (train, held) = records.split_at(3);
    let directory = std::env::temp_dir().join(format!("gbc-export-band-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&directory);
    let keep = Keep {
        directory: directory.clone(),
        model: ("model.gbm", ""),
        data: "fixture",
        recoveries: 0,
    };
    let plan = Plan {
        members: 4,
        resample: Resample::Experiments,
        jobs: 2,
        level: 0.9,
    };
    let options = TrainOptions {
        epochs: 2,
        seed: 3,
        precision: Precision::F64,
        ..TrainOptions::default()
    };
    let data = TrainingData {
        train,
        validation: held,
        part: Part::All,
    };
    let trained = ensemble::train_ensemble(
        &model,
        &data,
        (&options, &Recipe::paper()),
        &plan,
        &keep,
        &|_| {},
    )
    .unwrap();
    assert!(trained.info.calibration.calibrated);
    let record = &held[0];
    let loaded = ensemble::load(&model, "", &directory).unwrap();
    let how = (Mode::Online, History::Measured, 1);
    let tables =
        ensemble::predict::member_tables(&model, ("", &loaded), held, how, &|_| {}).unwrap();
    let mine: Vec<PredictionTable> = tables.iter().map(|t| t[0].clone()).collect();
    // As trained; then with noise a third of the substrate's range and scores twice as far
    // out, so that the floor cuts the band.
    let mut info = trained.info.clone();
    assert_eq!(recompute(&model, &directory, record, &info, &mine), 0);
    let largest = (record.states[0].iter().flatten()).fold(0.0, |m: f64, v| m.max(v.abs()));
    info.band.noise[0].absolute = largest / 3.0;
    for score in &mut info.calibration.states[0].scores {
        *score *= 2.0;
    }
    let floored = recompute(&model, &directory, record, &info, &mine);
    assert!(floored > 0, "the floor cuts the band somewhere");
    let _ = std::fs::remove_dir_all(&directory);
}

/// Writes `info` as the ensemble's `ensemble.json`, exports the ensemble, steps each
/// member's file in tract along `record`, and checks the band recomputed from the
/// companion file against `gbc predict`'s from the members' tables `mine`; returns the
/// rows whose lower edge is the floor.
fn recompute(
    model: &crate::ir::Model,
    directory: &Path,
    record: &Record,
    info: &ensemble::EnsembleInfo,
    mine: &[PredictionTable],
) -> usize {
    let text = serde_json::to_string(info).unwrap();
    std::fs::write(directory.join(ensemble::ENSEMBLE_FILE), text).unwrap();
    let out = directory.join("exported").join("chemostat.onnx");
    std::fs::create_dir_all(out.parent().unwrap()).unwrap();
    let exported = super::ensemble::export(model, "", directory, Precision::F64, &out).unwrap();
    exported.write().unwrap();
    assert!(!out.exists(), "no single map for an ensemble");
    // The companion file, read as a controller would.
    let text = std::fs::read_to_string(directory.join("exported/chemostat.band.json")).unwrap();
    let band: Value = serde_json::from_str(&text).unwrap();
    let base_level = band["base_level"].as_f64().unwrap();
    let state = &band["states"][0];
    assert_eq!(state["state"], "S");
    assert_eq!(state["noise"]["floor"].as_f64(), Some(0.0));
    let members = band["members"].as_array().unwrap();
    assert_eq!(members.len(), info.used().count());
    let start = (record.times.iter())
        .position(|&t| t == mine[0].columns[0][0])
        .unwrap();
    let runs: Vec<Vec<Vec<f64>>> = (members.iter().zip(&exported.members))
        .map(|(member, (_, own))| {
            let file = directory
                .join("exported")
                .join(member["onnx"].as_str().unwrap());
            let map = Exported {
                bytes: std::fs::read(file).unwrap(),
                layout: own.layout.clone(),
            };
            free_run(&map, record, start).0
        })
        .collect();
    // gbc predict's band on the same run.
    let predicted = ensemble::predict_table(model, info, (record, mine), Some(0.9)).unwrap();
    let column = |name: &str| {
        let header = &predicted.table.header;
        predicted.table.columns[header.iter().position(|h| h == name).unwrap()].clone()
    };
    let (s, lo, hi) = (column("S"), column("S_lo"), column("S_hi"));
    assert_eq!(
        s.len(),
        runs[0].len() + 1,
        "the start row, then one per step"
    );
    let mut floored = 0;
    for step in 0..runs[0].len() {
        let predictions: Vec<f64> = runs.iter().map(|run| run[step][0]).collect();
        let (m, l, h) = recipe_band(&predictions, state, base_level);
        let row = step + 1;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
        assert!(close(m, s[row]), "row {row}: median {m} against {}", s[row]);
        assert!(close(l, lo[row]), "row {row}: lo {l} against {}", lo[row]);
        assert!(close(h, hi[row]), "row {row}: hi {h} against {}", hi[row]);
        floored += usize::from(l == 0.0);
    }
    floored
}
