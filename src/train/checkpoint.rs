//! Runs that are never lost: checkpoints between epochs, resuming from one, and early
//! stopping on the validation loss.
//!
//! A checkpoint is two files in the run directory: `checkpoint.json` (epochs done and
//! planned, the curriculum's rollout length, the shuffling generator's state, Adam's step
//! count, the log so far, the best validation loss) and `checkpoint.safetensors` (the
//! weights, Adam's moments, the best weights for early stopping and each training track's
//! reference with the model's fill, all `f64`). Resuming sets all of it back before the next
//! epoch, so that a run stopped after epoch `k` and resumed ends bit for bit where the
//! uninterrupted run ends: the weights, the Adam state and the generator are exactly the
//! state after epoch `k`, the epoch loop starts at `k + 1`, and the hidden states (refreshed
//! at the start of every epoch from the weights) and the fill (kept in the checkpoint) are
//! what the uninterrupted run has there.
//!
//! [`RunControl`] says what the epoch loop does between epochs; the loop in `fit.rs` calls
//! [`Safety`] after each epoch.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use rand_chacha::ChaCha8Rng;

use crate::engine::graph::{AdamState, NamedTensor, Network};

use super::fit::epoch_end::EpochEnd;
use super::tensors::{read_tensors, write_tensors};
use super::validation::Course;
use super::{Event, TrainError, TrainOptions};

/// The checkpoint's metadata file in a run directory.
pub const CHECKPOINT_FILE: &str = "checkpoint.json";
/// The checkpoint's tensors in a run directory.
pub const CHECKPOINT_TENSORS: &str = "checkpoint.safetensors";

/// What a training run does between epochs besides training.
#[derive(Debug, Clone, Default)]
pub struct RunControl {
    /// The run directory checkpoints go to (none: no checkpoint is written).
    pub directory: Option<PathBuf>,
    /// Write a checkpoint after every `N`th epoch.
    pub every: Option<usize>,
    /// Set (by a signal handler) to stop after the current epoch with a checkpoint.
    pub stop: Option<Arc<AtomicBool>>,
    /// Stop after this epoch with a checkpoint, as if interrupted there.
    pub stop_after: Option<usize>,
    /// Stop when the validation loss has not improved for this many epochs; the weights of
    /// the best epoch are kept.
    pub early_stop: Option<usize>,
    /// Validate after every `N`th epoch and after the last (the errors go to the log and
    /// to [`Event::Validation`]) without early stopping; `--early-stop` validates every
    /// epoch anyway.
    pub validate_every: Option<usize>,
    /// End training after this epoch, keeping its weights (the rollout schedule stays that
    /// of all the epochs): `--toward-mechanism auto`'s chosen stop ([`super::toward`]).
    pub last_epoch: Option<usize>,
    /// A checkpoint to continue from.
    pub resume: Option<Checkpoint>,
    /// What the caller keeps with each checkpoint (the CLI: its command line).
    pub command: serde_json::Value,
    /// When the loss, a weight or a param goes NaN or infinite, end training with the last
    /// finite epoch's weights and report where ([`super::TrainReport::diverged`]) instead of
    /// failing with [`TrainError::Diverged`].
    pub keep_last_finite: bool,
    /// Under `keep_last_finite`, how many times a non-finite epoch sends training back to
    /// the last finite one at half the learning rate (and half the rollout) before the run
    /// ends ([`super::recovery`]).
    pub recoveries: usize,
    /// Test hook: the loss of epoch `.0` reads NaN on its first `.1` tries.
    pub poison: Option<(usize, usize)>,
}

/// One epoch in the training log.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpochRow {
    /// 1-based epoch.
    pub epoch: usize,
    /// Rollout steps per window (1: one-step pairs).
    pub horizon: usize,
    /// Mean training loss.
    #[serde(with = "crate::json")]
    pub loss: f64,
    /// Seconds since training started (over every part of a resumed run).
    #[serde(with = "crate::json")]
    pub seconds: f64,
    /// Pooled offline validation error, when computed (early stopping).
    #[serde(with = "crate::json", default)]
    pub offline: Option<f64>,
    /// Pooled online validation error, when computed (early stopping).
    #[serde(with = "crate::json", default)]
    pub online: Option<f64>,
}

