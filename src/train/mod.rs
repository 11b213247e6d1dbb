//! Training of grey-box models on data (spec section 4; Lovelett et al. 2020, section 2).
//!
//! [`train`] turns a record into one-step pairs ([`pairs`]), normalises with the training
//! split, resolves closure magnitudes and warns about stiff balances ([`analysis`]), then
//! runs Adam on shuffled mini-batches of the backend network and reports the paper's two
//! validation errors ([`evaluate`]). [`artifacts`] saves and reloads a trained network,
//! [`predict`] runs it along a record, [`mod@bench`] times its training steps.
//!
//! Decisions this module makes:
//! - **Split**: the first `--train-points` pairs train; the remaining pairs of the same record
//!   validate, or every pair of `--val FILE`. Without `--train-points` all pairs train when a
//!   validation file is given, else the first 70 %.
//! - **Normalisation**: mean and standard deviation of each input and measured state over
//!   the rows the training pairs cover (a constant column gets std 1).
//! - **Hidden states** (none in the paper's models) start at their declared initial values at
//!   the first row and are integrated along the record with the measured states reset to the
//!   data at every step; their estimates enter the pairs as constants, refreshed each epoch
//!   with the current network (no gradient flows through their history).
//! - **Online error**: a free run starting at the first validation pair with the true history
//!   before it, driven by the data's inputs, over `--online-horizon` (default: to the end).

pub mod analysis;
pub mod artifacts;
pub mod balances;
pub mod bench;
mod error;
pub mod evaluate;
mod fit;
pub mod pairs;
pub mod polish;
pub mod predict;
pub mod recipe;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_recipe;
mod validation;
pub mod windows;

#[cfg(test)]
pub(crate) mod fixtures;

use crate::backend::{Network, Normalisation, Precision, Setup};
use crate::data::Dataset;
use crate::ir;

pub use analysis::StiffnessWarning;
pub use balances::BalanceFit;
pub use error::TrainError;
use evaluate::run_in_hidden;
pub use evaluate::{Divergence, ErrorSet, PhysicalRange};
use pairs::{first_pair_row, stage_fractions, PairTable, Record};
pub use polish::{ParamEstimate, PolishSummary};
pub use recipe::{Engine, Objective, ParamSource, Recipe};
pub use validation::Validation;
use validation::{refresh_hidden, validate, validation_splits, Split};

/// Share of the pairs that train when neither `--train-points` nor `--val` is given.
pub const DEFAULT_TRAIN_SHARE: f64 = 0.7;

/// Options of a training run.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainOptions {
    /// Passes over the training pairs.
    pub epochs: usize,
    /// Pairs per Adam step.
    pub batch_size: usize,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Number of training pairs (the first ones); see the module documentation.
    pub train_points: Option<usize>,
    /// Seed of the initialisation and the shuffling.
    pub seed: u64,
    /// Element type.
    pub precision: Precision,
    /// RK4 sub-steps per sample.
    pub substeps: usize,
    /// Length (model time) of the online free run; `None` runs to the end.
    pub online_horizon: Option<f64>,
    /// Which implementation runs the one-step epochs.
    pub engine: Engine,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions {
            epochs: 100,
            batch_size: 50,
            learning_rate: 1e-3,
            train_points: None,
            seed: 0,
            precision: Precision::F32,
            substeps: 1,
            online_horizon: None,
            engine: Engine::Graph,
        }
    }
}

/// Something worth telling the user while training runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Event<'a> {
    /// Before the first epoch: the stiffness estimate found a problem.
    Warning(&'a StiffnessWarning),
    /// Before the first epoch.
    Started {
        /// Epochs to run.
        epochs: usize,
        /// Training pairs.
        train_pairs: usize,
        /// Validation pairs.
        validation_pairs: usize,
    },
    /// After each epoch.
    Epoch {
        /// 1-based epoch.
        epoch: usize,
        /// Mean training loss over the epoch (normalised units; over every rollout step
        /// for a multi-step epoch).
        loss: f64,
        /// Steps per window (1: one-step pairs).
        horizon: usize,
    },
}

/// Validation errors in normalised units (the paper's two errors): of the first
/// validation set, and of every validation set.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    /// Offline validation error of the untrained network.
    pub initial_offline: Option<ErrorSet>,
    /// Online validation error of the untrained network.
    pub initial_online: Option<ErrorSet>,
    /// Offline validation error (one step from true history).
    pub offline: Option<ErrorSet>,
    /// Online validation error (free run).
    pub online: Option<ErrorSet>,
    /// Both errors of every validation set, the first being the one above.
    #[serde(default)]
    pub validations: Vec<ValidationErrors>,
}

