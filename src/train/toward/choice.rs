//! `--toward-mechanism auto`: where training stops, chosen by leave-one-experiment-out
//! cross-validation over the training experiments.
//!
//! A fresh grey box is its fitted mechanism (every closure's last layer at zero), so
//! stopping after `e` epochs pulls it toward the mechanism, the harder the earlier, and
//! stopping after 0 epochs *is* the mechanism. Each fold trains on all training experiments
//! but one, without a pull, and scores the one it did not see by its online (free-run)
//! error before the first epoch and every few epochs ([`CANDIDATES`] in all). The stop is
//! the fewest epochs whose mean error over the folds is within one standard error (of the
//! folds' paired differences) of the lowest: where training does not beat the mechanism on
//! experiments it did not see by more than the folds disagree, the grey box stays the
//! mechanism. The validation experiments of the run are never used.
//!
//! The folds train on threads; `on_event` hears of them on the calling thread.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;

use crate::ir;
use crate::record::Record;

use super::super::{train_run, RunControl};
use super::super::{Event, Part, Recipe, TrainError, TrainOptions, TrainingData};
use super::TowardMechanism;

/// About how many stops `auto` scores besides 0 (every `ceil(epochs / CANDIDATES)`th
/// epoch, and the last).
pub const CANDIDATES: usize = 40;

/// One stop `auto` scored: the folds' held-out online errors after `epoch` epochs.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Candidate {
    /// Epochs trained (0: the mechanism).
    pub epoch: usize,
    /// Each scored fold's online error, in [`StopChoice::held_out`] order (`None`: its free
    /// run left the physical range or its training had ended non-finite).
    pub errors: Vec<Option<f64>>,
    /// Their mean (`None` where a fold has none).
    #[serde(with = "crate::json")]
    pub mean: Option<f64>,
}

/// How `auto` chose where training stops.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StopChoice {
    /// The epochs asked for (the rollout schedule is theirs).
    pub epochs: usize,
    /// The experiment each scored fold held out.
    pub held_out: Vec<String>,
    /// Folds that scored nothing, with why.
    pub failed: Vec<(String, String)>,
    /// Every stop scored, by epoch.
    pub candidates: Vec<Candidate>,
    /// The stop with the lowest mean error.
    pub best: usize,
    /// The stop chosen: the fewest epochs within one standard error of `best`.
    pub chosen: usize,
    /// Seconds the folds took.
    #[serde(with = "crate::json")]
    pub seconds: f64,
}

impl StopChoice {
    /// The candidate of `epoch`.
    pub fn at(&self, epoch: usize) -> Option<&Candidate> {
        self.candidates.iter().find(|c| c.epoch == epoch)
    }
}

/// What `auto` tells as it goes ([`Event::Strength`]).
#[derive(Debug, Clone, PartialEq)]
pub enum ChoiceEvent<'a> {
    /// `folds` trainings of `epochs` epochs each start.
    Started {
        /// Folds in all.
        folds: usize,
        /// Epochs of each.
        epochs: usize,
    },
    /// Fold `fold` (0-based) finished `epoch`.
    Epoch {
        /// 0-based fold.
        fold: usize,
        /// Its epoch.
        epoch: usize,
    },
    /// Fold `fold`, holding out `held_out`, is done.
    FoldDone {
        /// 0-based fold.
        fold: usize,
        /// The experiment it held out.
        held_out: &'a str,
    },
    /// The stop chosen.
    Chosen(&'a StopChoice),
}

/// One fold's held-out online error by epoch, or why it has none.
type Curve = Result<Vec<(usize, Option<f64>)>, String>;

/// What a fold's thread sends the calling thread.
enum Message {
    Epoch(usize, usize),
    Done(usize, Result<Curve, TrainError>),
}

/// Chooses where a run of `options` stops ([`StopChoice`]); `Ok(Err(why))` where it cannot
/// be chosen (fewer than two whole training experiments, no closure, no epoch), and the run
/// then trains every epoch without a pull. `control` lends its stop flag to the folds.
pub fn choose(
    model: &ir::Model,
    data: &TrainingData,
    (options, recipe): (&TrainOptions, &Recipe),
    control: &RunControl,
    on_event: &mut dyn FnMut(Event),
) -> Result<Result<StopChoice, String>, TrainError> {
    if let Some(why) = unchoosable(model, data, options) {
        return Ok(Err(why));
    }
    let started = std::time::Instant::now();
    let folds = data.train.len();
    on_event(Event::Strength(ChoiceEvent::Started {
        folds,
        epochs: options.epochs,
    }));
    let fold_options = TrainOptions {
        toward_mechanism: TowardMechanism::Strength(0.0),
        ..options.clone()
    };
    let fold_control = RunControl {
        validate_every: Some(options.epochs.div_ceil(CANDIDATES).max(1)),
        stop: control.stop.clone(),
        keep_last_finite: true,
        ..RunControl::default()
    };
    let how = (&fold_options, recipe, &fold_control);
    let curves = fold_curves(model, data.train, how, on_event)?;
    let mut choice = scored(options.epochs, data.train, curves);
    choice.seconds = started.elapsed().as_secs_f64();
    if choice.held_out.len() < 2 {
        let failed: Vec<String> = (choice.failed.iter())
            .map(|(name, why)| format!("{name}: {why}"))
            .collect();
        return Ok(Err(format!(
            "fewer than two folds scored ({})",
            failed.join("; ")
        )));
    }
    on_event(Event::Strength(ChoiceEvent::Chosen(&choice)));
    Ok(Ok(choice))
}

