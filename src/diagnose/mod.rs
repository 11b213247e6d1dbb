//! Sim-to-real gap diagnosis (`gbc diagnose`).
