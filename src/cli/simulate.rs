//! `gbc simulate MODEL --t-end T --dt H -o OUT.csv`: integrate a model without closures
//! and write the sampled record as CSV; with `--weights RUN_DIR`, a what-if run of a trained
//! model ([`whatif`]).
//!
//! Columns: `t`, the inputs, the measured states, the hidden states (with `--hidden`), then
//! the outputs. `--noise SPEC` adds measurement noise ([`noise`]): `--noise 0.01` perturbs
//! the measured states relatively, `y * (1 + 0.01 N(0, 1))`, `--noise declared` by the
//! model's `noise` declarations, `--noise X=4%+0.01` one quantity by the combined model;
//! drawn row by row from a ChaCha8 generator seeded with `--seed`; hidden states and
//! outputs without noise stay exact. `--init X=V` replaces a state's declared
//! initial value; `--params FILE` sets the params to those `gbc train` or `gbc diagnose`
//! fitted ([`params`]); `--effect NAME` applies a candidate effect before lowering.

mod noise;
mod params;
mod range;
mod whatif;

#[cfg(test)]
mod tests_inputs;

use super::progress::{Announce, Count, Reporter};
use super::{CommandError, CommandResult};
use crate::ir::Model;
use crate::signal::Signal;
use crate::sim::{SimOptions, Tolerances, Trajectory};
use miette::Diagnostic;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Arguments of `gbc simulate`.
#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// The model file (with closures only with --weights).
    pub model: PathBuf,
    /// Time of the last sample.
    #[arg(long, allow_negative_numbers = true)]
    pub t_end: f64,
    /// Sampling step (also the step of a `next` model; with --weights, default: the run's
    /// step).
    #[arg(long, allow_negative_numbers = true)]
    pub dt: Option<f64>,
    /// The CSV file to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Time of the first sample (default 0; with --history, its last row).
    #[arg(long, allow_negative_numbers = true)]
    pub t_start: Option<f64>,
    /// A trained run (`gbc train -o DIR`): free-run the trained model (a what-if run).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["params", "noise", "warmup"])]
    pub weights: Option<PathBuf>,
    /// With --weights of an ensemble run: the level of the prediction band (`X_lo`, `X_hi`).
    #[arg(long, value_name = "LEVEL", default_value_t = crate::ensemble::DEFAULT_LEVEL)]
    pub band: f64,
    /// With --weights: measured data before the start (its rows up to --t-start are the
    /// history the embedding reads; its row at --t-start is the initial state).
    #[arg(long, value_name = "FILE", requires = "weights")]
    pub history: Option<PathBuf>,
    /// How the history's columns are named.
    #[command(flatten)]
    pub columns: super::data::ColumnArgs,
    /// An initial value, `NAME=VALUE` (a measured or hidden state; repeatable).
    #[arg(long = "init", value_name = "NAME=VALUE", value_parser = parse_init)]
    pub init: Vec<(String, f64)>,
    /// Params fitted by `gbc train` (run.json or `--json` file) or `gbc diagnose --json`.
    #[arg(long, value_name = "FILE")]
    pub params: Option<PathBuf>,
    /// Apply a candidate effect of the model before simulating (repeatable).
    #[arg(long = "effect", value_name = "NAME")]
    pub effects: Vec<String>,
    /// An input programme, `NAME=PROGRAM`, e.g. `u=steps(hold=5..40, seed=1)` (one per
    /// input).
    ///
    /// Programmes, each held between its switches:
    /// `steps(lo=, hi=, hold=MIN..MAX, seed=)` random levels in [lo, hi] (default: the
    /// input's declared bounds), each held for a random multiple of the step between MIN and
    /// MAX (model time; default 5 to 40 steps; `hold=H` exactly H); `const(V)` the value V;
    /// `chirp(lo=, hi=, f0=, f1=, period=)` a sine between lo and hi whose frequency rises
    /// linearly from f0 to f1 over each period, sampled on the grid t_start + k dt;
    /// `schedule(T:V, T:V, ...)` the level V from time T on; `csv(FILE)`,
    /// `csv(FILE, COLUMN)` or `csv(FILE, COLUMN, experiment=NAME)` a data column (default:
    /// the input's name) read as a record's input: any time spacing, empty cells hold the
    /// last value, `experiment=` picks one experiment of a file that has several.
    /// Arguments are KEY=VALUE or positional in the order shown (docs/language.md).
    #[arg(long = "input", value_name = "NAME=PROGRAM")]
    pub inputs: Vec<String>,
    /// Settle this long at the first input values before recording.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub warmup: f64,
    /// Measurement noise of the record (repeatable): `0.01` (1 % relative on every measured
    /// state, and on outputs that declare noise), `declared` (the model's `noise`
    /// declarations), `X=4%+0.01` (one state or output: 4 % of the value and 0.01 in its
    /// unit, sigma = sqrt(0.01^2 + (0.04 X)^2)), `3%`, `0%+0.02`; specs replace the
    /// declarations per quantity, `X=0` removes one. Gaussian, drawn with --seed.
    #[arg(
        long = "noise",
        value_name = "SPEC",
        allow_negative_numbers = true,
        value_parser = crate::ir::parse_noise_spec
    )]
    pub noise: Vec<crate::ir::NoiseSpec>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Bounds of a measured state, `NAME=LO..HI` (repeatable; `..HI`, `LO..` for one
    /// side): the run stops before the first sample outside them, with a warning saying
    /// where and why. Without it only a value that is not finite ends a run (with
    /// `--weights`, the run's range from its training data applies instead).
    #[arg(long = "range", value_name = "NAME=LO..HI", value_parser = range::parse_range)]
    pub ranges: Vec<(String, f64, f64)>,
    /// Also write the hidden states (a what-if run, `--weights`, always does).
    #[arg(long)]
    pub hidden: bool,
    /// Relative tolerance of the integrator.
    #[arg(long, default_value = "1e-9", allow_negative_numbers = true)]
    pub rtol: f64,
    /// Absolute tolerance of the integrator.
    #[arg(long, default_value = "1e-12", allow_negative_numbers = true)]
    pub atol: f64,
    /// Most integration steps in the whole run before it stops with an error that names the
    /// fastest balance.
    #[arg(long, value_name = "N", default_value_t = crate::sim::DEFAULT_MAX_STEPS)]
    pub max_steps: usize,
    /// Integration method: `auto` (explicit Dormand–Prince, Radau IIA where the balances
    /// turn stiff), `explicit` or `implicit`.
    #[arg(long, value_name = "METHOD", default_value = "auto", value_parser = parse_method)]
    pub integrator: crate::sim::Method,
}

