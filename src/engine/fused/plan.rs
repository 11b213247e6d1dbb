//! The fixed layout of a fused step: where each closure's tensors sit in the one flat weight
//! vector, and how its raw embedding columns are normalised and completed by the stage
//! estimate. Built once from the model and the [`Setup`], the same way the graph backend
//! builds its network, so the two read the same [`NamedTensor`] lists.

use crate::engine::error::BackendError;
use crate::engine::graph::layout::{closure_layout, ClosureLayout};
use crate::engine::setup::Setup;
use crate::ir::{self, Activation};
use crate::numeric::NamedTensor;

/// One closure network's place in the step.
#[derive(Debug, Clone)]
pub struct ClosurePlan {
    /// Layer widths: the embedding width, the hidden widths, the number of outputs.
    pub widths: Vec<usize>,
    /// Hidden-layer activation.
    pub activation: Activation,
    /// Start of each layer's weight (`widths[l] x widths[l + 1]`, row-major) in the flat
    /// weight vector.
    pub weight_at: Vec<usize>,
    /// Start of each layer's bias.
    pub bias_at: Vec<usize>,
    /// The graph backend's layout of the closure: its embedding normalisation
    /// ([`ClosureLayout::normalise_into`]) is the fused step's too.
    pub layout: ClosureLayout,
    /// `(column, state index, 1 / std)` of every lag-0 state column.
    pub stage_columns: Vec<(usize, usize, f64)>,
}

impl ClosurePlan {
    /// Number of affine layers.
    pub fn layers(&self) -> usize {
        self.widths.len() - 1
    }

    /// The embedding width (network inputs).
    pub fn width(&self) -> usize {
        self.widths[0]
    }
}

/// The layout of every closure and of the params in the flat weight vector.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The closures, in model order.
    pub closures: Vec<ClosurePlan>,
    /// Start and length of the raw params in the flat weight vector (length 0 if none).
    pub params: (usize, usize),
    /// Start and length of every named tensor, in [`NamedTensor`] order.
    pub tensors: Vec<(usize, usize)>,
    /// Names and shapes of the tensors (values empty).
    pub names: Vec<(String, Vec<usize>)>,
}

impl Plan {
    /// Lays out `model`'s tensors in the order of `template` (the graph backend's
    /// [`crate::engine::graph::Network::weights`]), checking that the two agree.
    pub fn build(
        model: &ir::Model,
        setup: &Setup,
        template: &[NamedTensor],
    ) -> Result<Plan, BackendError> {
        let mut tensors = Vec::with_capacity(template.len());
        let mut start = 0;
        for tensor in template {
            tensors.push((start, tensor.values.len()));
            start += tensor.values.len();
        }
        let mut next_tensor = 0;
        let mut closures = Vec::with_capacity(model.closures.len());
        for closure in &model.closures {
            let plan = closure_plan(model, closure, setup, &tensors, next_tensor)?;
            next_tensor += 2 * plan.layers();
            closures.push(plan);
        }
        let params = match template.get(next_tensor) {
            Some(tensor) if tensor.name == crate::vocabulary::PARAMS_TENSOR => tensors[next_tensor],
            _ => (start, 0),
        };
        let expected = next_tensor + usize::from(params.1 > 0);
        if expected != template.len() || params.1 != model.params.len() {
            return Err(BackendError::internal(format!(
                "the fused step expected {expected} tensors, the network has {}",
                template.len()
            )));
        }
        let names = (template.iter())
            .map(|t| (t.name.clone(), t.shape.clone()))
            .collect();
        Ok(Plan {
            closures,
            params,
            tensors,
            names,
        })
    }
}

fn closure_plan(
    model: &ir::Model,
    closure: &ir::Closure,
    setup: &Setup,
    tensors: &[(usize, usize)],
    first_tensor: usize,
) -> Result<ClosurePlan, BackendError> {
    let mut widths = vec![closure.embedding.width()];
    widths.extend(closure.network.hidden.iter().copied());
    widths.push(closure.outputs.len());
    let (mut weight_at, mut bias_at) = (Vec::new(), Vec::new());
    for layer in 0..widths.len() - 1 {
        let index = first_tensor + 2 * layer;
        let (weight, bias) = tensors
            .get(index)
            .zip(tensors.get(index + 1))
            .ok_or_else(|| BackendError::internal("the network has too few tensors"))?;
        if weight.1 != widths[layer] * widths[layer + 1] || bias.1 != widths[layer + 1] {
            return Err(BackendError::internal(format!(
                "layer {layer} of closure `{}` has an unexpected size",
                closure.name
            )));
        }
        weight_at.push(weight.0);
        bias_at.push(bias.0);
    }
    let layout = closure_layout(model, closure, setup, first_tensor)?;
    let stage_columns = (layout.state_columns.entries.iter())
        .map(|entry| (entry.column, entry.state, entry.factor))
        .collect();
    Ok(ClosurePlan {
        widths,
        activation: closure.network.activation,
        weight_at,
        bias_at,
        layout,
        stage_columns,
    })
}
