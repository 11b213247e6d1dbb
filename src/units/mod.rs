//! The unit algebra: units of measure as products of powers of prefixed symbols
//! (`g L^-1`, `mol/L/s`, `1/h`), with their dimension and scale for comparison.
//!
//! Powers are rational so that `sqrt` and Hill exponents (`S^2.7`) keep a unit: they are
//! stored in fixed point, in units of 1/[`POWER_DENOMINATOR`] (halves, thirds, quarters and
//! two decimal places are exact); a power that is not representable makes the unit unknown
//! to the checks rather than wrong.
//!
//! Symbols are the SI base units gbc models need and a few domain units: `g`, `mol`, `L`,
//! `m`, `K`, `s` (all of which take the prefixes `p n u µ m c d k M`), `min`, `h`, `d`
//! (no prefixes), and the pure numbers `%` (10^-2) and `ppm` (10^-6), dimensionless
//! with a scale (no prefixes either). `-` is dimensionless. Two units are equal when they
//! have the same dimension and scale (`g/L` is `mg/mL`, `%/%` is `-`); units of one
//! dimension and different scales (`g/L` and `mg/L`, `1/h` and `1/min`, `%` and `-`)
//! differ by a factor that [`Comparison::Scale`] names.

mod symbols;

#[cfg(test)]
pub use symbols::{Base, Prefix};
pub use symbols::{Symbol, SYMBOL_NAMES};

use crate::ast::{SUnit, Span, UnitExpr};
use std::fmt;

/// Number of base dimensions: mass, amount, length, time, temperature.
pub const DIMENSIONS: usize = 5;

/// Powers are stored as integer multiples of `1 / POWER_DENOMINATOR`.
pub const POWER_DENOMINATOR: i32 = 600;

/// A unit: a product of powers of symbols, merged and kept in a canonical order.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Default)]
pub struct Unit {
    factors: Vec<(Symbol, i32)>,
}

/// How two units relate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Comparison {
    /// Same dimension and scale.
    Equal,
    /// Same dimension; `1 a = factor b`.
    Scale(f64),
    /// Different dimensions.
    Incompatible,
}

impl Unit {
    /// The dimensionless unit `-`.
    pub fn dimensionless() -> Unit {
        Unit::default()
    }

    /// One symbol to the first power.
    pub fn symbol(symbol: Symbol) -> Unit {
        Unit {
            factors: vec![(symbol, POWER_DENOMINATOR)],
        }
    }

    /// Parses a unit written without brackets, such as `g/L` or `1/h` (used for `time` and
    /// by tools); `None` if it is not a valid unit.
    pub fn parse(text: &str) -> Option<Unit> {
        let source = format!("model m\nconst c [{text}] = 1\n");
        let model = crate::syntax::parse(&source).ok()?;
        let crate::ast::ItemKind::Const(consts) = &model.items.first()?.kind else {
            return None;
        };
        resolve(consts.first()?.unit.as_ref()?).ok()
    }

    /// The factors with their powers, in canonical order.
    pub fn factors(&self) -> Vec<(Symbol, f64)> {
        (self.factors.iter())
            .map(|(s, p)| (*s, f64::from(*p) / f64::from(POWER_DENOMINATOR)))
            .collect()
    }

    /// Whether the unit has no factors at all (`-`).
    pub fn is_one(&self) -> bool {
        self.factors.is_empty()
    }

    /// The product of two units.
    pub fn mul(&self, other: &Unit) -> Unit {
        let mut factors = self.factors.clone();
        for (symbol, power) in &other.factors {
            match factors.iter_mut().find(|(s, _)| s == symbol) {
                Some((_, existing)) => *existing += power,
                None => factors.push((*symbol, *power)),
            }
        }
        factors.retain(|(_, power)| *power != 0);
        factors.sort_by_key(|(symbol, _)| symbol.order());
        Unit { factors }
    }

    /// The quotient `self / other`.
    pub fn div(&self, other: &Unit) -> Unit {
        self.mul(&other.powi(-1))
    }