/// The state of a run after an epoch (`checkpoint.json`; the tensors are read and written
/// beside it).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Checkpoint {
    /// The gbc version that wrote it.
    pub version: String,
    /// Epochs done.
    pub epoch: usize,
    /// Epochs planned.
    pub epochs: usize,
    /// The curriculum's phase: the rollout length of the last epoch (1: one-step).
    pub horizon: usize,
    /// The training seed.
    pub seed: u64,
    /// The shuffling generator: its seed (hex), stream and word position.
    pub rng: (String, u64, String),
    /// Adam steps taken.
    pub adam_steps: u64,
    /// The names of the weight tensors, in the network's order (the file's is by name).
    pub tensors: Vec<String>,
    /// Every epoch so far.
    pub log: Vec<EpochRow>,
    /// The epoch with the lowest validation loss so far and that loss (early stopping).
    #[serde(default)]
    pub best: Option<(usize, f64)>,
    /// What the caller kept with it ([`RunControl::command`]).
    #[serde(default)]
    pub command: serde_json::Value,
    /// The weights after the epoch.
    #[serde(skip)]
    pub weights: Vec<NamedTensor>,
    /// Adam's moments, in weights order.
    #[serde(skip)]
    pub adam: AdamState,
    /// The weights of the best epoch (early stopping).
    #[serde(skip)]
    pub best_weights: Vec<NamedTensor>,
    /// Each training track's reference (`[state][knot]`, the model's fill included).
    #[serde(skip)]
    pub references: Vec<Vec<Vec<f64>>>,
}

