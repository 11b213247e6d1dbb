//! How a training run ended, as `run.json` and `ensemble.json` record it.

use std::fmt;

/// How a training run (or an ensemble member's) ended. Written as its words: `finished`,
/// `failed` (training went non-finite and no recovery was left; the run's divergence says
/// where), `failed: why` (a member that could not train) or `diverged: epoch N, what` (a
/// member that went non-finite and kept its last finite weights).
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(into = "String", from = "String")]
pub enum TrainingStatus {
    /// Training ran to its end.
    #[default]
    Finished,
    /// Training failed; why, when it is not told elsewhere.
    Failed(Option<String>),
    /// Training went non-finite at `epoch` (1-based): `what` went non-finite.
    Diverged {
        /// The epoch.
        epoch: usize,
        /// What went non-finite, in words.
        what: String,
    },
}

impl fmt::Display for TrainingStatus {
    fn fmt(&self, formatter: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TrainingStatus::Finished => formatter.write_str("finished"),
            TrainingStatus::Failed(None) => formatter.write_str("failed"),
            TrainingStatus::Failed(Some(why)) => write!(formatter, "failed: {why}"),
            TrainingStatus::Diverged { epoch, what } => {
                write!(formatter, "diverged: epoch {epoch}, {what}")
            }
        }
    }
}

impl From<TrainingStatus> for String {
    fn from(status: TrainingStatus) -> String {
        status.to_string()
    }
}

impl From<String> for TrainingStatus {
    /// The status its words say; words of no status read as a failure saying them.
    fn from(words: String) -> Self {
        let diverged = (words.strip_prefix("diverged: epoch "))
            .and_then(|rest| rest.split_once(", "))
            .and_then(|(epoch, what)| Some((epoch.parse().ok()?, what.to_string())));
        if let Some((epoch, what)) = diverged {
            return TrainingStatus::Diverged { epoch, what };
        }
        match words.as_str() {
            "finished" => TrainingStatus::Finished,
            "failed" => TrainingStatus::Failed(None),
            _ => TrainingStatus::Failed(Some(
                (words.strip_prefix("failed: "))
                    .unwrap_or(&words)
                    .to_string(),
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_status_reads_back_from_its_words() {
        for status in [
            TrainingStatus::Finished,
            TrainingStatus::Failed(None),
            TrainingStatus::Failed(Some("the loss became NaN, at epoch 2".into())),
            TrainingStatus::Diverged {
                epoch: 7,
                what: "param `mu`, = inf".into(),
            },
        ] {
            assert_eq!(TrainingStatus::from(status.to_string()), status);
        }
        assert_eq!(
            TrainingStatus::from("stopped early".to_string()),
            TrainingStatus::Failed(Some("stopped early".into()))
        );
    }

    #[test]
    fn a_status_is_written_as_its_words_in_json() {
        let json = serde_json::to_string(&TrainingStatus::Finished).unwrap();
        assert_eq!(json, "\"finished\"");
        let back: TrainingStatus = serde_json::from_str("\"failed\"").unwrap();
        assert_eq!(back, TrainingStatus::Failed(None));
    }
}
