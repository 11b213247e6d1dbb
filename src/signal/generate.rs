//! Sampling a typed program into a [`Signal`] on a simulation's time grid.

use super::error::{ArgumentSource, SignalError};
use super::piecewise::Signal;
use super::program::{Hold, Levels, Number, Switch};
use crate::ir::Input;
use miette::SourceSpan;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// The most sampling intervals a program may generate.
pub const MAX_SAMPLES: usize = 10_000_000;

/// Hold of `steps` without `hold=`, in sampling steps (both ends included).
pub const DEFAULT_HOLD_STEPS: (usize, usize) = (5, 40);

/// The sampling grid `t_start + k dt`, `k = 0..intervals`, covering `[t_start, t_end]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Grid {
    pub t_start: f64,
    pub t_end: f64,
    pub dt: f64,
    pub intervals: usize,
}

impl Grid {
    /// Checks the span and step, and counts the intervals (the last one may reach past
    /// `t_end` by less than a step).
    pub fn new(t_start: f64, t_end: f64, dt: f64) -> Result<Grid, SignalError> {
        let bad = |expected: &str, found: String| SignalError::BadHorizon {
            expected: expected.to_string(),
            found,
        };
        if !(t_start.is_finite() && t_end.is_finite() && t_end > t_start) {
            return Err(bad(
                "an end time after the start time",
                format!("{t_start} to {t_end}"),
            ));
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(bad("a positive sampling step", format!("{dt}")));
        }
        let count = ((t_end - t_start) / dt - 1e-9).ceil().max(1.0);
        if count > MAX_SAMPLES as f64 {
            return Err(bad(
                &format!("at most {MAX_SAMPLES} sampling steps"),
                format!("{count} steps of {dt} from {t_start} to {t_end}"),
            ));
        }
        Ok(Grid {
            t_start,
            t_end,
            dt,
            intervals: count as usize,
        })
    }

    /// The time of grid point `k`.
    pub fn time(&self, k: usize) -> f64 {
        self.t_start + k as f64 * self.dt
    }
}

/// What every generator needs: the argument (for labels), the input and the grid.
pub(super) struct Context<'a> {
    pub source: &'a ArgumentSource,
    /// The program's kind (`steps`, ...).
    pub kind_name: &'static str,
    /// Where the kind is written: the label of errors about defaulted arguments.
    pub kind_span: SourceSpan,
    pub input: &'a Input,
    pub grid: Grid,
}