impl Checkpoint {
    /// Writes the checkpoint into `directory`: the tensors first, then the metadata, each
    /// atomically (a checkpoint whose metadata is there is whole). Weights that are not all
    /// finite are refused ([`crate::io::IoError::NotFinite`]): a checkpoint is always a
    /// state training can go on from.
    pub fn save(&self, directory: &Path) -> Result<(), TrainError> {
        let found = crate::finite::in_tensors(&self.weights, &[])
            .or_else(|| crate::finite::in_tensors(&self.best_weights, &[]));
        let path = directory.join(CHECKPOINT_TENSORS);
        crate::finite::refuse(&path, found, super::tensors::NOT_FINITE_HELP)?;
        let mut tensors = Vec::new();
        fn prefixed<'t>(
            prefix: &'t str,
            tensors: &'t [NamedTensor],
        ) -> impl Iterator<Item = NamedTensor> + 't {
            (tensors.iter()).map(move |t| NamedTensor {
                name: format!("{prefix}/{}", t.name),
                ..t.clone()
            })
        }
        tensors.extend(prefixed("weights", &self.weights));
        tensors.extend(prefixed("best", &self.best_weights));
        for (moment, values) in [("first", &self.adam.first), ("second", &self.adam.second)] {
            for (tensor, values) in self.weights.iter().zip(values) {
                tensors.push(NamedTensor {
                    name: format!("adam.{moment}/{}", tensor.name),
                    shape: vec![values.len()],
                    values: values.clone(),
                });
            }
        }
        for (index, states) in self.references.iter().enumerate() {
            let knots = states.first().map_or(0, Vec::len);
            tensors.push(NamedTensor {
                name: format!("reference/{index:06}"),
                shape: vec![states.len(), knots],
                values: states.concat(),
            });
        }
        write_tensors(&directory.join(CHECKPOINT_TENSORS), &tensors)?;
        let json = serde_json::to_string_pretty(self).map_err(|error| bad(directory, error))?;
        crate::io::write_atomic(&directory.join(CHECKPOINT_FILE), json.as_bytes())?;
        Ok(())
    }

    /// Reads the checkpoint of `directory`.
    pub fn load(directory: &Path) -> Result<Checkpoint, TrainError> {
        let path = directory.join(CHECKPOINT_FILE);
        let text = std::fs::read_to_string(&path).map_err(|error| TrainError::NoCheckpoint {
            directory: directory.display().to_string(),
            found: format!(
                "no readable {CHECKPOINT_FILE} ({})",
                crate::io::describe(&error)
            ),
        })?;
        let mut checkpoint: Checkpoint =
            serde_json::from_str(&text).map_err(|error| bad(directory, error))?;
        let mut groups: std::collections::BTreeMap<(String, String), NamedTensor> =
            std::collections::BTreeMap::new();
        for tensor in read_tensors(&directory.join(CHECKPOINT_TENSORS))? {
            let Some((group, name)) = tensor.name.split_once('/') else {
                return Err(bad(directory, format!("a tensor `{}`", tensor.name)));
            };
            let key = (group.to_string(), name.to_string());
            let named = NamedTensor {
                name: name.to_string(),
                ..tensor.clone()
            };
            groups.insert(key, named);
        }
        let mut take = |group: &str, name: &str| groups.remove(&(group.into(), name.into()));
        for name in &checkpoint.tensors.clone() {
            let missing = || bad(directory, format!("no tensor `{name}`"));
            checkpoint
                .weights
                .push(take("weights", name).ok_or_else(missing)?);
            checkpoint
                .adam
                .first
                .push(take("adam.first", name).ok_or_else(missing)?.values);
            checkpoint
                .adam
                .second
                .push(take("adam.second", name).ok_or_else(missing)?.values);
            checkpoint.best_weights.extend(take("best", name));
        }
        for ((group, _), tensor) in groups {
            if group != "reference" {
                return Err(bad(
                    directory,
                    format!("a tensor `{group}/{}`", tensor.name),
                ));
            }
            let knots = tensor.shape.get(1).copied().unwrap_or(0).max(1);
            let states = tensor.values.chunks(knots).map(<[f64]>::to_vec).collect();
            checkpoint.references.push(states);
        }
        checkpoint.adam.steps = checkpoint.adam_steps;
        Ok(checkpoint)
    }

    /// Removes a checkpoint from `directory` (after the run finished), if there is one.
    pub fn remove(directory: &Path) {
        for file in [CHECKPOINT_FILE, CHECKPOINT_TENSORS] {
            let _ = std::fs::remove_file(directory.join(file));
        }
    }

    /// The shuffling generator as it was.
    fn generator(&self) -> Option<ChaCha8Rng> {
        use rand::SeedableRng;
        let (seed, stream, position) = &self.rng;
        let mut bytes = [0u8; 32];
        for (index, byte) in bytes.iter_mut().enumerate() {
            *byte = u8::from_str_radix(seed.get(2 * index..2 * index + 2)?, 16).ok()?;
        }
        let mut rng = ChaCha8Rng::from_seed(bytes);
        rng.set_stream(*stream);
        rng.set_word_pos(position.parse().ok()?);
        Some(rng)
    }
}

/// The early-stopping rule: the best validation loss so far, and whether `patience` epochs
/// have passed without improving on it. A loss that is not finite never improves.
#[derive(Debug, Clone, PartialEq)]
pub struct EarlyStop {
    /// Epochs without improvement before stopping.
    pub patience: usize,
    /// The best epoch and its loss.
    pub best: Option<(usize, f64)>,
}

impl EarlyStop {
    /// Records `loss` at `epoch`; returns whether it is the best so far.
    pub fn observe(&mut self, epoch: usize, loss: f64) -> bool {
        let better = loss.is_finite() && self.best.is_none_or(|(_, best)| loss < best);
        if better {
            self.best = Some((epoch, loss));
        }
        better
    }

    /// Whether training should stop after `epoch`.
    pub fn exhausted(&self, epoch: usize) -> bool {
        self.best
            .is_some_and(|(best, _)| epoch >= best + self.patience.max(1))
    }
}