/// Why `auto` cannot choose for this run, if it cannot.
fn unchoosable(model: &ir::Model, data: &TrainingData, options: &TrainOptions) -> Option<String> {
    if model.closures.is_empty() {
        Some("the model has no closure".into())
    } else if options.epochs == 0 {
        Some("no epoch runs".into())
    } else if options.train_points.is_some() {
        Some("the training record is cut to --train-points".into())
    } else if data.train.len() < 2 {
        Some(format!(
            "{} training experiment (each fold trains on the others; at least two are needed)",
            data.train.len()
        ))
    } else {
        None
    }
}

/// Trains every fold on threads; returns each fold's curve in fold order.
fn fold_curves(
    model: &ir::Model,
    records: &[Record],
    how: (&TrainOptions, &Recipe, &RunControl),
    on_event: &mut dyn FnMut(Event),
) -> Result<Vec<Curve>, TrainError> {
    let folds = records.len();
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(folds);
    let next = AtomicUsize::new(0);
    let (sender, receiver) = mpsc::channel::<Message>();
    let mut curves: Vec<Option<Result<Curve, TrainError>>> = (0..folds).map(|_| None).collect();
    std::thread::scope(|scope| {
        for _ in 0..threads {
            let sender = sender.clone();
            let next = &next;
            scope.spawn(move || loop {
                let fold = next.fetch_add(1, Ordering::SeqCst);
                if fold >= folds {
                    break;
                }
                let tell = |epoch| sender.send(Message::Epoch(fold, epoch)).is_ok();
                let curve = fold_curve(model, (records, fold), how, tell);
                if sender.send(Message::Done(fold, curve)).is_err() {
                    break;
                }
            });
        }
        drop(sender);
        for message in receiver {
            match message {
                Message::Epoch(fold, epoch) => {
                    on_event(Event::Strength(ChoiceEvent::Epoch { fold, epoch }));
                }
                Message::Done(fold, curve) => {
                    let held_out = records[fold].name.as_str();
                    on_event(Event::Strength(ChoiceEvent::FoldDone { fold, held_out }));
                    curves[fold] = Some(curve);
                }
            }
        }
    });
    let curves: Vec<Curve> = (curves.into_iter())
        .map(|curve| curve.unwrap_or_else(|| Ok(Err("its thread ended early".into()))))
        .collect::<Result<_, _>>()
        .map_err(|error| match error {
            TrainError::Interrupted { .. }
            | TrainError::Backend(crate::engine::graph::BackendError::Stopped) => {
                TrainError::StoppedBefore {
                    phase: "its folds were choosing where training stops".into(),
                }
            }
            error => error,
        })?;
    Ok(curves)
}

/// Fold `index`: trains on the other records and scores the one held out before the first
/// epoch and at every validated epoch. A training that fails on the data is the fold's
/// `Err(why)`; an I/O or internal failure, or an interruption, is the call's error.
fn fold_curve(
    model: &ir::Model,
    (records, index): (&[Record], usize),
    (options, recipe, control): (&TrainOptions, &Recipe, &RunControl),
    tell: impl Fn(usize) -> bool,
) -> Result<Curve, TrainError> {
    if crate::train::checkpoint::stop_requested(control) {
        // Asked to stop: the folds not yet started are not started.
        return Err(TrainError::StoppedBefore {
            phase: "its folds were choosing where training stops".into(),
        });
    }
    let train: Vec<Record> = (records.iter().enumerate())
        .filter(|(other, _)| *other != index)
        .map(|(_, r)| r.clone())
        .collect();
    let data = TrainingData {
        train: &train,
        validation: std::slice::from_ref(&records[index]),
        part: Part::All,
    };
    let mut curve = Vec::new();
    let mut listen = |event: Event| {
        if let Event::Validation { epoch, online, .. } = event {
            curve.push((epoch, online));
            tell(epoch);
        }
    };
    let trained = match train_run(model, &data, (options, recipe), control, &mut listen) {
        Ok(trained) => trained,
        Err(error @ (TrainError::Io(_) | TrainError::Backend(_))) => return Err(error),
        Err(error @ TrainError::Interrupted { .. }) => return Err(error),
        Err(error) => return Ok(Err(format!("its training failed: {error}"))),
    };
    let Some(start) = trained.report.metrics.initial_online.as_ref() else {
        return Ok(Err("its free run scores no measured cell".into()));
    };
    curve.insert(0, (0, Some(start.overall)));
    Ok(Ok(curve))
}

