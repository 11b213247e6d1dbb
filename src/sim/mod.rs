//! Simulation of models without closures.
