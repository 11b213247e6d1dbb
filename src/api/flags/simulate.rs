//! The flags of `gbc simulate` ([`SimulateArgs`]) and the simulation they ask for.

use std::path::PathBuf;

use super::data::ColumnArgs;
use crate::api::SimulateSpec;
use crate::solve::ode::Tolerances;

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
    pub columns: ColumnArgs,
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
    pub fn spec(&self) -> SimulateSpec {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_parse_with_either_side_left_out() {
        assert!(parse_range("S=5..1").is_err() && parse_range("S=a..1").is_err());
        assert_eq!(
            parse_range(" X = ..2"),
            Ok(("X".into(), f64::NEG_INFINITY, 2.0))
        );
    }
}
