//! # models
//!
//! Structures, excitation, integrators, data generation and the filter partitions of the
//! N-storey Bouc–Wen shear chain (SPEC §1–3, §5–6).
//!
//! - [`building`]: the validated building (masses, hysteretic storeys, damping form), 0-based;
//! - [`structure`]: the N-storey shear chain with hysteretic elements, its continuous right-hand
//!   side, forward-Euler map, accelerations and restoring forces; presets in [`preset`];
//! - [`law`]: the hysteresis laws of the elements (Bouc–Wen), one file each: rate, partials,
//!   parameter names, record, validation and prior;
//! - [`integrate`]: classical RK4 (truth) and adaptive Dormand–Prince 5(4) (validation);
//! - [`excitation`] and [`readers`]: ground motions (El Centro, Kanai–Tajimi, harmonic, user
//!   records in CSV and PEER `.AT2`); [`ground_motions`]: vendored PEER NGA records by name;
//!   [`ground_between`]: the measured ground motion between its samples (linear or band-limited);
//! - [`import`]: real recordings (sensor CSV exports, CSMIP V2 records) and a channel map
//!   into a field-data set, with every repair logged;
//! - [`limits`]: the limits on every size and value that comes from a user;
//! - [`dataset`]: truth and noisy measurements from named random streams; [`description`]: a
//!   building as a user describes it (storeys, masses, hysteretic storeys, sensors);
//! - [`priors`] and [`filtering`]: the priors of SPEC §3 and the three filter partitions
//!   (augmented state, MLN-RBPF/Storvik, MPF-EKF2) implementing the `core-filters` traits.

pub mod building;
pub mod dataset;
pub mod description;
pub mod excitation;
pub mod filtering;
pub mod ground_between;
pub mod ground_motions;
pub mod import;
pub mod integrate;
pub mod law;
pub mod limits;
pub mod modal;
pub mod preset;
pub mod priors;
pub mod readers;
pub mod sensors;
pub mod structure;
