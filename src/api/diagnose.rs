//! The sim-to-real gap of a mechanistic model ([`crate::diagnose`]): a [`DiagnoseSpec`] in,
//! a [`Diagnosis`] out that renders itself as the CLI's text, JSON and HTML.

use super::{hold_out, ApiError, Model};
use crate::diagnose::{self, Options, Problem, Progress, Report};
use crate::ir::NoiseSpec;
use crate::record::Record;

/// What a diagnosis is asked for, with the defaults of `gbc diagnose`.
#[derive(Debug, Clone, Default)]
pub struct DiagnoseSpec {
    /// Restarts, seed, history span and dimension, tail share, initial-state fit, loci,
    /// minimum rows.
    pub options: Options,
    /// Experiments of the data set held out from the fits and scored (`--holdout`).
    pub holdout: Vec<String>,
    /// Measurement noise specs (`--noise X=5%`), over the model's `noise` lines.
    pub noise: Vec<NoiseSpec>,
    /// Fits run at a time (`--jobs`; `None`: one per core).
    pub jobs: Option<usize>,
}

impl DiagnoseSpec {
    /// The run's measurement noise: the model's `noise` lines with the specs over them
    /// ([`crate::ir::merge_noise`]); a spec that names no measured quantity is refused.
    /// Checked before any data is read, so that a bad spec is the error a user sees first.
    pub fn noise_of(&self, model: &Model) -> Result<Vec<crate::ir::Noise>, ApiError> {
        let ir = model.ir();
        crate::ir::merge_noise(ir, &self.noise, &ir.measured()).map_err(ApiError::user)
    }
}

/// A finished diagnosis.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// Everything the diagnosis found (what `--json` writes).
    pub report: Report,
}

/// Diagnoses `model` against `records` (and the experiments of `val`, which are only
/// scored) as `spec` asks; `on_progress` hears of each stage and each fit done.
pub fn diagnose(
    model: &Model,
    (records, val): (Vec<Record>, Vec<Record>),
    spec: &DiagnoseSpec,
    on_progress: &(dyn Fn(Progress) + Sync),
) -> Result<Diagnosis, ApiError> {
    if spec.jobs == Some(0) {
        return Err(ApiError::user(crate::solve::fit::FitError::BadOption {
            option: "--jobs".into(),
            expected: "at least 1 thread".into(),
            found: "0".into(),
            help: "--jobs 2 runs two fits at a time".into(),
        }));
    }
    let ir = model.ir();
    let noise = spec.noise_of(model)?;
    check_holdout_names(&records, &spec.holdout)?;
    let (train, mut held) = hold_out(records, &spec.holdout)?;
    held.extend(val);
    let problem = Problem {
        name: &model.origin,
        source: &model.source,
        checked: &model.compiled.checked,
        model: ir,
        records: &train,
        held_out: &held,
    };
    let options = Options {
        noise: Some(noise),
        ..spec.options.clone()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(spec.jobs.unwrap_or(0))
        .build()
        .map_err(|e| ApiError::Internal(format!("cannot start worker threads: {e}")))?;
    let report = pool
        .install(|| diagnose::diagnose(&problem, &options, on_progress))
        .map_err(ApiError::user)?;
    check_finite(&report)?;
    Ok(Diagnosis { report })
}

/// `--holdout 0.3` (the old spelling of a tail split) names no experiment: a clear error
/// that points to `--val-fraction`.
fn check_holdout_names(records: &[Record], holdout: &[String]) -> Result<(), ApiError> {
    for name in holdout {
        let known = records.iter().any(|r| &r.name == name);
        if !known && name.trim().parse::<f64>().is_ok() {
            let names: Vec<&str> = records.iter().map(|r| r.name.as_str()).collect();
            return Err(ApiError::user(crate::solve::fit::FitError::BadOption {
                option: "--holdout".into(),
                expected: format!("the name of an experiment ({})", names.join(", ")),
                found: name.clone(),
                help: format!(
                    "--holdout names experiments to hold out; to score the last share of each \
                     experiment use --val-fraction {name}"
                ),
            }));
        }
    }
    Ok(())
}

/// Refuses a report whose fitted params or initial states are not finite: they are its
/// result (a diverged effect's gap is infinite by design and written as such).
fn check_finite(report: &Report) -> Result<(), ApiError> {
    let params = (report.fitted_params.iter()).map(|(name, value)| (name.as_str(), *value));
    let starts = (report.initial_states.iter()).map(|s| (s.state.as_str(), s.value));
    let found = crate::finite::in_named(params)
        .map(|what| format!("the fitted param {what}"))
        .or_else(|| {
            crate::finite::in_named(starts).map(|what| format!("the initial state {what}"))
        });
    let help = "the fit of the model went non-finite: check the params' initial values and \
                constraints";
    let path = std::path::Path::new("the report");
    crate::finite::refuse(path, found, help).map_err(ApiError::user)
}

impl Diagnosis {
    /// The text report `gbc diagnose` prints.
    pub fn text(&self) -> String {
        diagnose::render::text(&self.report)
    }

    /// The report as the JSON `--json` writes.
    pub fn json(&self) -> Result<String, ApiError> {
        serde_json::to_string_pretty(&self.report).map_err(|e| ApiError::Internal(e.to_string()))
    }

    /// The HTML page `--html` writes.
    pub fn html(&self) -> String {
        diagnose::html::page(&self.report)
    }

    /// Each figure of the page as `(file name, SVG)` (`--figures DIR`).
    pub fn figures(&self) -> Vec<(String, String)> {
        diagnose::html::figures(&self.report)
    }
}