    /// The unit to an integer power.
    pub fn powi(&self, n: i32) -> Unit {
        if n == 0 {
            return Unit::dimensionless();
        }
        Unit {
            factors: self.factors.iter().map(|(s, p)| (*s, p * n)).collect(),
        }
    }

    /// The unit to a real power, when every resulting power is representable (a multiple
    /// of `1 / POWER_DENOMINATOR`); `sqrt` is `powf(0.5)`.
    pub fn powf(&self, x: f64) -> Option<Unit> {
        if !x.is_finite() {
            return None;
        }
        let mut factors = Vec::with_capacity(self.factors.len());
        for (symbol, power) in &self.factors {
            let scaled = f64::from(*power) * x;
            let rounded = scaled.round();
            if (scaled - rounded).abs() > 1e-6 || rounded.abs() > f64::from(i32::MAX / 2) {
                return None;
            }
            if rounded != 0.0 {
                factors.push((*symbol, rounded as i32));
            }
        }
        Some(Unit { factors })
    }

    /// Exponents of mass, amount, length, time and temperature, times `POWER_DENOMINATOR`.
    pub fn dimension(&self) -> [i32; DIMENSIONS] {
        let mut dims = [0; DIMENSIONS];
        for (symbol, power) in &self.factors {
            for (total, base) in dims.iter_mut().zip(symbol.base.dimension()) {
                *total += base * power;
            }
        }
        dims
    }

    /// The size of the unit in base units (g, mol, m, s, K): `mg/L` is 1.
    pub fn scale(&self) -> f64 {
        self.factors
            .iter()
            .map(|(symbol, power)| {
                symbol
                    .scale()
                    .powf(f64::from(*power) / f64::from(POWER_DENOMINATOR))
            })
            .product()
    }

    /// Whether the dimension is zero (`-`, `g/g`, but also `h/min`, whose scale is 60).
    pub fn is_dimensionless(&self) -> bool {
        self.dimension() == [0; DIMENSIONS]
    }

    /// How `self` relates to `other`.
    pub fn compare(&self, other: &Unit) -> Comparison {
        if self.dimension() != other.dimension() {
            return Comparison::Incompatible;
        }
        let ratio = self.scale() / other.scale();
        if (ratio - 1.0).abs() <= 1e-9 {
            Comparison::Equal
        } else {
            Comparison::Scale(ratio)
        }
    }

    /// Whether the two units are the same quantity unit.
    pub fn same(&self, other: &Unit) -> bool {
        self.compare(other) == Comparison::Equal
    }

    /// The dimension in words: "mass per volume", "amount per volume per time".
    pub fn dimension_words(&self) -> String {
        let dims = self.dimension();
        let mut parts: Vec<(&str, i32)> = vec![("mass", dims[0]), ("amount", dims[1])];
        if dims[2] % (3 * POWER_DENOMINATOR) == 0 {
            parts.push(("volume", dims[2] / 3));
        } else {
            parts.push(("length", dims[2]));
        }
        parts.push(("temperature", dims[4]));
        parts.push(("time", dims[3]));
        let word = |(name, power): &(&str, i32)| match power.abs() {
            POWER_DENOMINATOR => name.to_string(),
            p => format!("{name}^{}", power_text(p)),
        };
        let numerator: Vec<String> = parts.iter().filter(|(_, p)| *p > 0).map(word).collect();
        let denominator: Vec<String> = parts.iter().filter(|(_, p)| *p < 0).map(word).collect();
        if numerator.is_empty() && denominator.is_empty() {
            return "dimensionless".to_string();
        }
        let mut text = if numerator.is_empty() {
            "1".to_string()
        } else {
            numerator.join(" ")
        };
        for part in denominator {
            text.push_str(" per ");
            text.push_str(&part);
        }
        text
    }
}

