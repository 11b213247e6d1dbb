//! `gbc bench`: how fast gbc trains and simulates the shipped models, on this machine.
//!
//! For each shipped model (bioreactor GB1, GB2 and the black-box map at 1000 training
//! pairs, the chemostat grey-box model at 500; batch 50), each precision and each step
//! implementation (`graph`, what `gbc train` runs, and `fused`, the hand-fused step of
//! `src/fused/`) it prints the median time of one Adam step and of one epoch. It also times
//! a 3000 h simulation of the bioreactor truth model, the stiff integrations of
//! `models/stiff/` ([`stiff`]) and, with `--full`, one paper-scale training end to end. `--json FILE` writes every measurement. Run it from the repository
//! root (or pass `--root`); docs/performance.md has the numbers and the peer comparison.

mod stiff;

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::options::TrainingFlags;
use super::train::{read_data, train_error};
use super::{CommandError, CommandResult};
use crate::backend::Precision;
use crate::numeric::median;
use crate::signal::Signal;
use crate::sim::SimOptions;
use crate::train::bench::{bench, BenchReport, Engine};
use crate::train::{Part, Recipe, Settings, TrainOptions, TrainingData};

/// Timed epochs per measurement when `--epochs` is left out.
const BENCH_EPOCHS: usize = 20;

/// A shipped model `gbc bench` times.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchModel {
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

/// The lab data set's experiments (`models/bioreactor/data/lab/`).
const LAB: [&str; 4] = ["run1.csv", "run2.csv", "run3.csv", "run4.csv"];

impl BenchModel {
    const ALL: [BenchModel; 5] = [
        BenchModel::Gb1,
        BenchModel::Gb2,
        BenchModel::Blackbox,
        BenchModel::Chemostat,
        BenchModel::Lab,
    ];

