//! Why an integration stopped early, and where: the state whose balance was fastest, its
//! time scale and the step the integrator was down to, so that a stuck run names its cause
//! instead of running for hours.

use std::fmt;

/// Why an integration stopped early.
#[derive(Debug, Clone, PartialEq, thiserror::Error, miette::Diagnostic)]
pub enum IntegrationError {
    /// The step size fell to the rounding level of the time.
    #[error("step size underflow at t = {t} (step {step:e}){stuck}")]
    #[diagnostic(
        code(gbm::E0705),
        help("the model may be singular near this time (a division by a state that reaches zero, a rate that blows up); check the balance named above, or loosen --rtol/--atol")
    )]
    StepSizeUnderflow {
        /// Time reached.
        t: f64,
        /// The step size that was too small.
        step: f64,
        /// Where the system was fastest.
        stuck: Stuck,
    },
    /// The right-hand side or the state became infinite or NaN.
    #[error("the state became non-finite at t = {t}{stuck}")]
    #[diagnostic(
        code(gbm::E0706),
        help("look for a division by zero, the log or square root of a negative value, or a state that runs away")
    )]
    NonFinite {
        /// Time reached.
        t: f64,
        /// Where the system was fastest (empty when not known).
        stuck: Stuck,
    },
    /// More steps than allowed were attempted.
    #[error("gave up at t = {t} after {steps} steps{stuck}")]
    #[diagnostic(
        code(gbm::E0707),
        help("the step budget is spent: the balance named above is far faster than the run (stiff), or its rate oscillates; check its constants (a Monod or inhibition constant far below the concentrations makes a balance stiff), loosen --rtol/--atol, or raise the budget with --max-steps")
    )]
    TooManySteps {
        /// Time reached.
        t: f64,
        /// Steps attempted.
        steps: usize,
        /// Where the system was fastest.
        stuck: Stuck,
    },
    /// Asked to stop (Ctrl-C, SIGTERM; [`crate::stop`]) before the end.
    #[error("stopped at t = {t} (Ctrl-C or SIGTERM)")]
    #[diagnostic(
        code(gbm::E0719),
        help("the run was asked to stop before its end; run it again to the end")
    )]
    Stopped {
        /// Time reached.
        t: f64,
    },
}

impl IntegrationError {
    /// The time the integration reached.
    pub fn time(&self) -> f64 {
        match self {
            IntegrationError::StepSizeUnderflow { t, .. }
            | IntegrationError::NonFinite { t, .. }
            | IntegrationError::TooManySteps { t, .. }
            | IntegrationError::Stopped { t } => *t,
        }
    }

    /// The same error with the stuck state named from `names` (one per integrated state).
    pub fn named(mut self, names: &[String]) -> Self {
        let stuck = match &mut self {
            IntegrationError::StepSizeUnderflow { stuck, .. }
            | IntegrationError::NonFinite { stuck, .. }
            | IntegrationError::TooManySteps { stuck, .. } => stuck,
            IntegrationError::Stopped { .. } => return self,
        };
        if let Some(index) = stuck.state {
            stuck.name = names.get(index).cloned();
        }
        self
    }

    /// A non-finite state at `t`, with nothing known of where.
    pub fn non_finite(t: f64) -> Self {
        IntegrationError::NonFinite {
            t,
            stuck: Stuck::default(),
        }
    }
}

/// Where a system was fastest when an integration gave up: the state whose balance has the
/// largest absolute row sum of the Jacobian (an upper bound on how fast it can change
/// relative to itself), and that time scale.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stuck {
    /// Index of the state in the integrated vector (`None`: not known).
    pub state: Option<usize>,
    /// Its name, once the caller has named it ([`IntegrationError::named`]).
    pub name: Option<String>,
    /// `1 / max_i sum_j |df_i/dy_j|`, in the model's time unit (infinite where the balances
    /// do not move).
    pub time_scale: f64,
    /// The step size the integrator was down to.
    pub step: f64,
    /// Whether the implicit method was running.
    pub implicit: bool,
}

impl Stuck {
    /// The fastest balance of a Jacobian (`n x n`, row-major) at a step of size `step`.
    pub fn from_jacobian(jacobian: &[f64], n: usize, step: f64, implicit: bool) -> Stuck {
        let rows = (0..n).map(|i| {
            jacobian[i * n..(i + 1) * n]
                .iter()
                .map(|v| v.abs())
                .sum::<f64>()
        });
        let fastest = rows
            .enumerate()
            .filter(|(_, sum)| !sum.is_nan())
            .max_by(|a, b| a.1.total_cmp(&b.1));
        Stuck {
            state: fastest.map(|(i, _)| i),
            name: None,
            time_scale: fastest.map_or(f64::INFINITY, |(_, sum)| 1.0 / sum),
            step,
            implicit,
        }
    }
}

impl fmt::Display for Stuck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Some(index) = self.state else {
            return Ok(());
        };
        let method = if self.implicit {
            "implicit"
        } else {
            "explicit"
        };
        match &self.name {
            Some(name) => write!(f, ": the balance of `{name}`")?,
            None => write!(f, ": the balance of state {}", index + 1)?,
        }
        write!(
            f,
            " changes on a time scale of {:.2e} there ({method} steps of {:.2e})",
            self.time_scale, self.step
        )
    }
}
