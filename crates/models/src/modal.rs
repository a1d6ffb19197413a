//! Modes of the linearised shear chain: natural frequencies and damping ratios from M, C, K.
//!
//! **Linearisation.** A linear element carries `f_j = k_j d_j + c_j δv_j`. A Bouc–Wen element
//! carries `f_j = k_j r_j + c_j δv_j` with `ṙ_j = δv_j − β|δv_j||r_j|^(n−1) r_j − γ δv_j |r_j|^n`;
//! at the rest state (`r_j = 0`, where every record starts) both nonlinear terms and their first
//! derivatives in `d_j` vanish for `n > 1` (for `n = 1` they are of second order in the motion's
//! amplitude), so `r_j = d_j` to first order and the element's **initial tangent stiffness** is
//! `k_j` — as for every hysteresis law, each being normalised to `ṙ = δv` at `r = 0`
//! (`crate::law::HysteresisLaw`). The linearised chain is therefore the chain with every element
//! linear, `K` and `C` assembled from `k_j`, `c_j` (element `j` links storey `j − 1`, or the
//! ground, to storey `j`) and `M = diag(m)`. This is the small-amplitude model: a yielding element is softer.
//!
//! **Modes.** The eigenvalues λ of the first-order matrix `A = [[0, I], [−M⁻¹K, −M⁻¹C]]` (real
//! Schur form, `nalgebra`) come in conjugate pairs for under-damped modes:
//! `λ = −ζω ± iω√(1 − ζ²)`, so ω = |λ| (natural circular frequency), ζ = −Re λ / |λ| and the
//! damped frequency is Im λ. Real eigenvalues belong to over-damped modes (ζ ≥ 1), which have no
//! resonance peak; they are counted, not listed. Non-proportional damping is handled exactly
//! (no modal-damping assumption).

use nalgebra::DMatrix;
use thiserror::Error;

use crate::law::HysteresisLaw;
use crate::structure::ShearChainOf;

/// One under-damped mode of the linearised chain.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mode {
    /// Natural (undamped) frequency ω/2π in Hz.
    pub frequency_hz: f64,
    /// Damped frequency ω√(1 − ζ²)/2π in Hz (where the resonance of a light mode sits).
    pub damped_hz: f64,
    /// Damping ratio ζ.
    pub damping_ratio: f64,
}

/// The modes of a linearised chain.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Modes {
    /// Under-damped modes by increasing natural frequency.
    pub modes: Vec<Mode>,
    /// Over-damped modes (pairs of real eigenvalues, ζ ≥ 1: no resonance).
    pub overdamped: usize,
    /// Eigenvalues with Re λ > 0 (a growing motion; none for positive k and c), counted in
    /// `modes` too when oscillatory (with a negative ζ).
    pub not_decaying: usize,
}

/// Failures of the modal analysis.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ModalError {
    #[error("the eigenvalue solver did not converge for the {dim}×{dim} state matrix")]
    NoConvergence { dim: usize },
    #[error(
        "non-finite entry or wrong sizes in the linearised matrices (check k, c and the masses)"
    )]
    NonFinite,
}

/// `M`, `C`, `K` of the linearised chain (see the module documentation); with mass-proportional
/// damping `C` includes `αM`.
pub fn linearised_matrices<L: HysteresisLaw>(
    chain: &ShearChainOf<L>,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    matrices(
        chain.masses(),
        chain.stiffness(),
        chain.damping(),
        chain.alpha(),
    )
}

/// `M`, `C`, `K` of a chain with storey masses `m`, element stiffnesses `k` and dampings `c`,
/// plus `αM` in `C` when `alpha` is given.
fn matrices(
    m: &[f64],
    k: &[f64],
    c: &[f64],
    alpha: Option<f64>,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let n = m.len();
    let mm = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(m));
    let assemble = |coef: &[f64]| {
        let mut a = DMatrix::<f64>::zeros(n, n);
        for j in 0..n {
            a[(j, j)] += coef[j];
            if j > 0 {
                a[(j - 1, j - 1)] += coef[j];
                a[(j - 1, j)] -= coef[j];
                a[(j, j - 1)] -= coef[j];
            }
        }
        a
    };
    let mut cc = assemble(c);
    if let Some(a) = alpha {
        for j in 0..n {
            cc[(j, j)] += a * m[j];
        }
    }
    (mm, cc, assemble(k))
}

/// The modes of the linearised chain (initial tangent stiffness of every Bouc–Wen element).
pub fn modes<L: HysteresisLaw>(chain: &ShearChainOf<L>) -> Result<Modes, ModalError> {
    modes_of_damped(
        chain.masses(),
        chain.stiffness(),
        chain.damping(),
        chain.alpha(),
    )
}

