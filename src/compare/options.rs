//! What a comparison is asked to do (its splits and options), what it trains, and what it
//! tells while it runs.

use crate::train::{Recipe, TrainOptions};

/// Which experiments are held out.
#[derive(Debug, Clone, PartialEq)]
pub enum Splits {
    /// One split: these experiments held out, the others train.
    Holdout(Vec<String>),
    /// Leave-one-experiment-out: each experiment held out in turn.
    LeaveOneOut,
}

/// How a comparison runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// The held-out experiments.
    pub splits: Splits,
    /// The grey box's seeds, one training per seed and split (the mechanism's fit takes the
    /// first).
    pub seeds: Vec<u64>,
    /// The training options of every run (their seed is replaced by each run's).
    pub training: TrainOptions,
    /// The training recipe (`gbc train`'s default).
    pub recipe: Recipe,
    /// Trainings run at a time.
    pub jobs: usize,
    /// Recoveries from a non-finite epoch per training (`gbc train --recoveries`).
    pub recoveries: usize,
}

/// One thing a comparison trains: the mechanism, or the grey box with one seed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Member {
    /// The fitted mechanism.
    Mechanism,
    /// The grey box before training (its network at zero, its params from the mechanism
    /// fit): the mechanism run through the grey box's own free run, which measures the
    /// numerical resolution of the comparison.
    Untrained,
    /// The grey box trained with this seed.
    GreyBox(u64),
}

impl std::fmt::Display for Member {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Member::Mechanism => write!(formatter, "the mechanism"),
            Member::Untrained => write!(formatter, "the grey box untrained"),
            Member::GreyBox(seed) => write!(formatter, "the grey box, seed {seed}"),
        }
    }
}

/// Something worth showing while a comparison runs.
#[derive(Debug, Clone, Copy)]
pub enum Event<'a> {
    /// Before the first run: how many trainings and fits there are.
    Started {
        /// Runs in all (per split: the mechanism and one per seed).
        runs: usize,
        /// Epochs of each grey-box training.
        epochs: usize,
    },
    /// A run finished an epoch (1-based).
    Epoch {
        /// What trains.
        member: Member,
        /// The experiments held out.
        held_out: &'a [String],
        /// The epoch.
        epoch: usize,
    },
    /// A run finished.
    Finished {
        /// What trained.
        member: Member,
        /// The experiments held out.
        held_out: &'a [String],
        /// Its wall-clock seconds.
        seconds: f64,
        /// Its mean held-out error (`None`: it failed or scored no cell).
        error: Option<f64>,
    },
}