impl Context<'_> {
    /// A constant level, checked against the input's bounds.
    pub fn constant(&self, value: Number) -> Result<Signal, SignalError> {
        self.within(value.value, value.span, String::new())?;
        Ok(Signal::constant(self.grid.t_start, value.value))
    }

    /// Random levels uniform in `[lo, hi]`, each held for a whole number of sampling steps
    /// drawn uniformly from the hold range (in steps), so that switches fall on the grid.
    pub fn steps(
        &self,
        levels: &Levels,
        hold: Option<Hold>,
        seed: u64,
    ) -> Result<Signal, SignalError> {
        let (lo, hi) = self.levels(levels)?;
        let (shortest, longest) = self.hold_steps(hold)?;
        let mut random = ChaCha8Rng::seed_from_u64(seed);
        let mut breaks = Vec::new();
        let mut values = Vec::new();
        let mut k = 0;
        while k < self.grid.intervals {
            breaks.push(self.grid.time(k));
            let fraction: f64 = random.gen();
            values.push((lo * (1.0 - fraction) + hi * fraction).clamp(lo, hi));
            k = k.saturating_add(random.gen_range(shortest..=longest));
        }
        Signal::new(breaks, values)
    }

    /// A linear chirp between `lo` and `hi`: `mid + amp sin(2 pi (f0 s + (f1 - f0) s^2 /
    /// (2 period)))` with `s` the time since the start modulo `period`, so the frequency
    /// rises linearly from `f0` to `f1` over each period; sampled on the grid and held.
    pub fn chirp(
        &self,
        levels: &Levels,
        f0: Option<Number>,
        f1: Option<Number>,
        period: Option<Number>,
    ) -> Result<Signal, SignalError> {
        let (lo, hi) = self.levels(levels)?;
        let grid = self.grid;
        let period = self.chirp_period(period)?;
        let f0 = self.frequency(f0, "f0", 1.0 / period)?;
        let f1 = self.frequency(f1, "f1", 0.1 / grid.dt)?;
        // Halved before adding, so that levels near the float range cannot overflow.
        let (middle, amplitude) = (0.5 * lo + 0.5 * hi, 0.5 * hi - 0.5 * lo);
        let breaks: Vec<f64> = (0..grid.intervals).map(|k| grid.time(k)).collect();
        let values = (0..grid.intervals)
            .map(|k| {
                let since = (k as f64 * grid.dt) % period;
                let cycles = f0 * since + (f1 - f0) * since * since / (2.0 * period);
                (middle + amplitude * (2.0 * PI * cycles).sin()).clamp(lo, hi)
            })
            .collect();
        Signal::new(breaks, values)
    }

    /// The levels of a schedule from their times on; the first switch at or before the
    /// start (before its time, the first level holds).
    pub fn schedule(&self, switches: &[Switch]) -> Result<Signal, SignalError> {
        let Some(first) = switches.first() else {
            return Signal::new(Vec::new(), Vec::new());
        };
        let slack = 1e-9 * self.grid.dt;
        if first.time > self.grid.t_start + slack {
            return Err(SignalError::ScheduleStart {
                src: self.source.clone(),
                span: first.span,
                t_start: self.grid.t_start,
                first: first.time,
            });
        }
        for switch in switches {
            self.within(switch.level, switch.span, String::new())?;
        }
        let times: Vec<f64> = switches.iter().map(|switch| switch.time).collect();
        let levels: Vec<f64> = switches.iter().map(|switch| switch.level).collect();
        Signal::at_changes(&times, &levels)
    }

    /// The levels: given, or the input's bounds; ordered and within the bounds.
    fn levels(&self, levels: &Levels) -> Result<(f64, f64), SignalError> {
        let lo = self.level(levels.lo, "lo", |(lo, _)| lo)?;
        let hi = self.level(levels.hi, "hi", |(_, hi)| hi)?;
        if lo.value > hi.value {
            return Err(SignalError::LoAboveHi {
                src: self.source.clone(),
                lo_span: lo.span,
                hi_span: hi.span,
                lo: lo.value,
                hi: hi.value,
            });
        }
        self.within(lo.value, lo.span, String::new())?;
        self.within(hi.value, hi.span, String::new())?;
        Ok((lo.value, hi.value))
    }

    /// One level, defaulting to a bound of the input (labelled at the program's name).
    fn level(
        &self,
        given: Option<Number>,
        key: &'static str,
        pick: fn((f64, f64)) -> f64,
    ) -> Result<Number, SignalError> {
        if let Some(number) = given {
            return Ok(number);
        }
        match self.input.bounds {
            Some(bounds) => Ok(Number {
                value: pick(bounds),
                span: self.kind_span,
            }),
            None => Err(SignalError::MissingArgument {
                src: self.source.clone(),
                span: self.kind_span,
                program: self.kind_name,
                key,
                reason: format!(
                    " (input `{}` declares no bounds to default to)",
                    self.input.name
                ),
                help: format!(
                    "give `lo=` and `hi=`, or declare `input {} in [LO, HI]` in the model",
                    self.input.name
                ),
            }),
        }
    }

    /// Checks a value against the input's declared bounds, if any.
    pub(super) fn within(
        &self,
        value: f64,
        span: SourceSpan,
        origin: String,
    ) -> Result<(), SignalError> {
        match self.input.bounds {
            Some((lo, hi)) if value < lo || value > hi => Err(SignalError::OutsideBounds {
                src: self.source.clone(),
                span,
                input: self.input.name.clone(),
                lo,
                hi,
                found: value,
                origin,
            }),
            _ => Ok(()),
        }
    }

    /// The hold range as whole numbers of sampling steps, both ends included.
    fn hold_steps(&self, hold: Option<Hold>) -> Result<(usize, usize), SignalError> {
        let Some(hold) = hold else {
            return Ok(DEFAULT_HOLD_STEPS);
        };
        let bad = |problem: String, help: String| SignalError::BadHold {
            src: self.source.clone(),
            span: hold.span,
            problem,
            help,
        };
        if hold.min <= 0.0 {
            let help = "holds are durations in model time units, e.g. `hold=5..40`".to_string();
            return Err(bad(format!("found a shortest hold of {}", hold.min), help));
        }
        if hold.max < hold.min {
            let help = "write the shorter duration first: `hold=MIN..MAX`".to_string();
            return Err(bad(
                format!("found the empty range {}..{}", hold.min, hold.max),
                help,
            ));
        }
        let dt = self.grid.dt;
        let shortest = (hold.min / dt - 1e-9).ceil().max(1.0);
        let longest = (hold.max / dt + 1e-9).floor();
        if longest < shortest {
            return Err(bad(
                format!(
                    "found {}..{}, which holds no multiple of the sampling step {dt}",
                    hold.min, hold.max
                ),
                format!(
                    "switches fall on sample times: widen the range to include a multiple of {dt}"
                ),
            ));
        }
        Ok((shortest as usize, longest as usize))
    }

    /// The sweep period: given and positive, or the whole horizon.
    fn chirp_period(&self, period: Option<Number>) -> Result<f64, SignalError> {
        let Some(period) = period else {
            return Ok(self.grid.t_end - self.grid.t_start);
        };
        if period.value > 0.0 {
            return Ok(period.value);
        }
        Err(SignalError::BadFrequency {
            src: self.source.clone(),
            span: period.span,
            key: "period",
            expected: "a positive duration".to_string(),
            found: period.value,
            help: "the period is the duration of one sweep from f0 to f1".to_string(),
        })
    }

    /// A frequency from 0 to the Nyquist frequency `1 / (2 dt)` of the grid.
    fn frequency(
        &self,
        given: Option<Number>,
        key: &'static str,
        default: f64,
    ) -> Result<f64, SignalError> {
        let (value, span) = given.map_or((default, self.kind_span), |n| (n.value, n.span));
        let nyquist = 0.5 / self.grid.dt;
        if (0.0..=nyquist).contains(&value) {
            return Ok(value);
        }
        Err(SignalError::BadFrequency {
            src: self.source.clone(),
            span,
            key,
            expected: format!("a frequency from 0 to the Nyquist frequency 1/(2 dt) = {nyquist}"),
            found: value,
            help: format!(
                "a sampling step of {} resolves frequencies up to {nyquist}; give `{key}=` in cycles per time unit",
                self.grid.dt
            ),
        })
    }
}
