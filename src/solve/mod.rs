//! The solving wing, below training and the diagnosis: what both ask of a model without
//! learning anything about it.
//!
//! - [`ode`]: the integration schemes (explicit Dormand–Prince, implicit Radau IIA, the
//!   switch between them), their forward sensitivities, step control and the free run of a
//!   model without closures.
//! - [`fit`]: a mechanistic model's params fitted to measured experiments by free runs,
//!   with their uncertainty and the measurement noise: the one fitter of `gbc train` and
//!   `gbc diagnose`.

pub mod fit;
pub mod ode;
