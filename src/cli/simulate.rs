//! `gbc simulate MODEL --t-end T --dt H -o OUT.csv`: integrate a model without closures
//! and write the sampled record as CSV; with `--weights RUN_DIR`, a what-if run of a trained
//! model. The work is [`crate::api::simulate`]: noise (`--noise`), ranges (`--range`),
//! initial values (`--init`), fitted params (`--params`) and effects (`--effect`) are its
//! spec's fields; this file parses the flags and prints notes, warnings and progress.

#[cfg(test)]
mod tests_inputs;

use super::progress::{Announce, Count, Reporter};
use super::{CommandError, CommandResult};
use crate::api::{SimulateEvent, SimulateSpec};
use crate::solve::ode::Tolerances;
use std::path::{Path, PathBuf};

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
    #[arg(long = "range", value_name = "NAME=LO..HI", value_parser = parse_range)]
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
    #[arg(long, value_name = "N", default_value_t = crate::solve::ode::DEFAULT_MAX_STEPS)]
    pub max_steps: usize,
    /// Integration method: `auto` (explicit Dormand–Prince, Radau IIA where the balances
    /// turn stiff), `explicit` or `implicit`.
    #[arg(long, value_name = "METHOD", default_value = "auto", value_parser = parse_method)]
    pub integrator: crate::solve::ode::Method,
}

/// `--integrator auto|explicit|implicit`.
fn parse_method(text: &str) -> Result<crate::solve::ode::Method, String> {
    use crate::solve::ode::Method;
    match text {
        "auto" => Ok(Method::Auto),
        "explicit" => Ok(Method::Explicit),
        "implicit" => Ok(Method::Implicit),
        other => Err(format!(
            "expected `auto`, `explicit` or `implicit`, found `{other}`"
        )),
    }
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

/// `NAME=LO..HI` (either side may be left out).
fn parse_range(argument: &str) -> Result<(String, f64, f64), String> {
    let expected = || format!("expected NAME=LO..HI (e.g. `S=0..50`), found `{argument}`");
    let (name, bounds) = argument.split_once('=').ok_or_else(expected)?;
    let (lo, hi) = bounds.split_once("..").ok_or_else(expected)?;
    let bound = |text: &str, open: f64| match text.trim() {
        "" => Ok(open),
        text => (text.parse::<f64>().ok().filter(|v| !v.is_nan())).ok_or_else(expected),
    };
    let (lo, hi) = (bound(lo, f64::NEG_INFINITY)?, bound(hi, f64::INFINITY)?);
    if lo >= hi {
        return Err(format!("expected LO below HI in `{argument}`"));
    }
    Ok((name.trim().to_string(), lo, hi))
}

impl SimulateArgs {
    /// The API's spec of these arguments.
    pub(crate) fn spec(&self) -> SimulateSpec {
        SimulateSpec {
            t_end: self.t_end,
            dt: self.dt,
            t_start: self.t_start,
            weights: self.weights.clone(),
            band: self.band,
            history: self.history.clone(),
            columns: self.columns.columns.clone(),
            init: self.init.clone(),
            params: self.params.clone(),
            inputs: self.inputs.clone(),
            warmup: self.warmup,
            noise: self.noise.clone(),
            seed: self.seed,
            ranges: self.ranges.clone(),
            hidden: self.hidden,
            tolerances: Tolerances {
                rtol: self.rtol,
                atol: self.atol,
            },
            max_steps: self.max_steps,
            integrator: self.integrator,
            jobs: None,
        }
    }
}

/// Simulates the model and writes the record.
pub fn run(args: &SimulateArgs) -> CommandResult {
    let mut inputs: Vec<&Path> = vec![&args.model];
    inputs.extend(args.history.as_deref());
    inputs.extend(args.params.as_deref());
    crate::io::ensure_not_input(&args.output, &inputs).map_err(CommandError::user)?;
    let model = crate::api::Model::from_file_with_effects(&args.model, &args.effects)?;
    // The stage starts before the warm-up; its total is known from the first sample on.
    let reporter = Reporter::new();
    let simulation =
        crate::api::simulate(&model, &args.spec(), &mut |event| show(&reporter, event))?;
    simulation.write_csv(&args.output)?;
    Ok(())
}

/// Prints a simulation's event on stderr: notes, warnings, the progress of its samples.
fn show(reporter: &Reporter, event: SimulateEvent) {
    match event {
        SimulateEvent::Note(note) => eprintln!("note: {note}"),
        SimulateEvent::Warning(warning) => eprintln!("warning: {warning}"),
        SimulateEvent::Started => {
            reporter.stage("simulating", 0, Count::Items("samples"), Announce::IfSlow)
        }
        SimulateEvent::Samples { done, total } => {
            if done == 1 {
                reporter.set_total(total as u64);
            }
            if done.is_multiple_of(1024) || done == total {
                reporter.update(done as u64, String::new());
            }
        }
        SimulateEvent::Finished => reporter.finish(),
        SimulateEvent::Members { members, jobs } => {
            eprintln!("running {members} members ({jobs} at once)")
        }
    }
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
        assert!(parse_range("S=5..1").is_err() && parse_range("S=a..1").is_err());
        assert_eq!(
            parse_range(" X = ..2"),
            Ok(("X".into(), f64::NEG_INFINITY, 2.0))
        );
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
}
