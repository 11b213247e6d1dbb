//! `gbc train`'s progress on stderr (a bar on a terminal, lines otherwise) and the
//! training log (`log.csv`) built from the epochs it hears of.

use std::io::IsTerminal;
use std::time::Instant;

use crate::train::checkpoint::EpochRow;
use crate::train::{self, ErrorSet, Event};

/// The progress bar and warnings on stderr, and the training log.
#[derive(Default)]
pub(super) struct Progress {
    bar: Option<indicatif::ProgressBar>,
    started: Option<Instant>,
    /// Seconds of the run before this process (resumed).
    before: f64,
    /// Rows of a resumed run's log, before this process.
    resumed: Vec<EpochRow>,
    /// Every epoch so far.
    rows: Vec<EpochRow>,
}

impl Progress {
    /// Continues the log of a checkpoint.
    pub(super) fn resume_from(&mut self, checkpoint: &train::Checkpoint) {
        self.resumed.clone_from(&checkpoint.log);
        self.before = checkpoint.log.last().map_or(0.0, |row| row.seconds);
    }

    pub(super) fn observe(&mut self, event: Event, epochs: usize) {
        match event {
            Event::Warning(warning) => eprintln!("warning: {warning}"),
            Event::Started {
                train_pairs,
                validation_pairs,
                ..
            } => {
                self.started = Some(Instant::now());
                self.rows.clone_from(&self.resumed);
                let message =
                    format!("training on {train_pairs} pairs, validating on {validation_pairs}");
                if !std::io::stderr().is_terminal() {
                    eprintln!("{message}");
                    return;
                }
                let bar = indicatif::ProgressBar::new(epochs as u64);
                let template = "epoch {pos}/{len} [{bar:30}] {msg} ETA {eta}";
                if let Ok(style) = indicatif::ProgressStyle::with_template(template) {
                    bar.set_style(style.progress_chars("=> "));
                }
                bar.set_position(self.rows.len() as u64);
                bar.println(message);
                self.bar = Some(bar);
            }
            Event::Epoch {
                epoch,
                loss,
                horizon,
            } => {
                let elapsed = self.started.map_or(0.0, |s| s.elapsed().as_secs_f64());
                let seconds = self.before + elapsed;
                self.rows.push(EpochRow {
                    epoch,
                    horizon,
                    loss,
                    seconds,
                    offline: None,
                    online: None,
                });
                match &self.bar {
                    Some(bar) => {
                        bar.set_message(format!("{horizon} step loss {loss:.3e}"));
                        bar.set_position(epoch as u64);
                    }
                    // Without a terminal, a line every twentieth of the run (and the last).
                    None if epoch % epochs.div_ceil(20).max(1) == 0 || epoch == epochs => {
                        eprintln!(
                            "epoch {epoch}/{epochs}: {horizon}-step loss {loss:.4e} ({seconds:.1} s)"
                        );
                    }
                    None => {}
                }
            }
            Event::Validation {
                epoch,
                offline,
                online,
            } => {
                if let Some(row) = self.rows.last_mut().filter(|r| r.epoch == epoch) {
                    (row.offline, row.online) = (offline, online);
                }
            }
            Event::EarlyStop {
                epoch,
                best_epoch,
                best_loss,
            } => {
                let message = format!(
                    "early stop after epoch {epoch}: no better validation loss for {} epochs; \
                     keeping the weights of epoch {best_epoch} (validation loss {best_loss:.4e})",
                    epoch - best_epoch
                );
                match &self.bar {
                    Some(bar) => bar.println(message),
                    None => eprintln!("{message}"),
                }
            }
        }
    }

    /// Each epoch's rollout length (1: one-step), a resumed run's earlier epochs first.
    pub(super) fn horizons(&self) -> Vec<usize> {
        (self.resumed.iter().chain(&self.rows))
            .map(|row| row.horizon)
            .collect()
    }

    /// The run's training log as CSV: one row per epoch (phase, loss, learning rate,
    /// seconds) and the validation errors where they were computed (before the first
    /// epoch, after every epoch with --early-stop, and after the last).
    pub(super) fn log(&self, report: Option<&train::TrainReport>, learning_rate: f64) -> String {
        let overall = |set: Option<&ErrorSet>| {
            set.map_or(String::new(), |s| crate::data::format_number(s.overall))
        };
        let number = |value: Option<f64>| value.map_or(String::new(), crate::data::format_number);
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
        let rate = crate::data::format_number(learning_rate);
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
                crate::data::format_number(row.loss),
                crate::data::format_number(row.seconds)
            ));
        }
        text
    }

    pub(super) fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}
