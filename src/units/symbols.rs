//! Unit symbols: the base units gbc knows and the SI prefixes they take.

use std::fmt;

/// A unit without prefix.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Base {
    /// `g`: gram (mass).
    Gram,
    /// `mol`: mole (amount of substance).
    Mole,
    /// `L`: litre, 10^-3 m^3 (volume).
    Litre,
    /// `m`: metre (length).
    Metre,
    /// `K`: kelvin (temperature).
    Kelvin,
    /// `s`: second (time).
    Second,
    /// `min`: minute, 60 s.
    Minute,
    /// `h`: hour, 3600 s.
    Hour,
    /// `d`: day, 86400 s.
    Day,
    /// `%`: percent, the pure number 10^-2.
    Percent,
    /// `ppm`: parts per million, the pure number 10^-6.
    PartsPerMillion,
}

impl Base {
    /// Every base, in canonical display order.
    pub const ALL: [Base; 11] = [
        Base::Gram,
        Base::Mole,
        Base::Litre,
        Base::Metre,
        Base::Kelvin,
        Base::Second,
        Base::Minute,
        Base::Hour,
        Base::Day,
        Base::Percent,
        Base::PartsPerMillion,
    ];

    /// The symbol written in a model.
    pub fn symbol(self) -> &'static str {
        match self {
            Base::Gram => "g",
            Base::Mole => "mol",
            Base::Litre => "L",
            Base::Metre => "m",
            Base::Kelvin => "K",
            Base::Second => "s",
            Base::Minute => "min",
            Base::Hour => "h",
            Base::Day => "d",
            Base::Percent => "%",
            Base::PartsPerMillion => "ppm",
        }
    }

    /// Exponents of mass, amount, length, time and temperature.
    pub fn dimension(self) -> [i32; super::DIMENSIONS] {
        match self {
            Base::Gram => [1, 0, 0, 0, 0],
            Base::Mole => [0, 1, 0, 0, 0],
            Base::Litre => [0, 0, 3, 0, 0],
            Base::Metre => [0, 0, 1, 0, 0],
            Base::Kelvin => [0, 0, 0, 0, 1],
            Base::Second | Base::Minute | Base::Hour | Base::Day => [0, 0, 0, 1, 0],
            Base::Percent | Base::PartsPerMillion => [0; super::DIMENSIONS],
        }
    }

    /// Size in base units (g, mol, m^3 or m, s, K; 1 for a pure number).
    pub fn scale(self) -> f64 {
        match self {
            Base::Litre => 1e-3,
            Base::Minute => 60.0,
            Base::Hour => 3600.0,
            Base::Day => 86400.0,
            Base::Percent => 1e-2,
            Base::PartsPerMillion => 1e-6,
            _ => 1.0,
        }
    }

    /// Whether SI prefixes apply (not to `min`, `h`, `d`, `%`, `ppm`).
    pub fn takes_prefix(self) -> bool {
        !matches!(
            self,
            Base::Minute | Base::Hour | Base::Day | Base::Percent | Base::PartsPerMillion
        )
    }
}

/// An SI prefix.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Prefix {
    /// `p`: 10^-12.
    Pico,
    /// `n`: 10^-9.
    Nano,
    /// `u` or `µ`: 10^-6.
    Micro,
    /// `m`: 10^-3.
    Milli,
    /// `c`: 10^-2.
    Centi,
    /// `d`: 10^-1.
    Deci,
    /// `k`: 10^3.
    Kilo,
    /// `M`: 10^6.
    Mega,
}

impl Prefix {
    /// Every prefix.
    pub const ALL: [Prefix; 8] = [
        Prefix::Pico,
        Prefix::Nano,
        Prefix::Micro,
        Prefix::Milli,
        Prefix::Centi,
        Prefix::Deci,
        Prefix::Kilo,
        Prefix::Mega,
    ];

    /// The prefix as written (`u` for micro; `µ` is read too).
    pub fn symbol(self) -> &'static str {
        match self {
            Prefix::Pico => "p",
            Prefix::Nano => "n",
            Prefix::Micro => "u",
            Prefix::Milli => "m",
            Prefix::Centi => "c",
            Prefix::Deci => "d",
            Prefix::Kilo => "k",
            Prefix::Mega => "M",
        }
    }

    /// The factor it stands for.
    pub fn factor(self) -> f64 {
        match self {
            Prefix::Pico => 1e-12,
            Prefix::Nano => 1e-9,
            Prefix::Micro => 1e-6,
            Prefix::Milli => 1e-3,
            Prefix::Centi => 1e-2,
            Prefix::Deci => 1e-1,
            Prefix::Kilo => 1e3,
            Prefix::Mega => 1e6,
        }
    }
}

/// A prefixed unit symbol such as `mg` or `L`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Symbol {
    /// The prefix, if any.
    pub prefix: Option<Prefix>,
    /// The unit.
    pub base: Base,
}

/// Every unprefixed symbol, for suggestions and documentation.
pub const SYMBOL_NAMES: [&str; 11] = ["g", "mol", "L", "m", "K", "s", "min", "h", "d", "%", "ppm"];

impl Symbol {
    /// Reads a symbol: an exact base first (`min` is minutes, `d` is days), then a prefix
    /// followed by a base that takes prefixes (`mg`, `mmol`, `uL`, `µm`, `kg`).
    pub fn parse(text: &str) -> Option<Symbol> {
        if let Some(base) = Base::ALL.into_iter().find(|b| b.symbol() == text) {
            return Some(Symbol { prefix: None, base });
        }
        let (prefix, rest) = if let Some(rest) = text.strip_prefix('µ') {
            (Prefix::Micro, rest)
        } else {
            let prefix = Prefix::ALL
                .into_iter()
                .find(|p| text.starts_with(p.symbol()))?;
            (prefix, &text[prefix.symbol().len()..])
        };
        let base = Base::ALL
            .into_iter()
            .find(|b| b.symbol() == rest && b.takes_prefix())?;
        Some(Symbol {
            prefix: Some(prefix),
            base,
        })
    }

    /// The base that `text` would be with a prefix it does not take (`mh`, `k%`, `uppm`),
    /// for a help line; `None` for a valid symbol or anything else.
    pub fn refused_prefix(text: &str) -> Option<Base> {
        if Symbol::parse(text).is_some() {
            return None;
        }
        let rest = text.strip_prefix('µ').or_else(|| {
            let prefix = Prefix::ALL
                .into_iter()
                .find(|p| text.starts_with(p.symbol()))?;
            Some(&text[prefix.symbol().len()..])
        })?;
        Base::ALL
            .into_iter()
            .find(|base| base.symbol() == rest && !base.takes_prefix())
    }

    /// Size in base units.
    pub fn scale(self) -> f64 {
        self.base.scale() * self.prefix.map_or(1.0, Prefix::factor)
    }

    /// Sort key of the canonical order: by base, then by prefix size.
    pub fn order(self) -> (Base, i64) {
        let exponent = self.prefix.map_or(0, |p| p.factor().log10().round() as i64);
        (self.base, exponent)
    }
}

impl fmt::Display for Symbol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(prefix) = self.prefix {
            write!(f, "{}", prefix.symbol())?;
        }
        write!(f, "{}", self.base.symbol())
    }
}
