//! How a model is trained beyond the basic options: the objective (the paper's one-step
//! loss or free-run rollouts with a curriculum), the params' own learning rate, gradient
//! clipping, the final polish of the params and the range a free run must stay in.
//!
//! **Multi-step objective** (the default): the first `warmup_share` of the epochs train on
//! one-step pairs as in the paper; then each epoch cuts the training pairs into
//! consecutive windows of `K` steps (multiple shooting: every window starts from the
//! data, the phase of the cut drawn anew each epoch) and minimises the mean squared
//! normalised error of the free runs over every window ([`crate::engine::windows`]), gradients
//! through the whole rollout. `K` grows linearly from 2 to `horizon` over the next
//! `ramp_share` of the epochs (the curriculum) and stays there. An epoch predicts each
//! training pair once whatever `K` is, so an epoch costs about as much as a one-step one
//! when a batch holds as many windows as a one-step batch holds pairs.
//!
//! **One-step objective** ([`Recipe::paper`]): every epoch on one-step pairs, one learning
//! rate, no polish: Lovelett et al. (2020), section 2.

use crate::ir;

/// The loss training minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Objective {
    /// The paper's: the mean squared normalised error of one-step predictions.
    OneStep,
    /// Free-run rollouts of up to `horizon` steps after a one-step warm-up.
    #[default]
    MultiStep,
}

impl Objective {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Objective::OneStep => "one-step",
            Objective::MultiStep => "multi-step",
        }
    }
}

/// Which implementation runs the training steps (one-step pairs and rollout windows).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// The fastest engine that runs the model: the hand-fused step where it supports the
    /// model (no measured outputs), the graph backend otherwise.
    #[default]
    Auto,
    /// The graph backend (dfdx) for every epoch.
    Graph,
    /// The hand-fused step for every epoch, one-step and rollout: the same results up to
    /// rounding, several times faster (an error for a model it does not support; the polish
    /// and the evaluation run on the graph backend).
    Fused,
}

impl Engine {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Auto => "auto",
            Engine::Graph => "graph",
            Engine::Fused => "fused",
        }
    }

    /// The fused step for `model`, if this engine runs one: always for
    /// [`Engine::Fused`] (a model it cannot run is an error), where it supports the model
    /// for [`Engine::Auto`], never for [`Engine::Graph`].
    pub fn fused_step(
        self,
        model: &ir::Model,
        setup: &crate::engine::graph::Setup,
    ) -> Result<Option<crate::engine::fused::FusedNetwork>, crate::engine::graph::BackendError>
    {
        use crate::engine::graph::BackendError;
        match self {
            Engine::Graph => Ok(None),
            Engine::Fused => crate::engine::fused::FusedNetwork::build(model, setup).map(Some),
            Engine::Auto => match crate::engine::fused::FusedNetwork::build(model, setup) {
                Ok(fused) => Ok(Some(fused)),
                Err(BackendError::Unsupported { .. }) => Ok(None),
                Err(error) => Err(error),
            },
        }
    }
}

/// Where the params come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ParamSource {
    /// For the multi-step objective, from the balances when
    /// [`super::balances::applicable`] (then held fixed while the network trains); else
    /// trained with the network.
    #[default]
    Auto,
    /// Estimated from the balances alone before training, held fixed ([`super::balances`]).
    Balances,
    /// Trained with the network by Adam (and polished, see [`Recipe::polish`]): the paper's.
    Train,
}

/// Default longest rollout, in steps.
pub const DEFAULT_HORIZON: usize = 50;
/// Default share of epochs trained one-step before rollouts start.
pub const DEFAULT_WARMUP_SHARE: f64 = 0.7;
/// Default share of epochs over which the rollout grows to its full horizon.
pub const DEFAULT_RAMP_SHARE: f64 = 0.15;
/// Default factor of the physical range a free run must stay in (see [`Recipe`]).
pub const DEFAULT_RANGE_FACTOR: f64 = 10.0;

/// Training choices beyond [`super::TrainOptions`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Recipe {
    /// The loss.
    pub objective: Objective,
    /// Longest rollout in steps (multi-step objective).
    pub horizon: usize,
    /// Share of the epochs trained one-step first (multi-step objective).
    #[serde(with = "crate::json")]
    pub warmup_share: f64,
    /// Share of the epochs over which the rollout grows from 2 steps to `horizon`.
    #[serde(with = "crate::json")]
    pub ramp_share: f64,
    /// Windows per Adam step (multi-step objective); `None`: the batch size.
    pub windows_per_batch: Option<usize>,
    /// Adam learning rate of the params; `None`: the network's.
    #[serde(with = "crate::json")]
    pub param_learning_rate: Option<f64>,
    /// Clip the gradient to this Euclidean norm; `None`: no clipping.
    #[serde(with = "crate::json")]
    pub max_gradient_norm: Option<f64>,
    /// After training, fit the params by Levenberg-Marquardt with the network frozen
    /// ([`super::polish`]); `None`: on for the multi-step objective, off for one-step.
    pub polish: Option<bool>,
    /// A free run stops when a measured state leaves `[-0.1 * max, factor * max]` (states
    /// never negative in training; see [`super::evaluate::UNDERSHOOT`]) or `[-factor * max|x|, factor * max|x|]`, the extremes taken
    /// over the training split, or becomes non-finite.
    #[serde(with = "crate::json")]
    pub range_factor: f64,
    /// Where the params come from (`Auto`: from the balances where they determine them).
    #[serde(default)]
    pub params: ParamSource,
    /// The budget a sparse record trains with when the epochs and the learning rate are
    /// at their defaults ([`SparseBudget`]); `None`: always the options' own (the command
    /// line clears it when `--epochs` or `--lr` is given, even at the default value).
    #[serde(default)]
    pub sparse_budget: Option<SparseBudget>,
}

