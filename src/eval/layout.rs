//! Where every quantity of a model lives in the one flat slot array compiled programs
//! read and write.

use crate::ir::{Model, Var};
use std::ops::Range;

/// Slot assignment for every quantity of a model, in the order inputs, measured states,
/// hidden states, consts, params, closure outputs (closure by closure).
///
/// Measured and hidden states are contiguous ([`Layout::state_range`]) in the same order as
/// [`Model::balances`], so an ODE state vector maps onto the slots by one copy.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    inputs: usize,
    states: usize,
    hidden: usize,
    consts: Vec<f64>,
    params: Vec<f64>,
    closure_offsets: Vec<usize>,
    len: usize,
}

impl Layout {
    /// The layout of `model`; remembers the const values and the params' initial values.
    pub fn new(model: &Model) -> Self {
        let fixed = model.inputs.len()
            + model.states.len()
            + model.hidden.len()
            + model.consts.len()
            + model.params.len();
        let mut closure_offsets = Vec::with_capacity(model.closures.len());
        let mut len = fixed;
        for closure in &model.closures {
            closure_offsets.push(len);
            len += closure.outputs.len();
        }
        Layout {
            inputs: model.inputs.len(),
            states: model.states.len(),
            hidden: model.hidden.len(),
            consts: model.consts.iter().map(|c| c.value).collect(),
            params: model.params.iter().map(|p| p.init).collect(),
            closure_offsets,
            len,
        }
    }

    /// The slot of `var`.
    ///
    /// `var` must belong to the model the layout was built from (an index out of range
    /// yields a slot that is out of range or belongs to another quantity).
    pub fn slot(&self, var: Var) -> usize {
        match var {
            Var::Input(i) => i,
            Var::State(i) => self.inputs + i,
            Var::Hidden(i) => self.inputs + self.states + i,
            Var::Const(i) => self.const_range().start + i,
            Var::Param(i) => self.param_range().start + i,
            Var::ClosureOutput { closure, output } => self.closure_offsets[closure] + output,
        }
    }

    /// Whether `var` indexes an existing quantity of the layout's model.
    pub fn contains(&self, var: Var) -> bool {
        match var {
            Var::Input(i) => i < self.inputs,
            Var::State(i) => i < self.states,
            Var::Hidden(i) => i < self.hidden,
            Var::Const(i) => i < self.consts.len(),
            Var::Param(i) => i < self.params.len(),
            Var::ClosureOutput { closure, output } => {
                let end = self
                    .closure_offsets
                    .get(closure + 1)
                    .copied()
                    .unwrap_or(self.len);
                self.closure_offsets
                    .get(closure)
                    .is_some_and(|&start| start + output < end)
            }
        }
    }

    /// Total number of slots.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Slots of the inputs.
    pub fn input_range(&self) -> Range<usize> {
        0..self.inputs
    }

    /// Slots of the measured then hidden states (the balance order).
    pub fn state_range(&self) -> Range<usize> {
        self.inputs..self.inputs + self.states + self.hidden
    }

    /// Slots of the consts.
    pub fn const_range(&self) -> Range<usize> {
        let start = self.state_range().end;
        start..start + self.consts.len()
    }

    /// Slots of the params.
    pub fn param_range(&self) -> Range<usize> {
        let start = self.const_range().end;
        start..start + self.params.len()
    }

    /// The value of const `index`, if it exists.
    pub fn const_value(&self, index: usize) -> Option<f64> {
        self.consts.get(index).copied()
    }

    /// A slot array with consts and params (at their initial values) filled in and every
    /// other slot zero.
    pub fn initial_slots(&self) -> Vec<f64> {
        let mut slots = vec![0.0; self.len];
        slots[self.const_range()].copy_from_slice(&self.consts);
        slots[self.param_range()].copy_from_slice(&self.params);
        slots
    }
}
