//! What a run does when an epoch goes non-finite (issue 24, "nothing lost"): it goes back
//! to the last finite epoch's weights and Adam state, halves the learning rate (and, in the
//! rollout phase, the longest rollout) and runs the epoch again, at most
//! [`super::RunControl::recoveries`] times; each try is a [`Recovery`], reported as a
//! warning. When the tries are used up the run ends with the last finite weights and an
//! [`super::EpochDivergence`] saying at which epoch, in which phase, why and what to try.

/// Recoveries from a non-finite epoch by default (`--recoveries`).
pub const DEFAULT_RECOVERIES: usize = 3;

/// One recovery from a non-finite epoch.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Recovery {
    /// The 1-based epoch that went non-finite.
    pub epoch: usize,
    /// What went non-finite, in words.
    pub what: String,
    /// The phase it went non-finite in.
    pub phase: EpochPhase,
    /// The epoch whose weights training went back to (0: the initial weights).
    pub back_to: usize,
    /// The learning rate of the network weights from then on.
    #[serde(with = "crate::json")]
    pub learning_rate: f64,
    /// The longest rollout from then on, in steps (1: one-step pairs).
    pub horizon: usize,
}

impl std::fmt::Display for Recovery {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            formatter,
            "epoch {} ({}) went non-finite: {}; went back to {} and continued with --lr {:e}",
            self.epoch,
            self.phase,
            self.what,
            kept_words(self.back_to),
            self.learning_rate
        )?;
        if self.horizon > 1 {
            write!(formatter, " and rollouts of at most {} steps", self.horizon)?;
        }
        Ok(())
    }
}

/// The weights of `epoch` in words ("the weights of epoch 3", "the initial weights").
pub fn kept_words(epoch: usize) -> String {
    match epoch {
        0 => "the initial weights".into(),
        epoch => format!("the weights of epoch {epoch}"),
    }
}

/// The phase of a run an epoch went non-finite in. Written into `run.json` as its words
/// ("one-step warm-up", "one-step", "rollouts of K steps", "polish"; empty in runs saved
/// before it was recorded).
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(into = "String", from = "String")]
pub enum EpochPhase {
    /// One-step pairs before the multi-step objective's rollouts.
    OneStepWarmUp,
    /// One-step pairs (the one-step objective).
    OneStep,
    /// Rollouts of this many steps.
    Rollouts(usize),
    /// The polish of the params after the epochs.
    Polish,
    /// Not recorded (a run saved before phases were).
    #[default]
    Unrecorded,
}

impl EpochPhase {
    /// The phase an epoch of `horizon` steps belongs to: one-step (the objective's, or the
    /// multi-step objective's warm-up) or rollouts of K steps.
    pub fn of_epoch(horizon: usize, multi_step: bool) -> Self {
        match (horizon, multi_step) {
            (0 | 1, true) => EpochPhase::OneStepWarmUp,
            (0 | 1, false) => EpochPhase::OneStep,
            (k, _) => EpochPhase::Rollouts(k),
        }
    }
}

impl std::fmt::Display for EpochPhase {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EpochPhase::OneStepWarmUp => formatter.write_str("one-step warm-up"),
            EpochPhase::OneStep => formatter.write_str("one-step"),
            EpochPhase::Rollouts(k) => write!(formatter, "rollouts of {k} steps"),
            EpochPhase::Polish => formatter.write_str("polish"),
            EpochPhase::Unrecorded => Ok(()),
        }
    }
}

impl From<EpochPhase> for String {
    fn from(phase: EpochPhase) -> String {
        phase.to_string()
    }
}

impl From<String> for EpochPhase {
    /// The phase its words name; words no phase has read as [`EpochPhase::Unrecorded`].
    fn from(words: String) -> Self {
        let rollouts = (words.strip_prefix("rollouts of "))
            .and_then(|rest| rest.strip_suffix(" steps"))
            .and_then(|k| k.parse().ok());
        match (words.as_str(), rollouts) {
            (_, Some(k)) => EpochPhase::Rollouts(k),
            ("one-step warm-up", _) => EpochPhase::OneStepWarmUp,
            ("one-step", _) => EpochPhase::OneStep,
            ("polish", _) => EpochPhase::Polish,
            _ => EpochPhase::Unrecorded,
        }
    }
}

/// What to try after a run went non-finite in `phase` at `learning_rate` (the last rate
/// tried).
pub fn advice(phase: &EpochPhase, learning_rate: f64) -> String {
    let lower = format!(
        "a lower learning rate (--lr {:e} or less)",
        learning_rate / 2.0
    );
    match phase {
        EpochPhase::Rollouts(_) => format!(
            "{lower}, shorter rollouts (--horizon), a longer one-step warm-up \
             (--warmup-share), --clip 1, or --precision f64"
        ),
        EpochPhase::Polish => "--polish off, or fix the params' initial values".into(),
        _ => format!(
            "{lower}, --clip 1, --substeps K (see the stiffness warnings), or --precision f64"
        ),
    }
}

/// The learning-rate scale and the longest rollout after one more recovery from an epoch
/// of `horizon` steps: the scale halved, and the rollout halved (at least 2) when it was
/// one.
pub fn backed_off((scale, cap): (f64, usize), horizon: usize) -> (f64, usize) {
    let cap = if horizon > 1 {
        (horizon / 2).max(2).min(cap)
    } else {
        cap
    };
    (scale / 2.0, cap)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backing_off_halves_the_rate_and_a_rollout_but_never_below_two_steps() {
        assert_eq!(backed_off((1.0, usize::MAX), 1), (0.5, usize::MAX));
        assert_eq!(backed_off((0.5, usize::MAX), 8), (0.25, 4));
        assert_eq!(backed_off((0.25, 4), 4), (0.125, 2));
        assert_eq!(backed_off((0.125, 2), 2), (0.0625, 2));
    }

    #[test]
    fn phases_and_advice_name_the_flags_that_help() {
        let words = |horizon, multi_step| EpochPhase::of_epoch(horizon, multi_step).to_string();
        assert_eq!(words(1, true), "one-step warm-up");
        assert_eq!(words(1, false), "one-step");
        assert_eq!(words(6, true), "rollouts of 6 steps");
        assert!(advice(&EpochPhase::Rollouts(6), 1e-3).contains("--horizon"));
        assert!(advice(&EpochPhase::OneStepWarmUp, 1e-3).contains("--lr 5e-4"));
        assert!(advice(&EpochPhase::Polish, 1e-3).contains("--polish off"));
    }

    #[test]
    fn a_phase_reads_back_from_its_words() {
        for phase in [
            EpochPhase::OneStepWarmUp,
            EpochPhase::OneStep,
            EpochPhase::Rollouts(12),
            EpochPhase::Polish,
            EpochPhase::Unrecorded,
        ] {
            assert_eq!(EpochPhase::from(phase.to_string()), phase);
        }
        assert_eq!(
            EpochPhase::from("rollouts of x steps".to_string()),
            EpochPhase::Unrecorded
        );
    }
}
