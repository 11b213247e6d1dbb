//! `gbc bench`: how fast gbc trains and simulates the shipped models, on this machine.
//!
//! For each shipped model (bioreactor GB1, GB2 and the black-box map at 1000 training
//! pairs, the chemostat grey-box model at 500; batch 50), each precision and each step
//! implementation (`graph`, what `gbc train` runs, and `fused`, the hand-fused step of
//! `src/fused/`) it prints the median time of one Adam step and of one epoch. It also times
//! a 3000 h simulation of the bioreactor truth model, the stiff integrations of
//! `models/stiff/` and, with `--full`, one paper-scale training end to end. `--json FILE`
//! writes every measurement. The work is [`gbc::api::bench`]. Run it from the repository
//! root (or pass `--root`); docs/performance.md has the numbers and the peer comparison.

use std::path::PathBuf;

use super::{CommandError, CommandResult};
use gbc::api::bench::{BenchModel, BenchSpec, Measurement, TrainingRow};
use gbc::api::flags::TrainingFlags;
use gbc::api::{self, Engine, Precision};

/// Timed epochs per measurement when `--epochs` is left out.
const BENCH_EPOCHS: usize = 20;

/// A shipped model `gbc bench` times ([`BenchModel`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchModelArg {
    /// models/bioreactor/gb1.gbm, 1000 pairs.
    Gb1,
    /// models/bioreactor/gb2.gbm, 1000 pairs.
    Gb2,
    /// models/bioreactor/blackbox.gbm, 1000 pairs.
    Blackbox,
    /// models/mm_chemostat/greybox.gbm, 500 pairs.
    Chemostat,
    /// GB1 on the lab data set (4 irregular experiments, missing cells) beside GB1 on the
    /// uniform record cut to the same number of measured cells.
    Lab,
}

impl From<BenchModelArg> for BenchModel {
    fn from(model: BenchModelArg) -> Self {
        match model {
            BenchModelArg::Gb1 => BenchModel::Gb1,
            BenchModelArg::Gb2 => BenchModel::Gb2,
            BenchModelArg::Blackbox => BenchModel::Blackbox,
            BenchModelArg::Chemostat => BenchModel::Chemostat,
            BenchModelArg::Lab => BenchModel::Lab,
        }
    }
}

/// Arguments of `gbc bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// The repository root holding `models/`.
    #[arg(long, default_value = ".", value_name = "DIR")]
    pub root: PathBuf,
    /// Time only these models (repeatable; default: all).
    #[arg(long = "model", value_enum, value_name = "MODEL")]
    pub models: Vec<BenchModelArg>,
    /// Timed epochs (after one warm-up), batch, learning rate, precision and engine (each
    /// left out: both precisions, both engines, 20 epochs), shared with `gbc train`.
    #[command(flatten)]
    pub settings: TrainingFlags,
    /// Do not time the simulations (the bioreactor truth model, the stiff models).
    #[arg(long)]
    pub no_simulation: bool,
    /// Also time one paper-scale training end to end (GB2, 1000 pairs, the paper's recipe,
    /// f32, graph backend, validation with a 200 h free run).
    #[arg(long)]
    pub full: bool,
    /// Epochs of the --full training.
    #[arg(long, default_value_t = 1000, value_name = "N")]
    pub full_epochs: usize,
    /// Write every measurement as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// Runs the benchmarks and prints a table.
pub fn run(args: &BenchArgs) -> CommandResult {
    println!(
        "{:<52} {:>6} {:>5} {:>6} {:>9} {:>10}",
        "model", "pairs", "type", "engine", "ms/step", "ms/epoch"
    );
    let spec = spec_of(args)?;
    let measurements = api::bench::bench(&spec, &mut print_measurement)?;
    if let Some(path) = &args.json {
        let json = measurements.json()?;
        api::write_atomic(path, json.as_bytes()).map_err(CommandError::user)?;
    }
    Ok(())
}

