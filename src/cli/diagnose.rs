//! `gbc diagnose SIM.gbm REAL.csv [--test TEST.csv]`: where a mechanistic model misses
//! the data, which of its candidate effects causes it, and how far it shrinks (spec
//! section 5; method in `docs/diagnose.md`). Text on stdout, optionally `--json` and
//! `--html` reports.

use super::{CommandError, CommandResult};
use crate::diagnose::{self, Options, Problem, Progress};
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Mutex;

/// Arguments of `gbc diagnose`.
#[derive(Debug, clap::Args)]
pub struct DiagnoseArgs {
    /// The mechanistic model (no closures); its `effect`s are the candidates.
    pub model: PathBuf,
    /// The measured record: `t`, the model's inputs and measured states.
    pub data: PathBuf,
    /// A separate held-out record (otherwise the last part of DATA is held out).
    #[arg(long, value_name = "TEST.csv")]
    pub test: Option<PathBuf>,
    /// Fraction of DATA held out when there is no --test.
    #[arg(long, default_value_t = 0.3)]
    pub holdout: f64,
    /// Seed of the random restarts (results are deterministic for a given seed).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Random restarts of each param fit, besides the declared or warm start.
    #[arg(long, default_value_t = 2)]
    pub restarts: usize,
    /// Delay of the history embedding of the corrections (model time units); by default
    /// 2 and 12 sampling steps are both tried.
    #[arg(long)]
    pub delay: Option<f64>,
    /// Lags of the history embedding, the present included.
    #[arg(long, default_value_t = 6)]
    pub dim: usize,
    /// Write the report as JSON (spec section 5 schema) to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write an HTML report with plots to this file.
    #[arg(long, value_name = "FILE")]
    pub html: Option<PathBuf>,
}

/// Runs the diagnosis and prints (and writes) its report.
pub fn run(args: &DiagnoseArgs) -> CommandResult {
    let mut inputs = vec![args.model.as_path(), args.data.as_path()];
    inputs.extend(args.test.as_deref());
    for output in [&args.json, &args.html].into_iter().flatten() {
        crate::io::ensure_not_input(output, &inputs).map_err(CommandError::user)?;
    }
    let name = args.model.display().to_string();
    let source = crate::driver::read_source(&args.model).map_err(|r| vec![r])?;
    let compiled = crate::driver::compile(&name, &source, &[])?;
    let model = &compiled.model;
    let columns: Vec<&str> = (model.inputs.iter().map(|i| i.name.as_str()))
        .chain(model.states.iter().map(|s| s.name.as_str()))
        .collect();
    let minimum = crate::data::MinRows::new(
        2 * diagnose::MIN_ROWS,
        "the diagnosis fits on one part and scores on another",
    );
    let train = crate::data::read(&args.data, &columns, minimum).map_err(CommandError::user)?;
    let test = match &args.test {
        Some(path) => Some(
            crate::data::read(path, &columns, diagnose::MIN_ROWS).map_err(CommandError::user)?,
        ),
        None => None,
    };
    let problem = Problem {
        name: &name,
        source: &source,
        checked: &compiled.checked,
        model,
        train: &train,
        test: test.as_ref(),
    };
    let options = Options {
        holdout: args.holdout,
        restarts: args.restarts,
        seed: args.seed,
        delay: args.delay,
        dim: args.dim,
        ..Options::default()
    };
    let bar = ProgressReporter::new();
    let outcome = diagnose::diagnose(&problem, &options, &|event| bar.update(event));
    bar.finish();
    let report = outcome.map_err(CommandError::user)?;
    print!("{}", diagnose::render::text(&report));
    if let Some(path) = &args.json {
        let json = serde_json::to_string_pretty(&report)
            .map_err(|e| CommandError::Internal(e.to_string()))?;
        crate::io::write_atomic(path, format!("{json}\n").as_bytes())
            .map_err(CommandError::user)?;
    }
    if let Some(path) = &args.html {
        crate::io::write_atomic(path, diagnose::html::page(&report).as_bytes())
            .map_err(CommandError::user)?;
    }
    Ok(())
}

/// A progress bar on stderr, shown only on a terminal.
struct ProgressReporter {
    bar: Mutex<Option<ProgressBar>>,
    visible: bool,
}

impl ProgressReporter {
    fn new() -> Self {
        ProgressReporter {
            bar: Mutex::new(None),
            visible: std::io::stderr().is_terminal(),
        }
    }

    fn update(&self, event: Progress) {
        if !self.visible {
            return;
        }
        let Ok(mut slot) = self.bar.lock() else {
            return;
        };
        match event {
            Progress::Stage { name, total } => {
                if let Some(bar) = slot.take() {
                    bar.finish_and_clear();
                }
                let bar = ProgressBar::new(total as u64);
                if let Ok(style) =
                    ProgressStyle::with_template("{msg:>20} [{bar:30}] {pos}/{len} {elapsed}")
                {
                    bar.set_style(style.progress_chars("=> "));
                }
                bar.set_message(name);
                *slot = Some(bar);
            }
            Progress::Item => {
                if let Some(bar) = slot.as_ref() {
                    bar.inc(1);
                }
            }
        }
    }

    fn finish(&self) {
        if let Ok(mut slot) = self.bar.lock() {
            if let Some(bar) = slot.take() {
                bar.finish_and_clear();
            }
        }
    }
}