/// `--integrator auto|explicit|implicit`.
fn parse_method(text: &str) -> Result<crate::sim::Method, String> {
    use crate::sim::Method;
    match text {
        "auto" => Ok(Method::Auto),
        "explicit" => Ok(Method::Explicit),
        "implicit" => Ok(Method::Implicit),
        other => Err(format!(
            "expected `auto`, `explicit` or `implicit`, found `{other}`"
        )),
    }
}

/// A problem with the arguments of `gbc simulate` itself.
#[derive(Debug, Clone, PartialEq, Error, Diagnostic)]
pub enum SimulateError {
    /// An input of the model has no `--input` program.
    #[error("input `{name}` has no program")]
    #[diagnostic(
        code(gbm::E0709),
        help(
            "give it one, e.g. `--input {name}=steps(hold=5..40)` or `--input {name}=const(0.5)`"
        )
    )]
    MissingInput {
        /// The input.
        name: String,
    },
    /// Two `--input` arguments name the same input.
    #[error("input `{name}` has two programs")]
    #[diagnostic(code(gbm::E0710), help("keep one `--input {name}=...`"))]
    DuplicateInput {
        /// The input.
        name: String,
    },
    /// `--range` names no measured state of the model.
    #[error("expected a measured state of the model in `--range`, found `{name}`")]
    #[diagnostic(code(gbm::E0718), help("{states}"))]
    UnknownRangeState {
        /// The name given.
        name: String,
        /// The measured states, with a suggestion.
        states: String,
    },
    /// `--init` names no state of the model.
    #[error("expected a state of the model in `--init`, found `{name}`")]
    #[diagnostic(code(gbm::E0715), help("{states}"))]
    UnknownInitState {
        /// The name given.
        name: String,
        /// The states, with a suggestion.
        states: String,
    },
    /// The params file cannot be used.
    #[error("cannot read params from `{path}`: {reason}")]
    #[diagnostic(
        code(gbm::E0716),
        help(
            "pass the run.json of `gbc train -o DIR` (or its `--json` file) or the file of \
             `gbc diagnose --json`"
        )
    )]
    BadParams {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// The history holds several experiments.
    #[error("expected one experiment in the history `{path}`, found {found}")]
    #[diagnostic(
        code(gbm::E0717),
        help("pass a file with one experiment, or one without an experiment column")
    )]
    SeveralHistories {
        /// The file.
        path: String,
        /// Experiments found.
        found: usize,
    },
}

