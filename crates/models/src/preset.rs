//! Named structures with their default excitation (SPEC §1–2).
//!
//! - `paper-3dof`: three unit-mass storeys, k = 8, c = 0.25, a Bouc–Wen element between the
//!   ground and storey 1 (β = 2, γ = 1, n = 2); El Centro × 3.0 at dt = 0.005 s.
//! - `paper-3dof-harmonic`: the same structure under `3·sin(4t)` m/s² for 31.18 s.
//! - `shear-chain` with a storey count N: the same per-storey values for N storeys, Bouc–Wen
//!   element at storey 1, El Centro × 3.0 ([`Preset::from_name`]).
//! - `building-chain` with a storey count N: a chain with the modal periods of a real building
//!   (T₁ from 0.32 s at 3 storeys to 3.6 s at 40), 2 % damping in its first mode, the paper's
//!   Bouc–Wen law at storey 1 and El Centro scaled so that the element yields
//!   ([`Preset::building`]; the choice is explained in `docs/scaling.md`).

use crate::excitation::{self, GroundMotion, DEFAULT_DT, EL_CENTRO_SCALE};
use crate::filtering::ChainPrior;
use crate::structure::{BoucWen, ShearChain, StructureError};
use thiserror::Error;

/// Amplitude (m/s²), frequency (rad/s) and duration (s) of the harmonic preset (SPEC §2).
pub const HARMONIC_AMPLITUDE: f64 = 3.0;
pub const HARMONIC_OMEGA: f64 = 4.0;
pub(crate) const HARMONIC_DURATION: f64 = 31.18;

/// The default excitation of a preset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum DefaultExcitation {
    /// El Centro 1940 N-S at this amplitude scale.
    ElCentro { scale: f64 },
    /// `amplitude·sin(omega·t)` for `duration` seconds.
    Harmonic {
        amplitude: f64,
        omega: f64,
        duration: f64,
    },
}

impl DefaultExcitation {
    /// The excitation sampled at `dt`.
    pub fn ground_motion(&self, dt: f64) -> GroundMotion {
        match *self {
            DefaultExcitation::ElCentro { scale } => crate::ground_motions::el_centro()
                .scaled(scale)
                .resample_linear(dt),
            DefaultExcitation::Harmonic {
                amplitude,
                omega,
                duration,
            } => excitation::harmonic(amplitude, omega, duration, dt),
        }
    }
}

/// A named structure with its default excitation and time step.
#[derive(Debug, Clone, PartialEq)]
pub struct Preset {
    pub name: String,
    pub chain: ShearChain,
    pub(crate) excitation: DefaultExcitation,
    pub dt: f64,
}

/// Unknown preset name or impossible storey count.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PresetError {
    #[error("unknown preset `{name}`; valid presets: {}", Preset::NAMES.join(", "))]
    Unknown { name: String },
    #[error("a shear chain needs at least one storey, got {storeys}")]
    NoStorey { storeys: usize },
    #[error("hysteretic: {0}")]
    Structure(#[from] StructureError),
}

/// The Bouc–Wen element of every preset (SPEC §1): β = 2, γ = 1, n = 2. An element placed at
/// another storey ([`Preset::set_hysteretic`]) gets the same parameters.
pub(crate) const BOUC_WEN_BETA: f64 = 2.0;
pub(crate) const BOUC_WEN_GAMMA: f64 = 1.0;
pub(crate) const BOUC_WEN_N: f64 = 2.0;

/// Storey stiffness of `building-chain` over a unit mass (s⁻²).
pub const BUILDING_K: f64 = 2000.0;
/// First-mode damping ratio of `building-chain`.
pub const BUILDING_ZETA1: f64 = 0.02;
/// Amplitude scale of El Centro for `building-chain`: the record in m/s² with the model's
/// length unit taken as 1/BUILDING_SCALE m, so that the Bouc–Wen element's saturation
/// (β + γ)^(−1/n) = 0.577 units is a yield drift of 0.577/BUILDING_SCALE m (see
/// `docs/scaling.md` for the measured yielding at each N).
pub(crate) const BUILDING_SCALE: f64 = 50.0;

/// Circular frequency of mode `i` (1-based) of a uniform fixed-free chain of `storeys` equal
/// masses `m` and springs `k`: ω_i = 2√(k/m) sin((2i − 1)π / (2(2N + 1))).
pub fn uniform_chain_omega(k: f64, m: f64, storeys: usize, i: usize) -> f64 {
    let n = storeys as f64;
    2.0 * (k / m).sqrt()
        * ((2.0 * i as f64 - 1.0) * std::f64::consts::PI / (2.0 * (2.0 * n + 1.0))).sin()
}

