//! The texts `gbc train` prints on stdout: when a run ends ([`summary`]: what trained, the
//! validation errors per experiment and pooled, where a free run left the physical range,
//! each experiment's initial state and each param with its standard error), and after a
//! leave-one-experiment-out cross-validation ([`cv_table`]) and after an ensemble
//! ([`ensemble_summary`]).

use std::fmt::Write as _;
use std::path::Path;

use crate::ensemble::{self, EnsembleInfo, Resample};
use crate::ir::Model;
use crate::plot::tick_label;
use crate::train::{self, ErrorSet, Trained};
use crate::trained::cv::{self, CrossValidation};

/// `writeln!` into a `String` (which cannot fail).
macro_rules! line {
    ($out:expr, $($arg:tt)*) => {{
        let _ = writeln!($out, $($arg)*);
    }};
}

/// The summary of `trained` (`seconds` of training; `run`: where the run was written;
/// `cross_validated`: `--cv` scored it, nothing else validates).
pub fn summary(
    model: &Model,
    trained: &Trained,
    seconds: f64,
    (run, cross_validated): (Option<&Path>, bool),
) -> String {
    let mut out = String::new();
    let report = &trained.report;
    line!(
        out,
        "trained `{}` on {} pairs for {} epochs ({}) in {seconds:.1} s (final loss {})",
        model.name,
        report.train_pairs,
        report.losses.len(),
        report.recipe.objective.name(),
        report
            .losses
            .last()
            .map_or("-".into(), |l| format!("{l:.4e}"))
    );
    let metrics = &report.metrics;
    if metrics.validations.is_empty() && cross_validated {
        line!(
            out,
            "this model trains on every experiment: the cross-validation above scores it"
        );
    } else if metrics.validations.is_empty() {
        line!(
            out,
            "nothing validates: pass --val FILE, --holdout NAME, --val-fraction SHARE or a \
             smaller --train-points"
        );
    }
    for set in &metrics.validations {
        line!(
            out,
            "validation on {} ({} pairs; MSE of z-scored states at measured cells):",
            set.name,
            set.pairs
        );
        print_errors(&mut out, set.offline.as_ref(), set.online.as_ref());
    }
    if metrics.validations.len() > 1 {
        line!(out, "validation pooled over every experiment:");
        print_errors(&mut out, metrics.offline.as_ref(), metrics.online.as_ref());
    }
    print_initial_states(&mut out, report);
    print_params(&mut out, trained);
    if let Some(distance) = &report.toward_mechanism {
        print_distance(&mut out, distance);
    }
    if let Some(directory) = run {
        line!(out, "run written to {}", directory.display());
    }
    out
}

/// One row per measured state; an error that could not be measured shows as `-`.
fn print_errors(out: &mut String, offline: Option<&ErrorSet>, online: Option<&ErrorSet>) {
    line!(
        out,
        "  {:<16} {:>12} {:>12}",
        "NMSE of state",
        "offline",
        "online"
    );
    let names: Vec<&String> = (offline.iter().chain(online.iter()))
        .flat_map(|set| set.per_state.iter().map(|(name, _)| name))
        .fold(Vec::new(), |mut names, name| {
            if !names.contains(&name) {
                names.push(name);
            }
            names
        });
    let of = |set: Option<&ErrorSet>, name: &str| {
        set.and_then(|s| s.per_state.iter().find(|(n, _)| n == name))
            .map_or("-".to_string(), |(_, e)| error(*e))
    };
    for name in names {
        line!(
            out,
            "  {name:<16} {:>12} {:>12}",
            of(offline, name),
            of(online, name)
        );
    }
    let overall = |set: Option<&ErrorSet>| set.map_or("-".to_string(), |s| error(s.overall));
    line!(
        out,
        "  {:<16} {:>12} {:>12}",
        "error (mean)",
        overall(offline),
        overall(online)
    );
    if let Some(divergence) = online.and_then(|s| s.divergence.as_ref()) {
        line!(out, "  {divergence}");
    }
}

/// The initial values that were not measured: declared or fitted per experiment.
fn print_initial_states(out: &mut String, report: &train::TrainReport) {
    let unmeasured: Vec<_> = (report.initial_states.iter())
        .flat_map(|state| {
            (state.states.iter())
                .filter(|(_, _, origin)| *origin != train::Origin::Measured)
                .map(move |(name, value, origin)| (&state.experiment, name, value, origin))
        })
        .collect();
    if unmeasured.is_empty() {
        return;
    }
    line!(
        out,
        "initial states not measured at an experiment's first row:"
    );
    for (experiment, name, value, origin) in unmeasured {
        let how = match origin {
            train::Origin::Declared => "declared",
            _ => "fitted",
        };
        line!(out, "  {experiment:<24} {name} = {value:.6} ({how})");
    }
}

