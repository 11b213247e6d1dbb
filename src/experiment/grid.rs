//! The grid of runs of a study and its slices: every (model, size, replicate) is one
//! [`RunSpec`] with a stable id, and `--shard K/N` picks every N-th run of the grid in a
//! fixed order, so the N slices partition the grid whatever machine runs them.

use std::fmt;
use std::str::FromStr;

use super::{ExperimentError, Study};

/// One training run of the grid.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunSpec {
    /// Stable id: `<label>-n<size>-r<replicate>` (e.g. `greybox-n500-r03`); the file name
    /// of its results.
    pub id: String,
    /// Index into the study's models.
    pub model: usize,
    /// Number of training pairs.
    pub size: usize,
    /// Replicate number, from 0.
    pub replicate: usize,
    /// Seed of initialisation and shuffling: the study's first seed plus the replicate.
    pub seed: u64,
}

impl RunSpec {
    /// Work of the run in pair-epochs (for progress and scheduling).
    pub fn cost(&self, epochs: usize) -> u64 {
        (self.size as u64) * (epochs as u64)
    }
}

/// The id of a run.
pub fn run_id(label: &str, size: usize, replicate: usize) -> String {
    format!("{label}-n{size}-r{replicate:02}")
}

/// Every run of `study`, largest training size first (so a pool that takes runs in order
/// starts the longest ones first), then replicate, then model.
pub fn grid(study: &Study) -> Vec<RunSpec> {
    let mut sizes = study.sorted_sizes();
    sizes.reverse();
    let mut runs = Vec::new();
    for size in sizes {
        for replicate in 0..study.replicates {
            for (model, spec) in study.models.iter().enumerate() {
                runs.push(RunSpec {
                    id: run_id(&spec.label, size, replicate),
                    model,
                    size,
                    replicate,
                    seed: study.first_seed.wrapping_add(replicate as u64),
                });
            }
        }
    }
    runs
}

/// Slice `index` (1-based) of `count` of a grid: `--shard K/N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// K, from 1 to N.
    pub index: usize,
    /// N.
    pub count: usize,
}

impl Shard {
    /// The whole grid.
    pub const ALL: Shard = Shard { index: 1, count: 1 };

    /// The runs of `runs` that belong to this slice: positions `K-1, K-1+N, K-1+2N, ...`
    /// (round robin over the largest-first order, so slices get similar work).
    pub fn select<'a>(&self, runs: &'a [RunSpec]) -> Vec<&'a RunSpec> {
        (runs.iter().enumerate())
            .filter(|(position, _)| position % self.count == self.index - 1)
            .map(|(_, run)| run)
            .collect()
    }

    /// Whether this is the whole grid.
    pub fn is_all(&self) -> bool {
        self.count == 1
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl FromStr for Shard {
    type Err = ExperimentError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let bad = || ExperimentError::BadOption {
            option: "--shard".into(),
            expected: "`K/N` with 1 <= K <= N, e.g. `3/8`".into(),
            found: format!("`{text}`"),
        };
        let (index, count) = text.split_once('/').ok_or_else(bad)?;
        let index: usize = index.trim().parse().map_err(|_| bad())?;
        let count: usize = count.trim().parse().map_err(|_| bad())?;
        if index == 0 || count == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}
