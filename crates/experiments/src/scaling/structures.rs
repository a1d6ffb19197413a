//! The structure values of the scaling study's cells, as the report states them: modal periods
//! and damping ratios of the linearised chain (the Bouc–Wen storeys at their initial stiffness
//! k, since dr/dx = 1 at r = 0), the excitation scale, and how far each Bouc–Wen element goes
//! towards its saturation (β + γ)^(−1/n) in the data of run 0 (the same for every run: the runs
//! differ by their noise only).

use crate::error::{Context, Result};
use nalgebra::{DMatrix, SymmetricEigen};
use serde::Serialize;

use crate::study::Study;

/// One structure of the axis.
#[derive(Debug, Clone, Serialize)]
pub struct StructureValues {
    pub label: String,
    pub storeys: usize,
    /// Fundamental and highest modal periods (s).
    pub t1: f64,
    pub tn: f64,
    /// Damping ratios of the first and of the highest mode.
    pub zeta1: f64,
    pub zetan: f64,
    /// Storey stiffness and damping of storey 1.
    pub k1: f64,
    pub c1: f64,
    /// Amplitude scale of the excitation.
    pub scale: f64,
    /// Duration of the data (s).
    pub duration: f64,
    /// The excitation (`el-centro` for the preset's record, else the vendored record's name).
    pub excitation: String,
    /// Peak of the clean ground acceleration after scaling (the model's units; m/s² when the
    /// length unit is the metre).
    pub pga: f64,
    /// Per Bouc–Wen element (1-based storey): max |r| / saturation in the data of run 0.
    pub yielding: Vec<(usize, f64)>,
}

/// Circular frequencies and damping ratios of the linear chain with masses `m`, storey
/// stiffnesses `k` and dampers `c` (fixed base): eigenpairs of M^(−1/2) K M^(−1/2), and
/// ζ_i = φ_iᵀ C̃ φ_i / (2 ω_i) with C̃ = M^(−1/2) C M^(−1/2) (exact for proportional damping,
/// the diagonal of the modal damping matrix otherwise). Ascending in ω.
pub fn modes(m: &[f64], k: &[f64], c: &[f64]) -> Vec<(f64, f64)> {
    let n = m.len();
    let chain_matrix = |s: &[f64]| {
        let mut a = DMatrix::<f64>::zeros(n, n);
        for j in 0..n {
            // Storey j connects floor j − 1 (the ground for j = 0) and floor j.
            a[(j, j)] += s[j];
            if j > 0 {
                a[(j - 1, j - 1)] += s[j];
                a[(j - 1, j)] -= s[j];
                a[(j, j - 1)] -= s[j];
            }
        }
        for i in 0..n {
            for j in 0..n {
                a[(i, j)] /= (m[i] * m[j]).sqrt();
            }
        }
        a
    };
    let kt = chain_matrix(k);
    let ct = chain_matrix(c);
    let eig = SymmetricEigen::new(kt);
    let mut out: Vec<(f64, f64)> = (0..n)
        .map(|i| {
            let w = eig.eigenvalues[i].max(0.0).sqrt();
            let phi = eig.eigenvectors.column(i);
            let cphi = &ct * phi;
            let zeta = phi.dot(&cphi) / (2.0 * w);
            (w, zeta)
        })
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out
}

/// The values of every structure of the study's axis (generates the clean data of run 0 of
/// each: a few milliseconds per structure).
pub fn structure_values(study: &Study) -> Result<Vec<StructureValues>> {
    (0..study.sweep.structures.len())
        .map(|i| {
            let st = &study.sweep.structures[i];
            let config = study.structure_config(Some(i), 0)?;
            let data = models::dataset::generate(&config)
                .with_context(|| format!("structure `{}`: generating its data", st.label))?;
            let chain = &data.chain;
            let modes = modes(chain.masses(), chain.stiffness(), chain.damping());
            let (first, last) = (modes[0], modes[modes.len() - 1]);
            let max_r = data.max_abs_r();
            let yielding = chain
                .bouc_wen()
                .iter()
                .enumerate()
                .map(|(e, b)| {
                    let ratio = chain.saturation(e).map_or(f64::NAN, |sat| max_r[e] / sat);
                    (b.storey + 1, ratio)
                })
                .collect();
            Ok(StructureValues {
                label: st.label.clone(),
                storeys: chain.storeys(),
                t1: 2.0 * std::f64::consts::PI / first.0,
                tn: 2.0 * std::f64::consts::PI / last.0,
                zeta1: first.1,
                zetan: last.1,
                k1: chain.stiffness()[0],
                c1: chain.damping()[0],
                scale: config.scale,
                duration: data.t.last().copied().unwrap_or(0.0),
                excitation: st
                    .excitation
                    .clone()
                    .unwrap_or_else(|| "el-centro (preset)".to_string()),
                pga: data.ug_clean.iter().fold(0.0_f64, |m, a| m.max(a.abs())),
                yielding,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use models::preset::{uniform_chain_omega, Preset};

    #[test]
    fn modes_of_the_uniform_chain() {
        // Closed form of the uniform chain; stiffness-proportional damping ζ_i = (c/k) ω_i / 2.
        let chain = Preset::building_chain(10).unwrap();
        let m = modes(chain.masses(), chain.stiffness(), chain.damping());
        let ratio = chain.damping()[0] / chain.stiffness()[0];
        for (i, (w, z)) in m.iter().enumerate() {
            let closed = uniform_chain_omega(2000.0, 1.0, 10, i + 1);
            assert!((w - closed).abs() < 1e-9 * closed, "mode {}", i + 1);
            assert!((z - ratio * w / 2.0).abs() < 1e-12, "mode {}", i + 1);
        }
        assert!((m[0].1 - 0.02).abs() < 1e-12);
        // A non-uniform mass is honoured (heavier top floor lowers ω₁).
        let heavy = modes(&[1.0, 1.0, 3.0], &[8.0; 3], &[0.25; 3]);
        let light = modes(&[1.0; 3], &[8.0; 3], &[0.25; 3]);
        assert!(heavy[0].0 < light[0].0);
    }
}