/// The validation loss of the current network: pooled offline and online errors.
pub(super) type ValidateNow<'v> =
    dyn FnMut(&Network) -> Result<(Option<f64>, Option<f64>), TrainError> + 'v;

/// What the epoch loop calls between epochs: resume, log, validate, checkpoint, stop.
pub(super) struct Safety<'a> {
    control: &'a RunControl,
    epochs: usize,
    seed: u64,
    started: Instant,
    /// Seconds of the run before this process (resumed).
    before: f64,
    log: Vec<EpochRow>,
    early: Option<EarlyStop>,
    /// The first epoch early stopping watches (the objective's last phase).
    count_from: usize,
    best_weights: Vec<NamedTensor>,
    validate: Option<&'a mut ValidateNow<'a>>,
    /// Epochs poisoned so far ([`RunControl::poison`]).
    poisoned: usize,
}

impl<'a> Safety<'a> {
    /// The hooks for `control` of a training that started at `started`; `validate`
    /// computes the validation loss (early stopping).
    pub fn new(
        control: &'a RunControl,
        (options, started): (&TrainOptions, Instant),
        validate: Option<&'a mut ValidateNow<'a>>,
    ) -> Self {
        let early = (control.early_stop).map(|patience| EarlyStop {
            patience,
            best: None,
        });
        Safety {
            control,
            epochs: options.epochs,
            seed: options.seed,
            started,
            before: 0.0,
            log: Vec::new(),
            early,
            count_from: 1,
            best_weights: Vec::new(),
            validate: validate
                .filter(|_| control.early_stop.is_some() || control.validate_every.is_some()),
            poisoned: 0,
        }
    }

    /// Early stopping watches epochs from `epoch` on: earlier ones train another objective
    /// (the one-step warm-up, the growing rollout), whose validation losses neither count
    /// as the best nor use up the patience.
    pub fn count_from(&mut self, epoch: usize) {
        self.count_from = epoch.max(1);
    }

    /// The Adam state of the checkpoint a run resumes from (none: a fresh start).
    pub fn resumed_adam(&self) -> Option<&AdamState> {
        self.control
            .resume
            .as_ref()
            .map(|checkpoint| &checkpoint.adam)
    }

    /// Before the first epoch: with a checkpoint, sets the network, the training tracks,
    /// the generator and the losses back to it; returns the first epoch to run.
    pub fn resume(
        &mut self,
        network: &mut Network,
        course: &mut Course,
        rng: &mut ChaCha8Rng,
        losses: &mut Vec<f64>,
    ) -> Result<usize, TrainError> {
        let Some(checkpoint) = &self.control.resume else {
            return Ok(1);
        };
        let changed = |what: String| Err(TrainError::ResumeChanged { what });
        if (checkpoint.epochs, checkpoint.seed) != (self.epochs, self.seed) {
            return changed(format!(
                "{} epochs and seed {} where the checkpoint has {} and {}",
                self.epochs, self.seed, checkpoint.epochs, checkpoint.seed
            ));
        }
        if checkpoint.references.len() != course.tracks.len()
            || (course.tracks.iter().zip(&checkpoint.references))
                .any(|(track, states)| track.states.len() != states.len())
        {
            return changed("other training experiments".into());
        }
        network.set_weights(&checkpoint.weights)?;
        for (track, states) in course.tracks.iter_mut().zip(&checkpoint.references) {
            if (track.states.iter().zip(states)).any(|(a, b)| a.len() != b.len()) {
                return changed("other training experiments".into());
            }
            track.states.clone_from(states);
        }
        *rng = checkpoint
            .generator()
            .ok_or_else(|| TrainError::NoCheckpoint {
                directory: self.directory(),
                found: "a damaged generator state".into(),
            })?;
        *losses = checkpoint.log.iter().map(|row| row.loss).collect();
        self.log.clone_from(&checkpoint.log);
        self.before = checkpoint.log.last().map_or(0.0, |row| row.seconds);
        if let Some(early) = &mut self.early {
            early.best = checkpoint.best;
        }
        self.best_weights.clone_from(&checkpoint.best_weights);
        Ok(checkpoint.epoch + 1)
    }

