//! The epochs of training: one-step epochs of shuffled pair batches and, for the
//! multi-step objective, rollout epochs over shuffled shooting windows (see
//! [`super::recipe`]).
//!
//! Every step goes through one [`Optimiser`] (weights and Adam's state) on top of a
//! [`Step`]: with [`Engine::Fused`] (and [`Engine::Auto`] where the fused step runs the
//! model) every batch, pairs and windows, on a [`FusedNetwork`], else on the graph
//! [`Network`]; a run never changes engine. The engines only compute gradients at the
//! optimiser's weights; the graph network is given the current weights before hidden
//! states are refreshed and at the end, so that the polish and the evaluation see the
//! trained network.

mod engines;
pub(super) mod epoch_end;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::engine::graph::{Network, Setup, StepSettings};
use crate::ir;

use super::checkpoint::Safety;
use super::recovery::{self, Recovery};
use super::split::Training;
use super::toward::Penalty;
use super::validation::{refresh, Course};
use super::{
    Engine, EpochDivergence, Event, Objective, Recipe, TrainError, TrainOptions, FILL_REFRESH,
};
use crate::engine::graph::RolloutBatch;
use crate::engine::pairs::stage_fractions;
use crate::engine::step::{Optimiser, StepBatch};
use crate::engine::windows::{rollout_batch_into, shooting_starts};
use engines::Engines;
use epoch_end::EpochEnd;

/// What the epochs need besides the network.
pub(super) struct Fit<'a> {
    pub model: &'a ir::Model,
    pub setup: &'a Setup,
    pub options: &'a TrainOptions,
    pub recipe: &'a Recipe,
    pub hidden_init: &'a [f64],
    /// Hold the params at their initial values (they came from the balances).
    pub freeze_params: bool,
    /// What trains on each track.
    pub trainings: &'a [Training],
}

