//! What a diagnosis is given and how it runs: the problem, the options, the progress it
//! reports, and the [`Context`] every step shares (the split, the bootstrap's blocks, how
//! corrections integrate), with the thresholds its verdicts use.

use super::error::DiagnoseError;
use super::ranking::Blocks;
use crate::check::Checked;
use crate::ir::Model;
use crate::record::Record;
use crate::solve::fit::simulate::Simulator;
use crate::solve::fit::split::{Holdout, Split, MIN_ROWS};
use crate::solve::fit::unknowns::Unknowns;
use crate::solve::fit::{check_fittable, FitError, FitOptions};
use crate::solve::ode::Method;

/// The gap is significant when it exceeds this multiple of the noise floor.
pub const SIGNIFICANCE: f64 = 2.0;
/// An effect (or an addition to the credited ones) is credited only when it removes at
/// least this fraction of the gap above the noise floor (and the gap is significant, and
/// its lead exceeds the ranking's uncertainty).
pub const CREDIT: f64 = 0.5;
/// The share of each experiment held out (its tail) when no split is asked for: scoring
/// tails keeps the transient of a start away from the score.
pub const DEFAULT_TAIL: f64 = 0.3;

/// What to diagnose.
#[derive(Debug, Clone, Copy)]
pub struct Problem<'a> {
    /// The model file's name (for messages).
    pub name: &'a str,
    /// The model's source text (corrections are synthesised from it).
    pub source: &'a str,
    /// The checked model (effects are lowered from it).
    pub checked: &'a Checked,
    /// The model lowered without effects.
    pub model: &'a Model,
    /// The experiments that train (with a tail split, their tails are scored).
    pub records: &'a [Record],
    /// Experiments that are only scored (`--holdout NAME`, `--val FILE`).
    pub held_out: &'a [Record],
}

/// How to diagnose.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Share of each training experiment's measured rows held out (its tail). `None`: whole
    /// held-out experiments if any are given, else a tail of [`DEFAULT_TAIL`].
    pub val_fraction: Option<f64>,
    /// Most random restarts of each fit besides the declared or warm start (fits stop
    /// earlier once two starts agree).
    pub restarts: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// Number of time windows of each held-out part.
    pub windows: usize,
    /// The longest time constant of the history features (model time units); `None`
    /// chooses it from the data.
    pub span: Option<f64>,
    /// Number of time constants of the history features.
    pub dim: usize,
    /// Whether hidden states start from values fitted per training experiment.
    pub fit_initial: bool,
    /// Whether the first row's measured cells of the training experiments are fitted as
    /// unknowns within their noise (the default; `--exact-starts` starts the free runs at
    /// them, the records spec's literal reading).
    pub fit_starts: bool,
    /// Whether to search the loci (free corrections at every let, group and balance; most
    /// of the cost). Without it the report answers which effects and how far only.
    pub locate: bool,
    /// The measurement noise (`ir::merge_noise` of the model's declarations and the
    /// command line's `--noise`); `None`: the model's declarations.
    pub noise: Option<Vec<crate::ir::Noise>>,
    /// Measured rows the training part needs, and below which a held-out score is said to
    /// rest on few rows; default [`MIN_ROWS`].
    pub min_rows: usize,
    /// Whether the constants a free run reads compete with the effects as candidates,
    /// each refitted as a param (`--hold-constants` turns it off).
    pub refit_constants: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            val_fraction: None,
            restarts: 15,
            seed: 0,
            windows: 20,
            span: None,
            dim: 5,
            fit_initial: false,
            fit_starts: true,
            locate: true,
            noise: None,
            min_rows: MIN_ROWS,
            refit_constants: true,
        }
    }
}

impl Options {
    /// The options of every fit the diagnosis makes.
    pub fn fitting(&self) -> FitOptions {
        FitOptions {
            restarts: self.restarts,
            seed: self.seed,
            fit_initial: self.fit_initial,
            fit_starts: self.fit_starts,
            noise: self.noise.clone(),
            min_rows: self.min_rows,
        }
    }
}

