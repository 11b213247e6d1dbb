//! `gbc`: the compiler of the `.gbm` grey-box modelling language.
//!
//! Pipeline (see `docs/architecture.md`): [`syntax`] parses text into the [`ast`], [`check`]
//! validates it and collects every error, [`ir`] lowers it into a plain compiled model,
//! [`eval`] turns its expressions into fast numeric programs, [`solve::ode`] integrates models
//! without closures, [`data`] reads measured records, [`engine`] builds the trainable
//! grey-box network, [`numeric`] holds the statistics, linear algebra and Levenberg–Marquardt
//! driver they all share.
//!
//! The library's whole public face is [`api`]: every other module is `pub(crate)`. The
//! command line (`src/cli/`, a module of the binary `src/main.rs`, not of this library)
//! and the Python package (`python/`) reach the compiler through `gbc::api` alone, so the
//! compiler holds that boundary.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod api;
pub(crate) mod ast;
pub(crate) mod check;
pub(crate) mod compare;
pub(crate) mod data;
pub(crate) mod diagnose;
pub(crate) mod diagnostics;
pub(crate) mod driver;
pub(crate) mod engine;
pub(crate) mod ensemble;
pub(crate) mod error;
pub(crate) mod eval;
pub(crate) mod experiment;
pub(crate) mod explain;
pub(crate) mod export;
pub(crate) mod finite;
pub(crate) mod format;
pub(crate) mod ide;
pub(crate) mod init;
pub(crate) mod io;
pub(crate) mod ir;
pub(crate) mod json;
pub(crate) mod numeric;
pub(crate) mod plot;
pub(crate) mod record;
pub(crate) mod signal;
pub(crate) mod solve;
pub(crate) mod stop;
pub(crate) mod suggest;
pub(crate) mod syntax;
pub(crate) mod train;
pub(crate) mod trained;
pub(crate) mod units;
pub(crate) mod vocabulary;