/// The errors of one validation set.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ValidationErrors {
    /// The record (a file, or the rest of the training record).
    pub name: String,
    /// Its pairs.
    pub pairs: usize,
    /// Offline error.
    pub offline: ErrorSet,
    /// Online error (with the divergence, if the free run left the physical range).
    pub online: ErrorSet,
}

/// What a training run reports.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainReport {
    /// Validation errors.
    pub metrics: Metrics,
    /// Trained param values, in declaration order.
    pub params: Vec<(String, f64)>,
    /// Stiffness warnings issued before training.
    pub warnings: Vec<StiffnessWarning>,
    /// Mean training loss of each epoch.
    pub losses: Vec<f64>,
    /// Number of training pairs.
    pub train_pairs: usize,
    /// Number of validation pairs (of the first validation set).
    pub validation_pairs: usize,
    /// The recipe trained with.
    pub recipe: Recipe,
    /// Each param with its standard error (see [`polish`]).
    pub estimates: Vec<ParamEstimate>,
    /// What the final polish of the params did, when it ran.
    pub polish: Option<PolishSummary>,
    /// The params' estimate from the balances, when they came from there (then held
    /// fixed while the network trained; see [`balances`]).
    pub balance_fit: Option<BalanceFit>,
}

/// A trained network with everything needed to reuse it.
pub struct Trained {
    /// The network.
    pub network: Network,
    /// How it was built.
    pub setup: Setup,
    /// What training reported.
    pub report: TrainReport,
}

