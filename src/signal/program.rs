//! Typed programs: the bound arguments of each kind turned into numbers, ranges and paths.

use super::error::{ArgumentSource, SignalError};
use super::parse::{Bound, Piece};
use miette::SourceSpan;

/// A number as written, with where.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Number {
    pub value: f64,
    pub span: SourceSpan,
}

/// Optional level bounds (`lo`, `hi`); absent ones default to the input's bounds.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Levels {
    pub lo: Option<Number>,
    pub hi: Option<Number>,
}

/// A hold-time range in model time units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Hold {
    pub min: f64,
    pub max: f64,
    pub span: SourceSpan,
}

/// The typed arguments of a program.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Kind {
    /// `steps(lo, hi, hold, seed)`.
    Steps {
        levels: Levels,
        hold: Option<Hold>,
        seed: u64,
    },
    /// `const(value)`.
    Const(Number),
    /// `chirp(lo, hi, f0, f1, period)`.
    Chirp {
        levels: Levels,
        f0: Option<Number>,
        f1: Option<Number>,
        period: Option<Number>,
    },
    /// `csv(file, column, experiment)`.
    Csv {
        file: Piece,
        column: Option<Piece>,
        experiment: Option<Piece>,
    },
    /// `schedule(T:V, ...)`: levels from given times on, times strictly increasing.
    Schedule(Vec<Switch>),
}

/// One switch of a schedule: `level` from `time` on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Switch {
    pub time: f64,
    pub level: f64,
    /// Where `T:V` is written.
    pub span: SourceSpan,
}

/// Seed of `steps` when none is given.
pub(super) const DEFAULT_SEED: u64 = 0;

/// Turns bound arguments into a typed program.
pub(super) fn typed(source: &ArgumentSource, bound: Bound) -> Result<Kind, SignalError> {
    let mut values = bound.values.into_iter();
    let mut next = || values.next().flatten();
    let missing = |key: &'static str, example: &str| SignalError::MissingArgument {
        src: source.clone(),
        span: bound.span,
        program: bound.name,
        key,
        reason: String::new(),
        help: format!("write e.g. `{example}`"),
    };
    Ok(match bound.name {
        "steps" => Kind::Steps {
            levels: levels(source, next(), next())?,
            hold: next().map(|piece| hold(source, &piece)).transpose()?,
            seed: next()
                .map(|piece| seed(source, &piece))
                .transpose()?
                .unwrap_or(DEFAULT_SEED),
        },
        "const" => {
            let value = next().ok_or_else(|| missing("value", "const(0.5)"))?;
            Kind::Const(number(source, &value, "value")?)
        }
        "chirp" => Kind::Chirp {
            levels: levels(source, next(), next())?,
            f0: optional_number(source, next(), "f0")?,
            f1: optional_number(source, next(), "f1")?,
            period: optional_number(source, next(), "period")?,
        },
        "csv" => Kind::Csv {
            file: next().ok_or_else(|| missing("file", "csv(inputs.csv)"))?,
            column: next(),
            experiment: next(),
        },
        _ => Kind::Schedule(schedule(source, values.flatten())?),
    })
}

/// The switches of a schedule, their times strictly increasing.
fn schedule(
    source: &ArgumentSource,
    pieces: impl Iterator<Item = Piece>,
) -> Result<Vec<Switch>, SignalError> {
    let mut switches: Vec<Switch> = Vec::new();
    for piece in pieces {
        let parsed = piece.text.split_once(':').and_then(|(time, level)| {
            Some((parse_finite(time.trim())?, parse_finite(level.trim())?))
        });
        let Some((time, level)) = parsed else {
            return Err(bad_number(
                source,
                &piece,
                "schedule",
                "a switch `T:V` (a time and a level)",
                "write each switch as the time it starts at and its level, e.g. `10:0.5`",
            ));
        };
        if let Some(previous) = switches.last().filter(|previous| previous.time >= time) {
            return Err(SignalError::ScheduleOrder {
                src: source.clone(),
                span: piece.span,
                previous_span: previous.span,
                time,
                previous: previous.time,
            });
        }
        switches.push(Switch {
            time,
            level,
            span: piece.span,
        });
    }
    Ok(switches)
}

fn levels(
    source: &ArgumentSource,
    lo: Option<Piece>,
    hi: Option<Piece>,
) -> Result<Levels, SignalError> {
    Ok(Levels {
        lo: optional_number(source, lo, "lo")?,
        hi: optional_number(source, hi, "hi")?,
    })
}

fn optional_number(
    source: &ArgumentSource,
    piece: Option<Piece>,
    key: &'static str,
) -> Result<Option<Number>, SignalError> {
    piece.map(|piece| number(source, &piece, key)).transpose()
}

/// A finite number.
fn number(
    source: &ArgumentSource,
    piece: &Piece,
    key: &'static str,
) -> Result<Number, SignalError> {
    match parse_finite(&piece.text) {
        Some(value) => Ok(Number {
            value,
            span: piece.span,
        }),
        None => Err(bad_number(
            source,
            piece,
            key,
            "a finite number",
            if piece.text.contains(':') {
                "levels from given times on are a schedule: write e.g. \
                 `schedule(0:0.2, 10:0.5, 24:0)`"
            } else {
                "numbers are written like `0.5`, `-2` or `1e-3`"
            },
        )),
    }
}

/// `A..B` or a single duration `H` (meaning `H..H`).
fn hold(source: &ArgumentSource, piece: &Piece) -> Result<Hold, SignalError> {
    let (min, max) = match piece.text.split_once("..") {
        Some((min, max)) => (parse_finite(min.trim()), parse_finite(max.trim())),
        None => {
            let single = parse_finite(&piece.text);
            (single, single)
        }
    };
    match (min, max) {
        (Some(min), Some(max)) => Ok(Hold {
            min,
            max,
            span: piece.span,
        }),
        _ => Err(bad_number(
            source,
            piece,
            "hold",
            "a duration range `MIN..MAX`",
            "write e.g. `hold=5..40` (model time units) or `hold=10` for a fixed hold",
        )),
    }
}

/// A whole number from 0 to 2^64 - 1.
fn seed(source: &ArgumentSource, piece: &Piece) -> Result<u64, SignalError> {
    piece.text.parse::<u64>().map_err(|_| {
        bad_number(
            source,
            piece,
            "seed",
            "a whole number",
            "write e.g. `seed=7`; the same seed gives the same signal",
        )
    })
}

fn parse_finite(text: &str) -> Option<f64> {
    text.parse::<f64>().ok().filter(|value| value.is_finite())
}

fn bad_number(
    source: &ArgumentSource,
    piece: &Piece,
    key: &'static str,
    expected: &'static str,
    help: &'static str,
) -> SignalError {
    SignalError::BadNumber {
        src: source.clone(),
        span: piece.span,
        key,
        expected,
        found: piece.text.clone(),
        help,
    }
}
