//! Input programs: piecewise-constant actuator signals for simulation.
