//! The whole diagnosis as a list of steps ([`STEPS`]): fit the model, rank the effects,
//! measure the gap against the noise, select a set of effects, locate the gap; then the
//! report. Each step reads what the ones before it left in [`Findings`]; a new step joins
//! by one entry. A stop asked for ([`crate::stop`]) is handled alike for every step: the
//! step under way ends at its best so far (or, where [`Stop::Discards`], credits nothing),
//! the later ones do not run, and the report says so ([`Report::partial`]).

use super::assemble;
use super::candidates::candidates;
use super::context::{Context, Options, Problem, Progress, SIGNIFICANCE};
use super::effects::{self, Ranking, Scored};
use super::error::DiagnoseError;
use super::locus::{self, Located};
use super::memory;
use super::report::{Locus, LocusKind, Report, Selection, StateGap, Timing};
use super::selection::{self, Levels};
use super::symbolic;
use crate::solve::fit::simulate::{tolerances, Simulator};
use crate::solve::fit::FitError;
use crate::solve::ode::Method;
use std::collections::BTreeMap;
use std::time::Instant;

/// One step of the diagnosis.
struct Step {
    /// The progress bar's stage it opens (none: the step opens its own, or none).
    stage: Option<Stage>,
    /// What a stop does to it.
    stop: Stop,
    /// Runs it.
    run: fn(&mut Findings) -> Result<(), DiagnoseError>,
    /// Where its seconds go in the report.
    timing: fn(&mut Timing, f64),
}

/// A stage of the progress bar.
struct Stage {
    /// What it does.
    name: &'static str,
    /// Its number of items, for the model.
    total: fn(&Context) -> usize,
}

/// What a stop asked for does to a step.
enum Stop {
    /// Nothing: the step is bookkeeping, and runs whatever happened before it.
    Never,
    /// The step does not run after a stop; a stop while it runs (while `phase`, in words)
    /// keeps what it found (its fits ended at their best so far).
    Keeps(&'static str),
    /// As [`Stop::Keeps`], but a stop while it runs throws away what it found (with the
    /// function given): a selection cut short credits nothing, a search of the loci cut
    /// short locates nothing.
    Discards(&'static str, fn(&mut Findings)),
}

/// The steps, in order.
const STEPS: [Step; 5] = [
    Step {
        stage: Some(Stage {
            name: "fitting the model",
            total: |_| 1,
        }),
        stop: Stop::Keeps("fitting the model"),
        run: |findings| findings.fit_model(),
        timing: |_, _| {},
    },
    Step {
        stage: Some(Stage {
            name: "fitting effects",
            total: |context| candidates(context.model, context.options.refit_constants).len(),
        }),
        stop: Stop::Keeps("fitting the effects"),
        run: |findings| findings.rank_effects(),
        timing: |timing, seconds| timing.effects = seconds,
    },
    Step {
        stage: None,
        stop: Stop::Never,
        run: |findings| findings.measure_gap(),
        timing: |_, _| {},
    },
    Step {
        stage: Some(Stage {
            name: "selecting effects",
            total: |context| {
                (candidates(context.model, context.options.refit_constants).len()).saturating_sub(1)
            },
        }),
        stop: Stop::Discards("selecting effects", |findings| findings.forget_selection()),
        run: |findings| findings.select(),
        timing: |timing, seconds| timing.selection = seconds,
    },
    Step {
        stage: None,
        stop: Stop::Discards("locating the gap", |findings| {
            findings.located = Located::default()
        }),
        run: |findings| findings.locate(),
        timing: |timing, seconds| timing.loci = seconds,
    },
];

/// Runs the whole diagnosis.
pub fn diagnose(
    problem: &Problem,
    options: &Options,
    progress: &(dyn Fn(Progress) + Sync),
) -> Result<Report, DiagnoseError> {
    let started = Instant::now();
    let mut findings = Findings::start(problem, options, progress)?;
    for step in &STEPS {
        findings.take(step)?;
    }
    findings.report(started.elapsed().as_secs_f64())
}

/// A diagnosis under way: the context the steps share and what they have found so far.
struct Findings<'a> {
    context: Context<'a>,
    /// The model compiled without effects.
    base: Simulator,
    progress: &'a (dyn Fn(Progress) + Sync),
    /// The model's own fit (from the first step on).
    before: Option<Scored>,
    ranking: Ranking,
    /// Each measured state's share of the gap, and the noise floor they give.
    states: Vec<StateGap>,
    noise_floor: f64,
    /// What a correct model's held-out runs add to the noise floor (`None`: unknown).
    held_out_spread: Option<f64>,
    selection: Selection,
    /// The fit of the credited set of effects, if any.
    credited_fit: Option<Scored>,
    /// The time constants of the history features (empty when the loci are not searched).
    taus: Vec<f64>,
    located: Located,
    timing: Timing,
    /// How a stop left the diagnosis, in words.
    partial: Option<String>,
}

impl<'a> Findings<'a> {
    /// The context of `problem`, with the model's free runs at its declared values checked
    /// (they must run) and the corrections' integration chosen from them.
    fn start(
        problem: &Problem<'a>,
        options: &'a Options,
        progress: &'a (dyn Fn(Progress) + Sync),
    ) -> Result<Self, DiagnoseError> {
        let mut context = Context::new(problem, options, progress)?;
        let mut base = Simulator::new(context.model, &[], tolerances())?;
        base.observe(context.model, &context.split.normalisation.observables)?;
        let stiff = check_runs(&context, &base)?;
        context.corrections = if stiff {
            Method::Auto
        } else {
            Method::Explicit
        };
        Ok(Findings {
            context,
            base,
            progress,
            before: None,
            ranking: Ranking::default(),
            states: Vec::new(),
            noise_floor: f64::NAN,
            held_out_spread: None,
            selection: Selection::default(),
            credited_fit: None,
            taus: Vec::new(),
            located: Located::default(),
            timing: Timing::default(),
            partial: None,
        })
    }

