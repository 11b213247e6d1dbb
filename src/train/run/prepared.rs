//! The first step of a run, [`prepare`]: the options checked, the grid, split and
//! normalisation laid out ([`Ground`]), closure magnitudes and stiffness warnings, the
//! params from the balances or a free-run fit of the mechanism, the network with the
//! sub-steps a stiff model needs, and the courses the epochs and the validation run over.

use std::borrow::Cow;

use crate::engine::graph::{Network, Setup};
use crate::engine::pairs::stage_fractions;
use crate::ir;
use crate::solve::fit::MechanismFit;
use crate::train::balances::{self, BalanceFit};
use crate::train::coverage::{Coverage, DENSE_SHARE};
use crate::train::prepare::Layout;
use crate::train::substeps;
use crate::train::validation::{refresh, Course};
use crate::train::{
    analysis, check_options, column_weights, hidden_initial_values, mechanism, with_initial_params,
    Event, Objective, ParamSource, Part, Recipe, TrainError, TrainOptions, TrainingData, Warning,
};

/// The phase that fits a model without closures, or a grey box's mechanism ([`mechanism`]).
pub const FITTING: &str = "fitting the params by free runs (as gbc diagnose)";

/// A run between its steps.
pub(super) struct Run<'m> {
    /// The model, with its params' initial values from the balances where they came from
    /// there.
    pub model: Cow<'m, ir::Model>,
    /// The grid, the tracks and their pairs, the split and the normalisation.
    pub layout: Layout,
    /// The hidden states' initial values.
    pub hidden_init: Vec<f64>,
    /// The stage fractions of one sub-step.
    pub fractions: Vec<f64>,
    /// The warnings the report keeps.
    pub warnings: Vec<Warning>,
    /// The params estimated from the balances, if they were.
    pub balance_fit: Option<BalanceFit>,
    /// The mechanism fitted by free runs, if it was.
    pub mechanism_fit: Option<MechanismFit>,
    /// What the one-step pairs and the windows reach of the data.
    pub coverage: Coverage,
    /// How the network was built.
    pub setup: Setup,
    /// The network.
    pub network: Network,
    /// The training tracks' course.
    pub training: Course,
    /// The validation tracks' course.
    pub validating: Course,
    /// Pairs the validation scores.
    pub validation_pairs: usize,
}

/// Whether no epoch trains `model`: it has no closure, and its params were `fitted` by
/// free runs or it has none (a fully known model is scored as declared: the held-out error
/// of a literature model whose every constant is known).
pub(super) fn trains_nothing(model: &ir::Model, fitted: bool) -> bool {
    model.closures.is_empty() && (fitted || model.params.is_empty())
}

/// Checks the options and builds everything the epochs need; tells `on_event` of
/// stiffness warnings and, last, that training starts.
pub(super) fn prepare<'m>(
    model: &'m ir::Model,
    data: &TrainingData,
    options: &TrainOptions,
    recipe: &Recipe,
    on_event: &mut dyn FnMut(Event),
) -> Result<Run<'m>, TrainError> {
    check_options(options, recipe)?;
    let how = (options, recipe);
    let ground = Ground::lay(model, data, how, on_event)?;
    let (balance_fit, mechanism_fit) = ground.initial_params(model, how, on_event)?;
    let model = match (&balance_fit, &mechanism_fit) {
        (Some(fit), _) => Cow::Owned(with_initial_params(model, fit)),
        (None, Some(fit)) => Cow::Owned(mechanism::with_fitted_params(model, fit)),
        (None, None) => Cow::Borrowed(model),
    };
    let (setup, network, substeps) = ground.network(&model, options, on_event)?;
    let Ground {
        layout,
        coverage,
        hidden_init,
        mut warnings,
        ..
    } = ground;
    // A stiffness warning the chosen sub-steps answer is not one.
    warnings.retain(|w| !matches!(w, Warning::Stiffness(s) if s.substeps_needed <= substeps));
    for warning in &warnings {
        on_event(Event::Warning(warning));
    }
    let fractions = stage_fractions(model.dynamics, setup.substeps);
    let how = (&fractions[..], &hidden_init[..]);
    let (training, validating) = courses(&model, &network, &layout, how, options)?;
    let validation_pairs = layout.scorings.iter().map(|s| s.pairs.len()).sum();
    on_event(Event::Started {
        epochs: if trains_nothing(&model, mechanism_fit.is_some()) {
            0
        } else {
            options.epochs
        },
        train_pairs: layout.pairs.len(),
        validation_pairs,
    });
    Ok(Run {
        model,
        layout,
        hidden_init,
        fractions,
        warnings,
        balance_fit,
        mechanism_fit,
        coverage,
        setup,
        network,
        training,
        validating,
        validation_pairs,
    })
}

/// What the data say before anything is fitted or built.
struct Ground<'d> {
    /// The data, with the part that trains as the options say.
    data: TrainingData<'d>,
    layout: Layout,
    coverage: Coverage,
    hidden_init: Vec<f64>,
    /// The closures' magnitudes.
    scales: Vec<Vec<f64>>,
    /// Stiffness warnings (at the sub-steps asked for) and dropped pairs.
    warnings: Vec<Warning>,
}

