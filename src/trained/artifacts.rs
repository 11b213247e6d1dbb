//! A training run on disk: `weights.safetensors` (every trainable tensor, `f64`),
//! `run.json` (everything needed to rebuild the network: the model's structure and source
//! hash, step and sub-steps, normalisation, closure magnitudes, embeddings, params, seed,
//! metrics and the gbc version) and `model.gbm`, a copy of the model source trained on.
//!
//! Reloading matches the weights to a model by its structure ([`structure`]), not its
//! text: a changed comment, const or balance is accepted with notes saying what changed; a
//! changed structure is refused (E0416) naming each changed part.

mod structure;

use std::path::Path;

pub use structure::{compare, differences, fingerprint, structure, Structure};

use sha2::{Digest, Sha256};

use crate::engine::graph::{NamedTensor, Network, Normalisation, Precision, Setup};
use crate::ir;

use super::status::TrainingStatus;
use crate::train::evaluate::PhysicalRange;
use crate::train::recipe::DEFAULT_RANGE_FACTOR;
use crate::train::tensors::{bad_run, read_tensors, write_tensors, NOT_FINITE_HELP};
use crate::train::{
    Engine, Metrics, ParamEstimate, PolishSummary, Recipe, TrainError, TrainOptions, TrainReport,
    Trained, Warning,
};

/// File name of the weights inside a run directory.
pub const WEIGHTS_FILE: &str = "weights.safetensors";
/// File name of the metadata inside a run directory.
pub const RUN_FILE: &str = "run.json";
/// File name of the copy of the model source inside a run directory.
pub const SOURCE_FILE: &str = "model.gbm";

/// The metadata of a run (`run.json`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunInfo {
    /// Version of gbc that trained it.
    pub gbc_version: String,
    /// The model trained.
    pub model: ModelInfo,
    /// The training data file.
    pub data: String,
    /// `der` or `next`.
    pub dynamics: String,
    /// Element type.
    pub precision: Precision,
    /// Seed.
    pub seed: u64,
    /// Sampling step `h`.
    #[serde(with = "crate::json")]
    pub step: f64,
    /// RK4 sub-steps per sample.
    pub substeps: usize,
    /// Names of the inputs, in the order of the normalisation vectors.
    pub inputs: Vec<String>,
    /// Names of the measured states, in the order of the normalisation vectors.
    pub states: Vec<String>,
    /// Normalisation of the training split.
    pub normalisation: Normalisation,
    /// Closure embeddings and output magnitudes.
    pub closures: Vec<ClosureInfo>,
    /// Trained param values.
    pub params: Vec<NamedValue>,
    /// Training options.
    pub training: TrainingInfo,
    /// The recipe (absent in runs saved before recipes existed).
    #[serde(default)]
    pub recipe: Option<Recipe>,
    /// Each param with its standard error.
    #[serde(default)]
    pub estimates: Vec<ParamEstimate>,
    /// What the final polish of the params did, when it ran.
    #[serde(default)]
    pub polish: Option<PolishSummary>,
    /// The params' estimate from the balances, when they came from there.
    #[serde(default)]
    pub balance_fit: Option<crate::train::BalanceFit>,
    /// The fit of a model without closures by free runs, when its params came from there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mechanism_fit: Option<crate::solve::fit::FitSummary>,
    /// What of each training experiment trained.
    #[serde(default)]
    pub coverage: crate::train::coverage::Coverage,
    /// Validation errors.
    pub metrics: Metrics,
    /// Warnings issued before training: stiff balances, steps with a target that do not
    /// train.
    pub warnings: Vec<Warning>,
    /// The weights file, relative to the run directory.
    pub weights: String,
    /// Where training went non-finite, when it did: the weights are then the kept epoch's
    /// (`gbc train` exits with E0415).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diverged: Option<crate::train::EpochDivergence>,
    /// `finished`, or `failed` when training went non-finite and no recovery was left
    /// (then [`RunInfo::diverged`] says where, in which phase, why and what to try).
    #[serde(default)]
    pub status: super::status::TrainingStatus,
    /// Each time training went back to its last finite epoch and continued, with a lower
    /// learning rate ([`crate::train::recovery`]); warnings, the run went on.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recoveries: Vec<crate::train::Recovery>,
    /// The pull toward the mechanism (its strength, how `auto` chose it) and how far each
    /// closure output and param moved from the mechanism.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub toward_mechanism: Option<crate::train::toward::MechanismDistance>,
}

