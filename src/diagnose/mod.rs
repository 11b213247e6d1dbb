//! Sim-to-real gap diagnosis (`gbc diagnose`, spec section 5): a mechanistic model against
//! measured data. Method and worked example: `docs/diagnose.md`.
//!
//! 1. **Gap.** The model's `param`s are fitted on the training part ([`fit`]: Levenberg–
//!    Marquardt on the z-scored free-run residuals); the held-out free run gives the gap,
//!    per measured state its share, free-run (online) and one-step (offline) errors. The
//!    noise floor ([`noise`]) says what a perfect model would score.
//! 2. **Where.** A free correction is added at each `let` and each balance in turn
//!    ([`locus`]), once seeing the present only and once the measured history; the held-out
//!    gap it leaves bounds what any mechanism there can achieve. Windows and regime
//!    ([`evaluate`]) say when and where the error lies; a sparse regression ([`symbolic`])
//!    proposes formulas for the correction.
//! 3. **Which and how far.** Every `effect` is applied, all params fitted, and the effects
//!    ranked by held-out gap ([`effects`]), refitted on both halves of the training part
//!    for confidence; the two best are also combined.

mod correction;
mod effects;
mod error;
mod evaluate;
mod features;
mod fit;
pub mod html;
mod locus;
mod noise;
mod record;
pub mod render;
mod report;
mod simulate;
mod symbolic;

pub use error::DiagnoseError;
pub use record::{Record, Split, MIN_ROWS};
pub use report::*;

use crate::check::Checked;
use crate::data::Dataset;
use crate::ir::Model;
use record::Normalisation;
use simulate::{tolerances, Simulator};

/// The gap is significant when it exceeds this multiple of the noise floor.
pub const SIGNIFICANCE: f64 = 2.0;
/// The best effect is credited when it removes at least this fraction of the gap above the
/// noise floor (and the gap is significant).
pub const CREDIT: f64 = 0.5;

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
    /// The training record.
    pub train: &'a Dataset,
    /// A separate held-out record; `None` holds out the tail of `train`.
    pub test: Option<&'a Dataset>,
}

/// How to diagnose.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// Fraction of the record held out when there is no separate test record.
    pub holdout: f64,
    /// Random restarts of each fit, besides the declared or warm start.
    pub restarts: usize,
    /// Seed of every random choice.
    pub seed: u64,
    /// Number of time windows of the held-out part.
    pub windows: usize,
    /// Delay of the history embedding of corrections (model time units); `None` tries a
    /// short (2 rows) and a long (12 rows) delay.
    pub delay: Option<f64>,
    /// Number of lags of the history embedding, the present included (>= 2).
    pub dim: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            holdout: 0.3,
            restarts: 2,
            seed: 0,
            windows: 20,
            delay: None,
            dim: 6,
        }
    }
}

/// Progress of a diagnosis, for a progress bar.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// A stage of `total` work items starts.
    Stage {
        /// What it does.
        name: &'static str,
        /// Number of items.
        total: usize,
    },
    /// One item of the current stage is done.
    Item,
}

/// Everything the stages share.
pub struct Context<'a> {
    problem: Problem<'a>,
    options: &'a Options,
    model: &'a Model,
    checked: &'a Checked,
    split: Split,
    normalisation: Normalisation,
}

impl Context<'_> {
    /// A seed for task `index`, derived from the user's seed.
    fn seed(&self, index: u64) -> u64 {
        self.options
            .seed
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(index.wrapping_mul(0xD1B5_4A32_D192_ED03))
    }
}

