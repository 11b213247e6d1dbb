//! Integration tests: one binary, a module per feature.

mod cli;
mod golden;
mod parser;