impl RunInfo {
    /// The range of a saved run: its training data's extremes and its `--range-factor`
    /// (the default for runs saved before recipes were recorded). What `gbc predict` and
    /// `gbc simulate --weights` judge a free run by.
    pub fn physical_range(&self) -> Option<PhysicalRange> {
        let factor = (self.recipe.as_ref()).map_or(DEFAULT_RANGE_FACTOR, |r| r.range_factor);
        PhysicalRange::new(&self.normalisation, factor)
    }
}

/// The model a run belongs to.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ModelInfo {
    /// Model name.
    pub name: String,
    /// The model file as given.
    pub path: String,
    /// sha256 of the model file's text (for information: weights are matched by
    /// structure).
    pub source_sha256: String,
    /// The structure the weights mean (empty in runs saved before it was recorded).
    #[serde(default)]
    pub structure: Structure,
    /// sha256 of the structure's canonical text ([`fingerprint`]).
    #[serde(default)]
    pub structure_sha256: String,
    /// The copy of the model source in the run directory, if one was written.
    #[serde(default)]
    pub source_file: Option<String>,
    /// The model's text, written to [`SOURCE_FILE`] by [`save`] (not part of `run.json`;
    /// empty after [`load`]: read the copy with [`trained_source`]).
    #[serde(skip)]
    pub source: String,
}

/// A closure's embedding and magnitudes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClosureInfo {
    /// Closure name.
    pub name: String,
    /// Observed variables.
    pub observe: Vec<String>,
    /// Embedding delay.
    #[serde(with = "crate::json")]
    pub delay: f64,
    /// Embedding dimension.
    pub dim: usize,
    /// Output magnitudes `s_o`.
    pub scales: Vec<NamedValue>,
}

/// A name with a number.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NamedValue {
    /// Name.
    pub name: String,
    /// Value.
    #[serde(with = "crate::json")]
    pub value: f64,
}

/// How the run trained.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrainingInfo {
    /// Epochs.
    pub epochs: usize,
    /// Batch size.
    pub batch_size: usize,
    /// Learning rate.
    #[serde(with = "crate::json")]
    pub learning_rate: f64,
    /// Training pairs.
    pub train_pairs: usize,
    /// Validation pairs.
    pub validation_pairs: usize,
    /// Mean loss of the last epoch.
    #[serde(with = "crate::json")]
    pub final_loss: Option<f64>,
    /// The engine that ran the training steps, graph or fused (`auto` resolved; runs saved
    /// before it was recorded: the graph backend; runs saved before rollouts ran on the
    /// fused step: `fused` ran their one-step epochs only).
    #[serde(default)]
    pub engine: Engine,
}

/// sha256 of a text, lowercase hex.
pub fn source_hash(source: &str) -> String {
    Sha256::digest(source.as_bytes())
        .iter()
        .map(|byte| format!("{byte:02x}"))
        .collect()
}

/// The metadata of a finished run.
pub fn run_info(
    model: &ir::Model,
    (model_path, source): (&str, &str),
    data_path: &str,
    options: &TrainOptions,
    trained: &Trained,
) -> RunInfo {
    let setup = &trained.setup;
    let report = &trained.report;
    RunInfo {
        gbc_version: env!("CARGO_PKG_VERSION").to_string(),
        model: model_info(model, model_path, source),
        data: data_path.to_string(),
        dynamics: match model.dynamics {
            ir::Dynamics::Continuous => "der".into(),
            ir::Dynamics::Discrete => "next".into(),
        },
        precision: setup.precision,
        seed: setup.seed,
        step: setup.step,
        substeps: setup.substeps,
        inputs: model.inputs.iter().map(|i| i.name.clone()).collect(),
        states: model.states.iter().map(|s| s.name.clone()).collect(),
        normalisation: setup.normalisation.clone(),
        closures: closure_infos(model, &setup.scales),
        params: (report.params.iter())
            .map(|(name, value)| NamedValue {
                name: name.clone(),
                value: *value,
            })
            .collect(),
        training: training_info(options, report),
        recipe: Some(report.recipe.clone()),
        estimates: report.estimates.clone(),
        polish: report.polish.clone(),
        balance_fit: report.balance_fit.clone(),
        mechanism_fit: report.mechanism_fit.clone(),
        coverage: report.coverage.clone(),
        metrics: report.metrics.clone(),
        warnings: report.warnings.clone(),
        weights: WEIGHTS_FILE.to_string(),
        diverged: report.diverged.clone(),
        status: if report.diverged.is_some() {
            TrainingStatus::Failed(None)
        } else {
            TrainingStatus::Finished
        },
        recoveries: report.recoveries.clone(),
        toward_mechanism: report.toward_mechanism.clone(),
    }
}

