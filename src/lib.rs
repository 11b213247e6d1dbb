//! `gbc`: the compiler of the `.gbm` grey-box modelling language.
//!
//! Pipeline (see `docs/architecture.md`): [`syntax`] parses text into the [`ast`], [`check`]
//! validates it and collects every error, [`ir`] lowers it into a plain compiled model,
//! [`eval`] turns its expressions into fast numeric programs, [`solve::ode`] integrates models
//! without closures, [`data`] reads measured records, [`engine`] builds the trainable
//! grey-box network, [`numeric`] holds the statistics, linear algebra and Levenberg–Marquardt
//! driver they all share, and [`cli`] is the command-line edge that renders diagnostics.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod api;
pub mod ast;
pub mod check;
pub mod cli;
pub mod compare;
pub mod data;
pub mod diagnose;
pub mod diagnostics;
pub mod driver;
pub mod engine;
pub mod ensemble;
pub mod error;
pub mod eval;
pub mod experiment;
pub mod explain;
pub mod export;
pub mod finite;
pub mod format;
pub mod ide;
pub mod init;
pub mod io;
pub mod ir;
pub mod json;
pub mod numeric;
pub mod plot;
pub mod record;
pub mod signal;
pub mod solve;
pub mod stop;
pub mod suggest;
pub mod syntax;
pub mod train;
pub mod trained;
pub mod units;
pub mod vocabulary;
