//! Atomic file output.