/// The model trained: its name, the file as given, its source and structure with their
/// hashes.
fn model_info(model: &ir::Model, path: &str, source: &str) -> ModelInfo {
    ModelInfo {
        name: model.name.clone(),
        path: path.to_string(),
        source_sha256: source_hash(source),
        structure: structure(model),
        structure_sha256: fingerprint(&structure(model)),
        source_file: Some(SOURCE_FILE.to_string()),
        source: source.to_string(),
    }
}

/// Each closure's embedding (the quantities it observes by name) and the magnitude
/// `scales` of its outputs.
fn closure_infos(model: &ir::Model, scales: &[Vec<f64>]) -> Vec<ClosureInfo> {
    let name_of = |var: ir::Var| match var {
        ir::Var::Input(i) => model.inputs[i].name.clone(),
        ir::Var::State(i) => model.states[i].name.clone(),
        other => format!("{other:?}"),
    };
    (model.closures.iter().zip(scales))
        .map(|(closure, scales)| ClosureInfo {
            name: closure.name.clone(),
            observe: closure
                .embedding
                .observe
                .iter()
                .map(|&v| name_of(v))
                .collect(),
            delay: closure.embedding.delay,
            dim: closure.embedding.dim,
            scales: (closure.outputs.iter().zip(scales))
                .map(|(o, &value)| NamedValue {
                    name: o.name.clone(),
                    value,
                })
                .collect(),
        })
        .collect()
}

/// How the run trained: the options asked for and the pairs, loss and engine it had.
fn training_info(options: &TrainOptions, report: &TrainReport) -> TrainingInfo {
    TrainingInfo {
        epochs: options.epochs,
        batch_size: options.batch_size,
        learning_rate: options.learning_rate,
        train_pairs: report.train_pairs,
        validation_pairs: report.validation_pairs,
        final_loss: report.losses.last().copied(),
        engine: report.engine,
    }
}

/// Writes `run.json` and the weights into `directory` (created if missing). Weights or
/// params that are not finite are refused ([`crate::io::IoError::NotFinite`]) before
/// anything is written.
pub fn save(directory: &Path, info: &RunInfo, network: &Network) -> Result<(), TrainError> {
    let weights = network.weights();
    let params = (info.params.iter()).map(|p| (p.name.as_str(), p.value));
    let found =
        crate::finite::in_tensors(&weights, &[]).or_else(|| crate::finite::in_named(params));
    crate::finite::refuse(&directory.join(WEIGHTS_FILE), found, NOT_FINITE_HELP)?;
    write_tensors(&directory.join(WEIGHTS_FILE), &weights)?;
    // A loaded run's metadata carries no source text: its copy stays as it is.
    if let Some(file) = info
        .model
        .source_file
        .as_ref()
        .filter(|_| !info.model.source.is_empty())
    {
        crate::io::write_atomic(&directory.join(file), info.model.source.as_bytes())?;
    }
    let json = serde_json::to_string_pretty(info)
        .map_err(|error| bad_run(&directory.join(RUN_FILE), error))?;
    crate::io::write_atomic(&directory.join(RUN_FILE), json.as_bytes())?;
    Ok(())
}

/// Reads a run directory back: its metadata and its weights.
pub fn load(directory: &Path) -> Result<(RunInfo, Vec<NamedTensor>), TrainError> {
    let run_path = directory.join(RUN_FILE);
    let text = std::fs::read_to_string(&run_path).map_err(|error| bad_run(&run_path, error))?;
    let info: RunInfo = serde_json::from_str(&text).map_err(|error| bad_run(&run_path, error))?;
    let weights = read_tensors(&directory.join(&info.weights))?;
    Ok((info, weights))
}

/// A run rebuilt for a model, with notes on how the model differs from the one trained.
pub struct Restored {
    /// The network with the trained weights.
    pub network: Network,
    /// Its setup.
    pub setup: Setup,
    /// The run's metadata.
    pub info: RunInfo,
    /// What differs from the model trained on, outside the structure (for stderr).
    pub notes: Vec<String>,
}