fn print_params(out: &mut String, trained: &Trained) {
    let report = &trained.report;
    if report.params.is_empty() {
        return;
    }
    match (&report.polish, &report.balance_fit) {
        _ if report.mechanism_fit.is_some() => {
            let fit = report
                .mechanism_fit
                .as_ref()
                .map_or((0, 0.0), |f| (f.starts, f.gap_train));
            let what = if trained.setup.scales.is_empty() {
                "the model, as gbc diagnose fits it"
            } else {
                "the mechanism (closure outputs at their priors), as gbc diagnose fits it"
            };
            line!(
                out,
                "params (fitted by free runs of {what} to every measured training cell; {} \
                 starts, training gap {:.4e}; held fixed in training; +- standard error):",
                fit.0,
                fit.1
            )
        }
        (_, Some(fit)) => line!(
            out,
            "params (from the balances over {} intervals, held fixed in training; rms scaled \
             residual {:.3e}; +- standard error):",
            fit.intervals,
            fit.rms_residual
        ),
        (Some(polish), None) => line!(
            out,
            "params (polished in {} steps, one-step loss {:.4e} -> {:.4e}; +- standard error):",
            polish.steps,
            polish.loss_before,
            polish.loss_after
        ),
        (None, None) => line!(out, "params (+- standard error):"),
    }
    for estimate in &report.estimates {
        if estimate.held {
            line!(
                out,
                "  {} = {:.6} (held at its declared value, no standard error)",
                estimate.name,
                estimate.value
            );
            continue;
        }
        let flag = if estimate.identified {
            ""
        } else {
            "  poorly identified"
        };
        line!(
            out,
            "  {} = {:.6} +- {:.2e} ({:.1} %){flag}",
            estimate.name,
            estimate.value,
            estimate.std_error.unwrap_or(f64::INFINITY),
            100.0 * estimate.relative_error.unwrap_or(f64::INFINITY)
        );
    }
}

/// `auto`'s stop: the folds' held-out errors at the mechanism, the best stop, the chosen
/// one and the last epoch.
fn print_choice(out: &mut String, choice: &train::StopChoice) {
    line!(
        out,
        "toward the mechanism, the stop chosen by cross-validation over the training \
         experiments ({} folds, {:.0} s; held-out online error per fold, and their mean):",
        choice.held_out.len(),
        choice.seconds
    );
    let mut shown: Vec<(usize, &str)> = vec![(0, "the mechanism")];
    shown.push((
        choice.chosen,
        "chosen (within one standard error of the best)",
    ));
    shown.push((choice.best, "best"));
    if let Some(last) = choice.candidates.last() {
        shown.push((last.epoch, "last"));
    }
    let mut seen = Vec::new();
    for (epoch, what) in shown {
        if seen.contains(&epoch) {
            continue;
        }
        seen.push(epoch);
        let Some(candidate) = choice.at(epoch) else {
            continue;
        };
        let folds: Vec<String> = (choice.held_out.iter().zip(&candidate.errors))
            .map(|(name, e)| format!("{name} {}", e.map_or("-".into(), error)))
            .collect();
        let mean = candidate.mean.map_or("-".into(), error);
        line!(
            out,
            "  epoch {epoch:<5} {mean} ({}) {what}",
            folds.join(", ")
        );
    }
    for (name, why) in &choice.failed {
        line!(out, "  fold without {name}: nothing scored ({why})");
    }
}

/// The pull toward the mechanism (and `auto`'s table) and how far the grey box moved.
fn print_distance(out: &mut String, distance: &train::toward::MechanismDistance) {
    if let Some(choice) = &distance.choice {
        print_choice(out, choice);
    }
    if let Some(why) = &distance.unchosen {
        line!(
            out,
            "toward the mechanism: auto trained every epoch without a pull ({why})"
        );
    }
    line!(
        out,
        "distance from the mechanism (strength {}; outputs over {} training points: *= RMS of \
         the factor - 1, += RMS of the correction over the prior's, none RMS of the output):",
        distance.strength,
        distance.outputs.first().map_or(0, |o| o.points)
    );
    for output in &distance.outputs {
        line!(
            out,
            "  {:<24} {:>4} {:.3e} (RMS change {:.3e})",
            output.name,
            output.prior,
            output.moved,
            output.rms_change
        );
    }
    for param in &distance.params {
        let errors = param
            .standard_errors
            .map_or(String::new(), |e| format!(", {e:+.2} standard errors"));
        line!(
            out,
            "  {} {:.6} -> {:.6}{errors}",
            param.name,
            param.start,
            param.value
        );
    }
}