    /// Takes `step` as its [`Stop`] says, after a stop or not, and times it.
    fn take(&mut self, step: &Step) -> Result<(), DiagnoseError> {
        if let Some(stage) = &step.stage {
            (self.progress)(Progress::Stage {
                name: stage.name,
                total: (stage.total)(&self.context),
            });
        }
        let started = Instant::now();
        match step.stop {
            Stop::Never => (step.run)(self)?,
            _ if self.partial.is_some() => {}
            Stop::Keeps(phase) => {
                (step.run)(self)?;
                self.partial = stopped_while(phase);
            }
            Stop::Discards(phase, discard) => {
                (step.run)(self)?;
                self.partial = stopped_while(phase);
                if self.partial.is_some() {
                    discard(self);
                }
            }
        }
        (step.timing)(&mut self.timing, started.elapsed().as_secs_f64());
        Ok(())
    }

    /// The model's own fit (every step after the first has it; without it, a step list
    /// out of order, an internal error).
    fn before(&self) -> Result<&Scored, DiagnoseError> {
        (self.before.as_ref())
            .ok_or_else(|| DiagnoseError::internal("a step ran before the model was fitted"))
    }

    /// The gap before and the noise floor (from [`Findings::measure_gap`] on).
    fn levels(&self) -> Result<Levels, DiagnoseError> {
        Ok(Levels {
            gap_before: self.before()?.gap,
            noise_floor: self.noise_floor,
            held_out_floor: self.noise_floor + self.held_out_spread.unwrap_or(0.0),
        })
    }

    /// Whether the gap exceeds the noise floor significantly.
    fn significant(&self) -> Result<bool, DiagnoseError> {
        let levels = self.levels()?;
        Ok(levels.gap_before.is_finite()
            && levels.gap_before > SIGNIFICANCE * levels.held_out_floor)
    }

    /// Fits the model's params (and starts) and scores it.
    fn fit_model(&mut self) -> Result<(), DiagnoseError> {
        let context = &self.context;
        let declared = BTreeMap::new();
        let model = (context.model.name.as_str(), context.model);
        let before = effects::fit_and_score(context, model, &declared, context.seed(0))?;
        (self.progress)(Progress::Done {
            item: context.model.name.clone(),
            seconds: before.summary.seconds,
        });
        self.timing.base_fit = before.summary.seconds;
        self.before = Some(before);
        Ok(())
    }