/// `NAME=VALUE` with a number.
fn parse_init(argument: &str) -> Result<(String, f64), String> {
    let (name, value) = argument
        .split_once('=')
        .ok_or_else(|| format!("expected NAME=VALUE (e.g. `X=0.2`), found `{argument}`"))?;
    let value: f64 = value
        .trim()
        .parse()
        .map_err(|_| format!("expected a number after `=`, found `{}`", value.trim()))?;
    if !value.is_finite() {
        return Err(format!("expected a finite initial value, found `{value}`"));
    }
    Ok((name.trim().to_string(), value))
}

/// The `--init` values in the model's state order (measured, then hidden).
fn initial_values(model: &Model, init: &[(String, f64)]) -> Result<Vec<Option<f64>>, CommandError> {
    let names: Vec<&str> = (model.states.iter().chain(&model.hidden))
        .map(|s| s.name.as_str())
        .collect();
    let mut values = vec![None; names.len()];
    for (name, value) in init {
        let index = names.iter().position(|n| n == name).ok_or_else(|| {
            CommandError::user(SimulateError::UnknownInitState {
                name: name.clone(),
                states: crate::suggest::did_you_mean(name, &names, "states"),
            })
        })?;
        values[index] = Some(*value);
    }
    Ok(values)
}

/// Simulates the model and writes the record.
pub fn run(args: &SimulateArgs) -> CommandResult {
    let mut inputs: Vec<&Path> = vec![&args.model];
    inputs.extend(args.history.as_deref());
    inputs.extend(args.params.as_deref());
    crate::io::ensure_not_input(&args.output, &inputs).map_err(CommandError::user)?;
    let effects: Vec<&str> = args.effects.iter().map(String::as_str).collect();
    let mut model = crate::driver::compile_file(&args.model, &effects)?.model;
    if let Some(weights) = &args.weights {
        return whatif::run(&model, weights, args);
    }
    if let Some(path) = &args.params {
        for note in params::apply(&mut model, path, &effects)? {
            eprintln!("note: {note}");
        }
    }
    let noise = noise::record_noise(&model, &args.noise)?;
    let range = range::simulation_range(&model, &args.ranges)?;
    let t_start = args.t_start.unwrap_or(0.0);
    let dt = args.dt.ok_or_else(missing_dt)?;
    let signals = input_signals(&model, args, (t_start, args.t_end, dt))?;
    let options = SimOptions {
        t_start,
        warmup: args.warmup,
        tolerances: Tolerances {
            rtol: args.rtol,
            atol: args.atol,
        },
        initial: initial_values(&model, &args.init)?,
        max_steps: args.max_steps,
        method: args.integrator,
        ..SimOptions::new(args.t_end, dt)
    };
    // The stage starts before the warm-up; its total is known from the first sample on.
    let reporter = Reporter::new();
    reporter.stage("simulating", 0, Count::Items("samples"), Announce::IfSlow);
    let mut progress = |done: usize, total: usize| {
        if done == 1 {
            reporter.set_total(total as u64);
        }
        if done.is_multiple_of(1024) || done == total {
            reporter.update(done as u64, String::new());
        }
    };
    let simulated = crate::sim::simulate_with_progress(&model, &signals, &options, &mut progress);
    reporter.finish();
    let mut trajectory = simulated.map_err(CommandError::user)?;
    range::stop_outside(&model, &mut trajectory, &range);
    noise::add_noise(&mut trajectory, &noise, args.seed);
    let table = csv_table(&model, &trajectory, args.hidden, &args.output)?;
    crate::io::write_atomic(&args.output, &table).map_err(CommandError::user)?;
    Ok(())
}

