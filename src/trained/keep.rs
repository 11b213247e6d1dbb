//! Where a family of saved runs goes and what each one's `run.json` records: the folds of
//! `gbc train --cv` ([`super::cv`]) and the members of an ensemble (`crate::ensemble`).

use std::path::PathBuf;

/// Where the runs are written and what they record.
#[derive(Debug, Clone)]
pub struct Keep<'a> {
    /// The run directory the runs go under (the folds' `cv/`; an ensemble's
    /// `ensemble.json` and `members/`).
    pub directory: PathBuf,
    /// The model file as given, and its text (for each run's `run.json`).
    pub model: (&'a str, &'a str),
    /// The data files, in words.
    pub data: &'a str,
    /// Recoveries from a non-finite epoch per run ([`crate::train::RunControl::recoveries`]).
    pub recoveries: usize,
}
