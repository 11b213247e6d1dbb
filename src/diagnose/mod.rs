//! Sim-to-real gap diagnosis (`gbc diagnose`, spec section 5): a mechanistic model against
//! a data set of experiments (irregular times, missing cells). Method and worked examples:
//! `docs/diagnose.md`.
//!
//! 1. **Gap.** The model's `param`s (and starts no cell or declaration gives) are fitted on
//!    the training parts ([`fit`]: Levenberg–Marquardt on the z-scored free-run residuals
//!    at measured cells, restarts spent where the starts disagree, standard errors and the
//!    direction the data leave free from [`uncertainty`]); the held-out free runs give the
//!    gap, per measured state its share, free-run (online) and one-step (offline) errors.
//!    The noise floor ([`noise`]) says what a perfect model would score.
//! 2. **Where.** A free correction is added at each `let`, each group of lets sharing an
//!    input and a form ([`graph`]) and each balance ([`locus`]), once seeing the present
//!    only and once a fading memory whose span is chosen from the data ([`memory`]); the
//!    held-out gap it leaves bounds what any mechanism there can achieve. Windows and
//!    regime ([`evaluate`]) say when and where the error lies; a sparse regression
//!    ([`symbolic`]) proposes formulas for the correction.
//! 3. **Which and how far.** Every `effect` is applied alone, all params fitted, and ranked
//!    by held-out gap with a block-bootstrap uncertainty ([`effects`], [`ranking`]); forward
//!    selection ([`selection`]) credits several effects in order while each pays for its
//!    params on held-out data.

mod assemble;
mod correction;
mod effects;
mod error;
mod evaluate;
mod features;
mod graph;
pub mod html;
mod locus;
pub mod memory;
mod ranking;
mod refine;
pub mod render;
mod report;
mod selection;
mod symbolic;

pub use crate::solve::fit::split::MIN_ROWS;
pub use error::DiagnoseError;
pub use report::*;

use crate::check::Checked;
use crate::ir::Model;
use crate::record::Record;
use crate::solve::fit::simulate::{tolerances, Simulator};
use crate::solve::fit::split::{Holdout, Split, Start};
use crate::solve::fit::unknowns::Unknowns;
use crate::solve::fit::{check_fittable, FitError, FitOptions};
use crate::solve::ode::Method;
use ranking::Blocks;
use std::time::Instant;

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
    /// unknowns (`--fit-starts`; else the free runs start at them, as the records spec says).
    pub fit_starts: bool,
    /// Whether to search the loci (free corrections at every let, group and balance; most
    /// of the cost). Without it the report answers which effects and how far only.
    pub locate: bool,
    /// The measurement noise (`ir::merge_noise` of the model's declarations and the
    /// command line's `--noise`); `None`: the model's declarations.
    pub noise: Option<Vec<crate::ir::Noise>>,
    /// Measured rows each part (training, held-out) needs; default [`MIN_ROWS`].
    pub min_rows: usize,
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
            fit_starts: false,
            locate: true,
            noise: None,
            min_rows: MIN_ROWS,
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
    problem: Problem<'a>,
    options: &'a Options,
    model: &'a Model,
    split: Split,
    blocks: Blocks,
    /// How the corrected models of the loci integrate: explicitly where the model's own
    /// free runs never turned stiff (a correction's wild trial values then fail fast, as
    /// they should, instead of being integrated implicitly at great cost), automatically
    /// where they did.
    corrections: Method,
}

impl<'a> Context<'a> {
    /// A seed for task `index`, derived from the user's seed.
    fn seed(&self, index: u64) -> u64 {
        self.options.fitting().task_seed(index)
    }

    /// The unknowns of a fit of `model` (compiled as `simulator`) on the split.
    fn unknowns(&self, model: &Model, simulator: &Simulator) -> Unknowns {
        Unknowns::of(&self.split, model, simulator)
    }
}