/// `--dt` is needed without `--weights`.
fn missing_dt() -> CommandError {
    CommandError::user(crate::sim::SimError::Options(
        "expected --dt (the sampling step), found none".into(),
    ))
}

/// One signal per model input, from the `--input` programs, sampled on the grid
/// `t_start + k dt` up to `t_end`.
fn input_signals(
    model: &Model,
    args: &SimulateArgs,
    (t_start, t_end, dt): (f64, f64, f64),
) -> Result<Vec<Signal>, CommandError> {
    let mut programs = vec![None; model.inputs.len()];
    let mut reports = Vec::new();
    // Inputs whose program was given but is defective: reported once, not also as missing.
    let mut defective: Vec<&str> = Vec::new();
    for text in &args.inputs {
        let parsed = crate::signal::parse_input_argument(text).and_then(|argument| {
            let input = argument.resolve(&model.inputs)?;
            Ok((input.name.clone(), argument.program))
        });
        match parsed {
            Ok((name, program)) => {
                let index = model.inputs.iter().position(|i| i.name == name);
                if let Some(Some(_)) = index.map(|index| programs[index].replace(program)) {
                    reports.push(report(SimulateError::DuplicateInput { name }));
                }
            }
            Err(error) => {
                defective.extend(text.split_once('=').map(|(name, _)| name.trim()));
                reports.push(report(error));
            }
        }
    }
    let mut signals = Vec::with_capacity(model.inputs.len());
    for (input, program) in model.inputs.iter().zip(&programs) {
        let Some(program) = program else {
            if defective.contains(&input.name.as_str()) {
                continue;
            }
            reports.push(report(SimulateError::MissingInput {
                name: input.name.clone(),
            }));
            continue;
        };
        match program.generate(input, t_start, t_end, dt) {
            Ok(signal) => signals.push(signal),
            Err(error) => reports.push(report(error)),
        }
    }
    if reports.is_empty() {
        Ok(signals)
    } else {
        Err(CommandError::User(reports))
    }
}

fn report(diagnostic: impl Diagnostic + Send + Sync + 'static) -> miette::Report {
    miette::Report::new(diagnostic)
}

/// The record as CSV text: `t`, inputs, measured states, hidden states (if asked), outputs.
fn csv_table<'a>(
    model: &'a Model,
    trajectory: &'a Trajectory,
    with_hidden: bool,
    path: &Path,
) -> Result<Vec<u8>, CommandError> {
    let named = |names: Vec<&'a String>, values: &'a [Vec<f64>]| {
        names.into_iter().zip(values.iter().map(Vec::as_slice))
    };
    let mut columns: Vec<(&String, &[f64])> = Vec::new();
    columns.extend(named(
        model.inputs.iter().map(|i| &i.name).collect(),
        &trajectory.inputs,
    ));
    columns.extend(named(
        model.states.iter().map(|s| &s.name).collect(),
        &trajectory.states,
    ));
    if with_hidden {
        columns.extend(named(
            model.hidden.iter().map(|s| &s.name).collect(),
            &trajectory.hidden,
        ));
    }
    columns.extend(named(
        model.outputs.iter().map(|o| &o.name).collect(),
        &trajectory.outputs,
    ));
    let mut named: Vec<(&str, &[f64])> = vec![("t", &trajectory.times)];
    named.extend(
        columns
            .iter()
            .map(|(name, values)| (name.as_str(), *values)),
    );
    let found = crate::finite::in_table(&named);
    crate::finite::refuse(path, found, crate::data::NOT_FINITE_HELP).map_err(CommandError::user)?;
    let header = std::iter::once("t").chain(columns.iter().map(|(name, _)| name.as_str()));
    let failed = |error: csv::Error| {
        CommandError::Internal(format!("cannot format `{}`: {error}", path.display()))
    };
    let mut writer = csv::Writer::from_writer(Vec::new());
    writer.write_record(header).map_err(failed)?;
    for (k, &t) in trajectory.times.iter().enumerate() {
        let row = std::iter::once(format_time(t))
            .chain(columns.iter().map(|(_, column)| format!("{:?}", column[k])));
        writer.write_record(row).map_err(failed)?;
    }
    writer.into_inner().map_err(|error| {
        CommandError::Internal(format!("cannot format `{}`: {error}", path.display()))
    })
}