impl Fit<'_> {
    fn settings(&self) -> StepSettings {
        StepSettings {
            learning_rate: self.options.learning_rate,
            param_learning_rate: if self.freeze_params {
                0.0
            } else {
                (self.recipe.param_learning_rate).unwrap_or(self.options.learning_rate)
            },
            max_gradient_norm: self.recipe.max_gradient_norm,
        }
    }

    /// The pull toward the mechanism at the run's fixed strength (`auto` was resolved
    /// before the epochs), the params toward their initial values.
    fn penalty(&self, network: &Network) -> Penalty {
        let strength = (self.options.toward_mechanism.strength()).unwrap_or(0.0);
        let start = crate::engine::graph::initial_raw_params(self.model);
        Penalty::new(self.model, &network.weights(), strength, &start)
    }

    /// Runs every epoch (from a checkpoint's, and until `safety` stops it); returns the
    /// mean training loss of each, the engine that ran them ([`Engine::Graph`] or
    /// [`Engine::Fused`]) and, under [`super::RunControl::keep_last_finite`], where training
    /// went non-finite. `network` ends with the trained weights and Adam state whichever
    /// engine ran the epochs: after a divergence, those of the last epoch whose weights
    /// were all finite (without `keep_last_finite` a divergence is
    /// [`TrainError::Diverged`]).
    pub fn run(
        &self,
        network: &mut Network,
        training: &mut Course,
        on_event: &mut dyn FnMut(Event),
        safety: &mut Safety,
    ) -> Result<Fitted, TrainError> {
        let options = self.options;
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed.wrapping_add(0x5eed));
        let mut losses = Vec::with_capacity(options.epochs);
        // A checkpoint puts its weights into `network`; the optimiser starts from them and
        // from its Adam state.
        let first = safety.resume(network, training, &mut rng, &mut losses)?;
        let mut engines = Engines {
            fused: options.engine.fused_step(self.model, self.setup)?,
            optimiser: Optimiser::new(network, options.precision)
                .resumed(safety.resumed_adam())?
                .with_penalty(self.penalty(network)),
            network,
            windows: RolloutBatch::default(),
            scale: 1.0,
            cap: usize::MAX,
            recovered: 0,
        };
        let mut epochs = Epochs {
            epoch: first,
            kept: (first - 1, engines.optimiser.clone()),
            kept_at: (rng.clone(), 1),
            rng,
            losses,
            recoveries: Vec::new(),
            fractions: stage_fractions(self.model.dynamics, options.substeps),
            fill: fill_schedule(training),
        };
        let mut diverged = None;
        while epochs.epoch <= options.epochs {
            match self.next_epoch(&mut epochs, &mut engines, training, on_event, safety)? {
                After::Next => epochs.epoch += 1,
                After::Again => {}
                After::Stop => break,
                After::Diverged(failed) => {
                    diverged = Some(failed);
                    break;
                }
            }
        }
        let engine = match engines.fused {
            Some(_) => Engine::Fused,
            None => Engine::Graph,
        };
        let diverged = settle(diverged, epochs.kept, &mut engines, safety)?;
        engines.graph_with_weights()?;
        let best = safety.finish(network)?;
        Ok(Fitted {
            losses: epochs.losses,
            engine,
            diverged: diverged.map(|d| EpochDivergence {
                kept_epoch: best.unwrap_or(d.kept_epoch),
                ..d
            }),
            recoveries: epochs.recoveries,
        })
    }

    /// Epoch `epochs.epoch`, told to `on_event` and handed to `safety`; what the epochs do
    /// next. A stop inside it ends the run at the last epoch kept
    /// ([`Safety::stopped_within`]); a non-finite loss recovers (the same epoch again) or
    /// ends the epochs.
    fn next_epoch(
        &self,
        epochs: &mut Epochs,
        engines: &mut Engines,
        training: &mut Course,
        on_event: &mut dyn FnMut(Event),
        safety: &mut Safety,
    ) -> Result<After, TrainError> {
        let (epoch, options) = (epochs.epoch, self.options);
        let horizon = (self.recipe.horizon_at(epoch, options.epochs))
            .min(engines.cap)
            .min(self.longest_window());
        let fractions = epochs.fractions.as_slice();
        self.refresh_before(epoch, engines, training, (fractions, epochs.fill))?;
        let how = ((epoch, horizon), fractions);
        let stop = || safety.stop_requested();
        let mut checked =
            self.checked_epoch(engines, training, how, (&mut epochs.rng, &stop), on_event)?;
        if safety.poisoned(epoch) {
            checked = Err(Unfinished::NotFinite(
                "the loss became NaN (injected by a test)".into(),
            ));
        }
        let loss = match checked {
            Ok(loss) => loss,
            Err(Unfinished::Stopped) => return Err(epochs.stop(engines, training, safety)),
            Err(Unfinished::NotFinite(what)) => {
                let failed = (epoch, horizon, what);
                return Ok(match self.recover(failed, &epochs.kept, engines, safety) {
                    Ok(recovery) => {
                        on_event(Event::Recovered(&recovery));
                        epochs.recoveries.push(recovery);
                        After::Again
                    }
                    Err(failed) => After::Diverged(failed),
                });
            }
        };
        epochs.losses.push(loss);
        on_event(Event::Epoch {
            epoch,
            loss,
            horizon,
        });
        let end = EpochEnd {
            epoch,
            horizon,
            loss,
            rng: &epochs.rng,
            course: training,
            engines,
        };
        let stop = safety.after_epoch(end, on_event)?;
        epochs.kept = (epoch, engines.optimiser.clone());
        epochs.kept_at = (epochs.rng.clone(), horizon);
        Ok(if stop { After::Stop } else { After::Next })
    }

    /// After epoch `failed.0` (of `failed.1` steps) went non-finite (`failed.2`): while
    /// recoveries are left, the optimiser goes back to `kept` at half the learning rate
    /// (and half the rollout) and the recovery is returned; else the failure, described.
    fn recover(
        &self,
        (epoch, horizon, what): (usize, usize, String),
        (kept_epoch, kept): &(usize, Optimiser),
        engines: &mut Engines,
        safety: &Safety,
    ) -> Result<Recovery, Failure> {
        let multi_step = self.recipe.objective == Objective::MultiStep;
        let phase = recovery::EpochPhase::of_epoch(horizon, multi_step);
        let learning_rate = self.options.learning_rate * engines.scale;
        if engines.recovered >= safety.recoveries() {
            let advice = recovery::advice(&phase, learning_rate);
            return Err(Failure {
                epoch,
                what,
                phase,
                advice,
            });
        }
        engines.recovered += 1;
        (engines.scale, engines.cap) = recovery::backed_off((engines.scale, engines.cap), horizon);
        engines.optimiser = kept.clone();
        Ok(Recovery {
            epoch,
            what,
            phase,
            back_to: *kept_epoch,
            learning_rate: self.options.learning_rate * engines.scale,
            horizon: horizon.min(engines.cap),
        })
    }

    /// Before an epoch after the first: the hidden states refreshed with the current
    /// weights, and the model's fill of unknown stretches when it is due (`fill`: whether
    /// any is needed, and every how many epochs).
    fn refresh_before(
        &self,
        epoch: usize,
        engines: &mut Engines,
        training: &mut Course,
        (fractions, (needs_fill, every)): (&[f64], (bool, usize)),
    ) -> Result<(), TrainError> {
        let fill_due = needs_fill && (epoch - 1).is_multiple_of(every);
        if epoch > 1 && (!self.model.hidden.is_empty() || fill_due) {
            let current = engines.graph_with_weights()?;
            refresh(
                current,
                self.model,
                training,
                (fractions, fill_due),
                self.hidden_init,
            )?;
        }
        Ok(())
    }

    /// One epoch with its batches told to `on_event`: its loss, or what went non-finite
    /// (the loss, or after the epoch a weight: a finite loss is the loss *before* the
    /// epoch's last step), or that `stop` asked it to end before its next batch.
    fn checked_epoch(
        &self,
        engines: &mut Engines,
        training: &Course,
        ((epoch, horizon), fractions): ((usize, usize), &[f64]),
        (rng, stop): (&mut ChaCha8Rng, &dyn Fn() -> bool),
        on_event: &mut dyn FnMut(Event),
    ) -> Result<Result<f64, Unfinished>, TrainError> {
        let mut on_batch = |done, batches| {
            on_event(Event::Batch {
                epoch,
                done,
                batches,
            })
        };
        let how = (horizon, fractions);
        match self.epoch(engines, training, how, (rng, stop), &mut on_batch) {
            Err(EpochFailure::Backend(error)) => Err(TrainError::Backend(error)),
            Err(EpochFailure::Stopped) => Ok(Err(Unfinished::Stopped)),
            Err(EpochFailure::NotFinite(loss)) => Ok(Err(Unfinished::NotFinite(format!(
                "the loss became {loss}"
            )))),
            Ok(loss) => {
                let params: Vec<String> =
                    self.model.params.iter().map(|p| p.name.clone()).collect();
                Ok(match engines.non_finite(&params) {
                    Some(found) => Err(Unfinished::NotFinite(format!("{found} after the epoch"))),
                    None => Ok(loss),
                })
            }
        }
    }

    /// One epoch of `horizon`-step windows (1: one-step pairs) on the engine that runs it;
    /// `on_batch` hears of each step (batches done, batches in the epoch).
    fn epoch(
        &self,
        engines: &mut Engines,
        training: &Course,
        (horizon, fractions): (usize, &[f64]),
        rng: (&mut ChaCha8Rng, &dyn Fn() -> bool),
        on_batch: &mut dyn FnMut(usize, usize),
    ) -> Result<f64, EpochFailure> {
        if horizon > 1 {
            return self.rollout_epoch(engines, training, (horizon, fractions), rng, on_batch);
        }
        self.one_step_epoch(engines, training, rng, on_batch)
    }

    fn one_step_epoch(
        &self,
        engines: &mut Engines,
        training: &Course,
        (rng, stop): (&mut ChaCha8Rng, &dyn Fn() -> bool),
        on_batch: &mut dyn FnMut(usize, usize),
    ) -> Result<f64, EpochFailure> {
        let settings = self.settings();
        let mut order: Vec<usize> = (0..training.table.len()).collect();
        order.shuffle(rng);
        let mut total = 0.0;
        let batches = order.len().div_ceil(self.options.batch_size.max(1));
        for (done, chunk) in order.chunks(self.options.batch_size).enumerate() {
            if stop() {
                return Err(EpochFailure::Stopped);
            }
            let batch = training.table.batch(chunk);
            let loss = engines.step(StepBatch::Pairs(&batch), &settings)?;
            finite(loss)?;
            total += loss * chunk.len() as f64;
            on_batch(done + 1, batches);
        }
        Ok(total / order.len().max(1) as f64)
    }

    /// The longest rollout window every training track holds: a horizon longer than a
    /// track left it out of every epoch (a record of short batches then trained on its few
    /// one-step pairs alone), so the rollout is capped at the shortest track (and the
    /// progress, the log and the report say the horizon that ran).
    fn longest_window(&self) -> usize {
        (self.trainings.iter())
            .map(|t| t.knots.len())
            .filter(|&knots| knots > 0)
            .min()
            .unwrap_or(1)
            .max(1)
    }

    fn rollout_epoch(
        &self,
        engines: &mut Engines,
        training: &Course,
        (horizon, fractions): (usize, &[f64]),
        (rng, stop): (&mut ChaCha8Rng, &dyn Fn() -> bool),
        on_batch: &mut dyn FnMut(usize, usize),
    ) -> Result<f64, EpochFailure> {
        let settings = self.settings();
        let horizon = horizon.min(self.longest_window());
        let phase = rng.gen_range(0..horizon);
        let mut starts = Vec::new();
        for (index, training_part) in self.trainings.iter().enumerate() {
            let knots = &training_part.knots;
            let tiles = shooting_starts(knots.start, knots.len(), horizon, phase);
            starts.extend(tiles.into_iter().map(|knot| (index, knot)));
        }
        if starts.is_empty() {
            return self.one_step_epoch(engines, training, (rng, stop), on_batch);
        }
        starts.shuffle(rng);
        let per_batch = (self.recipe.windows_per_batch)
            .unwrap_or(self.options.batch_size)
            .max(1);
        let mut total = 0.0;
        // The buffers of the last epoch's batches (a failed step loses them with the run).
        let mut batch = std::mem::take(&mut engines.windows);
        let mut ordered = Vec::with_capacity(per_batch);
        let batches = starts.len().div_ceil(per_batch);
        for (done, chunk) in starts.chunks(per_batch).enumerate() {
            if stop() {
                engines.windows = batch;
                return Err(EpochFailure::Stopped);
            }
            // In track order, so that windows of one uniform track share their feedback.
            ordered.clear();
            ordered.extend_from_slice(chunk);
            ordered.sort_by_key(|&(track, _)| track);
            let data = (
                &training.tracks[..],
                &training.hidden[..],
                &training.weights[..],
                &self.setup.normalisation.observables[..],
            );
            rollout_batch_into(&mut batch, self.model, data, &ordered, (horizon, fractions));
            let loss = engines.step(StepBatch::Windows(&batch), &settings)?;
            finite(loss)?;
            total += loss * chunk.len() as f64;
            on_batch(done + 1, batches);
        }
        engines.windows = batch;
        Ok(total / starts.len() as f64)
    }
}

