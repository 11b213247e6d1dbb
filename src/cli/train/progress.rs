//! `gbc train`'s progress on stderr (through the shared [`Reporter`]: a bar on a terminal,
//! else a line when training starts and one every few seconds, within slow epochs too) and
//! the training log (`log.csv`) built from the epochs it hears of.

use std::time::Instant;

use crate::cli::progress::{Announce, Count, Reporter};
use gbc::api::{
    format_number, Checkpoint, ChoiceEvent, EpochRow, ErrorSet, SparseBudget, TrainEvent as Event,
    TrainReport, TrainingCoverage, DENSE_ONE_STEP_SHARE, TRAINING_PHASE,
};

/// The stage of `--toward-mechanism auto`'s folds.
const CHOOSING: &str = "choosing the stop";

/// The progress and warnings on stderr, and the training log.
#[derive(Default)]
pub(super) struct Progress {
    reporter: Reporter,
    started: Option<Instant>,
    /// Seconds of the run before this process (resumed).
    before: f64,
    /// Rows of a resumed run's log, before this process.
    resumed: Vec<EpochRow>,
    /// Every epoch so far.
    rows: Vec<EpochRow>,
    /// The last epoch's loss in words.
    last_loss: String,
    /// Whether the run has no epochs (a model without closures, fitted by free runs, or
    /// `--epochs 0`).
    fitted_only: bool,
    /// The epochs the run takes, once settled (a sparse record's budget, `auto`'s stop).
    epochs: Option<usize>,
    /// `auto`'s folds: their count, epochs each, and each one's last epoch.
    folds: Option<(usize, usize, Vec<usize>)>,
}

impl Progress {
    /// Continues the log of a checkpoint.
    pub(super) fn resume_from(&mut self, checkpoint: &Checkpoint) {
        self.resumed.clone_from(&checkpoint.log);
        self.before = checkpoint.log.last().map_or(0.0, |row| row.seconds);
    }

    /// Shows one event of the training (`epochs`: the epochs planned) and keeps its epoch
    /// for the log.
    pub(super) fn observe(&mut self, event: Event, epochs: usize) {
        match event {
            Event::Warning(warning) => self.reporter.println(&format!("warning: {warning}")),
            Event::Recovered(recovery) => {
                self.reporter.println(&format!("warning: {recovery}"));
            }
            Event::Started {
                epochs,
                train_pairs,
                validation_pairs,
            } => self.started(epochs, train_pairs, validation_pairs),
            Event::Coverage(coverage, warmup) => self.coverage(coverage, warmup),
            Event::Budget(budget) => self.budget(&budget),
            Event::Substeps(substeps) => self.reporter.println(&format!(
                "note: the model turns stiff along the training records: training takes \
                 {substeps} RK4 sub-steps per step (as --substeps {substeps} would)"
            )),
            Event::Phase(name) => self.phase(name, epochs),
            Event::Batch {
                epoch,
                done,
                batches,
            } => self.batch(epoch, done, batches),
            Event::Epoch {
                epoch,
                loss,
                horizon,
            } => self.epoch(epoch, loss, horizon, epochs),
            Event::Validation {
                epoch,
                offline,
                online,
            } => {
                if let Some(row) = self.rows.last_mut().filter(|r| r.epoch == epoch) {
                    (row.offline, row.online) = (offline, online);
                }
            }
            Event::Strength(choice) => self.strength(&choice),
            Event::EarlyStop {
                epoch,
                best_epoch,
                best_loss,
            } => self.early_stop(epoch, best_epoch, best_loss),
        }
    }

    /// Training starts: `epochs` (none: the run is fitted only), on `train_pairs`.
    fn started(&mut self, epochs: usize, train_pairs: usize, validation_pairs: usize) {
        if epochs == 0 {
            self.fitted_only = true;
            self.reporter.println(&format!(
                "no epoch runs; validating on {validation_pairs} pairs"
            ));
            return;
        }
        self.started = Some(Instant::now());
        self.rows.clone_from(&self.resumed);
        self.reporter.println(&format!(
            "training on {train_pairs} pairs, validating on {validation_pairs}"
        ));
    }

    /// A sparse record's coverage by one-step pairs, and the warm-up share it trains with.
    fn coverage(&self, coverage: &TrainingCoverage, warmup: f64) {
        let share = coverage.one_step_share();
        if share < DENSE_ONE_STEP_SHARE {
            for record in &coverage.records {
                self.reporter.println(&format!("note: {record}"));
            }
            self.reporter.println(&format!(
                "note: one-step pairs reach {:.0} % of the measured cells; the one-step \
                 warm-up is shortened to {:.0} % of the epochs and free-run windows \
                 train on every cell (help: --objective one-step would train on the \
                 pairs alone)",
                100.0 * share,
                100.0 * warmup
            ));
        }
    }

    /// A sparse record's budget of epochs and learning rate.
    fn budget(&mut self, budget: &SparseBudget) {
        self.epochs = Some(budget.epochs);
        self.reporter.println(&format!(
            "note: a sparse record takes one Adam step per epoch: training {} epochs \
             at learning rate {} (as --epochs {} --lr {} would)",
            budget.epochs, budget.learning_rate, budget.epochs, budget.learning_rate
        ));
    }

    /// A phase starts: the epochs as a stage counting them, any other shown once it is slow.
    fn phase(&mut self, name: &'static str, epochs: usize) {
        match name {
            TRAINING_PHASE if self.fitted_only => {}
            TRAINING_PHASE => {
                let count = Count::Items("epochs");
                let epochs = self.epochs.unwrap_or(epochs);
                self.reporter
                    .stage(TRAINING_PHASE, epochs as u64, count, Announce::Now);
                self.reporter.update(self.rows.len() as u64, String::new());
            }
            name => self.reporter.stage(name, 0, Count::Time, Announce::IfSlow),
        }
    }