impl fmt::Display for Unit {
    /// Canonical text: numerator factors by juxtaposition (or `1`), then `/factor` for each
    /// negative power; `-` when dimensionless. It parses back to the same unit.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.factors.is_empty() {
            return write!(f, "-");
        }
        let power = |p: i32| {
            if p == POWER_DENOMINATOR {
                String::new()
            } else {
                format!("^{}", power_text(p))
            }
        };
        let numerator: Vec<String> = (self.factors.iter())
            .filter(|(_, p)| *p > 0)
            .map(|(s, p)| format!("{s}{}", power(*p)))
            .collect();
        if numerator.is_empty() {
            write!(f, "1")?;
        } else {
            write!(f, "{}", numerator.join(" "))?;
        }
        for (symbol, p) in self.factors.iter().filter(|(_, p)| *p < 0) {
            write!(f, "/{symbol}{}", power(-p))?;
        }
        Ok(())
    }
}

/// A stored power as text: `2`, `0.5`, `2.7`.
fn power_text(power: i32) -> String {
    if power % POWER_DENOMINATOR == 0 {
        return (power / POWER_DENOMINATOR).to_string();
    }
    format_factor(f64::from(power) / f64::from(POWER_DENOMINATOR))
}

/// `1 a = F b` with `F >= 1` (swapping the two if needed), and `F` in words: the sentence a
/// scale-mismatch help line uses. The pure number `-` is written bare: `1 = 100 %`.
pub fn conversion(a: &Unit, b: &Unit) -> (String, String) {
    let ratio = a.scale() / b.scale();
    let (big, small, factor) = if ratio >= 1.0 {
        (a, b, ratio)
    } else {
        (b, a, 1.0 / ratio)
    };
    let factor_text = format_factor(factor);
    let quantity = |number: &str, unit: &Unit| {
        if unit.is_one() {
            number.to_string()
        } else {
            format!("{number} {unit}")
        }
    };
    let sentence = format!("{} = {}", quantity("1", big), quantity(&factor_text, small));
    (sentence, factor_text)
}

/// A conversion factor in short text: whole numbers exactly, others to six significant digits.
pub fn format_factor(factor: f64) -> String {
    if (factor - factor.round()).abs() <= 1e-9 * factor.abs() && factor.abs() < 1e15 {
        format!("{}", factor.round() as i64)
    } else {
        let text = format!("{factor:.5e}");
        match text.split_once('e') {
            Some((mantissa, exponent)) => {
                let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
                let exponent: i32 = exponent.parse().unwrap_or(0);
                if (-4..6).contains(&exponent) {
                    let value: f64 = format!("{mantissa}e{exponent}").parse().unwrap_or(factor);
                    format!("{value}")
                } else {
                    format!("{mantissa}e{exponent}")
                }
            }
            None => text,
        }
    }
}

/// Resolves a unit annotation into a [`Unit`], or every unknown symbol with its span.
pub fn resolve(unit: &SUnit) -> Result<Unit, Vec<(Span, String)>> {
    let mut unknown = Vec::new();
    let resolved = resolve_node(unit, &mut unknown);
    if unknown.is_empty() {
        Ok(resolved)
    } else {
        Err(unknown)
    }
}

fn resolve_node(unit: &SUnit, unknown: &mut Vec<(Span, String)>) -> Unit {
    match &unit.node {
        UnitExpr::Dimensionless | UnitExpr::One => Unit::dimensionless(),
        UnitExpr::Symbol(text) => match Symbol::parse(text) {
            Some(symbol) => Unit::symbol(symbol),
            None => {
                unknown.push((unit.span, text.clone()));
                Unit::dimensionless()
            }
        },
        UnitExpr::Pow(base, n) => resolve_node(base, unknown).powi(*n),
        UnitExpr::Mul(a, b) => resolve_node(a, unknown).mul(&resolve_node(b, unknown)),
        UnitExpr::Div(a, b) => resolve_node(a, unknown).div(&resolve_node(b, unknown)),
    }
}

#[cfg(test)]
mod tests;