/// The training budget of a sparse record. Its rollout epoch holds a few windows (one per
/// batch of off-line assays), so one Adam step, where a dense record's holds tens: the
/// 100 epochs at 1e-3 that train a dense record move a sparse one's network by about a
/// hundredth of what it needs (`docs/training.md`, "Sparse records"). Where a sparse run
/// does not need the steps, `--toward-mechanism auto` stops it early.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SparseBudget {
    /// Epochs.
    pub epochs: usize,
    /// Adam learning rate of the network.
    #[serde(with = "crate::json")]
    pub learning_rate: f64,
}

/// The default [`SparseBudget`].
pub const SPARSE_BUDGET: SparseBudget = SparseBudget {
    epochs: 400,
    learning_rate: 1e-2,
};

impl Default for Recipe {
    fn default() -> Self {
        Recipe {
            objective: Objective::MultiStep,
            horizon: DEFAULT_HORIZON,
            warmup_share: DEFAULT_WARMUP_SHARE,
            ramp_share: DEFAULT_RAMP_SHARE,
            windows_per_batch: None,
            param_learning_rate: None,
            max_gradient_norm: None,
            polish: None,
            range_factor: DEFAULT_RANGE_FACTOR,
            params: ParamSource::Auto,
            sparse_budget: Some(SPARSE_BUDGET),
        }
    }
}

impl Recipe {
    /// The paper's recipe: one-step loss, one learning rate, no polish.
    pub fn paper() -> Recipe {
        Recipe {
            objective: Objective::OneStep,
            polish: Some(false),
            params: ParamSource::Train,
            sparse_budget: None,
            ..Recipe::default()
        }
    }

    /// Whether the params are to be estimated from the balances before training (where
    /// they determine them: see [`super::balances::applicable`]).
    pub fn params_from_balances(&self) -> bool {
        match self.params {
            ParamSource::Balances => true,
            ParamSource::Train => false,
            ParamSource::Auto => self.objective == Objective::MultiStep,
        }
    }

    /// Whether the params are polished after training.
    pub fn polishes(&self, model: &ir::Model) -> bool {
        !model.params.is_empty()
            && self
                .polish
                .unwrap_or(self.objective == Objective::MultiStep)
    }

    /// The first epoch (1-based, of `epochs`) whose rollout has its final length: before it
    /// the objective still changes (one-step warm-up, then the growing rollout), so early
    /// stopping counts from there.
    pub fn full_horizon_from(&self, epochs: usize) -> usize {
        let last = self.horizon_at(epochs.max(1), epochs);
        (1..=epochs.max(1))
            .find(|&epoch| self.horizon_at(epoch, epochs) == last)
            .unwrap_or(1)
    }

    /// The rollout length of 1-based `epoch` out of `epochs` (1: one-step pairs).
    pub fn horizon_at(&self, epoch: usize, epochs: usize) -> usize {
        if self.objective == Objective::OneStep || self.horizon <= 1 {
            return 1;
        }
        let progress = (epoch - 1) as f64 / epochs.max(1) as f64;
        if progress < self.warmup_share {
            return 1;
        }
        let ramp = ((progress - self.warmup_share) / self.ramp_share.max(1e-12)).min(1.0);
        let grown = 2.0 + ramp * (self.horizon as f64 - 2.0);
        ((grown + 1e-9).floor() as usize).clamp(2, self.horizon)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curriculum_warms_up_one_step_then_grows_to_the_horizon() {
        let recipe = Recipe {
            horizon: 10,
            warmup_share: 0.5,
            ramp_share: 0.25,
            ..Recipe::default()
        };
        let schedule: Vec<usize> = (1..=100).map(|e| recipe.horizon_at(e, 100)).collect();
        assert!(schedule[..50].iter().all(|&k| k == 1));
        assert_eq!(schedule[50], 2);
        assert!(schedule.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(schedule[62], 5);
        assert!(schedule[75..].iter().all(|&k| k == 10));
        assert!((1..=100).all(|e| Recipe::paper().horizon_at(e, 100) == 1));
    }

    /// Early stopping counts from the first epoch of the full rollout: every earlier epoch
    /// is shorter, every later one full; a one-step recipe counts from the first epoch.
    #[test]
    fn early_stopping_counts_from_the_full_rollout() {
        let recipe = Recipe::default();
        for epochs in [1, 7, 100, 333] {
            let from = recipe.full_horizon_from(epochs);
            let last = recipe.horizon_at(epochs, epochs);
            assert!(
                (1..from).all(|e| recipe.horizon_at(e, epochs) < last),
                "{epochs}"
            );
            assert!((from..=epochs).all(|e| recipe.horizon_at(e, epochs) == last));
        }
        assert!(
            recipe.full_horizon_from(100) > 70,
            "after the one-step warm-up"
        );
        let one_step = Recipe {
            objective: Objective::OneStep,
            ..Recipe::default()
        };
        assert_eq!(one_step.full_horizon_from(100), 1);
    }
}
