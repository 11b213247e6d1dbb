//! `gbc simulate --range NAME=LO..HI`: the range a plain simulation stays in, judged by the
//! one rule every free run is judged by ([`PhysicalRange`], docs/training.md "Divergence").

use super::{CommandError, SimulateError};
use crate::ir::Model;
use crate::sim::Trajectory;
use crate::train::PhysicalRange;

/// `NAME=LO..HI` (either side may be left out).
pub(super) fn parse_range(argument: &str) -> Result<(String, f64, f64), String> {
    let expected = || format!("expected NAME=LO..HI (e.g. `S=0..50`), found `{argument}`");
    let (name, bounds) = argument.split_once('=').ok_or_else(expected)?;
    let (lo, hi) = bounds.split_once("..").ok_or_else(expected)?;
    let bound = |text: &str, open: f64| match text.trim() {
        "" => Ok(open),
        text => (text.parse::<f64>().ok().filter(|v| !v.is_nan())).ok_or_else(expected),
    };
    let (lo, hi) = (bound(lo, f64::NEG_INFINITY)?, bound(hi, f64::INFINITY)?);
    if lo >= hi {
        return Err(format!("expected LO below HI in `{argument}`"));
    }
    Ok((name.trim().to_string(), lo, hi))
}

/// The range a plain simulation stays in: unbounded but for `--range` (docs/training.md,
/// "Free runs and the physical range").
pub(super) fn simulation_range(
    model: &Model,
    ranges: &[(String, f64, f64)],
) -> Result<PhysicalRange, CommandError> {
    let names: Vec<&str> = model.states.iter().map(|s| s.name.as_str()).collect();
    let mut range = PhysicalRange::unbounded(names.len());
    for (name, lo, hi) in ranges {
        let index = names.iter().position(|n| n == name).ok_or_else(|| {
            CommandError::user(SimulateError::UnknownRangeState {
                name: name.clone(),
                states: crate::suggest::did_you_mean(name, &names, "measured states"),
            })
        })?;
        (range.lower[index], range.upper[index]) = (*lo, *hi);
    }
    Ok(range)
}

/// Cuts `trajectory` before the first sample outside `range`, warning where and why.
pub(super) fn stop_outside(model: &Model, trajectory: &mut Trajectory, range: &PhysicalRange) {
    let names: Vec<String> = model.states.iter().map(|s| s.name.clone()).collect();
    let run = (trajectory.times.as_slice(), trajectory.states.as_slice());
    if let Some(divergence) = range.first_exit(&names, "", run) {
        eprintln!("warning: {divergence}; the run stops before it");
        trajectory.truncate(divergence.row);
    }
}

#[cfg(test)]
mod tests {
    use super::parse_range;

    #[test]
    fn ranges_parse_with_either_side_open_and_refuse_an_empty_one() {
        assert_eq!(parse_range("S=0..5"), Ok(("S".into(), 0.0, 5.0)));
        assert_eq!(
            parse_range("S=-0.1.."),
            Ok(("S".into(), -0.1, f64::INFINITY))
        );
        assert_eq!(
            parse_range(" X = ..2"),
            Ok(("X".into(), f64::NEG_INFINITY, 2.0))
        );
        assert!(parse_range("S=5..1").is_err());
        assert!(parse_range("S=0:5").is_err());
        assert!(parse_range("S=a..1").is_err());
    }
}
