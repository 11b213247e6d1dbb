//! What fixes an engine besides the model ([`Setup`]: step, sub-steps, element type,
//! seed, normalisation, closure magnitudes), and the one match on the element type that
//! both engines' wrappers run their calls through ([`dispatch`]).

use crate::ir;
use crate::record::Normalisation;
use crate::solve::ode::tableau::RK4;

/// The element type the network trains in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// 32-bit floats (faster).
    #[default]
    F32,
    /// 64-bit floats.
    F64,
}

impl Precision {
    /// The name in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

/// Everything besides the model that fixes the network.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    /// The nominal step `h`: the integration grid's longest step (`--dt`; the sampling step
    /// of a uniform record), taken by batch rows that give no step of their own.
    pub step: f64,
    /// RK4 sub-steps per sample (1 = the paper's single step).
    pub substeps: usize,
    /// Element type.
    pub precision: Precision,
    /// Seed of the weight initialisation.
    pub seed: u64,
    /// Normalisation of embeddings and loss.
    pub normalisation: Normalisation,
    /// Magnitude `s_o` of every closure output, `scales[closure][output]`.
    pub scales: Vec<Vec<f64>>,
}

impl Setup {
    /// Number of distinct stage times per step at which embeddings are needed: RK4's
    /// ([`crate::solve::ode::tableau::Tableau::stage_times`]: `2K + 1`, offsets `m h / 2K`,
    /// `m = 0..=2K`) for `der` models, 1 for `next` models.
    pub fn stage_offsets(&self, dynamics: ir::Dynamics) -> usize {
        match dynamics {
            ir::Dynamics::Continuous => RK4.stage_times(self.substeps),
            ir::Dynamics::Discrete => 1,
        }
    }
}

/// Runs `$body` with `$net` bound to whichever precision the caller's `Inner::Single` /
/// `Inner::Double` value holds (the graph engine's [`crate::engine::graph::Network`] and
/// the fused engine's [`crate::engine::fused::FusedNetwork`] share that shape).
macro_rules! dispatch {
    ($self:expr, $net:ident => $body:expr) => {
        match &$self.inner {
            Inner::Single($net) => $body,
            Inner::Double($net) => $body,
        }
    };
    (mut $self:expr, $net:ident => $body:expr) => {
        match &mut $self.inner {
            Inner::Single($net) => $body,
            Inner::Double($net) => $body,
        }
    };
}
pub(crate) use dispatch;
