//! Numbers as a person reads them in reports.

/// A number with 3 significant digits, in plain or scientific notation; "diverged" for an
/// infinite gap.
pub fn num(value: f64) -> String {
    if !value.is_finite() {
        return if value.is_nan() {
            "n/a".into()
        } else {
            "diverged".into()
        };
    }
    let magnitude = value.abs();
    if magnitude != 0.0 && !(1e-3..1e5).contains(&magnitude) {
        format!("{value:.2e}")
    } else {
        let decimals = if magnitude == 0.0 {
            0
        } else {
            (2 - magnitude.log10().floor() as i32).max(0) as usize
        };
        format!("{value:.decimals$}")
    }
}
