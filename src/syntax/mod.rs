//! Syntax: the pest binding.
