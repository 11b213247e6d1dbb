//! A hand-fused training step (performance study, issue 8).