    /// Within an epoch: where it is, after the last epoch's loss.
    fn batch(&self, epoch: usize, done: usize, batches: usize) {
        let within = format!("epoch {epoch} at batch {done}/{batches}");
        let message = match self.last_loss.as_str() {
            "" => within,
            loss => format!("{loss}; {within}"),
        };
        self.reporter.update(epoch as u64 - 1, message);
    }

    /// An epoch ended with `loss` over windows of `horizon` steps: its row of the log, and
    /// a progress line now after the last of `epochs`.
    fn epoch(&mut self, epoch: usize, loss: f64, horizon: usize, epochs: usize) {
        let elapsed = self.started.map_or(0.0, |s| s.elapsed().as_secs_f64());
        self.rows.push(EpochRow {
            epoch,
            horizon,
            loss,
            seconds: self.before + elapsed,
            offline: None,
            online: None,
        });
        self.last_loss = format!("{horizon}-step loss {loss:.4e}");
        self.reporter.update(epoch as u64, self.last_loss.clone());
        if epoch == epochs {
            self.reporter.report_now();
        }
    }

    /// Early stopping ended training after `epoch`, keeping `best_epoch`'s weights.
    fn early_stop(&self, epoch: usize, best_epoch: usize, best_loss: f64) {
        self.reporter.println(&format!(
            "early stop after epoch {epoch}: no better validation loss for {} epochs; \
             keeping the weights of epoch {best_epoch} (validation loss {best_loss:.4e})",
            epoch - best_epoch
        ));
    }

    /// `--toward-mechanism auto`, as it goes: the folds' epochs as one stage, each fold's
    /// end, the stop chosen.
    fn strength(&mut self, event: &ChoiceEvent) {
        match *event {
            ChoiceEvent::Started { folds, epochs } => {
                self.folds = Some((folds, epochs, vec![0; folds]));
                self.reporter.println(&format!(
                    "toward the mechanism: {folds} folds (each training experiment held out \
                     once) choose where training stops"
                ));
                let total = (folds * epochs) as u64;
                let count = Count::Items("fold epochs");
                self.reporter.stage(CHOOSING, total, count, Announce::Now);
            }
            ChoiceEvent::Epoch { fold, epoch } => {
                if let Some((_, _, done)) = self.folds.as_mut() {
                    done[fold] = epoch;
                    let sum: usize = done.iter().sum();
                    self.reporter
                        .update(sum as u64, format!("fold {}", fold + 1));
                }
            }
            ChoiceEvent::FoldDone { fold, held_out } => {
                if let Some((folds, _, _)) = self.folds {
                    self.reporter.println(&format!(
                        "toward the mechanism: fold {}/{folds} (without {held_out}) done",
                        fold + 1
                    ));
                }
            }
            ChoiceEvent::Chosen(choice) => {
                self.reporter.finish();
                let error = |epoch| {
                    (choice.at(epoch).and_then(|c| c.mean))
                        .map_or("-".into(), |e| format!("{e:.4}"))
                };
                let stop = match choice.chosen {
                    0 => "0 epochs: the grey box stays its mechanism".to_string(),
                    e => format!("after epoch {e} of {}", choice.epochs),
                };
                self.reporter.println(&format!(
                    "toward the mechanism: stopping {stop} (held-out online error, mean over \
                     the folds: mechanism {}, best {} at epoch {}, chosen {})",
                    error(0),
                    error(choice.best),
                    choice.best,
                    error(choice.chosen)
                ));
                self.epochs = Some(choice.chosen);
            }
        }
    }

    /// The run's training log as CSV: one row per epoch (phase, loss, learning rate,
    /// seconds) and the validation errors where they were computed (before the first
    /// epoch, after every epoch with --early-stop, and after the last).
    pub(super) fn log(&self, report: Option<&TrainReport>, learning_rate: f64) -> String {
        let overall =
            |set: Option<&ErrorSet>| set.map_or(String::new(), |s| format_number(s.overall));
        let number = |value: Option<f64>| value.map_or(String::new(), format_number);
        let mut text = String::from(
            "epoch,phase,horizon,train_loss,validation_offline,validation_online,learning_rate,seconds\n",
        );
        let metrics = report.map(|r| &r.metrics);
        text.push_str(&format!(
            "0,initial,,,{},{},,0\n",
            overall(metrics.and_then(|m| m.initial_offline.as_ref())),
            overall(metrics.and_then(|m| m.initial_online.as_ref()))
        ));
        let last = self.rows.len();
        let rate = format_number(learning_rate);
        for (index, row) in self.rows.iter().enumerate() {
            let phase = if row.horizon > 1 {
                "multi-step"
            } else {
                "one-step"
            };
            let unscored = row.offline.is_none() && row.online.is_none();
            let (offline, online) = match metrics.filter(|_| index + 1 == last && unscored) {
                Some(m) => (overall(m.offline.as_ref()), overall(m.online.as_ref())),
                None => (number(row.offline), number(row.online)),
            };
            text.push_str(&format!(
                "{},{phase},{},{},{offline},{online},{rate},{}\n",
                row.epoch,
                row.horizon,
                format_number(row.loss),
                format_number(row.seconds)
            ));
        }
        text
    }

    pub(super) fn finish(&mut self) {
        self.reporter.finish();
    }
}
