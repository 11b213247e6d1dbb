//! Training of grey-box models on data.
