//! Rendering and location of diagnostics.
