//! The range a plain simulation stays in (`--range NAME=LO..HI`), judged by the one rule
//! every free run is judged by ([`PhysicalRange`], docs/training.md "Divergence").

use super::SimulateError;
use crate::ir::Model;
use crate::solve::ode::Trajectory;
use crate::train::PhysicalRange;

/// The range a plain simulation stays in: unbounded but for `ranges`, `(state, lo, hi)`
/// (docs/training.md, "Free runs and the physical range").
pub(super) fn simulation_range(
    model: &Model,
    ranges: &[(String, f64, f64)],
) -> Result<PhysicalRange, SimulateError> {
    let names: Vec<&str> = model.states.iter().map(|s| s.name.as_str()).collect();
    let mut range = PhysicalRange::unbounded(names.len());
    for (name, lo, hi) in ranges {
        let index = (names.iter().position(|n| n == name)).ok_or_else(|| {
            SimulateError::UnknownRangeState {
                name: name.clone(),
                states: crate::suggest::did_you_mean(name, &names, "measured states"),
            }
        })?;
        (range.lower[index], range.upper[index]) = (*lo, *hi);
    }
    Ok(range)
}

/// Cuts `trajectory` before the first sample outside `range`; says where and why.
pub(super) fn stop_outside(
    model: &Model,
    trajectory: &mut Trajectory,
    range: &PhysicalRange,
) -> Option<String> {
    let names: Vec<String> = model.states.iter().map(|s| s.name.clone()).collect();
    let run = (trajectory.times.as_slice(), trajectory.states.as_slice());
    let divergence = range.first_exit(&names, "", run)?;
    trajectory.truncate(divergence.row);
    Some(divergence.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_range_bounds_its_state_and_an_unknown_name_is_refused() {
        let model = crate::driver::compile("m.gbm", "model m\nstate x = 1\nder x = x\n", &[])
            .unwrap()
            .model;
        let range = simulation_range(&model, &[("x".into(), 0.0, 2.0)]).unwrap();
        assert_eq!((range.lower[0], range.upper[0]), (0.0, 2.0));
        let unknown = simulation_range(&model, &[("y".into(), 0.0, 2.0)]).unwrap_err();
        assert!(matches!(unknown, SimulateError::UnknownRangeState { .. }));
    }
}
