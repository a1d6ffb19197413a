//! Second-order (Hessian) terms of the EKF2 from sparse constant Hessians (SPEC §4, §6).
//!
//! For a map with component Hessians 𝓗ⁱ and a Gaussian input with covariance `P`, the EKF2 adds
//! `½ tr(𝓗ⁱ P)` to mean component `i` and `½ tr(𝓗ⁱ P 𝓗^{i'} P)` to covariance entry `(i, i')`.
//! With the Hessians stored as entry lists, the double trace collapses to a sum over pairs of
//! entries, so the cost is the product of the non-zero counts instead of `n³` per pair of outputs.

use nalgebra::{SMatrix, SVector};

use crate::model::{HessianEntry, SparseHessians};

/// Second-order terms from sparse constant Hessians, SPEC §4:
/// `mean[i] = ½ tr(𝓗ⁱ P)`, `cov[i][i'] = ½ tr(𝓗ⁱ P 𝓗^{i'} P)` for outputs `i, i' < NO`.
///
/// `mean` and `cov` are overwritten. `P` must be symmetric (the filters keep it so).
///
/// Derivation (why the loops below are right): an entry `(a, b, v)` with `a ≠ b` stands for
/// `𝓗_ab = 𝓗_ba = v`. Expanding the traces over both orientations of each entry and using the
/// symmetry of `P`, a pair of entries `(a, b, v)`, `(c, d, w)` contributes
/// `v' w' (P_ac P_bd + P_ad P_bc)` to `cov[out₁][out₂]`, and one entry contributes `v' P_ab` to
/// `mean[out]`, where `v' = v/2` for a diagonal entry (`a = b`) and `v' = v` otherwise.
/// The pair contribution is symmetric in the two entries, so each unordered pair is visited once.
///
/// Cost ∝ (number of entries)². Entries with `output ≥ NO` or an index `≥ N` are a programmer
/// error (assert).
#[track_caller]
pub fn second_order_terms<const N: usize, const NO: usize>(
    hess: &SparseHessians,
    p: &SMatrix<f64, N, N>,
    mean: &mut SVector<f64, NO>,
    cov: &mut SMatrix<f64, NO, NO>,
) {
    mean.fill(0.0);
    cov.fill(0.0);
    let entries = hess.entries();
    for e in entries {
        assert!(
            e.output < NO && e.a < N && e.b < N,
            "Hessian entry {e:?} out of range for {NO} outputs and {N} inputs"
        );
    }
    let weight = |e: &HessianEntry| if e.a == e.b { 0.5 * e.value } else { e.value };
    let pair = |e1: &HessianEntry, e2: &HessianEntry| {
        weight(e1)
            * weight(e2)
            * (p[(e1.a, e2.a)] * p[(e1.b, e2.b)] + p[(e1.a, e2.b)] * p[(e1.b, e2.a)])
    };
    // Entries are visited in runs of equal output (models push them output by output), so that
    // each (run, run) block accumulates in a register and touches `cov` once. Any order is
    // correct: runs are then merely shorter.
    let run_end = |start: usize| {
        let o = entries[start].output;
        start
            + entries[start..]
                .iter()
                .take_while(|e| e.output == o)
                .count()
    };
    let mut s1 = 0;
    while s1 < entries.len() {
        let e1_end = run_end(s1);
        let g1 = &entries[s1..e1_end];
        let o1 = g1[0].output;
        let (mut acc_mean, mut acc_cov) = (0.0, 0.0);
        for (n1, e1) in g1.iter().enumerate() {
            acc_mean += weight(e1) * p[(e1.a, e1.b)];
            acc_cov += pair(e1, e1);
            for e2 in &g1[(n1 + 1)..] {
                acc_cov += 2.0 * pair(e1, e2);
            }
        }
        mean[o1] += acc_mean;
        cov[(o1, o1)] += acc_cov;
        let mut s2 = e1_end;
        while s2 < entries.len() {
            let e2_end = run_end(s2);
            let g2 = &entries[s2..e2_end];
            let o2 = g2[0].output;
            let mut acc = 0.0;
            for e1 in g1 {
                for e2 in g2 {
                    acc += pair(e1, e2);
                }
            }
            cov[(o1, o2)] += acc;
            cov[(o2, o1)] += acc;
            s2 = e2_end;
        }
        s1 = e1_end;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector1, Vector2};

    #[test]
    fn scalar_quadratic_matches_hand_computation() {
        // f(x) = x0 x1 + 3 x2², Hessian entries (0,1)=1 and (2,2)=6.
        let mut h = SparseHessians::new();
        h.push(0, 0, 1, 1.0);
        h.push(0, 2, 2, 6.0);
        let p = Matrix3::new(2.0, 0.5, 0.1, 0.5, 1.0, 0.2, 0.1, 0.2, 0.3);
        let mut mean = Vector1::zeros();
        let mut cov = nalgebra::Matrix1::zeros();
        second_order_terms(&h, &p, &mut mean, &mut cov);
        // ½ tr(H P) with H = [[0,1,0],[1,0,0],[0,0,6]].
        let hd = h.dense(0, 3);
        let pd = nalgebra::DMatrix::from_iterator(3, 3, p.iter().copied());
        let expected_mean = 0.5 * (&hd * &pd).trace();
        let expected_cov = 0.5 * (&hd * &pd * &hd * &pd).trace();
        assert!((mean[0] - expected_mean).abs() < 1e-14);
        assert!((cov[(0, 0)] - expected_cov).abs() < 1e-14);
        // Explicit: mean = P01 + 3 P22.
        assert!((mean[0] - (0.5 + 0.9)).abs() < 1e-14);
    }

    #[test]
    fn empty_hessians_give_zero_terms() {
        let h = SparseHessians::new();
        let mut mean = Vector2::new(1.0, 1.0);
        let mut cov = nalgebra::Matrix2::identity();
        second_order_terms(&h, &Matrix3::identity(), &mut mean, &mut cov);
        assert_eq!(mean, Vector2::zeros());
        assert_eq!(cov, nalgebra::Matrix2::zeros());
    }

    #[test]
    #[should_panic(expected = "out of range")]
    fn output_beyond_range_is_a_programmer_error() {
        let mut h = SparseHessians::new();
        h.push(2, 0, 1, 1.0);
        let mut mean = Vector2::zeros();
        let mut cov = nalgebra::Matrix2::zeros();
        second_order_terms(&h, &Matrix3::identity(), &mut mean, &mut cov);
    }
}
