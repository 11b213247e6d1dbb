//! The weights file (`weights.safetensors`): the named `f64` tensors of a network, written
//! atomically and read back in the file's order. Checkpoints and saved runs both keep their
//! weights in it (the saved runs of `gbc train` among them).

use std::path::Path;

use crate::engine::graph::NamedTensor;

use super::TrainError;

/// Help of a refusal to write weights or params that are not finite.
pub const NOT_FINITE_HELP: &str = "training went non-finite; lower the learning rate (--lr) \
     or clip the gradient (--clip 1), add --substeps K, or train in --precision f64";

/// Writes `tensors` as little-endian `f64` safetensors to `path` (atomically).
pub fn write_tensors(path: &Path, tensors: &[NamedTensor]) -> Result<(), TrainError> {
    let bytes: Vec<Vec<u8>> = (tensors.iter())
        .map(|t| t.values.iter().flat_map(|v| v.to_le_bytes()).collect())
        .collect();
    let views = (tensors.iter().zip(&bytes))
        .map(|(tensor, data)| {
            let view = safetensors::tensor::TensorView::new(
                safetensors::Dtype::F64,
                tensor.shape.clone(),
                data,
            );
            view.map(|v| (tensor.name.clone(), v))
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|error| bad_run(path, error))?;
    let serialized = safetensors::serialize(views, &None).map_err(|error| bad_run(path, error))?;
    crate::io::write_atomic(path, &serialized)?;
    Ok(())
}

/// Reads the `f64` tensors of a safetensors file, in the file's order.
pub fn read_tensors(path: &Path) -> Result<Vec<NamedTensor>, TrainError> {
    let bytes = std::fs::read(path).map_err(|error| bad_run(path, error))?;
    let tensors =
        safetensors::SafeTensors::deserialize(&bytes).map_err(|error| bad_run(path, error))?;
    let mut weights = Vec::new();
    for (name, view) in tensors.tensors() {
        if view.dtype() != safetensors::Dtype::F64 {
            return Err(bad_run(
                path,
                format!("expected f64 tensors, found {:?} in `{name}`", view.dtype()),
            ));
        }
        let values = (view.data().chunks_exact(8))
            .map(|chunk| {
                let mut word = [0u8; 8];
                word.copy_from_slice(chunk);
                f64::from_le_bytes(word)
            })
            .collect();
        weights.push(NamedTensor {
            name,
            shape: view.shape().to_vec(),
            values,
        });
    }
    Ok(weights)
}

/// A run file that cannot be read or written, as [`TrainError::BadRun`].
pub(crate) fn bad_run(path: &Path, error: impl std::fmt::Display) -> TrainError {
    TrainError::BadRun {
        path: path.display().to_string(),
        reason: error.to_string(),
    }
}
