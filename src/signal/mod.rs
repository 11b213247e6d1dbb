//! Input programs: piecewise-constant actuator signals (spec section 4: inputs are held
//! constant between switches), written on the command line as `--input NAME=PROGRAM`.
//!
//! # Programs
//!
//! A program is `KIND(ARGUMENTS)`; arguments are `KEY=VALUE` or, in the order listed,
//! positional; values may be double-quoted (for file names with commas or parentheses).
//! `steps` and `chirp` are sampled on the simulation's grid `t_start + k dt` and held
//! between samples (zero-order hold), so the result is always a [`Signal`].
//!
//! - `steps(lo=, hi=, hold=MIN..MAX, seed=)`: random levels drawn uniformly from
//!   `[lo, hi]`, each held for a duration drawn uniformly among the multiples of the
//!   sampling step in `[MIN, MAX]` (model time units), so switches fall on sample times.
//!   `hold=H` means exactly `H`. Defaults: `lo`/`hi` the input's declared bounds (an
//!   error if it declares none), holds of 5 to 40 sampling steps, `seed=0`. The same seed
//!   gives the same signal (ChaCha8 generator).
//! - `const(V)`: the value `V` throughout.
//! - `chirp(lo=, hi=, f0=, f1=, period=)`: a sinusoid between `lo` and `hi` whose
//!   frequency rises *linearly* from `f0` to `f1` over each `period` (then the sweep
//!   restarts). Defaults: the input's bounds, `period` the whole simulated span,
//!   `f0 = 1/period`, `f1 = 1/(10 dt)`. Frequencies (cycles per time unit) must lie in
//!   `[0, 1/(2 dt)]`, the Nyquist range of the grid.
//! - `schedule(T:V, T:V, ...)`: the level `V` from time `T` on, until the next switch;
//!   times strictly increasing, the first at or before the start. Switches fall where they
//!   are written, on the grid or not.
//! - `csv(FILE)`, `csv(FILE, COLUMN)` or `csv(FILE, COLUMN, EXPERIMENT)`: column `COLUMN`
//!   (default: the input's name) of a data file read by the rules of [`crate::data`], as
//!   an input of a record: times at any spacing, a value at the experiment's first row,
//!   then each given value held until the next (empty and `NA` cells hold the last one).
//!   A file with an experiment column and several experiments needs `experiment=NAME`
//!   (the third argument); a file of one experiment needs none. The file must start at or
//!   before the simulation and, its last row held for one more interval (its last time
//!   step or the sampling step, the longer), reach its end. Relative paths are relative to
//!   the working directory.
//!
//! `schedule` and `csv` switch at their own times; the others on the grid. A signal breaks
//! only where its value changes. Every level (given, defaulted or read) must lie within
//! the input's declared bounds.

mod csv;
mod error;
mod generate;
mod parse;
mod piecewise;
mod program;

pub use error::{ArgumentSource, SignalError};
#[cfg(test)]
pub use generate::DEFAULT_HOLD_STEPS;
pub use piecewise::Signal;

use crate::ir::Input;
use crate::suggest::did_you_mean;
use generate::{Context, Grid};
use miette::{NamedSource, SourceSpan};
use program::Kind;
use std::sync::Arc;

/// A parsed input program, ready to be sampled for an input on a time grid.
#[derive(Debug, Clone)]
pub struct Program {
    source: ArgumentSource,
    #[cfg(test)]
    span: SourceSpan,
    kind_name: &'static str,
    kind_span: SourceSpan,
    kind: Kind,
}

impl Program {
    /// The program as written.
    #[cfg(test)]
    pub fn text(&self) -> &str {
        let start = self.span.offset();
        &self.source.inner()[start..start + self.span.len()]
    }

