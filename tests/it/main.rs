//! Integration tests: one binary, a module per feature.

mod artifacts;
mod authoring;
mod child;
mod cli;
mod compare;
mod diagnose;
mod editor;
mod ensemble;
mod golden;
mod lsp;
mod noise;
mod records;
mod runs;
mod safety;
mod shapes;
mod stiff;
mod whatif;