/// The choice from the folds' curves.
fn scored(epochs: usize, records: &[Record], curves: Vec<Curve>) -> StopChoice {
    let (mut held_out, mut failed, mut scored) = (Vec::new(), Vec::new(), Vec::new());
    for (record, curve) in records.iter().zip(curves) {
        match curve {
            Ok(curve) => {
                held_out.push(record.name.clone());
                scored.push(curve);
            }
            Err(why) => failed.push((record.name.clone(), why)),
        }
    }
    let mut stops: Vec<usize> = (scored.iter().flatten()).map(|&(e, _)| e).collect();
    stops.sort_unstable();
    stops.dedup();
    let candidates: Vec<Candidate> = (stops.into_iter())
        .map(|epoch| candidate(epoch, &scored))
        .collect();
    let (best, chosen) = stop(&candidates);
    StopChoice {
        epochs,
        held_out,
        failed,
        candidates,
        best,
        chosen,
        seconds: 0.0,
    }
}

/// The folds' errors after `epoch`: a fold without that epoch (its training ended
/// non-finite before it) or with a non-finite error has none.
fn candidate(epoch: usize, curves: &[Vec<(usize, Option<f64>)>]) -> Candidate {
    let errors: Vec<Option<f64>> = (curves.iter())
        .map(|curve| {
            (curve.iter())
                .find(|(e, _)| *e == epoch)
                .and_then(|&(_, error)| error.filter(|e| e.is_finite()))
        })
        .collect();
    let known: Option<Vec<f64>> = errors.iter().copied().collect();
    let mean = known
        .filter(|k| !k.is_empty())
        .map(|k| k.iter().sum::<f64>() / k.len() as f64);
    Candidate {
        epoch,
        errors,
        mean,
    }
}

/// The best stop (lowest mean, the earlier on a tie) and the chosen one: the earliest whose
/// paired difference from the best, over the folds, has a mean within one standard error.
/// Without any scored stop, 0 for both.
pub(super) fn stop(candidates: &[Candidate]) -> (usize, usize) {
    let score = |c: &Candidate| c.mean.unwrap_or(f64::INFINITY);
    let Some(best) =
        (candidates.iter())
            .filter(|c| score(c).is_finite())
            .fold(None::<&Candidate>, |kept, c| match kept {
                Some(k) if score(k) <= score(c) => Some(k),
                _ => Some(c),
            })
    else {
        return (0, 0);
    };
    let within = |c: &Candidate| {
        let differences: Option<Vec<f64>> = (c.errors.iter().zip(&best.errors))
            .map(|(a, b)| Some((*a)? - (*b)?))
            .collect();
        differences.is_some_and(|d| {
            let n = d.len() as f64;
            let mean = d.iter().sum::<f64>() / n;
            let spread = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
            mean <= (spread / n).sqrt()
        })
    };
    let chosen = (candidates.iter())
        .filter(|c| c.epoch <= best.epoch)
        .find(|c| within(c))
        .map_or(best.epoch, |c| c.epoch);
    (best.epoch, chosen)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(epoch: usize, errors: &[f64]) -> Candidate {
        let errors: Vec<Option<f64>> = errors.iter().map(|&e| Some(e)).collect();
        let mean = Some(errors.iter().map(|e| e.unwrap()).sum::<f64>() / errors.len() as f64);
        Candidate {
            epoch,
            errors,
            mean,
        }
    }

    /// Training that helps every fold by far more than the folds disagree is kept; one that
    /// helps by less than the spread of its paired differences goes back to the earliest
    /// stop within it (here the mechanism); one that only hurts stays at the mechanism.
    #[test]
    fn the_stop_is_the_earliest_within_one_standard_error_of_the_best() {
        let clear = [
            candidate(0, &[0.4, 0.3, 0.5]),
            candidate(10, &[0.2, 0.15, 0.25]),
            candidate(20, &[0.05, 0.04, 0.06]),
            candidate(30, &[0.06, 0.05, 0.08]),
        ];
        assert_eq!(stop(&clear), (20, 20));
        let noise = [
            candidate(0, &[0.10, 0.20, 0.30]),
            candidate(10, &[0.05, 0.26, 0.27]),
        ];
        // The mechanism's paired differences from the best (epoch 10) are +0.05, -0.06,
        // +0.03: mean 0.0067, well within their standard error (0.034).
        assert_eq!(stop(&noise), (10, 0));
        let worse = [
            candidate(0, &[0.1, 0.2]),
            candidate(10, &[0.3, 0.4]),
            candidate(20, &[0.5, 0.9]),
        ];
        assert_eq!(stop(&worse), (0, 0));
    }

    /// A stop at which a fold has no error (its free run left the range) is never best,
    /// and nothing scored at all stops at the mechanism.
    #[test]
    fn a_stop_missing_a_fold_is_never_chosen() {
        let mut broken = candidate(20, &[0.01, 0.01]);
        broken.errors[1] = None;
        broken.mean = None;
        let candidates = [
            candidate(0, &[0.4, 0.5]),
            candidate(10, &[0.1, 0.12]),
            broken,
        ];
        assert_eq!(stop(&candidates), (10, 10));
        assert_eq!(stop(&[]), (0, 0));
    }
}
