//! Summary statistics: mean and standard deviation with one rule for a constant column,
//! medians and order statistics, root mean squares.

/// A standard deviation at or below this fraction of the mean's magnitude is rounding noise
/// of a constant column (see [`mean_std`]).
pub const CONSTANT_COLUMN: f64 = 1e-12;

/// Mean and population standard deviation of `values` (0 and 1 for an empty slice).
///
/// The deviation is replaced by 1 when it is not finite or not above
/// `CONSTANT_COLUMN * max(|mean|, 1e-300)`, so that a constant column keeps its errors in its
/// own units. The bound is relative because a column whose values are all equal does not
/// always get an exact 0: the mean of `n` copies of 0.1 is not 0.1 in floating point, and the
/// deviation comes out near `1e-17`, which would blow every error in that column up by
/// `1e17`. Rounding in the mean is a few ulps, about `1e-16 |mean|`, so `1e-12 |mean|`
/// separates it from any real variation by four orders of magnitude; the floor `1e-300`
/// makes a column of zeros (mean 0, deviation 0) constant too.
pub fn mean_std(values: &[f64]) -> (f64, f64) {
    let count = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / count;
    let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / count;
    let std = variance.sqrt();
    let varies = std > CONSTANT_COLUMN * mean.abs().max(1e-300) && std.is_finite();
    (mean, if varies { std } else { 1.0 })
}

/// The median of the values that are not NaN (the mean of the two middle ones for an even
/// count; two equal middle values, infinities included, are the median as they are); `None`
/// when there are none.
pub fn median(values: &[f64]) -> Option<f64> {
    let sorted = sorted_numbers(values);
    if sorted.is_empty() {
        return None;
    }
    let (low, high) = (sorted[(sorted.len() - 1) / 2], sorted[sorted.len() / 2]);
    Some(if low == high {
        high
    } else {
        (low + high) / 2.0
    })
}

/// The order statistic at `fraction` of the values that are not NaN: the
/// `floor(fraction * n)`-th smallest counting from 0 (clamped to the largest), so that
/// `0.5` gives the upper median and `0.01` the first percentile; `None` when there are none.
pub fn order_statistic(values: &[f64], fraction: f64) -> Option<f64> {
    let sorted = sorted_numbers(values);
    let last = sorted.len().checked_sub(1)?;
    let index = (fraction.clamp(0.0, 1.0) * sorted.len() as f64).floor() as usize;
    Some(sorted[index.min(last)])
}

/// The standard normal distribution function `Phi(x) = erfc(-x / sqrt 2) / 2`, through
/// `libm`'s complementary error function (a port of FreeBSD's, within an ulp or two): as
/// any other library's `Phi` to about `1e-15` (a band recomputed elsewhere from the
/// exported facts agrees); 0 and 1 in the far tails, NaN for NaN.
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// `sqrt(mean(v^2))` (0 for an empty slice).
pub fn root_mean_square(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len().max(1) as f64).sqrt()
}

/// The values that are not NaN, in ascending order.
fn sorted_numbers(values: &[f64]) -> Vec<f64> {
    let mut sorted: Vec<f64> = values.iter().copied().filter(|v| !v.is_nan()).collect();
    sorted.sort_by(f64::total_cmp);
    sorted
}
