//! `gbc compare`: one comparison a user can trust (issue 25). On the same held-out
//! experiments (`--holdout`) or leave-one-experiment-out folds (`--cv`), scored by the one
//! error measure (`docs/error-measure.md`):
//!
//! - the **mechanism**: the grey box with every closure output at its prior, or zero
//!   ([`ir::Model::mechanism`]), or a closure-free model given, fitted by the one fitter of
//!   mechanistic params ([`crate::solve::fit::mechanism`], through [`train::train_run`], so
//!   that its error is the one `gbc train` reports for it) and run free on each held-out
//!   experiment from its first row;
//! - the **grey box**, trained with `gbc train`'s defaults once per seed, run free the same
//!   way: the median over seeds, the min–max range, and how many free runs diverged;
//! - the **naive forecast** ([`naive`]): the training experiments' mean at the same time
//!   since the start.
//!
//! [`run`] trains everything on `jobs` threads, [`score`] reduces the runs to scores and a
//! verdict, [`render`] writes the text table and [`html`] the report with the free runs
//! drawn side by side. The method is in `docs/compare.md`.

mod comparison;
mod error;
pub mod html;
pub mod naive;
mod options;
pub mod render;
mod run;
pub mod score;
mod scoring;
#[cfg(test)]
mod tests;

pub use comparison::Comparison;
#[cfg(test)]
pub use comparison::{MemberRun, SplitResult};
pub use error::CompareError;
pub use options::{Event, Options, Splits};
pub use run::compare;
#[cfg(test)]
pub use score::{Score, Standing, Verdict};
