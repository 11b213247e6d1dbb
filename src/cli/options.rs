//! The training flags `gbc train`, `gbc experiment` and `gbc bench` share: one clap struct
//! over [`Settings`] (whose `Default` is the one default table), and the one mapping from a
//! setting's field to the flag that sets it, so that a bad value is reported as the flag the
//! user typed.

use crate::backend::Precision;
use crate::train::{Engine, Settings, TowardMechanism, TrainError};

use super::CommandError;

/// The shared training flags; each left out keeps the value it overrides (the study file's,
/// or the default of [`Settings`]).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct TrainingFlags {
    /// Passes over the training pairs (`gbc bench`: timed epochs).
    #[arg(long, value_name = "N", help = with_default("Passes over the training pairs (`gbc bench`: timed epochs, 20)", Settings::default().epochs))]
    pub epochs: Option<usize>,
    /// Pairs per Adam step.
    #[arg(long, value_name = "N", help = with_default("Pairs per Adam step", Settings::default().batch_size))]
    pub batch: Option<usize>,
    /// Adam learning rate.
    #[arg(long, value_name = "LR", help = with_default("Adam learning rate", Settings::default().learning_rate))]
    pub lr: Option<f64>,
    /// Element type (`gbc bench`: both when left out).
    #[arg(long, value_enum, help = with_default("Element type (`gbc bench`: both when left out)", Settings::default().precision.name()))]
    pub precision: Option<Precision>,
    /// RK4 sub-steps per sample (for stiff balances).
    #[arg(long, value_name = "K", help = with_default("RK4 sub-steps per sample (for stiff balances)", Settings::default().substeps))]
    pub substeps: Option<usize>,
    /// What runs the training steps (`gbc bench`: both when left out).
    #[arg(long, value_enum, help = with_default("What runs the training steps: the fastest that runs the model, the graph backend, or the hand-fused step (`gbc bench`: graph and fused when left out)", Settings::default().engine.name()))]
    pub engine: Option<Engine>,
    /// Strength of the pull toward the mechanism, or `auto`.
    #[arg(long, value_name = "STRENGTH", help = with_default("Strength of the pull of the closures' last layers toward zero (the mechanism) and of trained params toward their start, relative to the normalised MSE loss; `auto` picks it by leave-one-experiment-out cross-validation over the training experiments", Settings::default().toward_mechanism))]
    pub toward_mechanism: Option<TowardMechanism>,
}

/// A flag's help line with the default taken from [`Settings`].
fn with_default(help: &str, default: impl std::fmt::Display) -> String {
    format!("{help} [default: {default}]")
}

impl TrainingFlags {
    /// Overrides the settings the flags give.
    pub fn apply(&self, settings: &mut Settings) {
        settings.epochs = self.epochs.unwrap_or(settings.epochs);
        settings.batch_size = self.batch.unwrap_or(settings.batch_size);
        settings.learning_rate = self.lr.unwrap_or(settings.learning_rate);
        settings.precision = self.precision.unwrap_or(settings.precision);
        settings.substeps = self.substeps.unwrap_or(settings.substeps);
        settings.engine = self.engine.unwrap_or(settings.engine);
        settings.toward_mechanism = (self.toward_mechanism).unwrap_or(settings.toward_mechanism);
    }

    /// The default settings with the flags applied, checked; a bad value names its flag.
    pub fn settings(&self) -> Result<Settings, CommandError> {
        let mut settings = Settings::default();
        self.apply(&mut settings);
        self.check(&settings)?;
        Ok(settings)
    }

    /// Checks `settings` (with these flags applied) and names a bad value by the flag when
    /// the user gave it; the caller reports a value from elsewhere (a study file) by its
    /// field.
    pub fn check(&self, settings: &Settings) -> Result<(), CommandError> {
        match settings.check() {
            Err(bad) if self.gave(bad.field) => Err(CommandError::user(TrainError::BadOption {
                option: flag_of(bad.field).unwrap_or(bad.field).to_string(),
                expected: bad.expected.into(),
                found: bad.found,
            })),
            _ => Ok(()),
        }
    }

    /// Whether the flag of `field` was given.
    fn gave(&self, field: &str) -> bool {
        match field {
            "batch_size" => self.batch.is_some(),
            "learning_rate" => self.lr.is_some(),
            "substeps" => self.substeps.is_some(),
            "toward_mechanism" => self.toward_mechanism.is_some(),
            _ => false,
        }
    }
}

pub use crate::train::{flag_of, with_flag};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_override_and_bad_flags_are_named_as_typed() {
        let flags = TrainingFlags {
            batch: Some(0),
            ..TrainingFlags::default()
        };
        let message: String = match flags.settings() {
            Err(CommandError::User(reports)) => reports.iter().map(|r| r.to_string()).collect(),
            other => panic!("expected a user error, found {other:?}"),
        };
        assert!(message.contains("--batch") && !message.contains("batch_size"));
        let flags = TrainingFlags {
            lr: Some(0.01),
            precision: Some(Precision::F64),
            ..TrainingFlags::default()
        };
        let settings = flags.settings().unwrap();
        assert_eq!(settings.learning_rate, 0.01);
        assert_eq!(settings.precision, Precision::F64);
        assert_eq!(settings.batch_size, Settings::default().batch_size);
        // A bad value from elsewhere (a study file) is left to its own check.
        let from_file = Settings {
            batch_size: 0,
            ..Settings::default()
        };
        assert!(TrainingFlags::default().check(&from_file).is_ok());
    }

    #[test]
    fn a_bug_from_any_stage_is_an_internal_error_and_bad_input_is_not() {
        let bug = crate::backend::BackendError::internal("rows differ");
        assert!(
            matches!(CommandError::user(TrainError::from(bug)), CommandError::Internal(m) if m.contains("rows differ"))
        );
        let input = TrainError::BadOption {
            option: "--batch".into(),
            expected: "a positive batch size".into(),
            found: "0".into(),
        };
        assert!(matches!(CommandError::user(input), CommandError::User(_)));
    }

    #[test]
    fn library_fields_become_flags() {
        let error = with_flag(TrainError::BadOption {
            option: "max_gradient_norm".into(),
            expected: "a positive gradient norm".into(),
            found: "-1".into(),
        });
        assert!(error.to_string().contains("--clip"));
    }
}
