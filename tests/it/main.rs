//! Integration tests: one binary, a module per feature.

mod cli;
mod format;
mod golden;
mod parser;
