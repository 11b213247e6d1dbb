//! Defects of an input program (`--input NAME=PROGRAM`), labelled in the argument's text.

use crate::data::DataError;
use miette::{Diagnostic, NamedSource, SourceSpan};
use std::sync::Arc;
use thiserror::Error;

/// The text of one `--input` argument, shared by every diagnostic about it.
pub type ArgumentSource = Arc<NamedSource<String>>;

/// A defect of an input program, or of a signal built from one.
#[derive(Debug, Clone, Error, Diagnostic)]
pub enum SignalError {
    /// The argument is not `NAME=PROGRAM`.
    #[error("expected `NAME=PROGRAM`, found `{found}`")]
    #[diagnostic(
        code(gbm::E0301),
        help("name the input, then its program, e.g. `u=steps(hold=5..40)`")
    )]
    NotAnAssignment {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The part that should be a name followed by `=`.
        #[label("expected an input name and `=`")]
        span: SourceSpan,
        /// The argument text.
        found: String,
    },
    /// The name is not an input of the model.
    #[error("expected the name of an input of the model, found `{name}`")]
    #[diagnostic(code(gbm::E0302))]
    UnknownInput {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The name.
        #[label("not an input")]
        span: SourceSpan,
        /// The name given.
        name: String,
        /// The model's inputs, with a suggestion.
        #[help]
        help: String,
    },
    /// The program text is malformed.
    #[error("expected {expected}, found {found}")]
    #[diagnostic(code(gbm::E0303))]
    Syntax {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// Where.
        #[label("here")]
        span: SourceSpan,
        /// What would have been accepted.
        expected: String,
        /// What was there.
        found: String,
        /// How to write it.
        #[help]
        help: String,
    },
    /// No program has this name.
    #[error("expected an input program, found `{name}`")]
    #[diagnostic(code(gbm::E0304))]
    UnknownProgram {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The name.
        #[label("unknown program")]
        span: SourceSpan,
        /// The name given.
        name: String,
        /// The programs, with a suggestion.
        #[help]
        help: String,
    },
    /// The program has no argument of this name.
    #[error("expected an argument of `{program}`, found `{key}`")]
    #[diagnostic(code(gbm::E0305))]
    UnknownKey {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The key.
        #[label("unknown argument")]
        span: SourceSpan,
        /// The program.
        program: &'static str,
        /// The key given.
        key: String,
        /// The program's keys, with a suggestion.
        #[help]
        help: String,
    },
    /// The same argument twice.
    #[error("argument `{key}` given twice")]
    #[diagnostic(code(gbm::E0306), help("give each argument once"))]
    DuplicateKey {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The second occurrence.
        #[label("again here")]
        span: SourceSpan,
        /// The first occurrence.
        #[label("first here")]
        first_span: SourceSpan,
        /// The key.
        key: &'static str,
    },
    /// A positional argument where none is accepted.
    #[error("unexpected argument `{found}` to `{program}`")]
    #[diagnostic(code(gbm::E0307))]
    UnexpectedArgument {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The argument.
        #[label("unexpected")]
        span: SourceSpan,
        /// The program.
        program: &'static str,
        /// The argument's text.
        found: String,
        /// The accepted form.
        #[help]
        help: String,
    },
    /// A value that is not the number (or range, or whole number) expected.
    #[error("expected {expected} for `{key}`, found `{found}`")]
    #[diagnostic(code(gbm::E0308))]
    BadNumber {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The value.
        #[label("not {expected}")]
        span: SourceSpan,
        /// The key.
        key: &'static str,
        /// What was expected, e.g. "a finite number".
        expected: &'static str,
        /// The value's text.
        found: String,
        /// An example.
        #[help]
        help: &'static str,
    },
    /// A needed argument is absent.
    #[error("expected an argument `{key}` for `{program}`, found none{reason}")]
    #[diagnostic(code(gbm::E0309))]
    MissingArgument {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The program.
        #[label("`{key}` missing")]
        span: SourceSpan,
        /// The program.
        program: &'static str,
        /// The missing key.
        key: &'static str,
        /// Why it cannot default, e.g. " (input `u` declares no bounds)"; may be empty.
        reason: String,
        /// How to supply it.
        #[help]
        help: String,
    },
    /// The lower level is above the upper one.
    #[error("expected `lo` <= `hi`, found lo = {lo} and hi = {hi}")]
    #[diagnostic(code(gbm::E0310), help("swap the two values"))]
    LoAboveHi {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The lower level (or the program, where it defaults to a bound).
        #[label("lo = {lo}")]
        lo_span: SourceSpan,
        /// The upper level (or the program, where it defaults to a bound).
        #[label("hi = {hi}")]
        hi_span: SourceSpan,
        /// The lower level.
        lo: f64,
        /// The upper level.
        hi: f64,
    },
    /// The hold range is empty, non-positive, or holds no multiple of the sampling step.
    #[error("expected a hold range of positive durations, {problem}")]
    #[diagnostic(code(gbm::E0311))]
    BadHold {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The range.
        #[label("this hold range")]
        span: SourceSpan,
        /// What is wrong, as "found ...".
        problem: String,
        /// How to fix it.
        #[help]
        help: String,
    },
    /// A level outside the input's declared bounds.
    #[error(
        "expected values of input `{input}` within its bounds [{lo}, {hi}], found {found}{origin}"
    )]
    #[diagnostic(
        code(gbm::E0312),
        help("choose values within the bounds declared by `input {input} in [{lo}, {hi}]`")
    )]
    OutsideBounds {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The offending value.
        #[label("outside [{lo}, {hi}]")]
        span: SourceSpan,
        /// The input.
        input: String,
        /// Its lower bound.
        lo: f64,
        /// Its upper bound.
        hi: f64,
        /// The value.
        found: f64,
        /// Where the value came from, e.g. " in `u.csv` row 7" (empty for a literal).
        origin: String,
    },
    /// A chirp frequency or period that cannot be sampled.
    #[error("expected {expected} for `{key}`, found {found}")]
    #[diagnostic(code(gbm::E0313))]
    BadFrequency {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The value (or the program, where it defaults).
        #[label("this {key}")]
        span: SourceSpan,
        /// The key.
        key: &'static str,
        /// The accepted range, in words.
        expected: String,
        /// The value.
        found: f64,
        /// How to fix it.
        #[help]
        help: String,
    },
    /// The CSV file does not cover the simulated time span.
    #[error("expected `{file}` to cover t = {t_start} to {t_end}, found t = {first} to {last}")]
    #[diagnostic(
        code(gbm::E0314),
        help("the file's first row must be at or before the start, and its last row, held for one more interval (its last time step or the sampling step, the longer), must reach the end")
    )]
    CsvCoverage {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The file name.
        #[label("this file")]
        span: SourceSpan,
        /// The file.
        file: String,
        /// Simulation start.
        t_start: f64,
        /// Simulation end.
        t_end: f64,
        /// The file's first time.
        first: f64,
        /// The file's last time.
        last: f64,
    },
    /// The time span or sampling step asked of a program is unusable.
    #[error("expected {expected}, found {found}")]
    #[diagnostic(
        code(gbm::E0315),
        help("check the simulation's start, end and sampling step")
    )]
    BadHorizon {
        /// What was expected.
        expected: String,
        /// What was given.
        found: String,
    },
    /// The switches of a schedule out of time order.
    #[error("expected switch times in increasing order, found {time} after {previous}")]
    #[diagnostic(
        code(gbm::E0317),
        help("write the switches of `schedule(T:V, ...)` in time order, each time once")
    )]
    ScheduleOrder {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The switch out of order.
        #[label("at t = {time}")]
        span: SourceSpan,
        /// The switch before it.
        #[label("after t = {previous}")]
        previous_span: SourceSpan,
        /// Its time.
        time: f64,
        /// The time of the switch before it.
        previous: f64,
    },
    /// A schedule whose first switch comes after the start of the simulation.
    #[error("expected the first switch at or before the start t = {t_start}, found t = {first}")]
    #[diagnostic(
        code(gbm::E0318),
        help("a schedule gives the level from its first switch on: begin with `{t_start}:V`")
    )]
    ScheduleStart {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The first switch.
        #[label("the first switch")]
        span: SourceSpan,
        /// The simulation's start.
        t_start: f64,
        /// The time of the first switch.
        first: f64,
    },
    /// A `csv(...)` file of several experiments, none of them chosen.
    #[error("expected one experiment in `{file}`, found {count}: {names}")]
    #[diagnostic(code(gbm::E0319))]
    CsvSeveralExperiments {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The file name.
        #[label("{count} experiments")]
        span: SourceSpan,
        /// The file.
        file: String,
        /// How many experiments it holds.
        count: usize,
        /// Their names, listed.
        names: String,
        /// How to choose one.
        #[help]
        help: String,
    },
    /// `experiment=NAME` names no experiment of the file.
    #[error("expected an experiment of `{file}`, found `{name}`")]
    #[diagnostic(code(gbm::E0320))]
    CsvUnknownExperiment {
        /// The argument.
        #[source_code]
        src: ArgumentSource,
        /// The name given.
        #[label("not an experiment of this file")]
        span: SourceSpan,
        /// The file.
        file: String,
        /// The name given.
        name: String,
        /// The file's experiments, with a suggestion.
        #[help]
        help: String,
    },
    /// Break times and values that do not make a piecewise-constant signal.
    #[error(transparent)]
    #[diagnostic(transparent)]
    InvalidSignal(#[from] crate::error::Bug),
    /// The CSV file of a `csv(...)` program is defective.
    #[error(transparent)]
    #[diagnostic(transparent)]
    Data(#[from] DataError),
}
