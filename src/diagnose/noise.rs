//! The measurement noise, estimated from the data alone.
//!
//! For white noise of standard deviation `sigma` on a signal that is smooth at the sampling
//! scale, take three consecutive measured cells of one state, `(t0, x0)`, `(t1, x1)`,
//! `(t2, x2)`: the middle one's distance from the line through the outer two,
//! `d = x1 - (a x0 + b x2)` with `a = (t2 - t1) / (t2 - t0)` and `b = (t1 - t0) / (t2 - t0)`,
//! is the noise's `e1 - a e0 - b e2`, of variance `sigma^2 (1 + a^2 + b^2)` (on uniform
//! rows, `a = b = 1/2`: a quarter of the second difference, whose variance is
//! `6 sigma^2`). We average `d^2 / (1 + a^2 + b^2)` over the training cells of every
//! experiment after dropping the largest 5 % (input switches bend the signal), and undo the
//! bias that trimming a Gaussian sample introduces. In normalised units (divided by the
//! training std), `sigma^2` is the gap a perfect model would show: the *noise floor*.
//! Sparse cells make the signal's own curvature between them count as noise, so the floor
//! errs high on thinned records.

use super::split::Split;

/// Fraction of the largest squared deviations ignored.
const TRIM: f64 = 0.05;
/// `E[z^2 | |z| <= q]` for a standard normal `z` and `q` its two-sided 95 % quantile
/// (1.95996): `1 - 2 q phi(q) / 0.95`.
const TRIMMED_SECOND_MOMENT: f64 = 0.758_547;

/// The noise variance of one column of cells at `times` (in its units squared), from its
/// measured cells; 0 with fewer than three.
#[cfg(test)]
pub fn noise_variance(times: &[f64], cells: &[Option<f64>]) -> f64 {
    let samples: Vec<(f64, f64)> = (times.iter().zip(cells))
        .filter_map(|(&t, cell)| cell.map(|v| (t, v)))
        .collect();
    let squares: Vec<f64> = samples.windows(3).filter_map(deviation).collect();
    trimmed_mean(squares)
}

/// `d^2 / (1 + a^2 + b^2)` of three samples (`None` if two share a time).
fn deviation(window: &[(f64, f64)]) -> Option<f64> {
    let [(t0, x0), (t1, x1), (t2, x2)] = [window[0], window[1], window[2]];
    let span = t2 - t0;
    if !(t1 > t0 && t2 > t1) {
        return None;
    }
    let (a, b) = ((t2 - t1) / span, (t1 - t0) / span);
    let d = x1 - (a * x0 + b * x2);
    Some(d * d / (1.0 + a * a + b * b))
}

fn trimmed_mean(mut squares: Vec<f64>) -> f64 {
    if squares.is_empty() {
        return 0.0;
    }
    squares.sort_by(f64::total_cmp);
    let keep = ((squares.len() as f64) * (1.0 - TRIM)).ceil().max(1.0) as usize;
    let kept = &squares[..keep.min(squares.len())];
    let mean = kept.iter().sum::<f64>() / kept.len() as f64;
    mean / TRIMMED_SECOND_MOMENT
}

/// Per measured state, the noise variance in normalised units, pooled over the training
/// parts of every experiment.
pub fn noise_floors(split: &Split) -> Vec<f64> {
    let norm = &split.normalisation;
    (0..norm.state_std.len())
        .map(|k| {
            let squares: Vec<f64> = (split.training())
                .flat_map(|(_, record, rows)| {
                    let samples: Vec<(f64, f64)> = (rows.clone())
                        .filter_map(|row| record.states[k][row].map(|v| (record.times[row], v)))
                        .collect();
                    samples.windows(3).filter_map(deviation).collect::<Vec<_>>()
                })
                .collect();
            trimmed_mean(squares) / norm.state_std[k].powi(2)
        })
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
        let times: Vec<f64> = (0..column.len()).map(|k| k as f64).collect();
        let cells: Vec<Option<f64>> = column.iter().copied().map(Some).collect();
        let estimate = noise_variance(&times, &cells).sqrt();
        assert!((estimate / sigma - 1.0).abs() < 0.05, "estimate {estimate}");
    }

    #[test]
    fn a_noise_free_smooth_signal_has_almost_no_noise() {
        let column: Vec<f64> = (0..500).map(|k| (k as f64 * 0.01).exp()).collect();
        // Second differences of exp(0.01 k) are about 1e-4 exp(0.01 k): tiny against the
        // signal's spread (its std is about 36).
        let (_, std) = crate::numeric::mean_std(&column);
        let times: Vec<f64> = (0..column.len()).map(|k| k as f64).collect();
        let cells: Vec<Option<f64>> = column.iter().copied().map(Some).collect();
        assert!(noise_variance(&times, &cells).sqrt() < 1e-3 * std);
    }

    #[test]
    fn recovers_white_noise_on_irregular_times_with_missing_cells() {
        // A slow sine sampled at random times (gaps of 1 to 4), a third of the cells empty.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let sigma = 0.02;
        let (mut times, mut cells) = (Vec::new(), Vec::new());
        let mut t = 0.0;
        for k in 0..6000 {
            t += 1.0 + 3.0 * ((k * 7919 % 1000) as f64 / 1000.0);
            let noise: f64 = StandardNormal.sample(&mut rng);
            times.push(t);
            cells.push((k % 3 != 0).then_some((t * 0.002).sin() + sigma * noise));
        }
        let estimate = noise_variance(&times, &cells).sqrt();
        assert!((estimate / sigma - 1.0).abs() < 0.05, "estimate {estimate}");
    }
}
