//! `gbc bench`: how fast gbc trains and simulates the shipped models, on this machine.
//!
//! For each shipped model (bioreactor GB1, GB2 and the black-box map at 1000 training
//! pairs, the chemostat grey-box model at 500; batch 50), each precision and each step
//! implementation (`graph` and `fused`) [`bench`] measures the median time of one Adam step
//! and of one epoch. It also times a 3000 h simulation of the bioreactor truth model, the
//! stiff integrations of `models/stiff/` ([`stiff`]) and, if asked, one paper-scale
//! training end to end. Each measurement is handed to the caller as it is made, and all of
//! them come back as [`Measurements`] (JSON). docs/performance.md has the numbers.

pub mod epochs;
mod stiff;

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::ApiError;
use crate::data::MinRows;
use crate::engine::graph::Precision;
use crate::numeric::median;
use crate::signal::Signal;
use crate::solve::ode::SimOptions;
use crate::train::{Part, Recipe, Settings, TrainOptions, TrainingData};
use epochs::{BenchReport, Engine};

pub use stiff::StiffRow;

/// A shipped model `gbc bench` times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
    /// Every benchmarked model.
    pub const ALL: [BenchModel; 5] = [
        BenchModel::Gb1,
        BenchModel::Gb2,
        BenchModel::Blackbox,
        BenchModel::Chemostat,
        BenchModel::Lab,
    ];

    /// Model file, data file and training pairs, relative to the repository root.
    pub fn files(self) -> (&'static str, &'static str, usize) {
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

/// What `gbc bench` measures.
#[derive(Debug, Clone)]
pub struct BenchSpec {
    /// The repository root holding `models/`.
    pub root: PathBuf,
    /// The models timed (default: all).
    pub models: Vec<BenchModel>,
    /// The training settings of every timed case (epochs: the timed epochs).
    pub settings: Settings,
    /// The element types timed.
    pub precisions: Vec<Precision>,
    /// The engines timed.
    pub engines: Vec<Engine>,
    /// Time the simulations (the bioreactor truth model, the stiff models).
    pub simulation: bool,
    /// Time one paper-scale training end to end with this many epochs.
    pub full: Option<usize>,
}

/// One measurement, as it is made.
#[derive(Debug, Clone)]
pub enum Measurement {
    /// One model, precision and engine.
    Training(TrainingRow),
    /// The bioreactor truth model's simulation.
    Simulation(SimulationRow),
    /// One stiff integration.
    Stiff(StiffRow),
    /// The paper-scale training.
    Full(FullRow),
}

/// One timed model, precision and engine.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TrainingRow {
    /// The case timed.
    pub model: String,
    /// Its timings.
    #[serde(flatten)]
    pub report: BenchReport,
}

/// The simulation timing.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SimulationRow {
    /// The model file.
    pub model: String,
    /// Hours simulated.
    pub hours: f64,
    /// Samples written.
    pub samples: usize,
    /// Median wall time of three runs.
    pub median_seconds: f64,
}

/// The end-to-end training timing.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FullRow {
    /// The model file.
    pub model: String,
    /// Training pairs.
    pub train_points: usize,
    /// Epochs.
    pub epochs: usize,
    /// Wall time, validation included.
    pub seconds: f64,
}

/// Everything measured, as written by `--json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Measurements {
    /// Cores of this machine.
    pub cores: usize,
    /// Every training case.
    pub training: Vec<TrainingRow>,
    /// The simulation, if timed.
    pub simulation: Option<SimulationRow>,
    /// The stiff integrations, if timed.
    pub stiff: Vec<StiffRow>,
    /// The paper-scale training, if timed.
    pub full: Option<FullRow>,
}

/// Measures what `spec` asks, handing each measurement to `on_measurement` as it is made.
pub fn bench(
    spec: &BenchSpec,
    on_measurement: &mut dyn FnMut(&Measurement),
) -> Result<Measurements, ApiError> {
    let mut measurements = Measurements {
        cores: std::thread::available_parallelism().map_or(1, usize::from),
        training: Vec::new(),
        simulation: None,
        stiff: Vec::new(),
        full: None,
    };
    for &model in &spec.models {
        for row in time_training(model, spec)? {
            on_measurement(&Measurement::Training(row.clone()));
            measurements.training.push(row);
        }
    }
    if spec.simulation {
        let simulation = time_simulation(&spec.root)?;
        on_measurement(&Measurement::Simulation(simulation.clone()));
        measurements.simulation = Some(simulation);
        for row in stiff::time_stiff(&spec.root)? {
            on_measurement(&Measurement::Stiff(row.clone()));
            measurements.stiff.push(row);
        }
    }
    if let Some(epochs) = spec.full {
        let full = time_full_training(&spec.root, epochs)?;
        on_measurement(&Measurement::Full(full.clone()));
        measurements.full = Some(full);
    }
    Ok(measurements)
}

