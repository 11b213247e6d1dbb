//! The training flags `gbc train`, `gbc experiment`, `gbc compare` and `gbc bench` share:
//! one clap struct over [`Settings`] (whose `Default` is the one default table), checked so
//! that a bad value is reported as the flag the user typed ([`crate::train::flag_of`], the
//! one mapping from a setting's field to its flag). Beside them, the clap mirrors of the
//! library's choices (element type, engine, template, message format), so that every clap
//! type of a library choice lives in [`crate::api::flags`].

use crate::api::ApiError;
use crate::engine::graph::Precision;
use crate::train::{flag_of, Engine, Settings, TowardMechanism, TrainError};

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
    pub precision: Option<PrecisionArg>,
    /// RK4 sub-steps per sample (for stiff balances).
    #[arg(long, value_name = "K", help = with_default("RK4 sub-steps per sample (for stiff balances)", Settings::default().substeps))]
    pub substeps: Option<usize>,
    /// What runs the training steps (`gbc bench`: both when left out).
    #[arg(long, value_enum, help = with_default("What runs the training steps: the fastest that runs the model, the graph backend, or the hand-fused step (`gbc bench`: graph and fused when left out)", Settings::default().engine.name()))]
    pub engine: Option<EngineArg>,
    /// Strength of the pull toward the mechanism, or `auto`.
    #[arg(long, value_name = "STRENGTH", help = with_default("Strength of the pull of the closures' last layers toward zero (the mechanism) and of trained params toward their start, relative to the normalised MSE loss; `auto` pulls by early stopping instead: the epochs are cut where leave-one-experiment-out cross-validation over the training experiments says (0: the mechanism itself); without two whole training experiments it trains every epoch without a pull", Settings::default().toward_mechanism))]
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
        settings.precision = self.precision.map_or(settings.precision, Precision::from);
        settings.substeps = self.substeps.unwrap_or(settings.substeps);
        settings.engine = self.engine.map_or(settings.engine, Engine::from);
        settings.toward_mechanism = (self.toward_mechanism).unwrap_or(settings.toward_mechanism);
    }

    /// The default settings with the flags applied, checked; a bad value names its flag.
    pub fn settings(&self) -> Result<Settings, ApiError> {
        let mut settings = Settings::default();
        self.apply(&mut settings);
        self.check(&settings)?;
        Ok(settings)
    }

    /// Checks `settings` (with these flags applied) and names a bad value by the flag when
    /// the user gave it; the caller reports a value from elsewhere (a study file) by its
    /// field.
    pub fn check(&self, settings: &Settings) -> Result<(), ApiError> {
        match settings.check() {
            Err(bad) if self.gave(bad.field) => Err(ApiError::user(TrainError::BadOption {
                option: flag_of(bad.field).unwrap_or(bad.field).to_string(),
                expected: bad.expected.into(),
                found: bad.found,
            })),
            _ => Ok(()),
        }
    }

    /// Whether `--epochs` or `--lr` was given: a sparse record then trains with them, not
    /// with its own budget ([`crate::train::recipe::SparseBudget`]).
    pub fn gives_budget(&self) -> bool {
        self.epochs.is_some() || self.lr.is_some()
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

/// Generates a clap mirror of a library enum: the same variants, in order, with the same
/// help, and the conversion into the library's type.
macro_rules! mirror {
    ($(#[$doc:meta])* $name:ident => $library:path { $($(#[$vdoc:meta])* $variant:ident,)* }) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
        pub enum $name {
            $($(#[$vdoc])* $variant,)*
        }

        impl From<$name> for $library {
            fn from(choice: $name) -> Self {
                match choice {
                    $($name::$variant => <$library>::$variant,)*
                }
            }
        }
    };
}

mirror! {
    /// `--precision`: the element type the network trains in ([`Precision`]).
    PrecisionArg => Precision {
        /// 32-bit floats (faster).
        F32,
        /// 64-bit floats.
        F64,
    }
}

mirror! {
    /// `--engine`: which implementation runs the training steps ([`Engine`]).
    EngineArg => Engine {
        /// The fastest engine that runs the model: the hand-fused step where it supports the
        /// model (no measured outputs), the graph backend otherwise.
        Auto,
        /// The graph backend (dfdx) for every epoch.
        Graph,
        /// The hand-fused step for every epoch, one-step and rollout: the same results up to
        /// rounding, several times faster (an error for a model it does not support; the polish
        /// and the evaluation run on the graph backend).
        Fused,
    }
}

mirror! {
    /// `gbc init --template`: a starting point ([`crate::init::Template`]).
    TemplateArg => crate::init::Template {
        /// A continuous culture on one substrate (dilution rate as input).
        Chemostat,
        /// A continuous bioreactor with product formation.
        Bioreactor,
        /// A batch culture (no input).
        Batch,
        /// A fed-batch culture with a growing volume (feed rate as input).
        Fedbatch,
    }
}

mirror! {
    /// `--message-format`: how diagnostics are printed
    /// ([`crate::diagnostics::MessageFormat`]).
    MessageFormatArg => crate::diagnostics::MessageFormat {
        /// Source excerpt with labels and help, as compilers print.
        Human,
        /// One line each: `file:line:column: error[code]: message`.
        Short,
        /// One JSON object per line.
        Json,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::with_flag;

    #[test]
    fn flags_override_and_bad_flags_are_named_as_typed() {
        let flags = TrainingFlags {
            batch: Some(0),
            ..TrainingFlags::default()
        };
        let message: String = match flags.settings() {
            Err(ApiError::User(reports)) => reports.iter().map(|r| r.to_string()).collect(),
            other => panic!("expected a user error, found {other:?}"),
        };
        assert!(message.contains("--batch") && !message.contains("batch_size"));
        let flags = TrainingFlags {
            lr: Some(0.01),
            precision: Some(PrecisionArg::F64),
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
        let bug = crate::engine::graph::BackendError::internal("rows differ");
        assert!(
            matches!(ApiError::user(TrainError::from(bug)), ApiError::Internal(m) if m.contains("rows differ"))
        );
        let input = TrainError::BadOption {
            option: "--batch".into(),
            expected: "a positive batch size".into(),
            found: "0".into(),
        };
        assert!(matches!(ApiError::user(input), ApiError::User(_)));
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