/// An error value for the summary: scientific notation, or `diverged`.
pub fn error(value: f64) -> String {
    if value.is_finite() {
        format!("{value:.4e}")
    } else {
        "diverged".to_string()
    }
}

/// The folds as text: per fold and pooled, the online error of each state and overall and
/// the offline error overall; then the medians, the divergences and the empty folds.
pub fn cv_table(model: &Model, result: &CrossValidation, directory: &Path) -> String {
    let mut out = String::new();
    let states: Vec<&str> = model.states.iter().map(|s| s.name.as_str()).collect();
    let _ = writeln!(
        out,
        "leave-one-experiment-out cross-validation ({} folds; MSE of z-scored states, \
         online per state):",
        result.folds.len()
    );
    let mut header = format!("  {:<24}", "held out");
    for state in &states {
        let _ = write!(header, " {state:>12}");
    }
    let _ = writeln!(out, "{header} {:>12} {:>12}", "online", "offline");
    let row =
        |out: &mut String, name: &str, online: Option<&ErrorSet>, offline: Option<&ErrorSet>| {
            let mut line = format!("  {name:<24}");
            for state in &states {
                let value = online
                    .and_then(|s| s.per_state.iter().find(|(n, _)| n == state))
                    .map_or("-".into(), |(_, e)| error(*e));
                let _ = write!(line, " {value:>12}");
            }
            let overall = |set: Option<&ErrorSet>| set.map_or("-".into(), |s| error(s.overall));
            let _ = writeln!(
                out,
                "{line} {:>12} {:>12}",
                overall(online),
                overall(offline)
            );
        };
    for fold in &result.folds {
        row(
            &mut out,
            &fold.held_out,
            fold.online.as_ref(),
            fold.offline.as_ref(),
        );
    }
    row(
        &mut out,
        "pooled",
        result.pooled_online.as_ref(),
        result.pooled_offline.as_ref(),
    );
    let median = |value: Option<f64>| value.map_or("-".into(), error);
    let pad = " ".repeat(13 * states.len());
    let _ = writeln!(
        out,
        "  {:<24}{pad} {:>12} {:>12}",
        "median",
        median(result.median_online),
        median(result.median_offline)
    );
    for fold in &result.folds {
        notes(&mut out, fold);
    }
    let _ = writeln!(
        out,
        "each fold's run and held-out free run: {}",
        directory.join(cv::CV_DIR).display()
    );
    out
}

/// A fold's divergences and why it validates nothing, each on a line.
fn notes(out: &mut String, fold: &cv::Fold) {
    let name = &fold.held_out;
    if let Some(divergence) = fold.online.as_ref().and_then(|s| s.divergence.as_ref()) {
        let _ = writeln!(out, "  fold `{name}`: {divergence}");
    }
    if let Some(diverged) = &fold.diverged {
        let _ = writeln!(
            out,
            "  fold `{name}`: training went non-finite in epoch {} ({}): {}; its run keeps \
             epoch {}",
            diverged.epoch, diverged.phase, diverged.what, diverged.kept_epoch
        );
    }
    if let Some(why) = &fold.nothing_validates {
        let _ = writeln!(out, "  fold `{name}` validates nothing: {why}");
    }
}

/// The text `gbc train --ensemble N` prints when the ensemble is done: each member, the
/// band's noise and calibration, its coverage of the held-out experiments, the errors.
pub fn ensemble_summary(
    model: &Model,
    info: &EnsembleInfo,
    seconds: f64,
    directory: &Path,
) -> String {
    let mut out = String::new();
    let used = info.used().count();
    line!(
        out,
        "trained an ensemble of {used} members of `{}` ({} of {} finished) in {seconds:.1} s, {}",
        model.name,
        used,
        info.members.len(),
        match info.resample {
            Resample::Experiments => "each on a bootstrap of whole training experiments",
            Resample::None => "each on every training experiment",
        }
    );
    for member in &info.members {
        line!(
            out,
            "  member {} (seed {}): trained on {}; {}{}",
            member.index,
            member.seed,
            member.trained_on.join(" "),
            member.status,
            member.validation_error.map_or(String::new(), |e| format!(
                ", held-out error {}",
                tick_label(e)
            ))
        );
    }
    band_lines(&mut out, info);
    coverage_lines(&mut out, info);
    line!(
        out,
        "ensemble written to {} (ensemble.json, members/, report.html)",
        directory.display()
    );
    out
}