    /// Whether the run was asked to stop (a caller's flag, or [`crate::stop`]: Ctrl-C,
    /// SIGTERM).
    pub fn stop_requested(&self) -> bool {
        stop_requested(self.control)
    }

    /// Stopped inside the epoch after `end.epoch` (whose state `end` holds again): writes
    /// the checkpoint of that last whole epoch, so that `--resume` runs the unfinished
    /// epoch again, and returns the interruption.
    pub fn stopped_within(&self, mut end: EpochEnd) -> TrainError {
        if let Some(directory) = self.control.directory.as_ref() {
            if let Err(error) = self.checkpoint(&mut end).save(directory) {
                return error;
            }
        }
        TrainError::Interrupted {
            epoch: end.epoch,
            epochs: self.epochs,
            directory: self.directory(),
        }
    }

    /// After an epoch: logs it, validates (early stopping), writes a checkpoint when one
    /// is due, and stops with [`TrainError::Interrupted`] when asked to. Returns whether
    /// training stops here (early stopping).
    pub fn after_epoch(
        &mut self,
        mut end: EpochEnd,
        on_event: &mut dyn FnMut(Event),
    ) -> Result<bool, TrainError> {
        let epoch = end.epoch;
        let mut row = EpochRow {
            epoch,
            horizon: end.horizon,
            loss: end.loss,
            seconds: self.before + self.started.elapsed().as_secs_f64(),
            offline: None,
            online: None,
        };
        let last = self
            .control
            .last_epoch
            .map_or(self.epochs, |l| l.min(self.epochs));
        let due_now = self.early.is_some()
            || epoch >= last
            || (self.control.validate_every).is_some_and(|n| epoch.is_multiple_of(n.max(1)));
        if let Some(validate) = self.validate.as_mut().filter(|_| due_now) {
            let (offline, online) = validate(end.network()?)?;
            (row.offline, row.online) = (offline, online);
            on_event(Event::Validation {
                epoch,
                offline,
                online,
            });
            let loss = online.or(offline).unwrap_or(f64::NAN);
            if let Some(early) = self.early.as_mut().filter(|_| epoch >= self.count_from) {
                if early.observe(epoch, loss) {
                    self.best_weights = end.state().0;
                }
            }
        }
        self.log.push(row);
        let control = self.control;
        let stop_asked = stop_requested(control);
        let interrupted = (stop_asked || control.stop_after == Some(epoch)) && epoch < self.epochs;
        let due = control
            .every
            .is_some_and(|n| n > 0 && epoch.is_multiple_of(n))
            && epoch < self.epochs;
        if let Some(directory) = control.directory.as_ref().filter(|_| interrupted || due) {
            self.checkpoint(&mut end).save(directory)?;
        }
        if interrupted {
            return Err(TrainError::Interrupted {
                epoch,
                epochs: self.epochs,
                directory: self.directory(),
            });
        }
        let early_stop = (self.early.as_ref()).is_some_and(|e| e.exhausted(epoch));
        let stop = early_stop || control.last_epoch.is_some_and(|l| epoch >= l);
        if let Some((best_epoch, best_loss)) = self.early.as_ref().and_then(|e| e.best) {
            if early_stop && epoch < self.epochs {
                on_event(Event::EarlyStop {
                    epoch,
                    best_epoch,
                    best_loss,
                });
            }
        }
        Ok(stop)
    }

    /// After the last epoch: with early stopping, the network takes the best epoch's
    /// weights; returns that epoch (none: the network keeps its own).
    pub fn finish(&self, network: &mut Network) -> Result<Option<usize>, TrainError> {
        if self.early.is_some() && !self.best_weights.is_empty() {
            network.set_weights(&self.best_weights)?;
            return Ok(self
                .early
                .as_ref()
                .and_then(|e| e.best)
                .map(|(epoch, _)| epoch));
        }
        Ok(None)
    }

