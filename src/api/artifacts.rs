//! The files a run writes, as typed values: its metadata (`run.json`, a [`RunInfo`]) with
//! the network ([`save`], [`load`], [`restore`]) and its weights (`weights.safetensors`,
//! [`read_tensors`], [`write_tensors`]), for tools that read or rewrite run directories.
//! Non-finite numbers are written by name (`"inf"`, `"nan"`) and read back.

pub use crate::train::tensors::{read_tensors, write_tensors};
pub use crate::train::{BalanceFit, Divergence, ErrorSet, ParamEstimate};
pub use crate::trained::artifacts::{load, restore, save, RunInfo};