/// The noise and calibration of each state.
fn band_lines(out: &mut String, info: &EnsembleInfo) {
    let level = info
        .coverage
        .as_ref()
        .map_or(ensemble::DEFAULT_LEVEL, |c| c.level);
    let calibration = &info.calibration;
    if let Some(reason) = &calibration.reason {
        line!(out, "band: not calibrated ({reason}); none is claimed");
        return;
    }
    let experiments: Vec<String> = (calibration.experiments.iter())
        .map(|(name, members)| match members.is_empty() {
            true => format!("{name} (no member left it out)"),
            false => format!(
                "{name} (members {})",
                members
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        })
        .collect();
    line!(
        out,
        "band calibrated out of bag on {}:",
        experiments.join(", ")
    );
    line!(
        out,
        "  {:<12} {:<44} {:>9} {:>10}",
        "state",
        "noise",
        "oob cells",
        "factor"
    );
    for (state, (noise, scores)) in (info.band.noise.iter().zip(&calibration.states)).enumerate() {
        let factor = calibration
            .factor(state, level)
            .map_or("-".into(), tick_label);
        let cells = if scores.pooled {
            format!("{} (pooled)", scores.cells)
        } else {
            scores.cells.to_string()
        };
        line!(
            out,
            "  {:<12} {:<44} {:>9} {:>10}",
            noise.state,
            noise.describe(),
            cells,
            factor
        );
    }
}

/// The coverage of the held-out experiments and the errors.
fn coverage_lines(out: &mut String, info: &EnsembleInfo) {
    let Some(coverage) = &info.coverage else {
        line!(out, "coverage: no held-out measured cell to count");
        return;
    };
    let share = |inside: usize, cells: usize| {
        format!(
            "{inside} of {cells} ({:.1} %)",
            100.0 * inside as f64 / cells.max(1) as f64
        )
    };
    line!(
        out,
        "coverage of the {} % band on held-out {}: {} measured cells inside",
        tick_label(100.0 * coverage.level),
        coverage.experiments.join(" "),
        share(coverage.overall.inside, coverage.overall.cells)
    );
    for count in &coverage.states {
        line!(
            out,
            "  {:<12} {}",
            count.state,
            share(count.inside, count.cells)
        );
    }
    let base = &coverage.uncalibrated;
    line!(
        out,
        "  (not calibrated, the members' spread with the noise at {} %: {})",
        tick_label(100.0 * info.band.base_level),
        share(base.inside, base.cells)
    );
    if let Some(errors) = &info.errors {
        let members: Vec<String> = errors.members.iter().map(|e| tick_label(*e)).collect();
        line!(
            out,
            "held-out error of the members' median {} (members: {})",
            tick_label(errors.median),
            members.join(", ")
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::toward::{param_distances, MechanismDistance};
    use crate::train::ParamEstimate;

    /// Issue 43 (GB1's `Y_X 0.435 -> 0.435, +96721.50 standard errors`): a move over a
    /// standard error of round-off is printed without a count of standard errors; a
    /// statistical one keeps its count.
    #[test]
    fn a_move_over_a_round_off_error_prints_no_count_of_standard_errors() {
        let source = "model t\nstate X = 1\nparam Y_X = 0.435 positive, k = 0.3 positive\n\
                      der X = -k * Y_X * X\n";
        let model = crate::driver::compile("t.gbm", source, &[]).unwrap().model;
        let values = [
            ("Y_X".to_string(), 0.435 + 9.67e-10),
            ("k".to_string(), 0.33),
        ];
        let estimates = [
            ParamEstimate::fitted("Y_X".into(), values[0].1, 1e-14),
            ParamEstimate::fitted("k".into(), 0.33, 0.01),
        ];
        let distance = MechanismDistance {
            strength: 0.0,
            choice: None,
            unchosen: None,
            outputs: Vec::new(),
            params: param_distances(&model, &values, &estimates),
        };
        let mut out = String::new();
        print_distance(&mut out, &distance);
        let line = |name: &str| {
            let prefix = format!("  {name} ");
            (out.lines())
                .find(|l| l.starts_with(&prefix))
                .unwrap()
                .to_string()
        };
        assert_eq!(line("Y_X"), "  Y_X 0.435000 -> 0.435000", "{out}");
        assert!(line("k").ends_with(", +3.00 standard errors"), "{out}");
    }
}
