//! Numbers in the JSON files gbc writes: every `f64` that can be infinite or NaN goes
//! through this one serde helper, so that every file gbc writes reads back.
//!
//! JSON has no infinity or NaN (`serde_json` writes them as `null`). Here a finite number
//! is written as a number and a non-finite one as a string: `"inf"`, `"-inf"` or `"nan"`.
//! Reading accepts numbers, those strings (also `"Infinity"`, `"-Infinity"`, `"NaN"`, any
//! case) and `null`, which files written before this rule hold for a value that was not
//! finite: it reads as NaN, except in error sets (the validation errors of `run.json`),
//! where it always meant a diverged run and reads as infinity ([`null_is_infinite`]).
//!
//! Use it on a field with `#[serde(with = "crate::json")]`; it serves `f64` and anything
//! built of it by [`Numbers`]: `Option`, `Vec`, arrays of two, tuples, maps by name.

use std::collections::BTreeMap;

use serde::de::{self, Deserializer, Visitor};
use serde::{Deserialize, Serialize, Serializer};

/// Writes `value` with every non-finite number as a string.
pub fn serialize<T: Numbers, S: Serializer>(value: &T, serializer: S) -> Result<S::Ok, S::Error> {
    value.to_wire().serialize(serializer)
}

/// Reads a value written by [`serialize`] (or by plain `serde_json`, `null` as NaN).
pub fn deserialize<'de, T: Numbers, D: Deserializer<'de>>(deserializer: D) -> Result<T, D::Error> {
    Ok(T::from_wire(T::Wire::deserialize(deserializer)?, f64::NAN))
}

/// The same as this module, with a legacy `null` read as infinity (error sets, whose
/// `null` always meant a diverged free run).
pub mod null_is_infinite {
    use super::*;

    /// Writes `value` as [`super::serialize`] does.
    pub fn serialize<T: Numbers, S: Serializer>(
        value: &T,
        serializer: S,
    ) -> Result<S::Ok, S::Error> {
        super::serialize(value, serializer)
    }

    /// Reads a value, `null` as infinity.
    pub fn deserialize<'de, T: Numbers, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<T, D::Error> {
        Ok(T::from_wire(
            T::Wire::deserialize(deserializer)?,
            f64::INFINITY,
        ))
    }
}

/// One number on the wire: a finite number, a named non-finite one, or `null` (legacy).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Number(Option<f64>);

impl Number {
    /// The number, `null` read as `null_value`.
    fn value(self, null_value: f64) -> f64 {
        self.0.unwrap_or(null_value)
    }
}

impl Serialize for Number {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            Some(value) if value.is_finite() => serializer.serialize_f64(value),
            Some(value) => serializer.serialize_str(name_of(value)),
            None => serializer.serialize_none(),
        }
    }
}

impl<'de> Deserialize<'de> for Number {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Number, D::Error> {
        deserializer.deserialize_any(NumberVisitor)
    }
}

/// The string a non-finite number is written as.
pub fn name_of(value: f64) -> &'static str {
    if value.is_nan() {
        "nan"
    } else if value > 0.0 {
        "inf"
    } else {
        "-inf"
    }
}

/// The non-finite number a string names, if it names one.
pub fn parse_name(text: &str) -> Option<f64> {
    match text.trim().to_ascii_lowercase().as_str() {
        "inf" | "+inf" | "infinity" | "+infinity" => Some(f64::INFINITY),
        "-inf" | "-infinity" => Some(f64::NEG_INFINITY),
        "nan" => Some(f64::NAN),
        _ => None,
    }
}

struct NumberVisitor;

impl Visitor<'_> for NumberVisitor {
    type Value = Number;

    fn expecting(&self, formatter: &mut std::fmt::Formatter) -> std::fmt::Result {
        formatter.write_str("a number or one of \"inf\", \"-inf\", \"nan\"")
    }

    fn visit_f64<E: de::Error>(self, value: f64) -> Result<Number, E> {
        Ok(Number(Some(value)))
    }

    fn visit_i64<E: de::Error>(self, value: i64) -> Result<Number, E> {
        Ok(Number(Some(value as f64)))
    }

    fn visit_u64<E: de::Error>(self, value: u64) -> Result<Number, E> {
        Ok(Number(Some(value as f64)))
    }

    fn visit_str<E: de::Error>(self, text: &str) -> Result<Number, E> {
        parse_name(text)
            .map(|value| Number(Some(value)))
            .ok_or_else(|| E::invalid_value(de::Unexpected::Str(text), &self))
    }

    fn visit_unit<E: de::Error>(self) -> Result<Number, E> {
        Ok(Number(None))
    }

    fn visit_none<E: de::Error>(self) -> Result<Number, E> {
        Ok(Number(None))
    }
}

/// A type made of `f64`s that this module writes and reads: its wire form has a
/// [`Number`] where it has an `f64`.
pub trait Numbers: Sized {
    /// The form written.
    type Wire: Serialize + for<'de> Deserialize<'de>;
    /// To the wire form.
    fn to_wire(&self) -> Self::Wire;
    /// From the wire form, a legacy `null` read as `null_value`.
    fn from_wire(wire: Self::Wire, null_value: f64) -> Self;
}

impl Numbers for f64 {
    type Wire = Number;
    fn to_wire(&self) -> Number {
        Number(Some(*self))
    }
    fn from_wire(wire: Number, null_value: f64) -> f64 {
        wire.value(null_value)
    }
}