/// Whether any training track needs the model's fill, and every how many epochs it is
/// refreshed: every epoch where an experiment never measures a state (that state is all
/// fill, the model's own run), else every [`FILL_REFRESH`].
fn fill_schedule(training: &Course) -> (bool, usize) {
    let needs_fill = training.tracks.iter().any(|t| !t.fully_known());
    let unmeasured =
        (training.tracks.iter()).any(|t| t.measured.iter().any(|m| !m.iter().any(|&x| x)));
    (needs_fill, if unmeasured { 1 } else { FILL_REFRESH })
}

/// The epochs' own state between them.
struct Epochs {
    /// The epoch under way (1-based).
    epoch: usize,
    /// The shuffling generator.
    rng: ChaCha8Rng,
    /// The mean training loss of each epoch that stayed finite.
    losses: Vec<f64>,
    /// The last state whose weights were all finite, and its epoch ...
    kept: (usize, Optimiser),
    /// ... with the generator and rollout there (a stop inside an epoch goes back to
    /// them).
    kept_at: (ChaCha8Rng, usize),
    /// Each recovery from a non-finite epoch.
    recoveries: Vec<Recovery>,
    /// The stage fractions of one sub-step.
    fractions: Vec<f64>,
    /// Whether hidden states need filling, and every how many epochs.
    fill: (bool, usize),
}