impl Preset {
    /// Names accepted by [`Preset::from_name`].
    pub const NAMES: [&'static str; 4] = [
        "paper-3dof",
        "paper-3dof-harmonic",
        "shear-chain",
        "building-chain",
    ];

    /// The paper's structure (SPEC §1) generalised to `storeys` storeys: unit masses, k = 8,
    /// c = 0.25, Bouc–Wen element (β = 2, γ = 1, n = 2) between the ground and storey 1.
    pub fn chain(storeys: usize) -> Result<ShearChain, PresetError> {
        Self::uniform_chain(storeys, 8.0, 0.25)
    }

    /// `storeys` storeys of unit mass, stiffness `k` and damping `c`, with the paper's Bouc–Wen
    /// element between the ground and storey 1.
    fn uniform_chain(storeys: usize, k: f64, c: f64) -> Result<ShearChain, PresetError> {
        if storeys == 0 {
            return Err(PresetError::NoStorey { storeys });
        }
        Ok(ShearChain::new(
            vec![1.0; storeys],
            vec![k; storeys],
            vec![c; storeys],
            vec![BoucWen {
                storey: 0,
                beta: BOUC_WEN_BETA,
                gamma: BOUC_WEN_GAMMA,
                n: BOUC_WEN_N,
            }],
        )
        .expect("the preset values are valid"))
    }

    /// `paper-3dof` (SPEC §1–2).
    pub fn paper_3dof() -> Self {
        Self::with_storeys(3)
            .expect("3 storeys")
            .renamed("paper-3dof")
    }

    /// `paper-3dof-harmonic` (SPEC §2).
    pub(crate) fn paper_3dof_harmonic() -> Self {
        Self {
            excitation: DefaultExcitation::Harmonic {
                amplitude: HARMONIC_AMPLITUDE,
                omega: HARMONIC_OMEGA,
                duration: HARMONIC_DURATION,
            },
            ..Self::paper_3dof()
        }
        .renamed("paper-3dof-harmonic")
    }

    /// `shear-chain`: the paper's per-storey values for `storeys` storeys, El Centro × 3.0.
    pub(crate) fn with_storeys(storeys: usize) -> Result<Self, PresetError> {
        Ok(Self {
            name: "shear-chain".to_string(),
            chain: Self::chain(storeys)?,
            excitation: DefaultExcitation::ElCentro {
                scale: EL_CENTRO_SCALE,
            },
            dt: DEFAULT_DT,
        })
    }

    /// The `building-chain` structure of `storeys` storeys: unit masses, k = [`BUILDING_K`] per
    /// storey (ω₁ = 2√k sin(π / (2(2N + 1))): T₁ = 0.32, 0.49, 0.94, 1.83, 3.62 s at N = 3, 5,
    /// 10, 20, 40 — about 0.1·N s, the rule of thumb for buildings), inter-storey dampers
    /// c = 2ζ₁k/ω₁ with ζ₁ = [`BUILDING_ZETA1`] (stiffness-proportional, so mode i has
    /// ζ_i = ζ₁ω_i/ω₁), and the paper's Bouc–Wen element at storey 1.
    pub fn building_chain(storeys: usize) -> Result<ShearChain, PresetError> {
        // ω₁ is a finite number for any count, zero included (refused by `uniform_chain`).
        let omega1 = uniform_chain_omega(BUILDING_K, 1.0, storeys, 1);
        let c = 2.0 * BUILDING_ZETA1 * BUILDING_K / omega1;
        Self::uniform_chain(storeys, BUILDING_K, c)
    }

    /// `building-chain` of `storeys` storeys under El Centro × `BUILDING_SCALE` (50).
    pub fn building(storeys: usize) -> Result<Self, PresetError> {
        Ok(Self {
            name: "building-chain".to_string(),
            chain: Self::building_chain(storeys)?,
            excitation: DefaultExcitation::ElCentro {
                scale: BUILDING_SCALE,
            },
            dt: DEFAULT_DT,
        })
    }

    fn renamed(mut self, name: &str) -> Self {
        self.name = name.to_string();
        self
    }

    /// A preset by name. `storeys` overrides the number of storeys (same per-storey values);
    /// `None` keeps the preset's own (3, or 3 for `shear-chain` as well).
    pub fn from_name(name: &str, storeys: Option<usize>) -> Result<Self, PresetError> {
        let mut p = match name {
            "paper-3dof" => Self::paper_3dof(),
            "paper-3dof-harmonic" => Self::paper_3dof_harmonic(),
            "shear-chain" => Self::with_storeys(3)?,
            "building-chain" => Self::building(storeys.unwrap_or(3))?,
            _ => {
                return Err(PresetError::Unknown {
                    name: name.to_string(),
                })
            }
        };
        if let Some(n) = storeys {
            p.chain = match name {
                // Its damping depends on N (ζ₁ is fixed, ω₁ falls with N).
                "building-chain" => Self::building_chain(n)?,
                _ => Self::chain(n)?,
            };
        }
        Ok(p)
    }

