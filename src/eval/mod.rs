//! Fast numeric programs compiled from IR expressions.