impl Measurements {
    /// Every measurement as JSON (what `--json` writes).
    pub fn json(&self) -> Result<String, ApiError> {
        serde_json::to_string_pretty(self)
            .map_err(|error| ApiError::Internal(format!("cannot encode results: {error}")))
    }
}

/// A shipped model, compiled.
fn load_model(path: &Path) -> Result<crate::ir::Model, ApiError> {
    Ok(crate::driver::compile_file(path, &[])?.model)
}

/// A record with the model's inputs and measured states (the single-record reader).
fn read_data(model: &crate::ir::Model, path: &Path) -> Result<crate::data::Dataset, ApiError> {
    let required: Vec<&str> = (model.inputs.iter().map(|i| i.name.as_str()))
        .chain(model.states.iter().map(|s| s.name.as_str()))
        .collect();
    crate::data::read(path, &required, MinRows::new(2, "one step needs two rows"))
        .map_err(ApiError::user)
}

/// Every requested precision and engine for one model.
fn time_training(which: BenchModel, spec: &BenchSpec) -> Result<Vec<TrainingRow>, ApiError> {
    let root = spec.root.as_path();
    let (model_file, data_file, train_points) = which.files();
    let model = load_model(&root.join(model_file))?;
    let data = read_data(&model, &root.join(data_file))?;
    let record = crate::train::record_of(&model, &data).map_err(ApiError::from)?;
    let mut cases = Vec::new();
    if which == BenchModel::Lab {
        let files: Vec<PathBuf> = (LAB.iter())
            .map(|f| root.join("models/bioreactor/data/lab").join(f))
            .collect();
        let lab = crate::api::read_records(&model, &files, &[])?;
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
        rows.extend(time_case(label, &model, (&data, *points), spec)?);
    }
    Ok(rows)
}

/// Every requested precision and engine for one data set.
fn time_case(
    label: &str,
    model: &crate::ir::Model,
    (data, train_points): (&TrainingData, Option<usize>),
    spec: &BenchSpec,
) -> Result<Vec<TrainingRow>, ApiError> {
    let settings = spec.settings;
    let mut rows = Vec::new();
    for &precision in &spec.precisions {
        for &engine in &spec.engines {
            let options = TrainOptions {
                train_points,
                ..TrainOptions::with(&Settings {
                    precision,
                    engine,
                    ..settings
                })
            };
            let report = epochs::bench(model, data, &options)?;
            rows.push(TrainingRow {
                model: label.to_string(),
                report,
            });
        }
    }
    Ok(rows)
}

/// 3000 h of the bioreactor truth model under random light steps, median of three runs.
fn time_simulation(root: &Path) -> Result<SimulationRow, ApiError> {
    let file = "models/bioreactor/truth.gbm";
    let model = load_model(&root.join(file))?;
    let (hours, dt) = (2999.0, 1.0);
    let program =
        crate::signal::parse_program("steps(hold=5..40, seed=1)").map_err(ApiError::user)?;
    let signals = (model.inputs.iter())
        .map(|input| program.generate(input, 0.0, hours, dt))
        .collect::<Result<Vec<Signal>, _>>()
        .map_err(ApiError::user)?;
    let options = SimOptions::new(hours, dt);
    let mut seconds = Vec::new();
    let mut samples = 0;
    for _ in 0..3 {
        let started = Instant::now();
        let trajectory =
            crate::solve::ode::simulate(&model, &signals, &options).map_err(ApiError::user)?;
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
fn time_full_training(root: &Path, epochs: usize) -> Result<FullRow, ApiError> {
    let (model_file, data_file, train_points) = BenchModel::Gb2.files();
    let model = load_model(&root.join(model_file))?;
    let data = read_data(&model, &root.join(data_file))?;
    let record = crate::train::record_of(&model, &data).map_err(ApiError::from)?;
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
        .map_err(ApiError::from)?;
    Ok(FullRow {
        model: model_file.to_string(),
        train_points,
        epochs,
        seconds: started.elapsed().as_secs_f64(),
    })
}
