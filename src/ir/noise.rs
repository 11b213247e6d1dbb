//! Measurement noise as plain data: the combined error model of each measured quantity,
//! `sigma(y) = sqrt(absolute^2 + (relative * y)^2)`, from the model's `noise` declarations
//! and the command line's `--noise` specs.
//!
//! `--noise SPEC` (repeatable) means the same in every command: the measurement noise of
//! the record. A spec is `NAME=LEVEL` (one measured state or output), `LEVEL` (every
//! measured quantity not named by another spec) or `declared` (the model's declarations as
//! they are). A level is one or two terms joined by `+`: `4%` (relative) and `0.01`
//! (absolute, in the quantity's unit), e.g. `X=4%+0.01`. A lone number without a name or a
//! `%` is relative, as `gbc simulate --noise 0.01` has always meant (1 %); an absolute
//! level for every quantity is written with a zero relative term, `0%+0.02`. Specs replace
//! the declarations per quantity ([`merge_noise`]); a level of zero removes a quantity's
//! noise.

use super::model::{Measured, Model, Noise, QuantityUnit};
use crate::check::noise::NoiseLevel;
use miette::Diagnostic;
use thiserror::Error;

impl Model {
    /// The name of a measured quantity.
    pub fn measured_name(&self, target: Measured) -> &str {
        match target {
            Measured::State(i) => &self.states[i].name,
            Measured::Output(i) => &self.outputs[i].name,
        }
    }

    /// The measured state or output called `name`.
    pub fn measured_named(&self, name: &str) -> Option<Measured> {
        let state = self.states.iter().position(|s| s.name == name);
        let output = || self.outputs.iter().position(|o| o.name == name);
        state
            .map(Measured::State)
            .or_else(|| output().map(Measured::Output))
    }

    /// The declared noise of a quantity, if any.
    pub fn noise_of(&self, target: Measured) -> Option<&Noise> {
        self.noise.iter().find(|noise| noise.target == target)
    }

    /// The declared standard deviation of a measurement of `target` at value `value`
    /// ([`sigma_of`] over [`Model::noise`]); `None` where the model declares none for it.
    pub fn declared_sigma(&self, target: Measured, value: f64) -> Option<f64> {
        sigma_of(&self.noise, target, value)
    }

    /// The unit of a measured quantity, if the model gives it one.
    pub fn measured_unit(&self, target: Measured) -> Option<&QuantityUnit> {
        self.unit(self.measured_name(target))
    }

    /// What the model alone says is measured: every measured state, and each output that
    /// declares noise (whether an output is measured is otherwise decided by the data's
    /// columns). The quantities a bare `--noise LEVEL` covers in `gbc simulate`.
    pub fn measured(&self) -> Vec<Measured> {
        let states = (0..self.states.len()).map(Measured::State);
        let outputs = (self.noise.iter())
            .map(|noise| noise.target)
            .filter(|target| matches!(target, Measured::Output(_)));
        let mut measured: Vec<Measured> = states.chain(outputs).collect();
        measured.sort_unstable();
        measured.dedup();
        measured
    }
}

/// The standard deviation of a measurement of `target` at value `value` under `noise`
/// (a model's declarations, [`Model::noise`], or what [`merge_noise`] returns):
/// `sqrt(absolute^2 + (relative * value)^2)`, or `None` where `target` has no noise.
pub fn sigma_of(noise: &[Noise], target: Measured, value: f64) -> Option<f64> {
    let level = noise.iter().find(|noise| noise.target == target)?;
    Some(level.sigma(value))
}

/// The checked declarations as IR noise, sorted by quantity (states first).
pub(super) fn lower_noise(levels: &[NoiseLevel], model: &Model) -> Vec<Noise> {
    let mut noise: Vec<Noise> = (levels.iter())
        .filter_map(|level| {
            Some(Noise {
                target: model.measured_named(&level.name)?,
                relative: level.relative,
                absolute: level.absolute,
            })
        })
        .collect();
    noise.sort_by_key(|noise| noise.target);
    noise
}

