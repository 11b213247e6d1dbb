//! Results as tables: `results.csv` (one row per run), `results.json` (the same runs with
//! every per-state value), `summary.csv` (median, min and max per model and size).

use std::path::Path;

use super::results::{summarise, RunResult, Spread, SummaryRow};
use super::{ExperimentFailure, Study};
use crate::data::format_number;

/// File names inside an experiment directory.
pub const RESULTS_CSV: &str = "results.csv";
/// Every run as JSON.
pub const RESULTS_JSON: &str = "results.json";
/// Median, min and max per model and size.
pub const SUMMARY_CSV: &str = "summary.csv";

/// Writes `results.csv`, `results.json` and `summary.csv` into `dir`.
pub fn write_tables(
    dir: &Path,
    study: &Study,
    results: &[RunResult],
) -> Result<(), ExperimentFailure> {
    let write = |name: &str, text: String| {
        crate::io::write_atomic(&dir.join(name), text.as_bytes()).map_err(ExperimentFailure::from)
    };
    write(RESULTS_CSV, results_csv(study, results)?)?;
    let json = serde_json::to_string_pretty(results)
        .map_err(|error| ExperimentFailure::Internal(format!("cannot encode results: {error}")))?;
    write(RESULTS_JSON, json)?;
    write(SUMMARY_CSV, summary_csv(&summarise(study, results))?)
}

/// A number cell: empty for a missing value, `inf` for a diverged one.
fn cell(value: Option<f64>) -> String {
    value.map_or(String::new(), format_number)
}

/// The value of an error measure of a run as a cell: empty when the run failed.
fn error_cell(result: &RunResult, value: Option<f64>) -> String {
    if result.is_ok() {
        format_number(value.unwrap_or(f64::INFINITY))
    } else {
        String::new()
    }
}

/// `results.csv`: id, model, size, replicate, seed, status, the errors, one column per
/// generalisation record and per param (the union over models, empty where a model has
/// none), final loss, pair counts, wall time, error message.
pub fn results_csv(study: &Study, results: &[RunResult]) -> Result<String, ExperimentFailure> {
    let generalisation: Vec<String> = (study.generalisation.iter())
        .map(|p| p.display().to_string())
        .collect();
    let mut params: Vec<String> = Vec::new();
    for measure in results.iter().flat_map(|r| &r.params) {
        if !params.contains(&measure.name) {
            params.push(measure.name.clone());
        }
    }
    let mut header: Vec<String> = ["id", "model", "size", "replicate", "seed", "status"]
        .map(String::from)
        .to_vec();
    header.extend(["offline_mse", "online_mse"].map(String::from));
    header.extend(
        generalisation
            .iter()
            .map(|g| format!("generalisation_mse:{g}")),
    );
    header.extend(params.iter().map(|p| format!("param:{p}")));
    header.extend(
        [
            "final_loss",
            "train_pairs",
            "validation_pairs",
            "wall_seconds",
            "error",
        ]
        .map(String::from),
    );
    let mut writer = csv::Writer::from_writer(Vec::new());
    let csv_error = |error: csv::Error| ExperimentFailure::Internal(format!("csv: {error}"));
    writer.write_record(&header).map_err(csv_error)?;
    for result in results {
        let mut row = vec![
            result.id.clone(),
            result.model.clone(),
            result.size.to_string(),
            result.replicate.to_string(),
            result.seed.to_string(),
            format!("{:?}", result.status).to_lowercase(),
            error_cell(result, result.offline_mse),
            error_cell(result, result.online_mse),
        ];
        for name in &generalisation {
            let value = RunResult::measure(&result.generalisation, name);
            row.push(value.map_or(String::new(), format_number));
        }
        for name in &params {
            let value = result.params.iter().find(|m| &m.name == name);
            row.push(cell(value.and_then(|m| m.value)));
        }
        row.extend([
            cell(result.final_loss),
            result.train_pairs.to_string(),
            result.validation_pairs.to_string(),
            format!("{:.3}", result.wall_seconds),
            result.error.clone().unwrap_or_default(),
        ]);
        writer.write_record(&row).map_err(csv_error)?;
    }
    finish(writer)
}

/// `summary.csv`: per model and size, run counts and the median, min and max of each error.
pub fn summary_csv(rows: &[SummaryRow]) -> Result<String, ExperimentFailure> {
    let mut writer = csv::Writer::from_writer(Vec::new());
    let csv_error = |error: csv::Error| ExperimentFailure::Internal(format!("csv: {error}"));
    let mut header: Vec<String> = ["model", "size", "ok", "failed", "online_blown_up"]
        .map(String::from)
        .to_vec();
    for metric in ["offline", "online"] {
        header.extend(["median", "min", "max"].map(|s| format!("{metric}_{s}")));
    }
    let generalisation: Vec<String> = (rows.first())
        .map(|r| {
            r.generalisation
                .iter()
                .map(|(name, _)| name.clone())
                .collect()
        })
        .unwrap_or_default();
    header.extend(
        generalisation
            .iter()
            .map(|g| format!("generalisation_median:{g}")),
    );
    header.push("wall_seconds_median".into());
    writer.write_record(&header).map_err(csv_error)?;
    for row in rows {
        let mut record = vec![
            row.model.clone(),
            row.size.to_string(),
            row.ok.to_string(),
            row.failed.to_string(),
            row.blown_up.to_string(),
        ];
        for spread in [row.offline, row.online] {
            record.extend(spread_cells(spread));
        }
        for (_, spread) in &row.generalisation {
            record.push(cell(spread.map(|s| s.median).filter(|v| !v.is_nan())));
        }
        record.push(
            row.wall_seconds
                .map_or(String::new(), |s| format!("{s:.3}")),
        );
        writer.write_record(&record).map_err(csv_error)?;
    }
    finish(writer)
}

fn spread_cells(spread: Option<Spread>) -> [String; 3] {
    match spread {
        Some(s) => [s.median, s.min, s.max].map(format_number),
        None => [String::new(), String::new(), String::new()],
    }
}

fn finish(writer: csv::Writer<Vec<u8>>) -> Result<String, ExperimentFailure> {
    let bytes = writer
        .into_inner()
        .map_err(|error| ExperimentFailure::Internal(format!("csv: {error}")))?;
    String::from_utf8(bytes).map_err(|error| ExperimentFailure::Internal(error.to_string()))
}
