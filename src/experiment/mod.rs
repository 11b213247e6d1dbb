//! Experiments: grids of training runs, results, figures (`gbc experiment`, `gbc demo`).