/// Runs the whole diagnosis.
pub fn diagnose(
    problem: &Problem,
    options: &Options,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Report, DiagnoseError> {
    let started = Instant::now();
    let mut context = context(problem, options)?;
    let base = Simulator::new(context.model, &[], tolerances())?;
    let stiff = check_runs(&context, &base)?;
    context.corrections = if stiff {
        Method::Auto
    } else {
        Method::Explicit
    };
    progress(Progress::Stage {
        name: "fitting the model",
        total: 1,
    });
    let declared = std::collections::BTreeMap::new();
    let before = effects::fit_and_score(&context, context.model, &declared, context.seed(0))?;
    progress(Progress::Done {
        item: context.model.name.clone(),
        seconds: before.summary.seconds,
    });
    let gap_before = before.gap;
    let mut partial = stopped_while("fitting the model");
    progress(Progress::Stage {
        name: "fitting effects",
        total: context.model.effects.len(),
    });
    let base_params = effects::named(context.model, &before.fitted.x);
    let effects_started = Instant::now();
    let ranking = match partial {
        Some(_) => effects::Ranking::default(),
        None => effects::rank_effects(&context, &before.named, gap_before, progress)?,
    };
    partial = partial.or_else(|| stopped_while("fitting the effects"));
    let effects_seconds = effects_started.elapsed().as_secs_f64();
    let noise = assemble::noise_estimates(&context, &before, &ranking);
    let states = assemble::state_gaps(&context, &base, &before, &noise);
    let noise_floor = assemble::noise_floor(&states);
    let significant = gap_before.is_finite() && gap_before > SIGNIFICANCE * noise_floor;
    progress(Progress::Stage {
        name: "selecting effects",
        total: context.model.effects.len().saturating_sub(1),
    });
    let levels = selection::Levels {
        gap_before,
        noise_floor,
    };
    let selection_started = Instant::now();
    let (selection, credited_fit) = match partial {
        Some(_) => Default::default(),
        None => selection::select(&context, &before, &ranking, levels, progress)?,
    };
    // A selection cut short credits nothing.
    let stopped = stopped_while("selecting effects");
    let (selection, credited_fit) = match stopped {
        Some(_) => Default::default(),
        None => (selection, credited_fit),
    };
    partial = partial.or(stopped);
    let selection_seconds = selection_started.elapsed().as_secs_f64();
    let loci_started = Instant::now();
    // Without a significant gap there is nothing to locate.
    let (taus, located) = if options.locate && significant && partial.is_none() {
        let taus = memory_time_constants(&context, &base, &before.fitted.x);
        let gaps = (gap_before, noise_floor);
        let located = locus::locate(&context, &before.fitted.x, &taus, gaps, progress)?;
        (taus, located)
    } else {
        (Vec::new(), locus::Located::default())
    };
    let loci_seconds = loci_started.elapsed().as_secs_f64();
    let (located, partial) = match partial.or_else(|| stopped_while("locating the gap")) {
        Some(note) => (locus::Located::default(), Some(note)),
        None => (located, None),
    };
    let memory = assemble::memory(&located, &ranking, &selection, (levels, &taus));
    let hints = match (&located.along, located.loci.first()) {
        (Some(along), Some(best)) if significant && !memory.history_needed => {
            symbolic::hints(along, &correction_name(best))
        }
        _ => Vec::new(),
    };
    let after = credited_fit.as_ref().or(ranking.fits.first());
    let after_name = match &credited_fit {
        Some(_) => selection.credited.join(" + "),
        None => ranking
            .scores
            .first()
            .map_or(String::new(), |s| s.name.clone()),
    };
    let series = assemble::series(&context, &before, after.map(|a| (a, after_name)));
    let (windows, regime) = assemble::where_and_when(&context, &before);
    let mut states = states;
    states.sort_by(|a, b| b.share.total_cmp(&a.share));
    Ok(Report {
        model: context.model.name.clone(),
        gap_before,
        gap_before_per_state: assemble::mean_over_states(&states),
        noise_floor,
        significant,
        states,
        history_dependent: memory.history_needed,
        memory,
        locus: located.loci,
        windows,
        regime,
        credited: selection.credited.first().cloned(),
        effects: ranking.scores,
        selection,
        confidence: ranking.confidence,
        hints,
        fitted_params: base_params,
        base_fit: before.summary.clone(),
        initial_states: assemble::initial_states(&context, &base, &before.fitted.x),
        split: assemble::split_summary(&context),
        timing: Timing {
            total: started.elapsed().as_secs_f64(),
            base_fit: before.summary.seconds,
            effects: effects_seconds,
            selection: selection_seconds,
            loci: loci_seconds,
            jobs: rayon::current_num_threads(),
        },
        series,
        partial,
    })
}

/// Where a stop asked for ([`crate::stop`]) left the diagnosis, in words, when one was.
fn stopped_while(phase: &str) -> Option<String> {
    crate::stop::requested().then(|| {
        format!(
            "stopped (Ctrl-C or SIGTERM) while {phase}; the fits of that phase ended at their \
             best so far and the later phases did not run, so nothing here is a verdict"
        )
    })
}

/// What the correction at a locus is, in words.
fn correction_name(locus: &Locus) -> String {
    match locus.kind {
        LocusKind::Balance => format!("correction of d{}/dt", locus.name),
        _ => format!("correction of {}", locus.name),
    }
}

/// The history's time constants: from the median row spacing up to the span (the user's,
/// or chosen from the residuals of the fitted model's training free runs).
fn memory_time_constants(context: &Context, base: &Simulator, x: &[f64]) -> Vec<f64> {
    let split = &context.split;
    let step = memory::median_step(split);
    let span = context.options.span.unwrap_or_else(|| {
        let mut simulator = base.clone();
        simulator.set_params(x);
        let fitted = &x[simulator.params().min(x.len())..];
        let runs: Vec<_> = (split.training())
            .map(|(index, record, rows)| {
                let overrides = split.overrides(index, fitted, simulator.hidden_count());
                simulator.free_run(record, &overrides, rows.end).ok()
            })
            .collect();
        memory::span_from_residuals(split, &runs)
    });
    memory::time_constants(step, span, context.options.dim)
}

fn context<'a>(problem: &Problem<'a>, options: &'a Options) -> Result<Context<'a>, DiagnoseError> {
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
    if options.fit_starts {
        split.fit_measured_starts(model);
    }
    split.declare_noise(options.noise.as_deref().unwrap_or(&model.noise));
    Ok(Context {
        problem: *problem,
        options,
        model,
        blocks: Blocks::new(&split),
        split,
        corrections: Method::Auto,
    })
}

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

/// The model must run on every experiment with its declared params.
/// Whether the model's free runs at its declared values succeed (an error if not), and
/// whether any of them turned stiff.
fn check_runs(context: &Context, base: &Simulator) -> Result<bool, DiagnoseError> {
    let mut simulator = base.clone();
    let declared = context.unknowns(context.model, base).defaults;
    simulator.set_params(&declared);
    let fitted = &declared[context.model.params.len()..];
    for (index, record) in context.split.records.iter().enumerate() {
        let overrides = context
            .split
            .overrides(index, fitted, simulator.hidden_count());
        simulator
            .free_run(record, &overrides, record.len())
            .map_err(|error| FitError::Unsimulable {
                reason: format!("experiment `{}`: {error}", record.name),
            })?;
    }
    Ok(simulator.implicit_steps() > 0)
}

/// Where a measured state's run starts, in words.
fn origin(start: Start) -> &'static str {
    match start {
        Start::Cell => "measured",
        Start::Declared => "declared",
        Start::Fitted(_) => "fitted",
        Start::CellFitted(_) => "measured, fitted from its cell",
        Start::Fixed(_) => "first measured value",
    }
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_held;
#[cfg(test)]
mod tests_jacobian;
#[cfg(test)]
mod tests_json;
#[cfg(test)]
mod tests_lab;
#[cfg(test)]
mod tests_sets;