/// Progress of a diagnosis, for a progress bar.
#[derive(Debug, Clone, PartialEq)]
pub enum Progress {
    /// A stage of `total` work items starts.
    Stage {
        /// What it does.
        name: &'static str,
        /// Number of items.
        total: usize,
    },
    /// A fit of the current stage ran a round of its starts.
    Round {
        /// Which fit (the model's name, or its effects joined by ` + `).
        fit: String,
        /// Starts run so far.
        done: usize,
        /// Starts its budget allows at most (it may stop sooner: once a round finds
        /// nothing new).
        max: usize,
        /// The best training gap so far (infinite while every start failed).
        best: f64,
        /// Seconds the fit has run.
        seconds: f64,
    },
    /// One item of the current stage is done.
    Done {
        /// What it was (a candidate effect, a locus).
        item: String,
        /// Seconds it took.
        seconds: f64,
    },
}

/// Everything the stages share.
pub struct Context<'a> {
    /// The model's text and checked form, which effects and corrections are lowered from.
    pub(super) problem: Problem<'a>,
    /// How to diagnose.
    pub(super) options: &'a Options,
    /// The model lowered without effects.
    pub(super) model: &'a Model,
    /// The experiments in model terms, and which rows fit and which are scored.
    pub(super) split: Split,
    /// The blocks of the scored rows the bootstrap draws.
    pub(super) blocks: Blocks,
    /// How the corrected models of the loci integrate: explicitly where the model's own
    /// free runs never turned stiff (a correction's wild trial values then fail fast, as
    /// they should, instead of being integrated implicitly at great cost), automatically
    /// where they did.
    pub(super) corrections: Method,
    /// Told how the diagnosis goes (down to each fit's rounds of starts).
    pub(super) progress: &'a (dyn Fn(Progress) + Sync),
}

impl<'a> Context<'a> {
    /// A seed for task `index`, derived from the user's seed.
    pub(super) fn seed(&self, index: u64) -> u64 {
        self.options.fitting().task_seed(index)
    }

    /// The unknowns of a fit of `model` (compiled as `simulator`) on the split.
    pub(super) fn unknowns(&self, model: &Model, simulator: &Simulator) -> Unknowns {
        Unknowns::of(&self.split, model, simulator)
    }

    /// The context of diagnosing `problem` with `options`: the options checked, the model
    /// checked fittable, the records split; corrections integrate automatically until the
    /// model's own free runs say otherwise.
    pub(super) fn new(
        problem: &Problem<'a>,
        options: &'a Options,
        progress: &'a (dyn Fn(Progress) + Sync),
    ) -> Result<Self, DiagnoseError> {
        let model = problem.model;
        check_options(options)?;
        check_fittable(model, problem.records.iter().chain(problem.held_out))?;
        let train = problem.records.to_vec();
        let held = problem.held_out.to_vec();
        let holdout = match options.val_fraction {
            Some(share) => Holdout::Tail(share),
            None if !held.is_empty() => Holdout::Experiments,
            None => Holdout::Tail(DEFAULT_TAIL),
        };
        let parts = (holdout, options.fit_initial);
        let mut split = Split::with_min_rows(model, (train, held), parts, options.min_rows)?;
        split.declare_noise(options.noise.as_deref().unwrap_or(&model.noise));
        if options.fit_starts {
            crate::solve::fit::noise::fit_uncertain_starts(&mut split, model);
        }
        Ok(Context {
            problem: *problem,
            options,
            model,
            blocks: Blocks::new(&split),
            split,
            corrections: Method::Auto,
            progress,
        })
    }
}

/// The options' values, each in its range.
fn check_options(options: &Options) -> Result<(), DiagnoseError> {
    let bad = |option: &str, expected: &str, found: String, help: &str| {
        DiagnoseError::Fit(FitError::BadOption {
            option: option.into(),
            expected: expected.into(),
            found,
            help: help.into(),
        })
    };
    if let Some(share) = options.val_fraction {
        if !(share > 0.0 && share < 1.0) {
            return Err(bad(
                "--val-fraction",
                "a share strictly between 0 and 1",
                share.to_string(),
                "--val-fraction 0.3 scores the last 30 % of each experiment's measured rows",
            ));
        }
    }
    options.fitting().check()?;
    if options.dim < 1 {
        return Err(bad(
            "--dim",
            "at least 1 time constant",
            options.dim.to_string(),
            "--dim sets how many filters of the history span, from the sampling step to --span",
        ));
    }
    if let Some(span) = options.span {
        if !(span > 0.0 && span.is_finite()) {
            return Err(bad(
                "--span",
                "a positive time",
                span.to_string(),
                "--span is the longest time constant of the history features, in the model's time unit",
            ));
        }
    }
    Ok(())
}