/// The API's spec of the flags: every model, both precisions and both engines unless
/// named, [`BENCH_EPOCHS`] timed epochs unless `--epochs`.
fn spec_of(args: &BenchArgs) -> Result<BenchSpec, CommandError> {
    let flags = TrainingFlags {
        epochs: Some(args.settings.epochs.unwrap_or(BENCH_EPOCHS)),
        ..args.settings.clone()
    };
    Ok(BenchSpec {
        root: args.root.clone(),
        models: match args.models.is_empty() {
            true => BenchModel::ALL.to_vec(),
            false => args.models.iter().map(|&m| m.into()).collect(),
        },
        settings: flags.settings()?,
        precisions: match args.settings.precision {
            Some(precision) => vec![precision.into()],
            None => vec![Precision::F32, Precision::F64],
        },
        engines: match args.settings.engine {
            Some(engine) => vec![engine.into()],
            None => vec![Engine::Graph, Engine::Fused],
        },
        simulation: !args.no_simulation,
        full: args.full.then_some(args.full_epochs),
    })
}

/// One measurement's line on stdout.
fn print_measurement(measurement: &Measurement) {
    match measurement {
        Measurement::Training(row) => print_row(row),
        Measurement::Simulation(simulation) => println!(
            "simulation of {} ({} h, {} samples): {:.1} ms",
            simulation.model,
            simulation.hours,
            simulation.samples,
            simulation.median_seconds * 1e3
        ),
        Measurement::Stiff(row) => println!(
            "{}: {:.2} ms ({} runs, {} steps, {} implicit)",
            row.case,
            row.median_seconds * 1e3,
            row.runs,
            row.accepted,
            row.implicit
        ),
        Measurement::Full(full) => println!(
            "paper-scale training of {} ({} pairs, {} epochs, validation included): {:.1} s",
            full.model, full.train_points, full.epochs, full.seconds
        ),
    }
}

fn print_row(row: &TrainingRow) {
    let report = &row.report;
    let precision = report.precision.name();
    println!(
        "{:<52} {:>6} {:>5} {:>6} {:>9.3} {:>10.2}",
        row.model,
        report.train_points,
        precision,
        report.engine.name(),
        report.median_step_seconds * 1e3,
        report.median_epoch_seconds * 1e3
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn root() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
    }

    #[test]
    fn every_benchmarked_model_and_record_is_shipped() {
        for model in BenchModel::ALL {
            let (model_file, data_file, _) = model.files();
            assert!(root().join(model_file).is_file(), "{model_file}");
            assert!(root().join(data_file).is_file(), "{data_file}");
        }
    }

    #[test]
    fn bench_writes_one_row_per_precision_and_engine() {
        let json = std::env::temp_dir().join(format!("gbc-bench-{}.json", std::process::id()));
        let args = BenchArgs {
            root: root(),
            models: vec![BenchModelArg::Chemostat],
            settings: TrainingFlags {
                epochs: Some(1),
                ..TrainingFlags::default()
            },
            no_simulation: true,
            full: false,
            full_epochs: 1,
            json: Some(json.clone()),
        };
        run(&args).unwrap();
        let written: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        std::fs::remove_file(&json).unwrap();
        let rows = written["training"].as_array().unwrap();
        let labels: Vec<(String, String)> = (rows.iter())
            .map(|r| (r["precision"].to_string(), r["engine"].to_string()))
            .collect();
        let distinct: std::collections::HashSet<_> = labels.iter().collect();
        assert!(labels.len() == 4 && distinct.len() == 4, "{labels:?}");
        for row in rows {
            assert_eq!(row["train_points"], 500);
            assert_eq!(row["steps_per_epoch"], 10);
            assert!(row["median_step_seconds"].as_f64().unwrap() > 0.0);
        }
        assert!(written["simulation"].is_null() && written["full"].is_null());
    }
}