/// Trains `model` on `data` with the default [`Recipe`], validating on `validation` when
/// given, else on the pairs after the training pairs; `on_event` hears of warnings and of
/// every epoch.
pub fn train(
    model: &ir::Model,
    data: &Dataset,
    validation: Option<&Dataset>,
    options: &TrainOptions,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained, TrainError> {
    let validations = match validation {
        Some(file) => vec![Validation::File(file)],
        None => vec![Validation::Rest],
    };
    train_with(
        model,
        data,
        &validations,
        options,
        &Recipe::default(),
        on_event,
    )
}

/// Trains `model` on `data` with `recipe`, validating on each of `validations` (the
/// report's headline errors are those of the first that has pairs).
pub fn train_with(
    model: &ir::Model,
    data: &Dataset,
    validations: &[Validation],
    options: &TrainOptions,
    recipe: &Recipe,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained, TrainError> {
    check_options(options, recipe)?;
    check_trainable(model)?;
    let record = record_of(model, data)?;
    check_delays(model, record.step)?;
    let first = first_pair_row(model, record.step);
    let available = pair_count(data, &record, first)?;
    let has_file = validations.iter().any(|v| matches!(v, Validation::File(_)));
    let train_count = train_pair_count(options, has_file, available)?;
    let train_rows: Vec<usize> = (first..first + train_count).collect();
    let normalisation = normalise(&record, first + train_count + 1);
    let hidden_init = hidden_initial_values(model)?;
    let scales = analysis::closure_scales(model, &record, &train_rows, &hidden_init)?;
    let warnings = analysis::stiffness(
        model,
        &scales,
        &record,
        &train_rows,
        &hidden_init,
        options.substeps,
    )?;
    for warning in &warnings {
        on_event(Event::Warning(warning));
    }
    let balance_fit = if recipe.params_from_balances() {
        balances::estimate(model, &scales, &record, &train_rows)?
    } else {
        None
    };
    if recipe.params == ParamSource::Balances && balance_fit.is_none() {
        return Err(TrainError::ParamsFromBalances {
            model: model.name.clone(),
        });
    }
    let fitted;
    let model = match &balance_fit {
        Some(fit) => {
            fitted = with_initial_params(model, fit);
            &fitted
        }
        None => model,
    };
    let setup = Setup {
        step: record.step,
        substeps: options.substeps,
        precision: options.precision,
        seed: options.seed,
        normalisation,
        scales,
    };
    let mut network = Network::build(model, &setup)?;
    let fractions = stage_fractions(model.dynamics, options.substeps);
    let hidden = run_in_hidden(&network, model, &record, &fractions, &hidden_init)?;
    let table = PairTable::build(model, &record, &train_rows, &hidden, &fractions);
    let mut training = Split {
        name: data.path.display().to_string(),
        record,
        table,
        hidden,
    };
    let mut validating = validation_splits(
        model,
        &training,
        validations,
        (first, &fractions),
        &hidden_init,
    )?;
    let validation_pairs = validating.first().map_or(0, |v| v.table.len());
    on_event(Event::Started {
        epochs: options.epochs,
        train_pairs: train_count,
        validation_pairs,
    });
    let range = PhysicalRange::new(&setup.normalisation, recipe.range_factor);
    let context = (&setup, options, range.as_ref());
    let mut metrics = Metrics::default();
    if let Some(split) = validating.first_mut() {
        let (offline, online) = validate(&network, model, split, context, &hidden_init)?;
        metrics.initial_offline = Some(offline);
        metrics.initial_online = Some(online);
    }
    let fit = fit::Fit {
        model,
        setup: &setup,
        options,
        recipe,
        hidden_init: &hidden_init,
        freeze_params: balance_fit.is_some(),
    };
    let losses = fit.run(&mut network, &mut training, on_event)?;
    refresh_hidden(&network, model, &mut training, &fractions, &hidden_init)?;
    let (polish, estimates) = match &balance_fit {
        Some(fit) => (None, fit.estimates.clone()),
        None => polish::polish_and_estimate(
            &mut network,
            model,
            &training.table,
            &setup,
            recipe.polishes(model),
        )?,
    };
    for split in &mut validating {
        let (offline, online) = validate(&network, model, split, context, &hidden_init)?;
        metrics.validations.push(ValidationErrors {
            name: split.name.clone(),
            pairs: split.table.len(),
            offline,
            online,
        });
    }
    if let Some(headline) = metrics.validations.first() {
        metrics.offline = Some(headline.offline.clone());
        metrics.online = Some(headline.online.clone());
    }
    let params = (model.params.iter().zip(network.param_values()))
        .map(|(p, v)| (p.name.clone(), v))
        .collect();
    let report = TrainReport {
        metrics,
        params,
        warnings,
        losses,
        train_pairs: train_count,
        validation_pairs,
        recipe: recipe.clone(),
        estimates,
        polish,
        balance_fit,
    };
    Ok(Trained {
        network,
        setup,
        report,
    })
}

fn check_options(options: &TrainOptions, recipe: &Recipe) -> Result<(), TrainError> {
    let bad = |option: &str, expected: &str, found: String| {
        Err(TrainError::BadOption {
            option: option.into(),
            expected: expected.into(),
            found,
        })
    };
    if options.batch_size == 0 {
        return bad("--batch", "a positive batch size", "0".into());
    }
    if options.substeps == 0 {
        return bad("--substeps", "a positive number of sub-steps", "0".into());
    }
    if !(options.learning_rate > 0.0 && options.learning_rate.is_finite()) {
        return bad(
            "--lr",
            "a positive learning rate",
            options.learning_rate.to_string(),
        );
    }
    let rate = recipe.param_learning_rate.unwrap_or(1.0);
    if !(rate > 0.0 && rate.is_finite()) {
        return bad("--param-lr", "a positive learning rate", rate.to_string());
    }
    if recipe.horizon == 0 {
        return bad("--horizon", "a positive number of steps", "0".into());
    }
    if !(recipe.range_factor >= 1.0 && recipe.range_factor.is_finite()) {
        return bad(
            "--range-factor",
            "a factor of at least 1",
            recipe.range_factor.to_string(),
        );
    }
    if let Some(norm) = recipe
        .max_gradient_norm
        .filter(|n| !(*n > 0.0 && n.is_finite()))
    {
        return bad("--clip", "a positive gradient norm", norm.to_string());
    }
    let shares = [recipe.warmup_share, recipe.ramp_share];
    if let Some(share) = shares.into_iter().find(|s| !(0.0..=1.0).contains(s)) {
        return bad(
            "--warmup/--ramp",
            "a share between 0 and 1",
            share.to_string(),
        );
    }
    if options.train_points == Some(0) {
        return bad("--train-points", "a positive number of pairs", "0".into());
    }
    if let Some(horizon) = options
        .online_horizon
        .filter(|h| !(*h > 0.0 && h.is_finite()))
    {
        return bad(
            "--online-horizon",
            "a positive time span",
            horizon.to_string(),
        );
    }
    Ok(())
}

fn check_trainable(model: &ir::Model) -> Result<(), TrainError> {
    if model.closures.is_empty() && model.params.is_empty() {
        return Err(TrainError::NothingToTrain {
            model: model.name.clone(),
        });
    }
    Ok(())
}

fn check_delays(model: &ir::Model, step: f64) -> Result<(), TrainError> {
    for closure in &model.closures {
        let embedding = &closure.embedding;
        if embedding.dim > 1 && embedding.delay < step * (1.0 - 1e-9) {
            return Err(TrainError::DelayBelowStep {
                closure: closure.name.clone(),
                delay: embedding.delay,
                step,
            });
        }
    }
    Ok(())
}

/// The measured states and inputs of `model` from `data`, as a [`Record`].
pub fn record_of(model: &ir::Model, data: &Dataset) -> Result<Record, TrainError> {
    let column = |name: &str| {
        data.column(name)
            .map(<[f64]>::to_vec)
            .ok_or_else(|| TrainError::MissingColumn {
                file: data.path.display().to_string(),
                column: name.to_string(),
            })
    };
    Ok(Record {
        step: data.step,
        times: data.times.clone(),
        inputs: (model.inputs.iter())
            .map(|i| column(&i.name))
            .collect::<Result<_, _>>()?,
        states: (model.states.iter())
            .map(|s| column(&s.name))
            .collect::<Result<_, _>>()?,
    })
}

pub(crate) fn pair_count(
    data: &Dataset,
    record: &Record,
    first: usize,
) -> Result<usize, TrainError> {
    if record.len() < first + 2 {
        return Err(TrainError::TooFewRows {
            file: data.path.display().to_string(),
            needed: first + 2,
            found: record.len(),
            reason: format!("{first} rows of embedding history and one step"),
        });
    }
    Ok(record.len() - 1 - first)
}

fn train_pair_count(
    options: &TrainOptions,
    has_validation_file: bool,
    available: usize,
) -> Result<usize, TrainError> {
    match options.train_points {
        Some(requested) if requested > available => Err(TrainError::TooManyTrainPoints {
            available,
            requested,
        }),
        Some(requested) => Ok(requested),
        None if has_validation_file => Ok(available),
        None => Ok(((available as f64 * DEFAULT_TRAIN_SHARE).round() as usize).clamp(1, available)),
    }
}

/// Mean and std of every input and measured state, and the range of every measured state,
/// over the first `rows` rows.
pub fn normalise(record: &Record, rows: usize) -> Normalisation {
    let stats = |series: &Vec<Vec<f64>>| -> (Vec<f64>, Vec<f64>) {
        series
            .iter()
            .map(|values| crate::numeric::mean_std(&values[..rows.min(values.len())]))
            .unzip()
    };
    let (state_mean, state_std) = stats(&record.states);
    let (input_mean, input_std) = stats(&record.inputs);
    let extreme = |pick: fn(f64, f64) -> f64, start: f64| -> Vec<f64> {
        (record.states.iter())
            .map(|values| {
                values[..rows.min(values.len())]
                    .iter()
                    .copied()
                    .fold(start, pick)
            })
            .collect()
    };
    Normalisation {
        state_mean,
        state_std,
        input_mean,
        input_std,
        state_min: extreme(f64::min, f64::INFINITY),
        state_max: extreme(f64::max, f64::NEG_INFINITY),
    }
}

/// Initial values of the hidden states (constant expressions of consts and params).
pub fn hidden_initial_values(model: &ir::Model) -> Result<Vec<f64>, TrainError> {
    (model.hidden.iter())
        .map(|state| {
            let init = state
                .init
                .as_ref()
                .ok_or_else(|| TrainError::HiddenWithoutInit {
                    name: state.name.clone(),
                })?;
            Ok(crate::eval::interpret(init, &|var| match var {
                ir::Var::Const(i) => model.consts.get(i).map_or(f64::NAN, |c| c.value),
                ir::Var::Param(i) => model.params.get(i).map_or(f64::NAN, |p| p.init),
                _ => f64::NAN,
            }))
        })
        .collect()
}

/// `model` with its params' initial values set to the balance estimate.
fn with_initial_params(model: &ir::Model, fit: &BalanceFit) -> ir::Model {
    let mut fitted = model.clone();
    for (param, estimate) in fitted.params.iter_mut().zip(&fit.estimates) {
        param.init = estimate.value;
    }
    fitted
}