    /// Samples the program for `input` from `t_start` to `t_end` with sampling step `dt`.
    pub fn generate(
        &self,
        input: &Input,
        t_start: f64,
        t_end: f64,
        dt: f64,
    ) -> Result<Signal, SignalError> {
        let context = Context {
            source: &self.source,
            kind_name: self.kind_name,
            kind_span: self.kind_span,
            input,
            grid: Grid::new(t_start, t_end, dt)?,
        };
        match &self.kind {
            Kind::Steps { levels, hold, seed } => context.steps(levels, *hold, *seed),
            Kind::Const(value) => context.constant(*value),
            Kind::Chirp {
                levels,
                f0,
                f1,
                period,
            } => context.chirp(levels, *f0, *f1, *period),
            Kind::Csv {
                file,
                column,
                experiment,
            } => context.csv(&csv::CsvSource {
                file,
                column: column.as_ref(),
                experiment: experiment.as_ref(),
            }),
            Kind::Schedule(switches) => context.schedule(switches),
        }
    }
}

/// Parses a program such as `steps(hold=5..40, seed=2)`.
pub fn parse_program(text: &str) -> Result<Program, SignalError> {
    let source = Arc::new(NamedSource::new("--input", text.to_string()));
    program_at(&source, 0)
}

/// One `--input NAME=PROGRAM` argument.
#[derive(Debug, Clone)]
pub struct InputArgument {
    /// The input's name.
    pub name: String,
    /// Where the name lies in the argument.
    pub name_span: SourceSpan,
    /// Its program.
    pub program: Program,
}

impl InputArgument {
    /// The model input this argument names, or an error suggesting the closest one.
    pub fn resolve<'model>(&self, inputs: &'model [Input]) -> Result<&'model Input, SignalError> {
        if let Some(input) = inputs.iter().find(|input| input.name == self.name) {
            return Ok(input);
        }
        let names: Vec<&str> = inputs.iter().map(|input| input.name.as_str()).collect();
        let help = if names.is_empty() {
            "the model declares no inputs".to_string()
        } else {
            did_you_mean(&self.name, &names, "the model's inputs")
        };
        Err(SignalError::UnknownInput {
            src: self.program.source.clone(),
            span: self.name_span,
            name: self.name.clone(),
            help,
        })
    }
}

/// Splits and parses a `NAME=PROGRAM` argument, e.g. `u=steps(lo=0, hi=1)`.
pub fn parse_input_argument(argument: &str) -> Result<InputArgument, SignalError> {
    let source = Arc::new(NamedSource::new("--input", argument.to_string()));
    let name_start = argument.len() - argument.trim_start().len();
    let name_length = parse::identifier_length(&argument[name_start..]);
    let after_name = &argument[name_start + name_length..];
    let Some(program_text) = after_name
        .trim_start()
        .strip_prefix('=')
        .filter(|_| name_length > 0)
    else {
        let span_end = if name_length > 0 {
            name_start + name_length
        } else {
            argument.len()
        };
        return Err(SignalError::NotAnAssignment {
            src: source,
            span: SourceSpan::new(name_start.into(), span_end - name_start),
            found: argument.to_string(),
        });
    };
    let program = program_at(&source, argument.len() - program_text.len())?;
    Ok(InputArgument {
        name: argument[name_start..name_start + name_length].to_string(),
        name_span: SourceSpan::new(name_start.into(), name_length),
        program,
    })
}

/// Parses the program starting at byte `start` of the argument.
fn program_at(source: &ArgumentSource, start: usize) -> Result<Program, SignalError> {
    let bound = parse::parse_bound(source, start)?;
    let (kind_name, kind_span) = (bound.name, bound.span);
    let kind = program::typed(source, bound)?;
    Ok(Program {
        source: source.clone(),
        #[cfg(test)]
        span: written_span(source, start),
        kind_name,
        kind_span,
        kind,
    })
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_csv;

/// Where the program starting at `start` lies in the argument, blanks around it left out.
#[cfg(test)]
fn written_span(source: &ArgumentSource, start: usize) -> SourceSpan {
    let text = source.inner();
    let program_start = start + (text.len() - start - text[start..].trim_start().len());
    let program_end = text.trim_end().len().max(program_start);
    SourceSpan::new(program_start.into(), program_end - program_start)
}
