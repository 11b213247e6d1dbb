//! The training settings every command shares, with the one table of their defaults:
//! `gbc train`, `gbc experiment` (flattened into the study file) and `gbc bench` all read
//! them from [`Settings`], and the command line reaches them through one set of flags
//! (`cli::options::TrainingFlags`).
//!
//! Checks name the setting by its field (as a study file spells it); the command line
//! checks its own flags before they reach a [`Settings`], so a bad value is reported as
//! what the user wrote.

use crate::engine::graph::Precision;

use super::toward::TowardMechanism;
use super::Engine;

/// The training settings shared by every command, with their defaults.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Settings {
    /// Passes over the training pairs.
    pub epochs: usize,
    /// Pairs per Adam step.
    pub batch_size: usize,
    /// Adam learning rate.
    #[serde(with = "crate::json")]
    pub learning_rate: f64,
    /// Element type.
    pub precision: Precision,
    /// RK4 sub-steps per sample.
    pub substeps: usize,
    /// What runs the training steps.
    pub engine: Engine,
    /// Strength of the pull toward the mechanism (`--toward-mechanism`; a number or
    /// `"auto"`, [`super::toward`]).
    pub toward_mechanism: TowardMechanism,
}

impl Default for Settings {
    /// The one default table of training.
    fn default() -> Self {
        Settings {
            epochs: 100,
            batch_size: 50,
            learning_rate: 1e-3,
            precision: Precision::F32,
            substeps: 1,
            engine: Engine::Auto,
            toward_mechanism: TowardMechanism::Auto,
        }
    }
}

/// A setting with a value it cannot take.
#[derive(Debug, Clone, PartialEq)]
pub struct BadSetting {
    /// The field, as a study file spells it (`batch_size`).
    pub field: &'static str,
    /// What is allowed.
    pub expected: &'static str,
    /// What was given.
    pub found: String,
}

impl Settings {
    /// Checks every value; the error names the first bad field. Zero epochs are allowed
    /// (a run that only evaluates its initial network); a study asks for at least one.
    pub fn check(&self) -> Result<(), BadSetting> {
        let bad = |field, expected, found: String| {
            Err(BadSetting {
                field,
                expected,
                found,
            })
        };
        if self.batch_size == 0 {
            return bad("batch_size", "a positive batch size", "0".into());
        }
        if self.substeps == 0 {
            return bad("substeps", "a positive number of sub-steps", "0".into());
        }
        if !(self.learning_rate > 0.0 && self.learning_rate.is_finite()) {
            let found = self.learning_rate.to_string();
            return bad("learning_rate", "a positive learning rate", found);
        }
        if !self.toward_mechanism.is_valid() {
            let found = self.toward_mechanism.to_string();
            return bad("toward_mechanism", "a finite strength >= 0, or auto", found);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_defaults_are_the_papers_and_a_file_may_leave_any_out() {
        let defaults = Settings::default();
        assert_eq!((defaults.batch_size, defaults.substeps), (50, 1));
        assert_eq!(defaults.learning_rate, 1e-3);
        assert_eq!(defaults.precision, Precision::F32);
        let read: Settings = serde_json::from_str(r#"{"batch_size": 20}"#).unwrap();
        assert_eq!(
            read,
            Settings {
                batch_size: 20,
                ..defaults
            }
        );
        assert!(defaults.check().is_ok());
    }

    #[test]
    fn checks_name_the_field() {
        let zero_batch = Settings {
            batch_size: 0,
            ..Settings::default()
        };
        assert_eq!(zero_batch.check().unwrap_err().field, "batch_size");
        let bad_rate = Settings {
            learning_rate: f64::NAN,
            ..Settings::default()
        };
        assert_eq!(bad_rate.check().unwrap_err().field, "learning_rate");
    }
}