/// The modes of the chain with masses `m`, stiffnesses `k` and dampings `c` (one per storey),
/// without the checks of [`ShearChainOf::with_elements`]: an identified θ with a negative damping still has
/// modes, and one that grows shows a negative ζ and is counted in `not_decaying`.
pub fn modes_of(m: &[f64], k: &[f64], c: &[f64]) -> Result<Modes, ModalError> {
    modes_of_damped(m, k, c, None)
}

/// [`modes_of`] with mass-proportional damping `αM` added to `C` when `alpha` is given (the
/// [`crate::structure::Damping::StoreyMass`] form; a negative identified α is analysed as it is).
pub fn modes_of_damped(
    m: &[f64],
    k: &[f64],
    c: &[f64],
    alpha: Option<f64>,
) -> Result<Modes, ModalError> {
    let n = m.len();
    if n == 0 || k.len() != n || c.len() != n || m.iter().any(|v| v.is_nan() || *v <= 0.0) {
        return Err(ModalError::NonFinite);
    }
    let (m, c, k) = matrices(m, k, c, alpha);
    let mut a = DMatrix::<f64>::zeros(2 * n, 2 * n);
    for i in 0..n {
        a[(i, n + i)] = 1.0;
        let inv = 1.0 / m[(i, i)];
        for j in 0..n {
            a[(n + i, j)] = -k[(i, j)] * inv;
            a[(n + i, n + j)] = -c[(i, j)] * inv;
        }
    }
    if a.iter().any(|v| !v.is_finite()) {
        return Err(ModalError::NonFinite);
    }
    let schur = nalgebra::linalg::Schur::try_new(a, f64::EPSILON, 10_000)
        .ok_or(ModalError::NoConvergence { dim: 2 * n })?;
    let eig = schur.complex_eigenvalues();
    let mut modes = Vec::new();
    let (mut real, mut not_decaying) = (0usize, 0usize);
    for l in eig.iter() {
        // Relative precision of the eigenvalues: an undamped mode's Re λ is 0 up to round-off.
        let w = l.norm();
        let tiny = 1e-12 * w;
        if l.re > tiny || w == 0.0 {
            not_decaying += 1;
        }
        // A conjugate pair is counted once (its member with Im > 0); a real eigenvalue (to the
        // solver's precision) belongs to an over-damped (or, positive, a diverging) mode.
        if l.im.abs() <= tiny {
            real += usize::from(l.re < 0.0);
        } else if l.im > 0.0 {
            let zeta = -l.re / w;
            modes.push(Mode {
                frequency_hz: w / std::f64::consts::TAU,
                damped_hz: l.im / std::f64::consts::TAU,
                damping_ratio: if zeta.abs() <= 1e-12 { 0.0 } else { zeta },
            });
        }
    }
    modes.sort_by(|x, y| x.frequency_hz.total_cmp(&y.frequency_hz));
    Ok(Modes {
        modes,
        overdamped: real / 2,
        not_decaying,
    })
}

/// One undamped mode shape of the chain: `K φ = ω² M φ`.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    /// Natural frequency ω/2π of the undamped chain, Hz.
    pub frequency_hz: f64,
    /// φ over storeys 1..N, scaled so that its largest component (in magnitude) is +1.
    pub phi: Vec<f64>,
}

