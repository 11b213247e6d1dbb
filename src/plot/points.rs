//! Preparing points for a chart: thinning long series, and keeping a runaway series from
//! flattening the others.

/// Most points drawn per series (longer series keep every k-th point and the last): a
/// figure 640 pixels wide shows no more.
pub const MAX_POINTS: usize = 1000;

/// Every k-th point and the last, so that at most about `most` remain.
pub fn thin(points: Vec<(f64, f64)>, most: usize) -> Vec<(f64, f64)> {
    let stride = points.len().div_ceil(most.max(1)).max(1);
    if stride == 1 {
        return points;
    }
    let last = points.len() - 1;
    (points.into_iter().enumerate())
        .filter(|(index, _)| index % stride == 0 || *index == last)
        .map(|(_, point)| point)
        .collect()
}

/// The finite range of `values` widened by half its span on each side (by half the
/// magnitude, at least 0.5, for a single value): room for a model to stray from the data.
/// Without finite values, everything.
pub fn widened_range(values: &[f64]) -> (f64, f64) {
    let finite = values.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if lo > hi {
        return (f64::NEG_INFINITY, f64::INFINITY);
    }
    let pad = if hi > lo {
        0.5 * (hi - lo)
    } else {
        lo.abs().max(1.0) * 0.5
    };
    (lo - pad, hi + pad)
}

/// A series clamped to `range` (so that one free run that runs away does not flatten the
/// others) and thinned to [`MAX_POINTS`], NaNs dropped; the name says `(clipped)` when any
/// point was moved.
pub fn clip(
    name: &str,
    points: impl Iterator<Item = (f64, f64)>,
    (lo, hi): (f64, f64),
) -> (String, Vec<(f64, f64)>) {
    let mut clipped = false;
    let points = (points.filter(|(_, y)| !y.is_nan()))
        .map(|(x, y)| {
            let inside = y.clamp(lo, hi);
            clipped |= inside != y;
            (x, inside)
        })
        .collect();
    let points = thin(points, MAX_POINTS);
    let name = if clipped {
        format!("{name} (clipped)")
    } else {
        name.to_string()
    };
    (name, points)
}

/// An axis title: the quantity's name with its unit, `X [g/L]`, or the name alone.
pub fn titled(name: &str, unit: Option<&str>) -> String {
    match unit {
        Some(unit) if !unit.is_empty() => format!("{name} [{unit}]"),
        _ => name.to_string(),
    }
}