    /// Moves the Bouc–Wen elements to the 0-based `storeys` (increasing; empty: a linear chain),
    /// each with the preset element's β, γ, n (SPEC §1). Masses, k and c are unchanged. The
    /// same law everywhere is the neutral choice: an element higher up sees smaller drifts and
    /// may stay nearly elastic, which `sysid simulate` shows as `max|r|/sat` per element.
    pub(crate) fn set_hysteretic(&mut self, storeys: &[usize]) -> Result<(), PresetError> {
        let elements = storeys
            .iter()
            .map(|&s| BoucWen {
                storey: s,
                beta: BOUC_WEN_BETA,
                gamma: BOUC_WEN_GAMMA,
                n: BOUC_WEN_N,
            })
            .collect();
        self.chain = ShearChain::new(
            self.chain.masses().to_vec(),
            self.chain.stiffness().to_vec(),
            self.chain.damping().to_vec(),
            elements,
        )?;
        Ok(())
    }

    /// The default prior of the filters on this preset's data, for a chain with the 0-based
    /// `hysteretic` storeys: SPEC §3's for the paper's presets (whose medians are tied to the
    /// paper's values: 10 for k = 8, 0.4 for c = 0.25); for `building-chain` the same prior
    /// carried to the building's values (medians 1.25 k and 1.6 c,
    /// as SPEC §3's are to the paper's).
    pub fn default_prior(name: &str, chain: &ShearChain, hysteretic: &[usize]) -> ChainPrior {
        match name {
            "building-chain" => {
                ChainPrior::relative_to(chain.stiffness(), chain.damping(), hysteretic)
            }
            _ => ChainPrior::paper(chain.storeys(), hysteretic),
        }
    }

    /// The preset's default excitation sampled at its `dt`.
    pub fn ground_motion(&self) -> GroundMotion {
        self.excitation.ground_motion(self.dt)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_by_name() {
        let p = Preset::from_name("paper-3dof", None).unwrap();
        assert_eq!(
            p.chain.theta(),
            vec![8., 8., 8., 0.25, 0.25, 0.25, 2., 1., 2.]
        );
        assert_eq!(p.ground_motion().len(), 6237);
        let h = Preset::from_name("paper-3dof-harmonic", None).unwrap();
        assert_eq!(h.chain, p.chain);
        let g = h.ground_motion();
        assert_eq!(g.len(), 6237);
        assert!((g.pga() - 3.0).abs() < 1e-3);
        let five = Preset::from_name("paper-3dof", Some(5)).unwrap();
        assert_eq!(five.chain.storeys(), 5);
        assert_eq!(five.chain.dim(), 11);
        let err = Preset::from_name("nope", None).unwrap_err().to_string();
        for n in Preset::NAMES {
            assert!(err.contains(n), "{err}");
        }
        assert!(Preset::from_name("shear-chain", Some(0)).is_err());
        for zero in [Preset::chain(0), Preset::building_chain(0)] {
            assert_eq!(zero.unwrap_err(), PresetError::NoStorey { storeys: 0 });
        }
        // The two uniform chains differ by their stiffness and damping only.
        let c = 2.0 * BUILDING_ZETA1 * BUILDING_K / uniform_chain_omega(BUILDING_K, 1.0, 2, 1);
        let element = [BOUC_WEN_BETA, BOUC_WEN_GAMMA, BOUC_WEN_N];
        for (chain, k, c) in [
            (Preset::chain(2).unwrap(), 8.0, 0.25),
            (Preset::building_chain(2).unwrap(), BUILDING_K, c),
        ] {
            assert_eq!(chain.theta(), [[k, k, c, c].as_slice(), &element].concat());
            assert_eq!(chain.bouc_wen()[0].storey, 0);
        }
    }

    #[test]
    fn hysteretic_elements_move_with_the_preset_law() {
        let mut p = Preset::from_name("shear-chain", Some(10)).unwrap();
        p.set_hysteretic(&[0, 5]).unwrap();
        let bw = p.chain.bouc_wen();
        assert_eq!(bw.len(), 2);
        assert_eq!((bw[0].storey, bw[1].storey), (0, 5));
        assert_eq!((bw[1].beta, bw[1].gamma, bw[1].n), (2.0, 1.0, 2.0));
        assert_eq!(p.chain.theta().len(), 2 * 10 + 6);
        assert!(p.set_hysteretic(&[10]).is_err());
        p.set_hysteretic(&[]).unwrap();
        assert!(p.chain.bouc_wen().is_empty());
    }
}