/// A sample time without the rounding noise of `t_start + k dt` (12 significant digits).
fn format_time(t: f64) -> String {
    let rounded: f64 = format!("{t:.11e}").parse().unwrap_or(t);
    format!("{rounded:?}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::ScratchDir;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Command {
        #[command(flatten)]
        args: SimulateArgs,
    }

    fn chemostat_path() -> String {
        concat!(env!("CARGO_MANIFEST_DIR"), "/models/mm_chemostat/truth.gbm").to_string()
    }

    /// Parses `gbc simulate` arguments for the chemostat truth model writing to `output`.
    fn args(output: &Path, extra: &[&str]) -> SimulateArgs {
        let output = output.display().to_string();
        let model = chemostat_path();
        let mut words = vec!["simulate", model.as_str(), "--t-end", "20", "--dt", "1"];
        words.extend(["-o", output.as_str()]);
        words.extend(extra);
        Command::try_parse_from(words).unwrap().args
    }

    fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
        let mut reader = csv::Reader::from_path(path).unwrap();
        let header = reader.headers().unwrap().iter().map(String::from).collect();
        let rows = reader
            .records()
            .map(|row| row.unwrap().iter().map(|v| v.parse().unwrap()).collect())
            .collect();
        (header, rows)
    }

    /// The chemostat's steady substrate level at inlet enzyme `e0`.
    fn steady_substrate(e0: f64) -> f64 {
        let (s0, theta, kcat, k_m) = (3e-2, 20.0, 0.14, 1.5e-2);
        let b = k_m - s0 + theta * kcat * e0;
        (-b + (b * b + 4.0 * s0 * k_m).sqrt()) / 2.0
    }

    #[test]
    fn default_tolerances_are_the_library_defaults() {
        let parsed = args(Path::new("out.csv"), &[]);
        assert_eq!(parsed.rtol, Tolerances::default().rtol);
        assert_eq!(parsed.atol, Tolerances::default().atol);
    }

    #[test]
    fn writes_columns_in_order_from_the_settled_state() {
        let scratch = ScratchDir::new("simulate-columns").unwrap();
        let output = scratch.join("chemostat.csv");
        let extra = ["--input", "E0=const(0.01)", "--warmup", "2000", "--hidden"];
        run(&args(&output, &extra)).unwrap();
        let (header, rows) = read_csv(&output);
        assert_eq!(header, ["t", "E0", "S", "E", "P", "r_true"]);
        assert_eq!(rows.len(), 21);
        let steady = steady_substrate(0.01);
        for (k, row) in rows.iter().enumerate() {
            assert_eq!(row[0], k as f64);
            assert_eq!(row[1], 0.01);
            assert!((row[2] / steady - 1.0).abs() < 1e-8, "S = {}", row[2]);
            assert!((row[3] / 0.01 - 1.0).abs() < 1e-8, "E = {}", row[3]);
            assert!((row[4] - (3e-2 - row[2])).abs() < 1e-15);
        }
    }

    #[test]
    fn noise_is_relative_seeded_and_on_measured_states_only() {
        let scratch = ScratchDir::new("simulate-noise").unwrap();
        let clean = scratch.join("clean.csv");
        let noisy = scratch.join("noisy.csv");
        let again = scratch.join("again.csv");
        let input = ["--input", "E0=steps(hold=3..6, seed=4)", "--hidden"];
        run(&args(&clean, &input)).unwrap();
        let with_noise =
            |seed: &'static str| [&input[..], &["--noise", "0.01", "--seed", seed]].concat();
        run(&args(&noisy, &with_noise("9"))).unwrap();
        run(&args(&again, &with_noise("9"))).unwrap();
        let (_, clean) = read_csv(&clean);
        let (_, noisy) = read_csv(&noisy);
        assert_eq!(noisy, read_csv(&again).1, "same seed, same record");
        let mut changed = 0;
        for (c, n) in clean.iter().zip(&noisy) {
            assert_eq!((c[0], c[1], c[3], c[4]), (n[0], n[1], n[3], n[4]));
            let relative = n[2] / c[2] - 1.0;
            assert!(relative.abs() < 0.06, "relative deviation {relative}");
            changed += usize::from(relative != 0.0);
        }
        assert_eq!(changed, clean.len());
    }

    fn codes(error: CommandError) -> Vec<String> {
        match error {
            CommandError::User(reports) => reports
                .iter()
                .filter_map(|r| r.code().map(|c| c.to_string()))
                .collect(),
            CommandError::Internal(message) => vec![message],
        }
    }

    #[test]
    fn input_programs_must_cover_each_input_once() {
        let scratch = ScratchDir::new("simulate-inputs").unwrap();
        let output = scratch.join("never.csv");
        let missing = run(&args(&output, &[])).unwrap_err();
        assert_eq!(codes(missing), ["gbm::E0709"]);
        let twice = ["--input", "E0=const(0.01)", "--input", "E0=const(0.02)"];
        assert_eq!(
            codes(run(&args(&output, &twice)).unwrap_err()),
            ["gbm::E0710"]
        );
        let noise = [
            "--input",
            "E0=const(0.01)",
            "--noise",
            "S=1%",
            "--noise",
            "S=2%",
        ];
        assert_eq!(
            codes(run(&args(&output, &noise)).unwrap_err()),
            ["gbm::E0135"]
        );
        let negative = [
            "simulate", "m.gbm", "--t-end", "1", "--dt", "1", "-o", "o.csv",
        ];
        let refused = Command::try_parse_from([&negative[..], &["--noise", "-1"]].concat());
        let message = refused.err().map(|e| e.to_string()).unwrap_or_default();
        assert!(
            message.contains("expected a finite noise level >= 0, found `-1`"),
            "{message}"
        );
        assert!(!output.exists());
    }

    #[test]
    fn an_output_that_goes_non_finite_is_refused_naming_where() {
        let scratch = ScratchDir::new("simulate-nan").unwrap();
        let model = scratch.join("decay.gbm");
        let source = "model decay\nstate x = 1\noutput y = sqrt(x - 0.5)\nder x = -x\n";
        std::fs::write(&model, source).unwrap();
        let output = scratch.join("decay.csv");
        let (model, out) = (model.display().to_string(), output.display().to_string());
        let words = [
            "simulate", &model, "--t-end", "2", "--dt", "0.25", "-o", &out,
        ];
        let error = run(&Command::try_parse_from(words).unwrap().args).unwrap_err();
        let CommandError::User(reports) = &error else {
            panic!("expected a user error, found {error:?}");
        };
        let message = reports[0].to_string();
        assert_eq!(codes(error), ["gbm::E0253"]);
        // x = e^-t falls below 0.5 after t = ln 2 = 0.69: the first sample past it.
        assert!(
            message.contains("`y` = NaN at t = 0.75 (row 4)"),
            "{message}"
        );
        assert!(!output.exists(), "nothing is written");
    }

    #[test]
    fn sample_times_print_without_rounding_noise() {
        assert_eq!(format_time(3.0 * 0.1), "0.3");
        assert_eq!(format_time(1799.0), "1799.0");
        assert_eq!(format_time(-2.5e-7), "-2.5e-7");
    }
}
