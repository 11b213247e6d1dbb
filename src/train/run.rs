//! [`train_with`] in four steps: [`prepare`] (options checked, grid, split, normalisation,
//! closure magnitudes, stiffness warnings, params from the balances, network and pair
//! tables), [`Run::fit`] (the epochs, [`super::fit`]), [`Run::evaluate`] (initial states
//! re-fitted, params polished, validation errors) and [`Run::report`] (the
//! [`TrainReport`]). Each step reads what the one before it left in [`Run`].

mod prepared;

use crate::engine::graph::Network;
use crate::ir;

use super::checkpoint::{RunControl, Safety};
use super::coverage::{Coverage, DENSE_SHARE};
use super::fit::Fitted;
use super::polish::{ParamEstimate, PolishSummary};
use super::prepare::Layout;
use super::recipe::SparseBudget;
use super::toward::{self, MechanismDistance, StopChoice, TowardMechanism};
use super::validation::{refresh, validate};
use super::{
    fit, initial, mechanism, polish, Event, InitialState, Metrics, Objective, Part, PhysicalRange,
    Recipe, TrainError, TrainOptions, TrainReport, Trained, TrainingData,
};
use prepared::{prepare, trains_nothing, Run};

/// Trains `model` on `data` with `recipe`: prepare (grid, split, normalisation, magnitudes,
/// params from the balances), fit, evaluate, report.
pub fn train_with(
    model: &ir::Model,
    data: &TrainingData,
    options: &TrainOptions,
    recipe: &Recipe,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained, TrainError> {
    let control = RunControl::default();
    train_run(model, data, (options, recipe), &control, on_event)
}

/// [`train_with`] under `control`: checkpoints, interruption, resuming and early stopping
/// A free run stopped by a stop request ([`crate::stop`]) as [`TrainError::StoppedBefore`]
/// while `phase`; any other error as it is.
fn stopped_in(error: TrainError, phase: &str) -> TrainError {
    match error {
        TrainError::Backend(crate::engine::graph::BackendError::Stopped) => {
            TrainError::StoppedBefore {
                phase: phase.into(),
            }
        }
        error => error,
    }
}

/// [`TrainError::StoppedBefore`] when `control` was asked to stop while `phase`.
fn unless_stopped(control: &RunControl, phase: &str) -> Result<(), TrainError> {
    if super::checkpoint::stop_requested(control) {
        return Err(TrainError::StoppedBefore {
            phase: phase.into(),
        });
    }
    Ok(())
}

/// ([`super::checkpoint`]).
pub fn train_run(
    model: &ir::Model,
    data: &TrainingData,
    (options, recipe): (&TrainOptions, &Recipe),
    control: &RunControl,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained, TrainError> {
    let started = std::time::Instant::now();
    let resolved = settle(model, data, (options, recipe), control, on_event)?;
    let control = RunControl {
        last_epoch: resolved.last_epoch.or(control.last_epoch),
        ..control.clone()
    };
    let (options, recipe, control) = (&resolved.options, &resolved.recipe, &control);
    let choice = (resolved.choice, resolved.unchosen);
    let mut run = prepare(model, data, options, recipe, on_event)?;
    unless_stopped(control, "it was preparing (fitting its mechanism)")?;
    // On a sparse record the one-step warm-up reaches few cells: it shrinks in proportion.
    let sparse = Recipe {
        warmup_share: run.coverage.warmup_share(recipe.warmup_share),
        ..recipe.clone()
    };
    let recipe = &sparse;
    // The sub-steps prepare chose for a stiff model.
    let stepped = TrainOptions {
        substeps: run.setup.substeps,
        ..options.clone()
    };
    let options = &stepped;
    if !run.layout.scorings.is_empty() {
        on_event(Event::Phase(VALIDATING));
    }
    let scoring = "it was scoring its start";
    let initial = (run.validate(options, recipe)).map_err(|error| stopped_in(error, scoring))?;
    unless_stopped(control, scoring)?;
    on_event(Event::Phase(TRAINING));
    let fitted = run.fit((options, recipe), (control, started), on_event)?;
    on_event(Event::Phase(EVALUATING));
    let polishes = fitted.diverged.is_none() && recipe.polishes(&run.model);
    let trained = run.network.weights();
    let mut evaluation = run.evaluate(options, recipe, polishes)?;
    let params: Vec<String> = run.model.params.iter().map(|p| p.name.clone()).collect();
    let mut fitted = fitted;
    if let Some(found) = crate::finite::in_tensors(&run.network.weights(), &params) {
        let epoch = fitted.losses.len();
        let what = format!("{found} after the polish");
        if !control.keep_last_finite {
            return Err(TrainError::Diverged { epoch, what });
        }
        // The polish went non-finite: the trained weights stay, unpolished.
        run.network.set_weights(&trained)?;
        evaluation = run.evaluate(options, recipe, false)?;
        let recovery = super::Recovery {
            epoch,
            what,
            phase: super::recovery::EpochPhase::Polish,
            back_to: epoch,
            learning_rate: options.learning_rate,
            horizon: recipe.horizon_at(epoch.max(1), options.epochs),
        };
        on_event(Event::Recovered(&recovery));
        fitted.recoveries.push(recovery);
    }
    let closures_trained = !run.model.closures.is_empty() && !fitted.losses.is_empty();
    if closures_trained && run.mechanism_fit.is_some() {
        mechanism::unassessed_once_trained(&mut evaluation.estimates);
    }
    let distance = run.distance(options, choice, &evaluation.estimates)?;
    Ok(run.report(options, recipe, (initial, evaluation), (fitted, distance)))
}

/// A run's options and recipe once the defaults that depend on the data are settled: a
/// sparse record's budget, and where `--toward-mechanism auto` stops.
pub struct Settled {
    /// The options to train with (the budget applied, the strength fixed: 0 after `auto`).
    pub options: TrainOptions,
    /// The recipe (no polish where `auto` stopped at 0).
    pub recipe: Recipe,
    /// The last epoch `auto` chose ([`RunControl::last_epoch`]; none at 0, where the
    /// options run no epoch).
    pub last_epoch: Option<usize>,
    /// How `auto` chose.
    pub choice: Option<StopChoice>,
    /// Why `auto` could not choose.
    pub unchosen: Option<String>,
}

/// Settles the sparse budget ([`Recipe::sparse_budget`], told as [`Event::Budget`]) and
/// `auto`: the folds choose the stop ([`toward::choose`]); the run then trains without a
/// pull and ends there (a stop at 0 is the mechanism itself: no epoch, no polish). An
/// ensemble settles once for all its members.
pub fn settle(
    model: &ir::Model,
    data: &TrainingData,
    (options, recipe): (&TrainOptions, &Recipe),
    control: &RunControl,
    on_event: &mut dyn FnMut(Event),
) -> Result<Settled, TrainError> {
    let mut options = options.clone();
    if let Some(budget) = sparse_budget(model, data, (&options, recipe))? {
        (options.epochs, options.learning_rate) = (budget.epochs, budget.learning_rate);
        on_event(Event::Budget(budget));
    }
    let mut resolved = Settled {
        options,
        recipe: recipe.clone(),
        last_epoch: None,
        choice: None,
        unchosen: None,
    };
    if resolved.options.toward_mechanism != TowardMechanism::Auto {
        return Ok(resolved);
    }
    let how = (&resolved.options, recipe);
    let found = toward::choose(model, data, how, control, on_event)?;
    resolved.options.toward_mechanism = TowardMechanism::Strength(0.0);
    match found {
        Ok(choice) if choice.chosen == 0 => {
            resolved.options.epochs = 0;
            resolved.recipe.polish = Some(false);
            resolved.choice = Some(choice);
        }
        Ok(choice) => {
            resolved.last_epoch = Some(choice.chosen);
            resolved.choice = Some(choice);
        }
        Err(why) => resolved.unchosen = Some(why),
    }
    Ok(resolved)
}

/// The budget of `recipe` where the record is sparse (one-step pairs reach under
/// [`DENSE_SHARE`] of the cells the windows reach), the model has closures to train by the
/// multi-step objective, and the epochs and learning rate are the defaults of
/// [`super::Settings`] (a caller who set either keeps both).
fn sparse_budget(
    model: &ir::Model,
    data: &TrainingData,
    (options, recipe): (&TrainOptions, &Recipe),
) -> Result<Option<SparseBudget>, TrainError> {
    let Some(budget) = recipe.sparse_budget else {
        return Ok(None);
    };
    let defaults = super::Settings::default();
    let at_defaults =
        (options.epochs, options.learning_rate) == (defaults.epochs, defaults.learning_rate);
    if !at_defaults || model.closures.is_empty() || recipe.objective != Objective::MultiStep {
        return Ok(None);
    }
    let data = TrainingData {
        part: (options.train_points).map_or(data.part, |n| Part::FirstPairs(Some(n))),
        ..*data
    };
    let layout = Layout::new(model, &data, options)?;
    let coverage = Coverage::of(model, (&layout.tracks, &layout.trainings), &layout.pairs);
    Ok((coverage.one_step_share() < DENSE_SHARE).then_some(budget))
}

/// The phase before the epochs ([`Event::Phase`]).
pub const VALIDATING: &str = "validating the untrained network";
/// The phase of the epochs.
pub const TRAINING: &str = "training";
/// The phase after the epochs.
pub const EVALUATING: &str = "evaluating the trained network";

/// What [`Run::evaluate`] finds.
struct Evaluation {
    metrics: Metrics,
    initial_states: Vec<InitialState>,
    polish: Option<PolishSummary>,
    estimates: Vec<ParamEstimate>,
}

impl Run<'_> {
    /// The validation errors of the network as it is (none without validation data).
    fn validate(&mut self, options: &TrainOptions, recipe: &Recipe) -> Result<Metrics, TrainError> {
        let mut metrics = Metrics::default();
        if self.layout.scorings.is_empty() {
            return Ok(metrics);
        }
        let range = PhysicalRange::new(&self.setup.normalisation, recipe.range_factor);
        let (offline, online, each) = validate(
            &self.network,
            &self.model,
            (&mut self.validating, &self.layout.scorings),
            (&self.setup, options, range.as_ref()),
            &self.hidden_init,
        )?;
        metrics.offline = offline;
        metrics.online = online;
        metrics.validations = each;
        Ok(metrics)
    }

    /// Runs the epochs: the mean training loss of each, the engine that ran them and where
    /// training went non-finite.
    fn fit(
        &mut self,
        (options, recipe): (&TrainOptions, &Recipe),
        (control, started): (&RunControl, std::time::Instant),
        on_event: &mut dyn FnMut(Event),
    ) -> Result<Fitted, TrainError> {
        // A fitted (or fully known) mechanism has nothing left to train: no epoch runs.
        let fitted_options = TrainOptions {
            epochs: 0,
            ..options.clone()
        };
        let options = match trains_nothing(&self.model, self.mechanism_fit.is_some()) {
            true => &fitted_options,
            false => options,
        };
        let fit = fit::Fit {
            model: &self.model,
            setup: &self.setup,
            options,
            recipe,
            hidden_init: &self.hidden_init,
            freeze_params: self.balance_fit.is_some() || self.mechanism_fit.is_some(),
            trainings: &self.layout.trainings,
        };
        let range = PhysicalRange::new(&self.setup.normalisation, recipe.range_factor);
        let context = (&self.setup, options, range.as_ref());
        let (validating, scorings, hidden_init) = (
            &mut self.validating,
            &self.layout.scorings,
            &self.hidden_init,
        );
        let model: &ir::Model = &self.model;
        let mut validate_now = |network: &Network| {
            let scoring = (&mut *validating, &scorings[..]);
            let (offline, online, _) = validate(network, model, scoring, context, hidden_init)?;
            Ok((offline.map(|s| s.overall), online.map(|s| s.overall)))
        };
        let validate_now = (!scorings.is_empty()).then_some(&mut validate_now as _);
        let mut safety = Safety::new(control, (options, started), validate_now);
        safety.count_from(recipe.full_horizon_from(options.epochs));
        fit.run(&mut self.network, &mut self.training, on_event, &mut safety)
    }

    /// After the epochs: initial states re-fitted on the training and validation data,
    /// hidden states refreshed, params polished (with `polishes`, unless they came from the
    /// balances), and the validation errors of the trained network.
    fn evaluate(
        &mut self,
        options: &TrainOptions,
        recipe: &Recipe,
        polishes: bool,
    ) -> Result<Evaluation, TrainError> {
        let mut initial_states = self.layout.initial.clone();
        let refit = (&mut initial_states[..], self.hidden_init.as_slice());
        initial::fit_initial_states(
            &self.network,
            &self.model,
            (&mut self.training, &self.fractions),
            &self.setup.normalisation,
            refit,
        )?;
        refresh(
            &self.network,
            &self.model,
            &mut self.training,
            (&self.fractions, true),
            &self.hidden_init,
        )?;
        let refit = (&mut initial_states[..], self.hidden_init.as_slice());
        initial::fit_initial_states(
            &self.network,
            &self.model,
            (&mut self.validating, &self.fractions),
            &self.setup.normalisation,
            refit,
        )?;
        let (polish, estimates) = match (&self.balance_fit, &self.mechanism_fit) {
            (Some(fit), _) => (None, fit.estimates.clone()),
            (None, Some(fit)) => (None, mechanism::param_estimates(&self.model, &fit.summary)),
            (None, None) => polish::polish_and_estimate(
                &mut self.network,
                &self.model,
                &self.training.table,
                &self.setup,
                polishes,
            )?,
        };
        let metrics = self.validate(options, recipe)?;
        Ok(Evaluation {
            metrics,
            initial_states,
            polish,
            estimates,
        })
    }

    /// How far the trained grey box is from its mechanism: each closure output over every
    /// knot of the training tracks, each param from its start (none without closures).
    fn distance(
        &mut self,
        options: &TrainOptions,
        (choice, unchosen): (Option<StopChoice>, Option<String>),
        estimates: &[super::ParamEstimate],
    ) -> Result<Option<MechanismDistance>, TrainError> {
        if self.model.closures.is_empty() {
            return Ok(None);
        }
        let knots: Vec<(usize, usize)> = (self.training.tracks.iter().enumerate())
            .flat_map(|(t, track)| (0..track.times.len()).map(move |k| (t, k)))
            .collect();
        let table = crate::engine::pairs::PairTable::build(
            &self.model,
            &self.training.tracks,
            &knots,
            &self.training.hidden,
            &self.fractions,
        );
        let batch = table.batch(&(0..knots.len()).collect::<Vec<_>>());
        let outputs = toward::output_distances(&mut self.network, &self.model, &batch)?;
        let values: Vec<(String, f64)> = (self.model.params.iter())
            .zip(self.network.param_values())
            .map(|(p, v)| (p.name.clone(), v))
            .collect();
        Ok(Some(MechanismDistance {
            strength: options.toward_mechanism.strength().unwrap_or(0.0),
            choice,
            unchosen,
            outputs,
            params: toward::param_distances(&self.model, &values, estimates),
        }))
    }

    /// The trained network and its report.
    fn report(
        self,
        options: &TrainOptions,
        recipe: &Recipe,
        (initial, evaluation): (Metrics, Evaluation),
        (fitted, distance): (Fitted, Option<MechanismDistance>),
    ) -> Trained {
        let metrics = Metrics {
            initial_offline: initial.offline,
            initial_online: initial.online,
            ..evaluation.metrics
        };
        let params = (self.model.params.iter().zip(self.network.param_values()))
            .map(|(p, v)| (p.name.clone(), v))
            .collect();
        let report = TrainReport {
            metrics,
            params,
            warnings: self.warnings,
            losses: fitted.losses,
            train_pairs: self.layout.pairs.len(),
            validation_pairs: self.validation_pairs,
            recipe: recipe.clone(),
            estimates: evaluation.estimates,
            polish: evaluation.polish,
            balance_fit: self.balance_fit,
            mechanism_fit: self.mechanism_fit.map(|fit| fit.summary),
            coverage: self.coverage,
            initial_states: evaluation.initial_states,
            dt: self.layout.grid.max_step,
            learning_rate: options.learning_rate,
            validated_from: super::validated_from(&self.layout),
            engine: fitted.engine,
            diverged: fitted.diverged,
            recoveries: fitted.recoveries,
            toward_mechanism: distance,
        };
        Trained {
            network: self.network,
            setup: self.setup,
            report,
        }
    }
}
