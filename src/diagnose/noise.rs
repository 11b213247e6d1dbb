//! The measurement noise, estimated from the data alone.
//!
//! For white noise of standard deviation `sigma` on a signal that is smooth at the sampling
//! scale, the second difference `x[i+1] - 2 x[i] + x[i-1]` is the noise's
//! `e[i+1] - 2 e[i] + e[i-1]`, of variance `6 sigma^2`. We average its square over the
//! training rows after dropping the largest 5 % (input switches bend the signal), and
//! undo the bias that trimming a Gaussian sample introduces. In normalised units (divided
//! by the training std), `sigma^2` is the gap a perfect model would show: the *noise floor*.

use super::record::Normalisation;

/// Fraction of the largest squared second differences ignored.
const TRIM: f64 = 0.05;
/// `E[z^2 | |z| <= q]` for a standard normal `z` and `q` its two-sided 95 % quantile
/// (1.95996): `1 - 2 q phi(q) / 0.95`.
const TRIMMED_SECOND_MOMENT: f64 = 0.758_547;

/// The noise variance of one column (in its units squared).
pub fn noise_variance(column: &[f64]) -> f64 {
    let mut squares: Vec<f64> = column
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).powi(2))
        .collect();
    if squares.is_empty() {
        return 0.0;
    }
    squares.sort_by(f64::total_cmp);
    let keep = ((squares.len() as f64) * (1.0 - TRIM)).ceil().max(1.0) as usize;
    let kept = &squares[..keep.min(squares.len())];
    let mean = kept.iter().sum::<f64>() / kept.len() as f64;
    mean / (6.0 * TRIMMED_SECOND_MOMENT)
}

/// Per measured state, the noise variance in normalised units.
pub fn noise_floors(
    states: &[Vec<f64>],
    rows: std::ops::Range<usize>,
    norm: &Normalisation,
) -> Vec<f64> {
    states
        .iter()
        .zip(&norm.std)
        .map(|(column, std)| noise_variance(&column[rows.clone()]) / (std * std))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn recovers_white_noise_on_a_smooth_signal() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let sigma = 0.05;
        let column: Vec<f64> = (0..4000)
            .map(|k| {
                let t = k as f64 * 0.01;
                let noise: f64 = StandardNormal.sample(&mut rng);
                (t).sin() * 3.0 + 1.0 + sigma * noise
            })
            .collect();
        let estimate = noise_variance(&column).sqrt();
        assert!((estimate / sigma - 1.0).abs() < 0.05, "estimate {estimate}");
    }

    #[test]
    fn a_noise_free_smooth_signal_has_almost_no_noise() {
        let column: Vec<f64> = (0..500).map(|k| (k as f64 * 0.01).exp()).collect();
        // Second differences of exp(0.01 k) are about 1e-4 exp(0.01 k): tiny against the
        // signal's spread (its std is about 36).
        let (_, std) = crate::numeric::mean_std(&column);
        assert!(noise_variance(&column).sqrt() < 1e-3 * std);
    }
}
