//! Where the checks collect their errors: every check runs and adds what it finds, so one
//! run reports them all.

use super::error::CheckError;

/// Where check errors are collected.
#[derive(Debug, Default)]
pub struct Sink {
    /// The errors so far, in the order found.
    pub errors: Vec<CheckError>,
}

impl Sink {
    /// Records an error.
    pub fn push(&mut self, error: CheckError) {
        self.errors.push(error);
    }
}