/// One `--noise` argument, as [`parse_noise_spec`] reads it.
#[derive(Debug, Clone, PartialEq)]
pub enum NoiseSpec {
    /// `declared`: the model's own noise declarations, unchanged.
    Declared,
    /// `X=4%+0.01` (one quantity) or `4%+0.01` (every measured quantity not named).
    Level {
        /// The quantity, or `None` for every measured quantity no other spec names.
        name: Option<String>,
        /// Relative standard deviation, a fraction of the value.
        relative: f64,
        /// Absolute standard deviation, in the quantity's unit.
        absolute: f64,
    },
}

/// Parses a `--noise` argument: `X=4%+0.01`, `S=0.02`, `OD=3%`, `4%`, `0.01` (a lone
/// number is relative: 1 %), `0%+0.02` or `declared`. The message of an error says what
/// was expected and what was found.
pub fn parse_noise_spec(text: &str) -> Result<NoiseSpec, String> {
    let text = text.trim();
    if text == "declared" {
        return Ok(NoiseSpec::Declared);
    }
    let (name, level) = match text.split_once('=') {
        Some((name, level)) => (Some(spec_name(name.trim())?), level.trim()),
        None => (None, text),
    };
    let lone_number = name.is_none() && split_terms(level).len() == 1 && !level.ends_with('%');
    let (relative, absolute) = spec_level(level)?;
    let (relative, absolute) = if lone_number {
        (absolute, 0.0)
    } else {
        (relative, absolute)
    };
    Ok(NoiseSpec::Level {
        name,
        relative,
        absolute,
    })
}

/// The name before `=`: a model name (letters, digits and `_`, not starting with a digit).
fn spec_name(name: &str) -> Result<String, String> {
    let mut chars = name.chars();
    let starts = chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_');
    if starts && chars.all(|c| c.is_ascii_alphanumeric() || c == '_') {
        Ok(name.to_string())
    } else {
        Err(format!(
            "expected the name of a measured state or output before `=`, found `{name}`"
        ))
    }
}

/// The relative (fraction) and absolute terms of a level such as `4%+0.01`.
fn spec_level(level: &str) -> Result<(f64, f64), String> {
    if level.is_empty() {
        return Err(format!(
            "expected a noise level such as `4%`, `0.01` or `4%+0.01`, found `{level}`"
        ));
    }
    let (mut relative, mut absolute) = (None, None);
    for term in split_terms(level) {
        let (number, slot, kind) = match term.strip_suffix('%') {
            Some(number) => (number.trim(), &mut relative, "relative"),
            None => (term, &mut absolute, "absolute"),
        };
        let value: f64 = number.parse().map_err(|_| {
            format!("expected a number in the noise level `{level}`, found `{number}`")
        })?;
        if !value.is_finite() || value < 0.0 {
            let within = if term == level {
                String::new()
            } else {
                format!(" in `{level}`")
            };
            return Err(format!(
                "expected a finite noise level >= 0, found `{term}`{within}"
            ));
        }
        let value = if kind == "relative" {
            value / 100.0
        } else {
            value
        };
        if slot.replace(value).is_some() {
            return Err(format!(
                "expected at most one {kind} term in `{level}`, found two (write `4%+0.01`)"
            ));
        }
    }
    Ok((relative.unwrap_or(0.0), absolute.unwrap_or(0.0)))
}

/// The terms of a level, split at each `+` that is not an exponent's sign (`1e+3`).
fn split_terms(level: &str) -> Vec<&str> {
    let bytes = level.as_bytes();
    let mut terms = Vec::new();
    let mut start = 0;
    for (index, &byte) in bytes.iter().enumerate() {
        let exponent = index > 0 && matches!(bytes[index - 1], b'e' | b'E');
        if byte == b'+' && !exponent {
            terms.push(level[start..index].trim());
            start = index + 1;
        }
    }
    terms.push(level[start..].trim());
    terms
}