    /// Model file, data file and training pairs, relative to the repository root.
    fn files(self) -> (&'static str, &'static str, usize) {
        const BIOREACTOR: &str = "models/bioreactor/data/steps.csv";
        match self {
            BenchModel::Gb1 => ("models/bioreactor/gb1.gbm", BIOREACTOR, 1000),
            BenchModel::Gb2 => ("models/bioreactor/gb2.gbm", BIOREACTOR, 1000),
            BenchModel::Blackbox => ("models/bioreactor/blackbox.gbm", BIOREACTOR, 1000),
            BenchModel::Chemostat => (
                "models/mm_chemostat/greybox.gbm",
                "models/mm_chemostat/data/steps.csv",
                500,
            ),
            BenchModel::Lab => ("models/bioreactor/gb1.gbm", BIOREACTOR, 0),
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
    pub models: Vec<BenchModel>,
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

/// One timed model, precision and engine.
#[derive(Debug, serde::Serialize)]
struct TrainingRow {
    model: String,
    #[serde(flatten)]
    report: BenchReport,
}

/// The simulation timing.
#[derive(Debug, serde::Serialize)]
struct SimulationRow {
    model: String,
    hours: f64,
    samples: usize,
    median_seconds: f64,
}

/// The end-to-end training timing.
#[derive(Debug, serde::Serialize)]
struct FullRow {
    model: String,
    train_points: usize,
    epochs: usize,
    seconds: f64,
}

/// Everything measured, as written by `--json`.
#[derive(Debug, serde::Serialize)]
struct Measurements {
    cores: usize,
    training: Vec<TrainingRow>,
    simulation: Option<SimulationRow>,
    stiff: Vec<stiff::StiffRow>,
    full: Option<FullRow>,
}

/// Runs the benchmarks and prints a table.
pub fn run(args: &BenchArgs) -> CommandResult {
    let models = if args.models.is_empty() {
        BenchModel::ALL.to_vec()
    } else {
        args.models.clone()
    };
    let mut measurements = Measurements {
        cores: std::thread::available_parallelism().map_or(1, usize::from),
        training: Vec::new(),
        simulation: None,
        stiff: Vec::new(),
        full: None,
    };
    println!(
        "{:<52} {:>6} {:>5} {:>6} {:>9} {:>10}",
        "model", "pairs", "type", "engine", "ms/step", "ms/epoch"
    );
    for model in models {
        for row in time_training(&args.root, model, args)? {
            print_row(&row);
            measurements.training.push(row);
        }
    }
    if !args.no_simulation {
        let simulation = time_simulation(&args.root)?;
        println!(
            "simulation of {} ({} h, {} samples): {:.1} ms",
            simulation.model,
            simulation.hours,
            simulation.samples,
            simulation.median_seconds * 1e3
        );
        measurements.simulation = Some(simulation);
        for row in stiff::time_stiff(&args.root)? {
            println!(
                "{}: {:.2} ms ({} runs, {} steps, {} implicit)",
                row.case,
                row.median_seconds * 1e3,
                row.runs,
                row.accepted,
                row.implicit
            );
            measurements.stiff.push(row);
        }
    }
    if args.full {
        let full = time_full_training(&args.root, args.full_epochs)?;
        println!(
            "paper-scale training of {} ({} pairs, {} epochs, validation included): {:.1} s",
            full.model, full.train_points, full.epochs, full.seconds
        );
        measurements.full = Some(full);
    }
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&measurements)
            .map_err(|error| CommandError::Internal(format!("cannot encode results: {error}")))?;
        crate::io::write_atomic(path, json.as_bytes()).map_err(CommandError::user)?;
    }
    Ok(())
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

/// Every requested precision and engine for one model.
fn time_training(
    root: &Path,
    which: BenchModel,
    args: &BenchArgs,
) -> Result<Vec<TrainingRow>, CommandError> {
    let (model_file, data_file, train_points) = which.files();
    let model = super::load_model(&root.join(model_file))?;
    let data = read_data(&model, &root.join(data_file))?;
    let record = crate::train::record_of(&model, &data).map_err(train_error)?;
    let mut cases = Vec::new();
    if which == BenchModel::Lab {
        let files: Vec<PathBuf> = (LAB.iter())
            .map(|f| root.join("models/bioreactor/data/lab").join(f))
            .collect();
        let lab = super::data::load_records(&model, &files, &Default::default())?;
        let cells: usize = lab.iter().map(|r| r.measured_cells()).sum();
        let same = cells.div_ceil(model.states.len().max(1));
        cases.push((
            format!("{model_file} lab: 4 experiments, {cells} cells"),
            lab,
            None,
        ));
        let label = format!("{model_file} uniform: {} cells", same * model.states.len());
        cases.push((label, vec![record], Some(same)));
    } else {
        cases.push((model_file.to_string(), vec![record], Some(train_points)));
    }
    let mut rows = Vec::new();
    for (label, records, points) in &cases {
        let data = TrainingData {
            train: records,
            validation: &[],
            part: points.map_or(Part::All, |n| Part::FirstPairs(Some(n))),
        };
        rows.extend(time_case(label, &model, (&data, *points), args)?);
    }
    Ok(rows)
}

/// Every requested precision and engine for one data set.
fn time_case(
    label: &str,
    model: &crate::ir::Model,
    (data, train_points): (&TrainingData, Option<usize>),
    args: &BenchArgs,
) -> Result<Vec<TrainingRow>, CommandError> {
    let precisions = match args.settings.precision {
        Some(precision) => vec![precision.into()],
        None => vec![Precision::F32, Precision::F64],
    };
    let engines = match args.settings.engine {
        Some(engine) => vec![engine.into()],
        None => vec![Engine::Graph, Engine::Fused],
    };
    let flags = TrainingFlags {
        epochs: Some(args.settings.epochs.unwrap_or(BENCH_EPOCHS)),
        ..args.settings.clone()
    };
    let settings = flags.settings()?;
    let mut rows = Vec::new();
    for &precision in &precisions {
        for &engine in &engines {
            let options = TrainOptions {
                train_points,
                ..TrainOptions::with(&Settings {
                    precision,
                    engine,
                    ..settings
                })
            };
            let report = bench(model, data, &options).map_err(train_error)?;
            rows.push(TrainingRow {
                model: label.to_string(),
                report,
            });
        }
    }
    Ok(rows)
}

/// 3000 h of the bioreactor truth model under random light steps, median of three runs.
fn time_simulation(root: &Path) -> Result<SimulationRow, CommandError> {
    let file = "models/bioreactor/truth.gbm";
    let model = super::load_model(&root.join(file))?;
    let (hours, dt) = (2999.0, 1.0);
    let program =
        crate::signal::parse_program("steps(hold=5..40, seed=1)").map_err(CommandError::user)?;
    let signals = (model.inputs.iter())
        .map(|input| program.generate(input, 0.0, hours, dt))
        .collect::<Result<Vec<Signal>, _>>()
        .map_err(CommandError::user)?;
    let options = SimOptions::new(hours, dt);
    let mut seconds = Vec::new();
    let mut samples = 0;
    for _ in 0..3 {
        let started = Instant::now();
        let trajectory =
            crate::sim::simulate(&model, &signals, &options).map_err(CommandError::user)?;
        seconds.push(started.elapsed().as_secs_f64());
        samples = trajectory.times.len();
    }
    Ok(SimulationRow {
        model: file.to_string(),
        hours: hours + dt,
        samples,
        median_seconds: median(&seconds).unwrap_or(f64::NAN),
    })
}

/// One paper-scale training of GB2 as `gbc train` runs it.
fn time_full_training(root: &Path, epochs: usize) -> Result<FullRow, CommandError> {
    let (model_file, data_file, train_points) = BenchModel::Gb2.files();
    let model = super::load_model(&root.join(model_file))?;
    let data = read_data(&model, &root.join(data_file))?;
    let record = crate::train::record_of(&model, &data).map_err(train_error)?;
    let options = TrainOptions {
        epochs,
        train_points: Some(train_points),
        online_horizon: Some(200.0),
        engine: Engine::Graph,
        ..TrainOptions::default()
    };
    let started = Instant::now();
    let data = TrainingData {
        train: std::slice::from_ref(&record),
        validation: &[],
        part: Part::FirstPairs(Some(train_points)),
    };
    crate::train::train_with(&model, &data, &options, &Recipe::paper(), &mut |_| {})
        .map_err(train_error)?;
    Ok(FullRow {
        model: model_file.to_string(),
        train_points,
        epochs,
        seconds: started.elapsed().as_secs_f64(),
    })
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
            models: vec![BenchModel::Chemostat],
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
