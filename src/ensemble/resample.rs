//! Bootstrap draws of whole experiments: member `k`'s draws come from its own seed alone,
//! so the same `--seed` gives the same members on any number of jobs.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// What the members are trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Resample {
    /// A bootstrap of whole training experiments (as many draws as experiments, with
    /// replacement) per member: the experiments a member did not draw calibrate the band.
    Experiments,
    /// Every member on every training experiment, differing by seed alone (no member is
    /// out of bag: the band cannot be calibrated).
    None,
}

/// The stream of the generator the draws use (other users of a seed use stream 0).
const STREAM: u64 = 0x656e_7365_6d62_6c65;

/// The training experiments (indices into `0..experiments`) a member with `seed` trains
/// on: `experiments` draws with replacement under [`Resample::Experiments`], in draw order;
/// every experiment once under [`Resample::None`].
pub fn draws(resample: Resample, experiments: usize, seed: u64) -> Vec<usize> {
    match resample {
        Resample::None => (0..experiments).collect(),
        Resample::Experiments => {
            let mut random = ChaCha8Rng::seed_from_u64(seed);
            random.set_stream(STREAM);
            (0..experiments)
                .map(|_| random.gen_range(0..experiments))
                .collect()
        }
    }
}

/// The experiments of `0..experiments` not among `draws` (out of bag), in order.
pub fn out_of_bag(draws: &[usize], experiments: usize) -> Vec<usize> {
    (0..experiments).filter(|e| !draws.contains(e)).collect()
}