/// A `--noise` spec that does not fit the model.
#[derive(Debug, Clone, PartialEq, Error, Diagnostic)]
pub enum NoiseSpecError {
    /// A spec names something that is not a measured state or output of the model.
    #[error("expected a measured state or output in `--noise`, found `{name}`{what}")]
    #[diagnostic(code(gbm::E0134))]
    NotMeasured {
        /// The name given.
        name: String,
        /// `, a hidden state` and the like, or nothing for an unknown name.
        what: String,
        /// The measured quantities, with a suggestion.
        #[help]
        help: String,
    },
    /// Two specs for one quantity, or two bare levels.
    #[error("expected one `--noise` spec for {what}, found two")]
    #[diagnostic(
        code(gbm::E0135),
        help("keep one; `--noise X=4%+0.01` sets `X`, a bare `--noise 1%` every other quantity")
    )]
    Twice {
        /// `X` in backticks, or `every quantity` for bare levels.
        what: String,
    },
}

/// The noise of a run: the model's declarations with the specs laid over them. A named
/// spec replaces its quantity's noise; a bare level applies to every quantity of
/// `measured` that no spec names (declared ones included); `declared` changes nothing.
/// Quantities whose level is zero are left out. Sorted by quantity (states first).
pub fn merge_noise(
    model: &Model,
    specs: &[NoiseSpec],
    measured: &[Measured],
) -> Result<Vec<Noise>, NoiseSpecError> {
    let mut noise: Vec<Noise> = model.noise.clone();
    let mut named: Vec<Measured> = Vec::new();
    let mut bare: Option<(f64, f64)> = None;
    for spec in specs {
        let NoiseSpec::Level {
            name,
            relative,
            absolute,
        } = spec
        else {
            continue;
        };
        let Some(name) = name else {
            if bare.replace((*relative, *absolute)).is_some() {
                let what = "every quantity".to_string();
                return Err(NoiseSpecError::Twice { what });
            }
            continue;
        };
        let target = resolve(model, name)?;
        if named.contains(&target) {
            let what = format!("`{name}`");
            return Err(NoiseSpecError::Twice { what });
        }
        named.push(target);
        set(&mut noise, target, *relative, *absolute);
    }
    if let Some((relative, absolute)) = bare {
        for &target in measured.iter().filter(|target| !named.contains(target)) {
            set(&mut noise, target, relative, absolute);
        }
    }
    noise.retain(|noise| !noise.is_zero());
    noise.sort_by_key(|noise| noise.target);
    Ok(noise)
}

/// Sets (or adds) the noise of `target`.
fn set(noise: &mut Vec<Noise>, target: Measured, relative: f64, absolute: f64) {
    noise.retain(|noise| noise.target != target);
    noise.push(Noise {
        target,
        relative,
        absolute,
    });
}

/// The measured quantity a spec names, or why it is none.
fn resolve(model: &Model, name: &str) -> Result<Measured, NoiseSpecError> {
    if let Some(target) = model.measured_named(name) {
        return Ok(target);
    }
    let mut measured: Vec<&str> = (model.states.iter().map(|s| s.name.as_str()))
        .chain(model.outputs.iter().map(|o| o.name.as_str()))
        .collect();
    measured.sort_unstable();
    let what = if model.hidden.iter().any(|h| h.name == name) {
        ", a hidden state (never measured)"
    } else if model.inputs.iter().any(|i| i.name == name) {
        ", an input (set, not measured)"
    } else if model.params.iter().any(|p| p.name == name) {
        ", a param (fitted, not measured)"
    } else if model.consts.iter().any(|c| c.name == name) {
        ", a const (known, not measured)"
    } else {
        ""
    };
    Err(NoiseSpecError::NotMeasured {
        name: name.to_string(),
        what: what.to_string(),
        help: crate::suggest::did_you_mean(name, &measured, "measured quantities"),
    })
}

#[cfg(test)]
mod tests;
