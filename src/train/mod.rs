//! Training of grey-box models on data sets (spec section 4; records spec; Lovelett et al.
//! 2020, section 2).
//!
//! [`train`] lays each experiment on its integration grid ([`prepare`], [`crate::record`]),
//! splits knots and experiments into training and validation ([`split`]), normalises over
//! the training part's measured cells, resolves closure magnitudes and warns about stiff
//! balances ([`analysis`]), then runs Adam on shuffled mini-batches of one-step pairs
//! ([`pairs`]) or free-run windows ([`windows`]) and reports the paper's two validation
//! errors per experiment and pooled ([`evaluate`]). What is done with a trained network
//! (saving and reloading it, predicting with it, its report, cross-validation's fold runs)
//! is the `trained` module's; `gbc bench` times training steps on this module's own
//! pipeline ([`crate::api::bench`]).
//!
//! Decisions this module makes (`docs/training.md` has them in full):
//! - **Loss** at measured cells only (and observables), each z-scored by its column's
//!   training statistics; `--weight X=W` scales a column's cells.
//! - **Hidden states** start at their declared initial values at each experiment's first
//!   knot and are integrated along it with the measured states reset to the data wherever
//!   the data know them; where they do not (long gaps, before the first cell) the run goes
//!   free and its values fill the reference. Both are refreshed with the current network
//!   (hidden states every epoch, the fill every [`FILL_REFRESH`] epochs); no gradient flows
//!   through them.
//! - **Online error**: a free run per validation experiment ([`split`] says from where),
//!   driven by the data's inputs, over `--online-horizon` (default: to the end).

pub mod analysis;
pub mod balances;
pub mod checkpoint;
pub mod coverage;
mod error;
pub mod evaluate;
mod fit;
mod flags;
pub mod initial;
pub mod mechanism;
pub mod polish;
pub(crate) mod prepare;
pub mod recipe;
pub mod recovery;
mod run;
pub mod settings;
pub mod split;
pub mod stepping;
mod substeps;
pub mod tensors;
#[cfg(test)]
mod tests;
pub mod toward;
pub(crate) mod validation;
pub mod warnings;

#[cfg(test)]
pub(crate) mod fixtures;

use crate::engine::graph::{Network, Precision, Setup};
use crate::ir;

pub use balances::BalanceFit;
pub use checkpoint::{Checkpoint, RunControl};
pub use error::TrainError;
pub use evaluate::{Divergence, ErrorSet, PhysicalRange};
pub use flags::{flag_of, with_flag};
pub use initial::{InitialState, Origin};
pub use polish::{ParamEstimate, PolishSummary};
pub use recipe::{Engine, Objective, ParamSource, Recipe, SparseBudget};
pub use recovery::Recovery;
pub use run::{settle, train_run, train_with, Settled, TRAINING};
pub use settings::Settings;
pub use split::{History, Part, TrainingData};
pub use toward::{StopChoice, TowardMechanism};
pub use warnings::Warning;

/// Epochs between refreshes of the model's fill of unknown stretches.
pub const FILL_REFRESH: usize = 10;

/// Options of a training run.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainOptions {
    /// Passes over the training pairs.
    pub epochs: usize,
    /// Pairs per Adam step.
    pub batch_size: usize,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Number of training pairs (the first ones) under the paper's protocol.
    pub train_points: Option<usize>,
    /// Seed of the initialisation and the shuffling.
    pub seed: u64,
    /// Element type.
    pub precision: Precision,
    /// RK4 sub-steps per grid step.
    pub substeps: usize,
    /// Length (model time) of the online free run; `None` runs to the end.
    pub online_horizon: Option<f64>,
    /// Which implementation runs the training steps.
    pub engine: Engine,
    /// Longest grid step (`None`: the median spacing of the densest measured column).
    pub dt: Option<f64>,
    /// Where whole-experiment free runs and training windows start.
    pub history: History,
    /// Loss weight of each named measured state (others weigh 1).
    pub column_weights: Vec<(String, f64)>,
    /// Strength of the pull toward the mechanism ([`toward`]).
    pub toward_mechanism: TowardMechanism,
}