/// Rebuilds the network of a run for `model`, whose file text is `source` (see
/// [`restore_with_notes`]).
pub fn restore(
    model: &ir::Model,
    source: &str,
    directory: &Path,
) -> Result<(Network, Setup, RunInfo), TrainError> {
    let restored = restore_with_notes(model, source, directory)?;
    Ok((restored.network, restored.setup, restored.info))
}

/// Rebuilds the network of a run for `model`, whose file text is `source`: a model whose
/// structure differs from the one trained is refused, one whose text differs otherwise is
/// accepted with notes on what changed.
pub fn restore_with_notes(
    model: &ir::Model,
    source: &str,
    directory: &Path,
) -> Result<Restored, TrainError> {
    let (info, mut weights) = load(directory)?;
    let params: Vec<String> = model.params.iter().map(|p| p.name.clone()).collect();
    if let Some(found) = crate::finite::in_tensors(&weights, &params) {
        let reason = format!(
            "expected finite weights, found {found} (the run went non-finite; gbc now keeps \
             the last finite epoch of such a run): train again"
        );
        return Err(bad_run(&directory.join(&info.weights), reason));
    }
    let notes = check_structure(model, source, &info, directory)?;
    check_fits(model, &info, directory)?;
    let setup = Setup {
        step: info.step,
        substeps: info.substeps,
        precision: info.precision,
        seed: info.seed,
        normalisation: info.normalisation.clone(),
        scales: (info.closures.iter())
            .map(|c| c.scales.iter().map(|s| s.value).collect())
            .collect(),
    };
    let mut network = Network::build(model, &setup)?;
    let order: Vec<String> = network.weights().into_iter().map(|t| t.name).collect();
    weights.sort_by_key(|t| {
        order
            .iter()
            .position(|n| n == &t.name)
            .unwrap_or(usize::MAX)
    });
    network.set_weights(&weights)?;
    Ok(Restored {
        network,
        setup,
        info,
        notes,
    })
}

/// The copy of the model source trained on, when the run directory holds one.
pub fn trained_source(directory: &Path, info: &RunInfo) -> Option<String> {
    let file = info.model.source_file.as_ref()?;
    std::fs::read_to_string(directory.join(file)).ok()
}

/// Refuses a model whose structure differs from the one trained; notes how its text
/// differs otherwise.
fn check_structure(
    model: &ir::Model,
    source: &str,
    info: &RunInfo,
    directory: &Path,
) -> Result<Vec<String>, TrainError> {
    let found = structure(model);
    let changes = compare(&info.model.structure, &found);
    if !info.model.structure.is_empty() && !changes.is_empty() {
        return Err(TrainError::ModelChanged {
            run: directory.display().to_string(),
            changes: changes.iter().map(ToString::to_string).collect(),
        });
    }
    let mut notes = Vec::new();
    if source_hash(source) == info.model.source_sha256 {
        return Ok(notes);
    }
    if info.model.structure.is_empty() {
        notes.push(format!(
            "the model text differs from the one the weights in `{}` were trained with; the \
             run predates structure records, so only the weights' shapes were checked",
            directory.display()
        ));
        return Ok(notes);
    }
    notes.push(format!(
        "the model text differs from the one the weights in `{}` were trained with; its \
         structure is the same, so the weights apply",
        directory.display()
    ));
    let trained = trained_source(directory, info)
        .and_then(|text| crate::driver::compile(SOURCE_FILE, &text, &[]).ok());
    if let Some(trained) = trained {
        notes.extend(
            differences(&trained.model, model)
                .into_iter()
                .map(|line| format!("changed: {line}")),
        );
    }
    Ok(notes)
}

/// Refuses a `run.json` whose vectors do not fit the model (an edited file).
fn check_fits(model: &ir::Model, info: &RunInfo, directory: &Path) -> Result<(), TrainError> {
    let norm = &info.normalisation;
    let fits = norm.state_mean.len() == model.states.len()
        && norm.state_std.len() == model.states.len()
        && norm.input_mean.len() == model.inputs.len()
        && norm.input_std.len() == model.inputs.len()
        && info.closures.len() == model.closures.len()
        && (info.closures.iter().zip(&model.closures))
            .all(|(saved, closure)| saved.scales.len() == closure.outputs.len())
        && info.step > 0.0
        && info.step.is_finite();
    if fits {
        Ok(())
    } else {
        Err(bad_run(
            &directory.join(RUN_FILE),
            "expected normalisation, closures and step that fit the model, found others",
        ))
    }
}