    /// How many recoveries a non-finite epoch may use ([`RunControl::recoveries`]; none
    /// without [`RunControl::keep_last_finite`]).
    pub fn recoveries(&self) -> usize {
        if self.control.keep_last_finite {
            self.control.recoveries
        } else {
            0
        }
    }

    /// Test hook ([`RunControl::poison`]): whether epoch `epoch`'s loss reads NaN on this
    /// try.
    pub fn poisoned(&mut self, epoch: usize) -> bool {
        let Some((at, tries)) = self.control.poison else {
            return false;
        };
        let hit = at == epoch && self.poisoned < tries;
        self.poisoned += usize::from(hit);
        hit
    }

    /// Whether a divergence ends training with the last finite weights
    /// ([`RunControl::keep_last_finite`]) rather than an error.
    pub fn keeps_last_finite(&self) -> bool {
        self.control.keep_last_finite
    }

    fn checkpoint(&self, end: &mut EpochEnd) -> Checkpoint {
        let (weights, adam) = end.state();
        let rng = end.rng;
        let seed: String = rng.get_seed().iter().map(|b| format!("{b:02x}")).collect();
        Checkpoint {
            version: env!("CARGO_PKG_VERSION").to_string(),
            epoch: end.epoch,
            epochs: self.epochs,
            horizon: end.horizon,
            seed: self.seed,
            rng: (seed, rng.get_stream(), rng.get_word_pos().to_string()),
            adam_steps: adam.steps,
            tensors: weights.iter().map(|t| t.name.clone()).collect(),
            log: self.log.clone(),
            best: self.early.as_ref().and_then(|e| e.best),
            command: self.control.command.clone(),
            weights,
            adam,
            best_weights: self.best_weights.clone(),
            references: end.course.tracks.iter().map(|t| t.states.clone()).collect(),
        }
    }

    fn directory(&self) -> String {
        (self.control.directory.as_ref()).map_or(String::new(), |d| d.display().to_string())
    }
}

fn bad(directory: &Path, error: impl std::fmt::Display) -> TrainError {
    TrainError::BadRun {
        path: directory.join(CHECKPOINT_FILE).display().to_string(),
        reason: error.to_string(),
    }
}

/// Whether `control`'s flag or the process's stop request ([`crate::stop`]) asks a run to
/// stop.
pub(super) fn stop_requested(control: &RunControl) -> bool {
    crate::stop::requested() || (control.stop.as_ref()).is_some_and(|s| s.load(Ordering::Relaxed))
}

#[cfg(test)]
mod tests {
    use super::EarlyStop;

    /// Feeds `losses` (epochs 1, 2, ...) and returns the epoch it stops after and the best.
    fn stops(patience: usize, losses: &[f64]) -> (Option<usize>, Option<(usize, f64)>) {
        let mut early = EarlyStop {
            patience,
            best: None,
        };
        for (index, &loss) in losses.iter().enumerate() {
            early.observe(index + 1, loss);
            if early.exhausted(index + 1) {
                return (Some(index + 1), early.best);
            }
        }
        (None, early.best)
    }

    #[test]
    fn early_stopping_waits_patience_epochs_after_the_best() {
        assert_eq!(stops(2, &[3.0, 2.0, 1.0, 0.5]), (None, Some((4, 0.5))));
        assert_eq!(
            stops(2, &[3.0, 2.0, 2.5, 2.6, 1.0]),
            (Some(4), Some((2, 2.0)))
        );
        assert_eq!(
            stops(3, &[1.0, 2.0, 0.9, 1.0, 1.1, 1.2]),
            (Some(6), Some((3, 0.9)))
        );
        // A diverged free run (infinite) or a missing error never counts as better.
        assert_eq!(
            stops(1, &[f64::INFINITY, 2.0, f64::NAN]),
            (Some(3), Some((2, 2.0)))
        );
    }
}
