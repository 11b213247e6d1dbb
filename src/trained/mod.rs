//! What is done with a trained network: its run directory (`run.json`, the weights and
//! the model's copy: [`artifacts`]), its predictions along a record and its what-if runs
//! ([`mod@predict`]), its report page ([`page`]), and `gbc train --cv`'s fold runs, each
//! saved with its held-out predictions ([`cv`]).
//!
//! It sits above [`crate::train`]: it reads training's results ([`crate::train::Trained`])
//! and options, and training never reads it (checkpoints keep their weights through
//! training's own weights file, [`crate::train::tensors`]).

pub mod artifacts;
pub mod cv;
pub mod keep;
pub mod page;
pub mod predict;
pub mod status;
