//! The flags of `gbc diagnose` ([`DiagnoseArgs`]) and the diagnosis they ask for.

use std::path::PathBuf;

use super::data::ColumnArgs;
use crate::api::{ApiError, DiagnoseSpec};
use crate::diagnose::Options;

/// Arguments of `gbc diagnose`.
#[derive(Debug, clap::Args)]
pub struct DiagnoseArgs {
    /// The mechanistic model (no closures); its `effect`s are the candidates.
    pub model: PathBuf,
    /// The data set: one or more CSV files, each an experiment (or several, with an
    /// `experiment` column); `t`, the inputs and the measured states, cells may be empty.
    #[arg(required = true, num_args = 1..)]
    pub data: Vec<PathBuf>,
    /// Files of whole experiments that are only scored (repeatable).
    #[arg(long, value_name = "FILE", num_args = 1.., alias = "test")]
    pub val: Vec<PathBuf>,
    /// Experiments of the data set that are only scored (repeatable).
    #[arg(long, value_name = "NAME", num_args = 1..)]
    pub holdout: Vec<String>,
    /// Score the last share of each experiment's measured rows (the free run still starts
    /// at the experiment's first row). Default: 0.3 when no experiment is held out.
    #[arg(long, value_name = "SHARE")]
    pub val_fraction: Option<f64>,
    /// Fit the initial values of the hidden states in every training experiment (else they
    /// start from their declared values): for experiments that do not start where the
    /// model's declarations say, e.g. records cut from one long run.
    #[arg(long)]
    pub fit_initial: bool,
    /// Start every training free run at its first row's measured values, taken as exact
    /// (the records spec's literal reading), instead of fitting them with the params within
    /// their noise (the default: a first assay is a measurement as noisy as any other; its
    /// cell stays a residual and bounds the start to 3 standard deviations of its noise).
    #[arg(long)]
    pub exact_starts: bool,
    /// The default since the measured starts are fitted (kept so that scripts that pass it
    /// still run; see `--exact-starts`).
    #[arg(long, hide = true, conflicts_with = "exact_starts")]
    pub fit_starts: bool,
    /// Hold every `const` at its declared value: only the model's effects are candidates.
    /// By default each constant a free run reads also competes, refitted as a param
    /// (`refit NAME`), so that a literature value or a guessed inoculum the data contradict
    /// is named rather than a look-alike effect credited.
    #[arg(long)]
    pub hold_constants: bool,
    /// How data columns are named.
    #[command(flatten)]
    pub columns: ColumnArgs,
    /// Seed of the random restarts (results are deterministic for a given seed).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Most random starts of each fit besides the declared or warm start; a fit runs at
    /// least four starts and stops at the first round that finds no better basin and has
    /// its best reached twice.
    #[arg(long, default_value_t = crate::diagnose::Options::default().restarts)]
    pub restarts: usize,
    /// The longest time constant of the history features of the free corrections (model
    /// time units); by default chosen from the residuals of the fitted model.
    #[arg(long, value_name = "T")]
    pub span: Option<f64>,
    /// Time constants of the history features, from the sampling step to the span.
    #[arg(long, default_value_t = 5)]
    pub dim: usize,
    /// Replaced by --span (the history is no longer a delay embedding).
    #[arg(long, hide = true)]
    pub delay: Option<f64>,
    /// Skip the locus search (the free corrections at every let, group and balance, most
    /// of the cost): rank and select the effects only.
    #[arg(long)]
    pub skip_loci: bool,
    /// Worker threads for the fits (default: every core).
    #[arg(long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Write the report as JSON (spec section 5 schema) to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write an HTML report with figures to this file.
    #[arg(long, value_name = "FILE")]
    pub html: Option<PathBuf>,
    /// Measured rows the training part needs; a held-out part with fewer is still scored,
    /// and the report says its score rests on few rows (a score of a few rows is noisy).
    #[arg(long, value_name = "N", default_value_t = crate::diagnose::MIN_ROWS)]
    pub min_rows: usize,
    /// Write the report's figures as SVG files into this directory.
    #[arg(long, value_name = "DIR")]
    pub figures: Option<PathBuf>,
    /// Measurement noise of the data, laid over the model's `noise` declarations
    /// (repeatable): `X=4%+0.01` (a measured state or output: 4 % of the value and 0.01 in
    /// its unit), `S=0.02`, `3%` (every measured quantity not named), `declared`; `X=0`
    /// removes one. Used for the noise floor and the fits' weights.
    #[arg(
        long = "noise",
        value_name = "SPEC",
        allow_negative_numbers = true,
        value_parser = crate::ir::parse_noise_spec
    )]
    pub noise: Vec<crate::ir::NoiseSpec>,
}

impl DiagnoseArgs {
    /// The diagnosis the flags ask for.
    pub fn spec(&self) -> Result<DiagnoseSpec, ApiError> {
        if let Some(delay) = self.delay {
            return Err(ApiError::user(crate::solve::fit::FitError::BadOption {
                option: "--delay".into(),
                expected: "--span T, the longest time constant of the history".into(),
                found: delay.to_string(),
                help: "the history of the free corrections is a fading memory now: --span sets \
                       its longest time constant and --dim how many it has"
                    .into(),
            }));
        }
        Ok(DiagnoseSpec {
            options: Options {
                val_fraction: self.val_fraction,
                restarts: self.restarts,
                seed: self.seed,
                span: self.span,
                dim: self.dim,
                fit_initial: self.fit_initial,
                fit_starts: !self.exact_starts,
                locate: !self.skip_loci,
                min_rows: self.min_rows,
                refit_constants: !self.hold_constants,
                ..Options::default()
            },
            holdout: self.holdout.clone(),
            noise: self.noise.clone(),
            jobs: self.jobs,
        })
    }
}