    /// Fits every effect alone and ranks them.
    fn rank_effects(&mut self) -> Result<(), DiagnoseError> {
        let before = self.before()?;
        let ranking =
            effects::rank_effects(&self.context, &before.named, before.gap, self.progress)?;
        self.ranking = ranking;
        Ok(())
    }

    /// Each measured state's share of the gap and its noise, and the noise floor.
    fn measure_gap(&mut self) -> Result<(), DiagnoseError> {
        let (context, before) = (&self.context, self.before()?);
        let noise = assemble::noise_estimates(context, before, &self.ranking);
        let states = assemble::state_gaps(context, &self.base, before, &noise);
        let spread = assemble::held_out_spread(context, &self.base, before, &states);
        self.noise_floor = assemble::noise_floor(&states);
        self.held_out_spread = spread;
        self.states = states;
        Ok(())
    }

    /// Credits a set of effects by forward selection.
    fn select(&mut self) -> Result<(), DiagnoseError> {
        let (levels, before) = (self.levels()?, self.before()?);
        let context = &self.context;
        (self.selection, self.credited_fit) =
            selection::select(context, before, &self.ranking, levels, self.progress)?;
        Ok(())
    }

    /// A selection cut short credits nothing.
    fn forget_selection(&mut self) {
        (self.selection, self.credited_fit) = Default::default();
    }

    /// Searches the loci, when asked and the gap is significant (else there is nothing to
    /// locate).
    fn locate(&mut self) -> Result<(), DiagnoseError> {
        if !(self.context.options.locate && self.significant()?) {
            return Ok(());
        }
        let x = &self.before()?.fitted.x;
        let taus = memory_time_constants(&self.context, &self.base, x);
        let gaps = (self.before()?.gap, self.noise_floor);
        self.located = locus::locate(&self.context, x, &taus, gaps, self.progress)?;
        self.taus = taus;
        Ok(())
    }

    /// The report of what the steps found, the diagnosis having taken `seconds`.
    fn report(self, seconds: f64) -> Result<Report, DiagnoseError> {
        let context = &self.context;
        let before = self.before()?;
        let (levels, significant) = (self.levels()?, self.significant()?);
        let memory = assemble::memory(
            &self.located,
            &self.ranking,
            &self.selection,
            (levels, &self.taus),
        );
        let hints = match (&self.located.along, self.located.loci.first()) {
            (Some(along), Some(best)) if significant && !memory.history_needed => {
                symbolic::hints(along, &correction_name(best))
            }
            _ => Vec::new(),
        };
        let series = assemble::series(context, before, self.after());
        let (windows, regime) = assemble::where_and_when(context, before);
        let mut states = self.states.clone();
        states.sort_by(|a, b| b.share.total_cmp(&a.share));
        Ok(Report {
            model: context.model.name.clone(),
            gap_before: before.gap,
            gap_before_per_state: assemble::mean_over_states(&states),
            noise_floor: self.noise_floor,
            held_out_spread: self.held_out_spread,
            significant,
            states,
            history_dependent: memory.history_needed,
            memory,
            locus: self.located.loci.clone(),
            windows,
            regime,
            credited: self.selection.credited.first().cloned(),
            effects: self.ranking.scores.clone(),
            selection: self.selection.clone(),
            confidence: self.ranking.confidence.clone(),
            hints,
            fitted_params: effects::named(context.model, &before.fitted.x),
            base_fit: before.summary.clone(),
            initial_states: assemble::initial_states(context, &self.base, &before.fitted.x),
            split: assemble::split_summary(context),
            timing: Timing {
                total: seconds,
                jobs: rayon::current_num_threads(),
                ..self.timing.clone()
            },
            series,
            partial: self.partial.clone(),
        })
    }

    /// The fit the series show after the model's: the credited set's, else the best
    /// effect's, with its name.
    fn after(&self) -> Option<(&Scored, String)> {
        let after = self.credited_fit.as_ref().or(self.ranking.fits.first());
        let name = match &self.credited_fit {
            Some(_) => self.selection.credited.join(" + "),
            None => (self.ranking.scores.first()).map_or(String::new(), |s| s.name.clone()),
        };
        after.map(|a| (a, name))
    }
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

/// Whether the model's free runs at its declared values succeed (an error if not: the
/// model must run on every experiment with its declared params), and whether any of them
/// turned stiff.
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
