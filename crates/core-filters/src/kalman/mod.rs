//! Gaussian filter steps (SPEC §4).