/// The undamped mode shapes of the chain with masses `m` and stiffnesses `k`, by increasing
/// frequency: the eigenvectors of the symmetric `M^(-1/2) K M^(-1/2)` (`nalgebra`'s symmetric
/// eigen-solver), mapped back by `M^(-1/2)`. These are the shapes a mode-shape comparison
/// (MAC) uses: with damping proportional to `M` and `K` they are the damped modes' shapes
/// exactly; otherwise the damped modes are complex and these are their classical-damping
/// approximation.
pub fn shapes_of(m: &[f64], k: &[f64]) -> Result<Vec<Shape>, ModalError> {
    let n = m.len();
    if n == 0
        || k.len() != n
        || m.iter().any(|v| !v.is_finite() || *v <= 0.0)
        || k.iter().any(|v| !v.is_finite())
    {
        return Err(ModalError::NonFinite);
    }
    let (_, _, kk) = matrices(m, k, &vec![0.0; n], None);
    let inv_sqrt: Vec<f64> = m.iter().map(|v| 1.0 / v.sqrt()).collect();
    let a = DMatrix::from_fn(n, n, |i, j| inv_sqrt[i] * kk[(i, j)] * inv_sqrt[j]);
    let eig = nalgebra::linalg::SymmetricEigen::try_new(a, f64::EPSILON, 10_000)
        .ok_or(ModalError::NoConvergence { dim: n })?;
    let mut shapes: Vec<Shape> = (0..n)
        .map(|r| {
            let w2 = eig.eigenvalues[r];
            let mut phi: Vec<f64> = (0..n)
                .map(|i| inv_sqrt[i] * eig.eigenvectors[(i, r)])
                .collect();
            let big = phi
                .iter()
                .copied()
                .fold(0.0_f64, |a, v| if v.abs() > a.abs() { v } else { a });
            if big != 0.0 {
                phi.iter_mut().for_each(|v| *v /= big);
            }
            Shape {
                frequency_hz: w2.max(0.0).sqrt() / std::f64::consts::TAU,
                phi,
            }
        })
        .collect();
    shapes.sort_by(|x, y| x.frequency_hz.total_cmp(&y.frequency_hz));
    Ok(shapes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::structure::{BoucWen, ShearChain};

    fn chain(n: usize, k: f64, c: f64, bw: bool) -> ShearChain {
        let elements = if bw {
            vec![BoucWen {
                storey: 0,
                beta: 2.0,
                gamma: 1.0,
                n: 2.0,
            }]
        } else {
            vec![]
        };
        ShearChain::new(vec![1.0; n], vec![k; n], vec![c; n], elements).unwrap()
    }

    #[test]
    fn an_undamped_uniform_chain_has_the_closed_form_frequencies() {
        // Unit masses, equal k: ω_r² = 4k sin²((2r − 1)π / (2(2N + 1))), r = 1..N.
        for n in [1, 3, 10] {
            let k = 8.0;
            let got = modes(&chain(n, k, 0.0, false)).unwrap();
            assert_eq!(got.modes.len(), n);
            for (r, mode) in got.modes.iter().enumerate() {
                let angle = (2 * r + 1) as f64 * std::f64::consts::PI / (2.0 * (2 * n + 1) as f64);
                let w = 2.0 * k.sqrt() * angle.sin();
                assert!(
                    (mode.frequency_hz * std::f64::consts::TAU / w - 1.0).abs() < 1e-10,
                    "N = {n}, mode {r}: {} vs {w}",
                    mode.frequency_hz * std::f64::consts::TAU
                );
                assert!(mode.damping_ratio.abs() < 1e-10);
            }
        }
    }

    #[test]
    fn stiffness_proportional_damping_gives_the_rayleigh_ratios() {
        // C = b K (equal c = b k per storey): ζ_r = b ω_r / 2, exactly, for every mode.
        let (k, b) = (200.0, 0.004);
        let got = modes(&chain(5, k, b * k, true)).unwrap();
        assert_eq!(got.modes.len(), 5);
        assert_eq!((got.overdamped, got.not_decaying), (0, 0));
        for (r, mode) in got.modes.iter().enumerate() {
            let angle = (2 * r + 1) as f64 * std::f64::consts::PI / 22.0;
            let w = 2.0 * k.sqrt() * angle.sin();
            let w_got = mode.frequency_hz * std::f64::consts::TAU;
            assert!((w_got / w - 1.0).abs() < 1e-10, "{w_got} vs {w}");
            assert!((mode.damping_ratio / (b * w / 2.0) - 1.0).abs() < 1e-9);
            let wd = w * (1.0 - (b * w / 2.0).powi(2)).sqrt();
            assert!((mode.damped_hz * std::f64::consts::TAU / wd - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn mass_proportional_damping_gives_alpha_over_two_omega() {
        // C = αM (no dashpots), unit masses, equal k: ζ_r = α/(2ω_r) with the closed-form ω_r.
        let (k, alpha) = (200.0, 0.6);
        let pure = chain(4, k, 0.0, false).with_mass_damping(alpha).unwrap();
        let got = modes(&pure).unwrap();
        assert_eq!(got.modes.len(), 4);
        for (r, mode) in got.modes.iter().enumerate() {
            let angle = (2 * r + 1) as f64 * std::f64::consts::PI / 18.0;
            let w = 2.0 * k.sqrt() * angle.sin();
            let w_got = mode.frequency_hz * std::f64::consts::TAU;
            assert!((w_got / w - 1.0).abs() < 1e-10, "{w_got} vs {w}");
            let zeta = alpha / (2.0 * w);
            assert!(
                (mode.damping_ratio / zeta - 1.0).abs() < 1e-9,
                "mode {r}: ζ {} vs {zeta}",
                mode.damping_ratio
            );
        }
        // Rayleigh C = αM + bK (c_j = b k_j), unequal masses: ζ_r = α/(2ω_r) + bω_r/2, with
        // ω_r from the undamped chain (proportional damping keeps its mode shapes).
        let (m, kk, b) = (vec![1.0, 1.03, 1.41], vec![3200.0, 3400.0, 3800.0], 1.4e-4);
        let c: Vec<f64> = kk.iter().map(|k| b * k).collect();
        let undamped = modes_of(&m, &kk, &[0.0; 3]).unwrap();
        let ray = ShearChain::new(m.clone(), kk.clone(), c.clone(), vec![])
            .unwrap()
            .with_mass_damping(0.54)
            .unwrap();
        let got = modes(&ray).unwrap();
        assert_eq!(got, modes_of_damped(&m, &kk, &c, Some(0.54)).unwrap());
        for (u, d) in undamped.modes.iter().zip(&got.modes) {
            let w = u.frequency_hz * std::f64::consts::TAU;
            let zeta = 0.54 / (2.0 * w) + b * w / 2.0;
            assert!((d.frequency_hz / u.frequency_hz - 1.0).abs() < 1e-10);
            assert!((d.damping_ratio / zeta - 1.0).abs() < 1e-9);
        }
        // The default form is the chain without α, to the bit.
        let plain = chain(3, k, 0.3, false);
        assert_eq!(
            modes(&plain).unwrap(),
            modes_of(&[1.0; 3], &[k; 3], &[0.3; 3]).unwrap()
        );
    }

    #[test]
    fn a_heavily_damped_oscillator_is_counted_as_overdamped() {
        // One storey, ζ = c / (2√(km)) = 2.
        let got = modes(&chain(1, 1.0, 4.0, false)).unwrap();
        assert!(got.modes.is_empty());
        assert_eq!(got.overdamped, 1);
        // A negative damping: the mode grows, ζ < 0, and it is counted as not decaying.
        let grow = modes_of(&[1.0], &[4.0], &[-0.4]).unwrap();
        assert_eq!(grow.not_decaying, 2);
        assert!((grow.modes[0].damping_ratio + 0.1).abs() < 1e-12);
        assert!(modes_of(&[1.0, 0.0], &[1.0, 1.0], &[0.0, 0.0]).is_err());
    }

    #[test]
    fn the_uniform_chains_shapes_are_the_closed_form_sines() {
        // Unit masses, equal k: φ_r(j) ∝ sin(j·(2r − 1)π / (2N + 1)), j = 1..N; M-orthogonal.
        let n = 5;
        let got = shapes_of(&[1.0; 5], &[8.0; 5]).unwrap();
        assert_eq!(got.len(), n);
        let modes = modes_of(&[1.0; 5], &[8.0; 5], &[0.0; 5]).unwrap();
        for (r, s) in got.iter().enumerate() {
            assert!((s.frequency_hz / modes.modes[r].frequency_hz - 1.0).abs() < 1e-10);
            let angle = (2 * r + 1) as f64 * std::f64::consts::PI / (2 * n + 1) as f64;
            let exact: Vec<f64> = (1..=n).map(|j| (j as f64 * angle).sin()).collect();
            let big = exact
                .iter()
                .copied()
                .fold(0.0_f64, |a, v| if v.abs() > a.abs() { v } else { a });
            for (got, want) in s.phi.iter().zip(&exact) {
                assert!(
                    (got - want / big).abs() < 1e-10,
                    "mode {r}: {:?} vs {exact:?}",
                    s.phi
                );
            }
            assert!(s.phi.iter().all(|v| v.abs() <= 1.0 + 1e-12));
        }
        // Unequal masses: K φ = ω² M φ and the shapes are M-orthogonal.
        let (m, k) = ([1.0, 1.03, 1.41], [3200.0, 3400.0, 3800.0]);
        let got = shapes_of(&m, &k).unwrap();
        let (mm, _, kk) = matrices(&m, &k, &[0.0; 3], None);
        for (r, s) in got.iter().enumerate() {
            let phi = nalgebra::DVector::from_column_slice(&s.phi);
            let w2 = (s.frequency_hz * std::f64::consts::TAU).powi(2);
            let resid = &kk * &phi - &mm * &phi * w2;
            assert!(resid.norm() < 1e-8 * (&kk * &phi).norm(), "mode {r}");
            for t in got.iter().skip(r + 1) {
                let psi = nalgebra::DVector::from_column_slice(&t.phi);
                assert!((phi.transpose() * &mm * psi)[(0, 0)].abs() < 1e-10);
            }
        }
        assert!(shapes_of(&[1.0, -1.0], &[1.0, 1.0]).is_err());
        assert!(shapes_of(&[1.0], &[f64::NAN]).is_err());
    }
}
