//! Closure outputs in the physics program: network output, prior and magnitude combined as
//! in spec section 3, then the declared constraint.
//!
//! A `positive` output with a prior keeps the prior exactly at `n = 0` and has no floor:
//! - `prior o *= p`: `o = max(p, 0) * g(n)` with
//!   `g(n) = max(n + 7/8, 0) + exp(8 min(n + 7/8, 0)) / 8`, which is `1 + n` (the
//!   unconstrained form) down to `n = -7/8` and `e^(8 (n + 7/8)) / 8` below, joined with
//!   value and slope: positive, `g(0) = 1` exactly (every constant a power of two), and it
//!   falls to zero about where `1 + n` does (`1/25` at `n = -1.02`), so a prior 25 times
//!   too large is corrected as easily as in the unconstrained form; `o` vanishes with its
//!   prior;
//! - `prior o += p`: `o = max(p + s n, 0)`, the additive form clipped at zero.
//!
//! An output `in [lo, hi]` starts at its prior (0 without one) clamped into the range
//! kept `w / 16` inside its ends (`w = hi - lo`), `q`: the output is
//! `lo + w sigmoid(z_q + 4 c / w)` with `z_q = ln((q - lo) / (hi - q))`, so that it is `q`
//! exactly at `n = 0`, and `c` the correction of the plain form (`s n`, or `p n` under
//! `*=`), which has unit slope where `q` is the middle of the range. The margin keeps the
//! start's slope at least a quarter of that: a prior on an end of the range cannot be
//! started at exactly, since an end is where the map's slope vanishes.
//!
//! A `positive` output without a prior is `s |n|`, computed as `max(s n, -s n)`: 0 at
//! `n = 0`, its mechanism's value. A non-negative map that is smooth and 0 at `n = 0` has
//! slope 0 there, so a network whose last layer starts at zero (as every one does) would
//! receive no gradient; the kink does not have that problem, because `max` passes the
//! gradient to its first argument at the tie (`Binary::Max`). Unlike `max(s n, 0)` it never
//! stops passing gradients: a clipped output whose first steps ask for less is 0 for every
//! sample and no later data can raise it again (a dead unit; the overflow grey box's
//! acetate secretion died so in its first epoch). Where the data ask for none, `n` hovers
//! about 0 within the optimiser's step. (Before issue 25 it was `s softplus(n)`, which
//! starts at `s ln 2`.)
//!
//! Every output is thus exactly its prior (or 0) at `n = 0`, clamped into its range. An
//! unconstrained output is the plain form of spec section 3.

use super::code::Instr;
use super::compile::Compiler;
use crate::engine::elementwise::{Binary, Unary};

/// Where the linear part of a positive factor under `*=` joins its exponential tail:
/// `n = -JOIN`, the factor there `TAIL = 1 - JOIN`.
pub const JOIN: f64 = 0.875;
/// The factor at the join, and the tail's decay length in `n`.
pub const TAIL: f64 = 1.0 - JOIN;
/// How far inside each end of its range an output `in [lo, hi]` starts at most, as a
/// share of `hi - lo` (module documentation).
pub const BOUNDED_MARGIN: f64 = 1.0 / 16.0;
use crate::engine::error::BackendError;
use crate::ir::{ClosureOutput, Constraint, PriorKind};