/// Names beside numbers (`(name, value)` pairs) pass through unchanged.
impl Numbers for String {
    type Wire = String;
    fn to_wire(&self) -> String {
        self.clone()
    }
    fn from_wire(wire: String, _: f64) -> String {
        wire
    }
}

/// An `Option<f64>`: `None` is `null`; a non-finite `Some` is its name. (A legacy `null`
/// reads as `None`.)
impl<T: Numbers> Numbers for Option<T> {
    type Wire = Option<T::Wire>;
    fn to_wire(&self) -> Self::Wire {
        self.as_ref().map(Numbers::to_wire)
    }
    fn from_wire(wire: Self::Wire, null_value: f64) -> Self {
        wire.map(|w| T::from_wire(w, null_value))
    }
}

impl<T: Numbers> Numbers for Vec<T> {
    type Wire = Vec<T::Wire>;
    fn to_wire(&self) -> Self::Wire {
        self.iter().map(Numbers::to_wire).collect()
    }
    fn from_wire(wire: Self::Wire, null_value: f64) -> Self {
        (wire.into_iter())
            .map(|w| T::from_wire(w, null_value))
            .collect()
    }
}

impl<T: Numbers> Numbers for [T; 2] {
    type Wire = (T::Wire, T::Wire);
    fn to_wire(&self) -> Self::Wire {
        (self[0].to_wire(), self[1].to_wire())
    }
    fn from_wire((a, b): Self::Wire, null_value: f64) -> Self {
        [T::from_wire(a, null_value), T::from_wire(b, null_value)]
    }
}

impl<A: Numbers, B: Numbers> Numbers for (A, B) {
    type Wire = (A::Wire, B::Wire);
    fn to_wire(&self) -> Self::Wire {
        (self.0.to_wire(), self.1.to_wire())
    }
    fn from_wire((a, b): Self::Wire, null_value: f64) -> Self {
        (A::from_wire(a, null_value), B::from_wire(b, null_value))
    }
}

impl<T: Numbers> Numbers for BTreeMap<String, T> {
    type Wire = BTreeMap<String, T::Wire>;
    fn to_wire(&self) -> Self::Wire {
        (self.iter())
            .map(|(name, value)| (name.clone(), value.to_wire()))
            .collect()
    }
    fn from_wire(wire: Self::Wire, null_value: f64) -> Self {
        (wire.into_iter())
            .map(|(name, value)| (name, T::from_wire(value, null_value)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Sample {
        #[serde(with = "crate::json")]
        plain: f64,
        #[serde(with = "crate::json")]
        maybe: Option<f64>,
        #[serde(with = "crate::json")]
        list: Vec<f64>,
        #[serde(with = "crate::json")]
        named: Vec<(String, f64)>,
        #[serde(with = "crate::json")]
        pair: [f64; 2],
        #[serde(with = "crate::json")]
        map: BTreeMap<String, f64>,
        #[serde(with = "crate::json::null_is_infinite")]
        error: f64,
    }

    /// Equality that counts NaN equal to NaN (bit patterns aside).
    fn same(a: f64, b: f64) -> bool {
        a == b || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn non_finite_numbers_are_written_by_name_and_read_back() {
        let (inf, nan) = (f64::INFINITY, f64::NAN);
        let sample = Sample {
            plain: inf,
            maybe: Some(-inf),
            list: vec![1.5, nan, -inf, 0.1 + 0.2],
            named: vec![("X".into(), inf), ("S".into(), 2.0)],
            pair: [-inf, 3.0],
            map: BTreeMap::from([("K".to_string(), nan), ("Y".to_string(), 0.5)]),
            error: nan,
        };
        let text = serde_json::to_string(&sample).unwrap();
        assert!(!text.contains("null"), "{text}");
        assert!(text.contains("\"inf\"") && text.contains("\"-inf\"") && text.contains("\"nan\""));
        let back: Sample = serde_json::from_str(&text).unwrap();
        assert_eq!(back.plain, inf);
        assert_eq!(back.maybe, Some(-inf));
        assert!(back
            .list
            .iter()
            .zip(&sample.list)
            .all(|(a, b)| same(*a, *b)));
        assert_eq!(back.list[3], 0.1 + 0.2, "finite numbers round-trip exactly");
        assert_eq!(back.named, sample.named);
        assert_eq!(back.pair, sample.pair);
        assert!(back.map["K"].is_nan() && back.map["Y"] == 0.5);
        assert!(back.error.is_nan());
    }

    #[test]
    fn legacy_null_and_other_spellings_read() {
        let text = r#"{"plain": null, "maybe": null, "list": [null, "Infinity", "-INF", 7],
            "named": [["X", null]], "pair": ["NaN", 1], "map": {"K": null}, "error": null}"#;
        let back: Sample = serde_json::from_str(text).unwrap();
        assert!(back.plain.is_nan());
        assert_eq!(back.maybe, None);
        assert!(back.list[0].is_nan());
        assert_eq!(&back.list[1..], &[f64::INFINITY, f64::NEG_INFINITY, 7.0]);
        assert!(back.named[0].1.is_nan());
        assert!(back.pair[0].is_nan());
        assert_eq!(
            back.error,
            f64::INFINITY,
            "a legacy null error is a diverged run"
        );
    }

    #[test]
    fn other_strings_are_refused_with_what_was_expected() {
        let text = r#"{"plain": "lots", "maybe": null, "list": [], "named": [], "pair": [1, 2],
            "map": {}, "error": 1}"#;
        let error = serde_json::from_str::<Sample>(text)
            .unwrap_err()
            .to_string();
        assert!(error.contains("\"inf\""), "{error}");
    }
}