impl<'d> Ground<'d> {
    /// Lays out `data` for `model` (told as [`Event::Coverage`] for a grey box) and
    /// estimates the closures' magnitudes and where the balances are stiff.
    fn lay(
        model: &ir::Model,
        data: &TrainingData<'d>,
        (options, recipe): (&TrainOptions, &Recipe),
        on_event: &mut dyn FnMut(Event),
    ) -> Result<Self, TrainError> {
        let train_points = options.train_points.map(Some);
        let data = TrainingData {
            part: train_points.map_or(data.part, Part::FirstPairs),
            ..*data
        };
        let layout = Layout::new(model, &data, options)?;
        let coverage = Coverage::of(model, (&layout.tracks, &layout.trainings), &layout.pairs);
        if !model.closures.is_empty() {
            on_event(Event::Coverage(
                &coverage,
                coverage.warmup_share(recipe.warmup_share),
            ));
        }
        let hidden_init = hidden_initial_values(model)?;
        let (tracks, intervals) = (&layout.tracks, &layout.intervals);
        let scales = analysis::closure_scales(model, tracks, intervals, &hidden_init)?;
        let stiff =
            analysis::stiffness(model, (tracks, intervals), &hidden_init, options.substeps)?;
        // Under the multi-step objective the steps without a pair still train in windows:
        // the coverage note says what trains instead.
        let dropped = (layout.dropped.clone())
            .filter(|_| recipe.objective == Objective::OneStep)
            .map(Warning::DroppedPairs);
        let warnings: Vec<Warning> = (stiff.into_iter().map(Warning::Stiffness))
            .chain(dropped)
            .collect();
        Ok(Ground {
            data,
            layout,
            coverage,
            hidden_init,
            scales,
            warnings,
        })
    }

    /// Where the params start: estimated from the balances, or the mechanism fitted by
    /// free runs (told as the [`FITTING`] phase), as the recipe asks and the data allow.
    fn initial_params(
        &self,
        model: &ir::Model,
        (options, recipe): (&TrainOptions, &Recipe),
        on_event: &mut dyn FnMut(Event),
    ) -> Result<(Option<BalanceFit>, Option<MechanismFit>), TrainError> {
        let (data, layout) = (&self.data, &self.layout);
        let mut mechanism_fit = match mechanism::source(model, data, recipe, &self.coverage) {
            Some(fitted) => {
                on_event(Event::Phase(FITTING));
                Some(mechanism::fit(&fitted, data, layout, options)?)
            }
            None => None,
        };
        let balance_fit = if recipe.params_from_balances() && mechanism_fit.is_none() {
            balances::estimate(model, &self.scales, &layout.tracks, &layout.intervals)?
        } else {
            None
        };
        if mechanism_fit.is_none() && balance_fit.is_none() {
            if let Some(fitted) = mechanism::fallback(model, data, recipe) {
                on_event(Event::Phase(FITTING));
                mechanism_fit = Some(mechanism::fit(&fitted, data, layout, options)?);
            }
        }
        if recipe.params == ParamSource::Balances && balance_fit.is_none() {
            return Err(TrainError::ParamsFromBalances {
                model: model.name.clone(),
            });
        }
        Ok((balance_fit, mechanism_fit))
    }

    /// The network of `model` and its setup, with as many sub-steps as training needs
    /// (more than asked are told as [`Event::Substeps`]), and the sub-steps training
    /// needs.
    fn network(
        &self,
        model: &ir::Model,
        options: &TrainOptions,
        on_event: &mut dyn FnMut(Event),
    ) -> Result<(Setup, Network, usize), TrainError> {
        let mut setup = Setup {
            step: self.layout.grid.max_step,
            substeps: options.substeps,
            precision: options.precision,
            seed: options.seed,
            normalisation: self.layout.normalisation.clone(),
            scales: self.scales.clone(),
        };
        let mut network = Network::build(model, &setup)?;
        let substeps = self.training_substeps(model, &network, options.substeps);
        if substeps > setup.substeps {
            setup.substeps = substeps;
            network = Network::build(model, &setup)?;
            on_event(Event::Substeps(substeps));
        }
        Ok((setup, network, substeps))
    }

    /// The sub-steps training needs, at least `asked`: as finely as a stiff balance needs,
    /// so that no user picks `--substeps`: on a sparse record as the model's own free runs
    /// over the training knots need (the data's intervals say little there); on a dense
    /// one as the stiffness estimate asks, where it warns.
    fn training_substeps(&self, model: &ir::Model, network: &Network, asked: usize) -> usize {
        if model.closures.is_empty() {
            // Nothing trains: the params were fitted by the exact integrator.
            asked
        } else if self.coverage.one_step_share() < DENSE_SHARE {
            let layout = &self.layout;
            let place = (&layout.tracks[..], &layout.trainings[..]);
            let fractions = stage_fractions(model.dynamics, asked);
            let how = (&fractions[..], &self.hidden_init[..]);
            substeps::training_substeps((network, model), place, how, asked)
        } else {
            (self.warnings.iter())
                .filter_map(|w| match w {
                    Warning::Stiffness(s) => Some(s.substeps_needed),
                    _ => None,
                })
                .fold(asked, usize::max)
                .min(substeps::MOST_TRAINING_SUBSTEPS)
        }
    }
}

/// The courses of the training tracks (their hidden states refreshed) and of the
/// validation tracks.
fn courses(
    model: &ir::Model,
    network: &Network,
    layout: &Layout,
    (fractions, hidden_init): (&[f64], &[f64]),
    options: &TrainOptions,
) -> Result<(Course, Course), TrainError> {
    let weights = column_weights(model, options)?;
    let observables = &layout.normalisation.observables;
    let mut training = Course::new(
        model,
        layout.tracks.clone(),
        (&layout.pairs, &weights, observables),
        fractions,
    );
    refresh(
        network,
        model,
        &mut training,
        (fractions, false),
        hidden_init,
    )?;
    let validating = Course::new(
        model,
        layout.validation_tracks.clone(),
        (&[], &weights, observables),
        fractions,
    );
    Ok((training, validating))
}
