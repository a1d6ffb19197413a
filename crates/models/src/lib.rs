//! # models
//!
//! Structures, excitation, integrators, data generation and the filter partitions of the
//! N-storey Bouc–Wen shear chain (SPEC §1–3, §5–6).
