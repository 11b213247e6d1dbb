//! Training of grey-box models on data.

#[cfg(test)]
pub(crate) mod fixtures;