impl Epochs {
    /// Goes back to the last epoch kept, as the stop inside the epoch under way asks: the
    /// error [`Safety::stopped_within`] makes of it.
    fn stop(&self, engines: &mut Engines, training: &Course, safety: &mut Safety) -> TrainError {
        engines.optimiser = self.kept.1.clone();
        let end = EpochEnd {
            epoch: self.kept.0,
            horizon: self.kept_at.1,
            loss: f64::NAN,
            rng: &self.kept_at.0,
            course: training,
            engines,
        };
        safety.stopped_within(end)
    }
}

/// What the epochs do after one.
enum After {
    /// The next epoch.
    Next,
    /// The same epoch again (after a recovery).
    Again,
    /// Stop ([`Safety`] said so).
    Stop,
    /// Stop: the epoch went non-finite with no recovery left.
    Diverged(Failure),
}

/// An epoch that went non-finite with no recovery left.
struct Failure {
    epoch: usize,
    what: String,
    phase: recovery::EpochPhase,
    advice: String,
}

/// After the epochs: a divergence is [`TrainError::Diverged`], or under
/// [`super::RunControl::keep_last_finite`] the optimiser goes back to `kept` (the last
/// finite epoch and its state) and the divergence is reported.
fn settle(
    diverged: Option<Failure>,
    (kept_epoch, kept): (usize, Optimiser),
    engines: &mut Engines,
    safety: &Safety,
) -> Result<Option<EpochDivergence>, TrainError> {
    let Some(failure) = diverged else {
        return Ok(None);
    };
    if !safety.keeps_last_finite() {
        return Err(TrainError::Diverged {
            epoch: failure.epoch,
            what: failure.what,
        });
    }
    engines.optimiser = kept;
    Ok(Some(EpochDivergence {
        epoch: failure.epoch,
        what: failure.what,
        kept_epoch,
        phase: failure.phase,
        advice: failure.advice,
    }))
}

/// What the epochs leave besides the network.
pub(super) struct Fitted {
    /// The mean training loss of each epoch that stayed finite.
    pub losses: Vec<f64>,
    /// The engine that ran them.
    pub engine: Engine,
    /// Where training went non-finite (under [`super::RunControl::keep_last_finite`]).
    pub diverged: Option<EpochDivergence>,
    /// Each recovery from a non-finite epoch ([`super::recovery`]).
    pub recoveries: Vec<Recovery>,
}

/// Why an epoch stopped.
enum EpochFailure {
    Backend(crate::engine::graph::BackendError),
    NotFinite(f64),
    /// Asked to stop before a batch.
    Stopped,
}

/// Why an epoch has no loss.
enum Unfinished {
    /// It went non-finite: what did.
    NotFinite(String),
    /// It was asked to stop.
    Stopped,
}

impl From<crate::engine::graph::BackendError> for EpochFailure {
    fn from(error: crate::engine::graph::BackendError) -> Self {
        EpochFailure::Backend(error)
    }
}

fn finite(loss: f64) -> Result<(), EpochFailure> {
    if loss.is_finite() {
        Ok(())
    } else {
        Err(EpochFailure::NotFinite(loss))
    }
}