impl Default for TrainOptions {
    fn default() -> Self {
        TrainOptions::with(&Settings::default())
    }
}

impl TrainOptions {
    /// The options of `settings` (the rest at their defaults: no train-point limit, seed 0,
    /// the whole online run, the grid's own step, held history, every cell weighing 1).
    pub fn with(settings: &Settings) -> Self {
        TrainOptions {
            epochs: settings.epochs,
            batch_size: settings.batch_size,
            learning_rate: settings.learning_rate,
            train_points: None,
            seed: 0,
            precision: settings.precision,
            substeps: settings.substeps,
            online_horizon: None,
            engine: settings.engine,
            dt: None,
            history: History::Held,
            column_weights: Vec::new(),
            toward_mechanism: settings.toward_mechanism,
        }
    }

    /// The shared settings among the options.
    pub fn settings(&self) -> Settings {
        Settings {
            epochs: self.epochs,
            batch_size: self.batch_size,
            learning_rate: self.learning_rate,
            precision: self.precision,
            substeps: self.substeps,
            engine: self.engine,
            toward_mechanism: self.toward_mechanism,
        }
    }
}

/// Something worth telling the user while training runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Event<'a> {
    /// Before the first epoch: a balance is too stiff, or steps with a target do not train.
    Warning(&'a Warning),
    /// An epoch went non-finite and training went back to the last finite one
    /// ([`recovery`]).
    Recovered(&'a Recovery),
    /// Before the first epoch.
    Started {
        /// Epochs to run.
        epochs: usize,
        /// Training pairs.
        train_pairs: usize,
        /// Validation pairs.
        validation_pairs: usize,
    },
    /// Before the first epoch: what of each training experiment trains, and the warm-up
    /// share the multi-step objective uses for it ([`coverage`]).
    Coverage(&'a coverage::Coverage, f64),
    /// Before the first epoch: the model's free runs over the training knots need this
    /// many sub-steps per step, and training takes them ([`substeps::training_substeps`]).
    Substeps(usize),
    /// Before anything trains: the record is sparse, and the run takes this budget
    /// ([`recipe::SparseBudget`]) for the epochs and learning rate left at their defaults.
    Budget(recipe::SparseBudget),
    /// A phase of the run starts: "validating the untrained network", "training" (the
    /// epochs), "evaluating the trained network" (initial states, polish, validation).
    Phase(&'static str),
    /// Within an epoch, after each Adam step (a slow epoch still shows life).
    Batch {
        /// 1-based epoch.
        epoch: usize,
        /// Batches done in this epoch.
        done: usize,
        /// Batches in this epoch.
        batches: usize,
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
    /// After an epoch, with early stopping: the pooled validation errors.
    Validation {
        /// 1-based epoch.
        epoch: usize,
        /// Offline error, if any pair scores it.
        offline: Option<f64>,
        /// Online error, if any free run scores it.
        online: Option<f64>,
    },
    /// `--toward-mechanism auto`: a fold of a candidate strength starts, a candidate is
    /// scored, or the strength is chosen ([`toward::choose`]).
    Strength(toward::ChoiceEvent<'a>),
    /// Early stopping ended training before the planned epochs.
    EarlyStop {
        /// The last epoch run.
        epoch: usize,
        /// The epoch whose weights are kept.
        best_epoch: usize,
        /// Its validation loss.
        best_loss: f64,
    },
}

/// Validation errors in normalised units (the paper's two errors): pooled over every
/// validation experiment, and per experiment.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Metrics {
    /// Offline validation error of the untrained network.
    pub initial_offline: Option<ErrorSet>,
    /// Online validation error of the untrained network.
    pub initial_online: Option<ErrorSet>,
    /// Offline validation error (one step from measured history), pooled.
    pub offline: Option<ErrorSet>,
    /// Online validation error (free runs), pooled.
    pub online: Option<ErrorSet>,
    /// Both errors of every validation experiment (or tail).
    #[serde(default)]
    pub validations: Vec<ValidationErrors>,
}

/// The errors of one validation experiment (or the validated part of one).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ValidationErrors {
    /// The experiment (with `(rest)` or `(tail)` when part of a training experiment).
    pub name: String,
    /// Its one-step pairs with measured history.
    pub pairs: usize,
    /// Offline error (absent without a pair whose history is measured).
    pub offline: Option<ErrorSet>,
    /// Online error (with the divergence, if the free run left the physical range).
    pub online: Option<ErrorSet>,
}

/// Where training went non-finite, and which weights it kept (a run under
/// [`RunControl::keep_last_finite`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpochDivergence {
    /// The 1-based epoch that went non-finite.
    pub epoch: usize,
    /// What went non-finite, in words: "the loss became NaN", "param `Y_X` = inf after
    /// the epoch".
    pub what: String,
    /// The epoch whose weights were kept: the last one whose weights were all finite (the
    /// best one with early stopping; 0: the initial weights).
    pub kept_epoch: usize,
    /// The phase it went non-finite in (unrecorded in runs saved before it was).
    #[serde(default)]
    pub phase: recovery::EpochPhase,
    /// What to try ([`recovery::advice`]).
    #[serde(default)]
    pub advice: String,
}

/// What a training run reports.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainReport {
    /// Validation errors.
    pub metrics: Metrics,
    /// Trained param values, in declaration order.
    pub params: Vec<(String, f64)>,
    /// Warnings issued before training: stiff balances, steps that do not train.
    pub warnings: Vec<Warning>,
    /// Mean training loss of each epoch.
    pub losses: Vec<f64>,
    /// Number of training pairs.
    pub train_pairs: usize,
    /// Number of validation pairs (over every validation experiment).
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
    /// The fit of a model without closures by free runs, when its params came from there
    /// ([`mechanism`]; then no epoch ran).
    pub mechanism_fit: Option<crate::solve::fit::FitSummary>,
    /// What of each training experiment trained ([`coverage`]).
    pub coverage: coverage::Coverage,
    /// Each experiment's initial state (training experiments first).
    pub initial_states: Vec<InitialState>,
    /// The grid's longest step.
    pub dt: f64,
    /// The Adam learning rate of the network weights.
    pub learning_rate: f64,
    /// Each training experiment whose later part validates (`--train-points`,
    /// `--val-fraction`), with the time its validated part starts.
    pub validated_from: Vec<(String, f64)>,
    /// The engine that ran the training steps ([`Engine::Auto`] resolved: graph or
    /// fused).
    pub engine: Engine,
    /// Where training went non-finite, when it did (under
    /// [`RunControl::keep_last_finite`]; the network then holds the kept epoch's weights,
    /// unpolished).
    pub diverged: Option<EpochDivergence>,
    /// Each time training went back to its last finite epoch and continued
    /// ([`RunControl::recoveries`]).
    pub recoveries: Vec<Recovery>,
    /// The pull toward the mechanism and how far the grey box moved from it (none for a
    /// model without closures; [`toward`]).
    pub toward_mechanism: Option<toward::MechanismDistance>,
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

/// Trains `model` on `data` with the default [`Recipe`]; `on_event` hears of warnings and
/// of every epoch.
#[cfg(test)]
pub fn train(
    model: &ir::Model,
    data: &TrainingData,
    options: &TrainOptions,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained, TrainError> {
    train_with(model, data, options, &Recipe::default(), on_event)
}

/// Per measured state, its loss weight (`--weight X=W`; 1 otherwise).
fn column_weights(model: &ir::Model, options: &TrainOptions) -> Result<Vec<f64>, TrainError> {
    let mut weights = vec![1.0; model.states.len()];
    for (name, weight) in &options.column_weights {
        let names: Vec<&str> = model.states.iter().map(|s| s.name.as_str()).collect();
        let index = names
            .iter()
            .position(|n| n == name)
            .ok_or_else(|| TrainError::BadOption {
                option: "column_weights".into(),
                expected: format!(
                    "a measured state ({})",
                    crate::suggest::did_you_mean(name, &names, "measured states")
                ),
                found: name.clone(),
            })?;
        if !(*weight > 0.0 && weight.is_finite()) {
            return Err(TrainError::BadOption {
                option: "column_weights".into(),
                expected: "a positive weight".into(),
                found: format!("{name}={weight}"),
            });
        }
        weights[index] = *weight;
    }
    Ok(weights)
}

/// Checks the options; errors name the field (`batch_size`, `max_gradient_norm`), which the
/// command line turns into its flag.
fn check_options(options: &TrainOptions, recipe: &Recipe) -> Result<(), TrainError> {
    let bad = |option: &str, expected: &str, found: String| {
        Err(TrainError::BadOption {
            option: option.into(),
            expected: expected.into(),
            found,
        })
    };
    if let Err(setting) = options.settings().check() {
        return bad(setting.field, setting.expected, setting.found);
    }
    let rate = recipe.param_learning_rate.unwrap_or(1.0);
    if !(rate > 0.0 && rate.is_finite()) {
        return bad(
            "param_learning_rate",
            "a positive learning rate",
            rate.to_string(),
        );
    }
    if recipe.horizon == 0 {
        return bad("horizon", "a positive number of steps", "0".into());
    }
    if !(recipe.range_factor >= 1.0 && recipe.range_factor.is_finite()) {
        return bad(
            "range_factor",
            "a factor of at least 1",
            recipe.range_factor.to_string(),
        );
    }
    if let Some(norm) = recipe
        .max_gradient_norm
        .filter(|n| !(*n > 0.0 && n.is_finite()))
    {
        return bad(
            "max_gradient_norm",
            "a positive gradient norm",
            norm.to_string(),
        );
    }
    for (field, share) in [
        ("warmup_share", recipe.warmup_share),
        ("ramp_share", recipe.ramp_share),
    ] {
        if !(0.0..=1.0).contains(&share) {
            return bad(field, "a share between 0 and 1", share.to_string());
        }
    }
    if options.train_points == Some(0) {
        return bad("train_points", "a positive number of pairs", "0".into());
    }
    if let Some(horizon) = options
        .online_horizon
        .filter(|h| !(*h > 0.0 && h.is_finite()))
    {
        return bad(
            "online_horizon",
            "a positive time span",
            horizon.to_string(),
        );
    }
    Ok(())
}

/// The training experiments whose later part validates, with the time it starts.
pub(crate) fn validated_from(layout: &prepare::Layout) -> Vec<(String, f64)> {
    (layout.scorings[..layout.part_scorings].iter())
        .filter_map(|scoring| {
            let track = &layout.tracks[scoring.track];
            let time = if scoring.scored_from.is_finite() {
                scoring.scored_from
            } else {
                *track.times.get(scoring.run_start)?
            };
            Some((track.name.clone(), time))
        })
        .collect()
}

/// How many one-step pairs `data`'s training experiments offer `model` (the largest
/// `train_points`), under `options`' grid and history.
pub fn available_pairs(
    model: &ir::Model,
    data: &TrainingData,
    options: &TrainOptions,
) -> Result<usize, TrainError> {
    let data = TrainingData {
        part: Part::FirstPairs(None),
        ..*data
    };
    Ok(prepare::Layout::new(model, &data, options)?.pairs.len())
}

/// The measured states and inputs of `model` from a complete record `data`, as a
/// [`crate::record::Record`].
pub fn record_of(
    model: &ir::Model,
    data: &crate::data::Dataset,
) -> Result<crate::record::Record, TrainError> {
    let column = |name: &str| {
        data.column(name)
            .map(<[f64]>::to_vec)
            .ok_or_else(|| TrainError::MissingColumn {
                file: data.path.display().to_string(),
                column: name.to_string(),
            })
    };
    let name = data.path.display().to_string();
    let mut record = crate::record::Record::complete(
        &name,
        data.times.clone(),
        (model.inputs.iter())
            .map(|i| column(&i.name))
            .collect::<Result<_, _>>()?,
        (model.states.iter())
            .map(|s| column(&s.name))
            .collect::<Result<_, _>>()?,
    );
    record.source = name;
    Ok(record)
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