/// Runs the whole diagnosis.
pub fn diagnose(
    problem: &Problem,
    options: &Options,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Report, DiagnoseError> {
    let context = context(problem, options)?;
    let base = Simulator::new(context.model, None, tolerances())?;
    check_runs(&context, &base)?;
    progress(Progress::Stage {
        name: "fitting the model",
        total: 1,
    });
    let declared = effects::named(context.model, &[]);
    let before = effects::fit_and_score(
        &context,
        context.model,
        &declared,
        effects::Part::Full,
        context.seed(0),
    )?;
    progress(Progress::Item);
    let base_params = effects::named(context.model, &before.fitted.params);
    let gap_before = before.gap;
    let mut fitted = base.clone();
    fitted.set_params(&before.fitted.params);
    let states = state_gaps(&context, &mut fitted, before.run.as_ref())?;
    let noise_floor = states.iter().map(|s| s.noise).sum::<f64>() / states.len().max(1) as f64;
    let significant = gap_before > SIGNIFICANCE * noise_floor;
    progress(Progress::Stage {
        name: "fitting effects",
        total: 3 * context.model.effects.len(),
    });
    let tick = || progress(Progress::Item);
    let ranking = effects::rank_effects(&context, &base_params, gap_before, &tick)?;
    let combined = effects::combine(&context, &ranking.scores, &base_params, gap_before)?;
    let credited = ranking
        .scores
        .first()
        .filter(|best| {
            significant && gap_before - best.gap_after >= CREDIT * (gap_before - noise_floor)
        })
        .map(|best| best.name.clone());
    let lags = locus::history_lags(delay_rows(&context)?, options.dim);
    let gaps = (gap_before, noise_floor);
    let located = locus::locate(&context, &before.fitted.params, &lags, gaps, progress)?;
    let history_dependent = significant && located.history_dependent;
    let hints = match (&located.along, located.loci.first()) {
        (Some(along), Some(best)) if significant => symbolic::hints(along, &correction_name(best)),
        _ => Vec::new(),
    };
    let series = series(&context, before.run.as_ref(), ranking.best_run.as_ref());
    let (windows, regime) = where_and_when(&context, &series);
    let mut states = states;
    states.sort_by(|a, b| b.share.total_cmp(&a.share));
    Ok(Report {
        model: context.model.name.clone(),
        gap_before,
        noise_floor,
        significant,
        states,
        locus: located.loci,
        history_dependent,
        windows,
        regime,
        effects: ranking.scores,
        credited,
        combined,
        confidence: ranking.confidence,
        hints,
        fitted_params: base_params,
        split: split_summary(&context),
        series,
    })
}

/// What the correction at a locus is, in words.
fn correction_name(locus: &Locus) -> String {
    match locus.kind {
        LocusKind::Balance => format!("correction of d{}/dt", locus.name),
        _ => format!("correction of {}", locus.name),
    }
}

/// The history delay in rows, if the user gave one.
fn delay_rows(context: &Context) -> Result<Option<usize>, DiagnoseError> {
    let options = context.options;
    if options.dim < 2 {
        return Err(DiagnoseError::BadOption {
            option: "--dim".into(),
            expected: "at least 2 lags".into(),
            found: options.dim.to_string(),
        });
    }
    let Some(delay) = options.delay else {
        return Ok(None);
    };
    let rows = (delay / context.split.train.step).round();
    if !(rows >= 1.0 && rows.is_finite()) {
        return Err(DiagnoseError::BadOption {
            option: "--delay".into(),
            expected: format!("at least one sampling step ({})", context.split.train.step),
            found: delay.to_string(),
        });
    }
    Ok(Some(rows as usize))
}

fn context<'a>(problem: &Problem<'a>, options: &'a Options) -> Result<Context<'a>, DiagnoseError> {
    let model = problem.model;
    if !model.closures.is_empty() {
        let names: Vec<&str> = model.closures.iter().map(|c| c.name.as_str()).collect();
        return Err(DiagnoseError::HasClosures {
            model: model.name.clone(),
            closures: names.join(", "),
        });
    }
    if !(options.holdout > 0.0 && options.holdout < 1.0) {
        return Err(DiagnoseError::BadOption {
            option: "--holdout".into(),
            expected: "a fraction strictly between 0 and 1".into(),
            found: options.holdout.to_string(),
        });
    }
    let train = Record::from_dataset(model, problem.train)?;
    let split = match problem.test {
        None => Split::tail(train, options.holdout)?,
        Some(test) => {
            let test = Record::from_dataset(model, test)?;
            if ((test.step - train.step) / train.step).abs() > 1e-6 {
                return Err(DiagnoseError::StepMismatch {
                    train: train.step,
                    test: test.step,
                });
            }
            Split::separate(train, test)?
        }
    };
    Ok(Context {
        problem: *problem,
        options,
        model,
        checked: problem.checked,
        normalisation: split.normalisation(),
        split,
    })
}

/// The model must run on both records with its declared params.
fn check_runs(context: &Context, base: &Simulator) -> Result<(), DiagnoseError> {
    let mut simulator = base.clone();
    let declared: Vec<f64> = context.model.params.iter().map(|p| p.init).collect();
    simulator.set_params(&declared);
    for record in [&context.split.train, &context.split.test] {
        simulator
            .free_run(record, record.len())
            .map_err(|error| DiagnoseError::Unsimulable {
                reason: error.to_string(),
            })?;
    }
    Ok(())
}

/// Per measured state: shares, online and offline errors, noise.
fn state_gaps(
    context: &Context,
    fitted: &mut Simulator,
    run: Option<&simulate::Run>,
) -> Result<Vec<StateGap>, DiagnoseError> {
    let (test, rows, norm) = (
        &context.split.test,
        context.split.test_rows.clone(),
        &context.normalisation,
    );
    let online = match run {
        Some(run) => evaluate::state_errors(run, test, rows.clone(), norm),
        None => vec![f64::INFINITY; context.model.states.len()],
    };
    let offline = evaluate::offline_errors(fitted, test, rows, norm)
        .unwrap_or_else(|_| vec![f64::INFINITY; online.len()]);
    let noise = noise::noise_floors(
        &context.split.train.states,
        context.split.train_rows.clone(),
        norm,
    );
    let total: f64 = online.iter().sum();
    Ok((context.model.states.iter().enumerate())
        .map(|(k, state)| StateGap {
            name: state.name.clone(),
            share: if total > 0.0 { online[k] / total } else { 0.0 },
            online: online[k],
            offline: offline[k],
            noise: noise[k],
        })
        .collect())
}

fn series(
    context: &Context,
    before: Option<&simulate::Run>,
    after: Option<&simulate::Run>,
) -> Series {
    let test = &context.split.test;
    let rows = context.split.test_rows.clone();
    let measured = context.model.states.len();
    let columns = |run: &simulate::Run| -> Vec<Vec<f64>> {
        (0..measured)
            .map(|k| (0..run.rows()).map(|row| run.row(row)[k]).collect())
            .collect()
    };
    Series {
        times: test.times[..rows.end].to_vec(),
        first_scored: rows.start,
        names: context
            .model
            .states
            .iter()
            .map(|s| s.name.clone())
            .collect(),
        data: test.states.iter().map(|c| c[..rows.end].to_vec()).collect(),
        before: before.map(columns).unwrap_or_default(),
        after: after.map(columns),
        errors: before
            .map(|run| evaluate::row_errors(run, test, rows, &context.normalisation))
            .unwrap_or_default(),
    }
}

fn where_and_when(context: &Context, series: &Series) -> (Vec<Window>, Vec<Regime>) {
    if series.errors.is_empty() {
        return (Vec::new(), Vec::new());
    }
    let rows = context.split.test_rows.clone();
    let test = &context.split.test;
    let mut found = evaluate::windows(
        &test.times,
        rows.clone(),
        &series.errors,
        context.options.windows,
    );
    let mut covered = 0.0;
    found.retain(|w| {
        let keep = covered < 0.5;
        covered += w.share;
        keep
    });
    let variables: Vec<(String, Vec<f64>)> = (context.model.inputs.iter().map(|i| &i.name))
        .zip(&test.inputs)
        .chain(
            context
                .model
                .states
                .iter()
                .map(|s| &s.name)
                .zip(&test.states),
        )
        .map(|(name, column)| (name.clone(), column[rows.clone()].to_vec()))
        .collect();
    (found, evaluate::regimes(&variables, &series.errors))
}

fn split_summary(context: &Context) -> SplitSummary {
    let rows = context.split.test_rows.clone();
    let times = &context.split.test.times;
    SplitSummary {
        train_rows: context.split.train_rows.len(),
        test_rows: rows.len(),
        t_test_start: times[rows.start],
        t_test_end: times[rows.end - 1],
        separate_test: context.problem.test.is_some(),
    }
}

#[cfg(test)]
mod tests;