impl Compiler<'_> {
    /// Output `output` of closure `closure` (module documentation).
    pub(super) fn closure_output(
        &mut self,
        closure: usize,
        output: usize,
    ) -> Result<usize, BackendError> {
        if let Some(&reg) = self.closure_output_regs.get(&(closure, output)) {
            return Ok(reg);
        }
        if self.in_progress.contains(&(closure, output)) {
            return Err(BackendError::internal(
                "a closure prior depends on its own output".to_string(),
            ));
        }
        let model = self.model;
        let spec = (model.closures.get(closure))
            .and_then(|c| c.outputs.get(output))
            .ok_or_else(|| {
                BackendError::internal(format!("no closure output {closure}.{output}"))
            })?;
        let net = self.push(Instr::Net { closure, output });
        self.in_progress.push((closure, output));
        let reg = if self.free_outputs {
            self.known_part_plus(spec, net)
        } else {
            let scale = (self.scales.get(closure))
                .and_then(|s| s.get(output))
                .copied()
                .ok_or_else(|| BackendError::internal(format!("no scale for {}", spec.name)));
            scale.and_then(|scale| self.output_value(spec, net, scale))
        };
        self.in_progress.pop();
        let reg = reg?;
        self.closure_output_regs.insert((closure, output), reg);
        Ok(reg)
    }

    /// [`super::Program::compile_with_free_outputs`]: the output's value at `n = 0` when it
    /// has a prior (0 without one) plus the slot `net`.
    fn known_part_plus(&mut self, spec: &ClosureOutput, net: usize) -> Result<usize, BackendError> {
        if spec.prior.is_none() {
            return Ok(net);
        }
        let silent = self.constant(0.0);
        let known = self.output_value(spec, silent, 1.0)?;
        Ok(self.binary(Binary::Add, known, net))
    }

    /// The value of `spec` from its network output register `net` and magnitude `scale`.
    fn output_value(
        &mut self,
        spec: &ClosureOutput,
        net: usize,
        scale: f64,
    ) -> Result<usize, BackendError> {
        let positive = matches!(spec.constraint, Constraint::Positive);
        if let Constraint::Bounds(lo, hi) = spec.constraint {
            return self.bounded_output(spec, net, scale, (lo, hi));
        }
        let Some(prior) = &spec.prior else {
            let s = self.constant(scale);
            let plain = self.binary(Binary::Mul, s, net);
            if positive {
                // `max(s n, -s n) = s |n|`: 0 at `n = 0`, the gradient of `s n` at the tie.
                let zero = self.constant(0.0);
                let mirrored = self.binary(Binary::Sub, zero, plain);
                return Ok(self.binary(Binary::Max, plain, mirrored));
            }
            return Ok(self.constrain(plain, spec.constraint, scale));
        };
        let p = self.expr(&prior.expr)?;
        let zero = self.constant(0.0);
        Ok(match (prior.kind, positive) {
            (PriorKind::Mul, true) => {
                let clipped = self.binary(Binary::Max, p, zero);
                let factor = self.positive_factor(net);
                self.binary(Binary::Mul, clipped, factor)
            }
            (PriorKind::Mul, false) => {
                let one = self.constant(1.0);
                let factor = self.binary(Binary::Add, one, net);
                let combined = self.binary(Binary::Mul, p, factor);
                self.constrain(combined, spec.constraint, scale)
            }
            (PriorKind::Add, positive) => {
                let s = self.constant(scale);
                let correction = self.binary(Binary::Mul, s, net);
                let combined = self.binary(Binary::Add, p, correction);
                if positive {
                    self.binary(Binary::Max, combined, zero)
                } else {
                    self.constrain(combined, spec.constraint, scale)
                }
            }
        })
    }

    /// `g(n) = max(n + 7/8, 0) + exp(8 min(0, n + 7/8)) / 8`: `1 + n` down to `n = -7/8`,
    /// an exponential tail below with the same value and slope at the join. At `n = 0`
    /// every term is exact (`7/8 + 1/8`).
    fn positive_factor(&mut self, net: usize) -> usize {
        let zero = self.constant(0.0);
        let shift = self.constant(JOIN);
        let shifted = self.binary(Binary::Add, net, shift);
        let upper = self.binary(Binary::Max, shifted, zero);
        let lower = self.binary(Binary::Min, zero, shifted);
        let steep = self.constant(1.0 / TAIL);
        let scaled = self.binary(Binary::Mul, steep, lower);
        let decay = self.unary(Unary::Exp, scaled);
        let tail = self.constant(TAIL);
        let tail = self.binary(Binary::Mul, tail, decay);
        self.binary(Binary::Add, upper, tail)
    }

    /// An output `in [lo, hi]` (module documentation): its start `q` (the prior, or 0,
    /// clamped into the range short of its ends) moved by the correction through a sigmoid.
    fn bounded_output(
        &mut self,
        spec: &ClosureOutput,
        net: usize,
        scale: f64,
        (lo, hi): (f64, f64),
    ) -> Result<usize, BackendError> {
        let (start, correction) = match &spec.prior {
            Some(prior) => {
                let p = self.expr(&prior.expr)?;
                let factor = match prior.kind {
                    PriorKind::Mul => p,
                    PriorKind::Add => self.constant(scale),
                };
                (p, self.binary(Binary::Mul, factor, net))
            }
            None => {
                let s = self.constant(scale);
                (self.constant(0.0), self.binary(Binary::Mul, s, net))
            }
        };
        let margin = (hi - lo) * BOUNDED_MARGIN;
        let top = self.constant(hi - margin);
        let bottom = self.constant(lo + margin);
        let below_top = self.binary(Binary::Min, start, top);
        let q = self.binary(Binary::Max, below_top, bottom);
        let low = self.constant(lo);
        let high = self.constant(hi);
        let above = self.binary(Binary::Sub, q, low);
        let under = self.binary(Binary::Sub, high, q);
        let odds = self.binary(Binary::Div, above, under);
        let centre = self.unary(Unary::Log, odds);
        let slope = self.constant(4.0 / (hi - lo));
        let moved = self.binary(Binary::Mul, slope, correction);
        let argument = self.binary(Binary::Add, centre, moved);
        Ok(self.constrain(argument, Constraint::Bounds(lo, hi), 1.0))
    }
}
