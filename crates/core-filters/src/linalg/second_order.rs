//! Second-order (Hessian) terms of the EKF2 from sparse constant Hessians (SPEC §4, §6), on
//! run-time dimensions and generic over [`Real`].
//!
//! For a map with component Hessians 𝓗ⁱ and a Gaussian input with covariance `P`, the EKF2 adds
//! `½ tr(𝓗ⁱ P)` to mean component `i` and `½ tr(𝓗ⁱ P 𝓗^{i'} P)` to covariance entry `(i, i')`.
//! With the Hessians as entry lists the double trace collapses to a sum over pairs of entries:
//! an entry `(a, b, v)` with `a ≠ b` stands for `𝓗_ab = 𝓗_ba = v`; with `v' = v/2` for a diagonal
//! entry and `v' = v` otherwise, one entry contributes `v' P_ab` to the mean and a pair of entries
//! `(a, b, v)`, `(c, d, w)` contributes `v' w' (P_ac P_bd + P_ad P_bc)` to the covariance
//! (expand the traces over both orientations of each entry and use the symmetry of `P`). The
//! cost is the square of the number of entries, not `n³` per pair of outputs.
//!
//! Only the outputs that have Hessian entries get terms; [`SecondOrder`] holds them compactly
//! (`k` outputs: a `k`-vector and a `k × k` matrix) with the output index of each.

use crate::model::SparseHessians;
use crate::real::Real;

/// One Hessian entry, with its weight `v'` (SPEC §4 derivation above).
#[derive(Debug, Clone, Copy)]
struct Term {
    a: usize,
    b: usize,
    weight: f64,
}

/// The sparse Hessians of a map, grouped by output, ready for [`SecondOrder::terms`].
#[derive(Debug, Clone, Default)]
pub struct SecondOrder {
    terms: Vec<Term>,
    /// Per group: (output index, first term, end of terms).
    groups: Vec<(usize, usize, usize)>,
}

impl SecondOrder {
    /// Groups `hess` by output (a stable sort: the order within an output is kept).
    /// `n` is the input dimension and `outputs` the number of outputs (checked).
    #[track_caller]
    pub fn new(hess: &SparseHessians, n: usize, outputs: usize) -> Self {
        let mut entries = hess.entries().to_vec();
        for e in &entries {
            assert!(
                e.output < outputs && e.a < n && e.b < n,
                "Hessian entry {e:?} out of range for {outputs} outputs and {n} inputs"
            );
        }
        entries.sort_by_key(|e| e.output);
        let mut terms = Vec::with_capacity(entries.len());
        let mut groups: Vec<(usize, usize, usize)> = Vec::new();
        for e in &entries {
            let weight = if e.a == e.b { 0.5 * e.value } else { e.value };
            match groups.last_mut() {
                Some(g) if g.0 == e.output => g.2 += 1,
                _ => groups.push((e.output, terms.len(), terms.len() + 1)),
            }
            terms.push(Term {
                a: e.a,
                b: e.b,
                weight,
            });
        }
        Self { terms, groups }
    }

    /// Number of outputs with terms (`k`).
    pub fn len(&self) -> usize {
        self.groups.len()
    }

    pub fn is_empty(&self) -> bool {
        self.groups.is_empty()
    }

    /// Output index of compact output `g`.
    #[inline]
    pub fn output(&self, g: usize) -> usize {
        self.groups[g].0
    }

    /// `mean[g] = ½ tr(𝓗^{o_g} P)` and `cov[g + h k] = ½ tr(𝓗^{o_g} P 𝓗^{o_h} P)` for the `k`
    /// outputs with terms (`P` symmetric `n × n` column-major; `mean` of length `k`, `cov`
    /// `k × k` column-major, exactly symmetric).
    #[inline]
    pub fn terms<T: Real>(&self, p: &[T], n: usize, mean: &mut [T], cov: &mut [T]) {
        let k = self.groups.len();
        let at = |i: usize, j: usize| p[i + j * n];
        let pair = |t1: &Term, t2: &Term| {
            T::splat(t1.weight * t2.weight)
                * (at(t1.a, t2.a) * at(t1.b, t2.b) + at(t1.a, t2.b) * at(t1.b, t2.a))
        };
        for (g1, &(_, s1, e1)) in self.groups.iter().enumerate() {
            let ts1 = &self.terms[s1..e1];
            let mut acc_mean = T::splat(0.0);
            let mut acc_cov = T::splat(0.0);
            for (i1, t1) in ts1.iter().enumerate() {
                acc_mean += T::splat(t1.weight) * at(t1.a, t1.b);
                acc_cov += pair(t1, t1);
                for t2 in &ts1[i1 + 1..] {
                    acc_cov += T::splat(2.0) * pair(t1, t2);
                }
            }
            mean[g1] = acc_mean;
            cov[g1 + g1 * k] = acc_cov;
            for (g2, &(_, s2, e2)) in self.groups.iter().enumerate().skip(g1 + 1) {
                let mut acc = T::splat(0.0);
                for t1 in ts1 {
                    for t2 in &self.terms[s2..e2] {
                        acc += pair(t1, t2);
                    }
                }
                cov[g1 + g2 * k] = acc;
                cov[g2 + g1 * k] = acc;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dense ½ tr(H P) and ½ tr(H P H' P) against the pair formula.
    #[test]
    fn pair_formula_matches_dense_traces() {
        let n = 4;
        let mut h = SparseHessians::new();
        h.push(2, 0, 1, 1.5);
        h.push(0, 2, 2, -3.0);
        h.push(2, 3, 3, 0.5);
        h.push(0, 1, 3, 2.0);
        h.push(2, 1, 2, -1.0);
        // A symmetric positive definite P.
        let a = [
            1.0, 0.3, -0.2, 0.5, 0.7, 1.1, 0.4, -0.6, 0.2, 0.9, 1.3, 0.1, -0.4, 0.8, 0.6, 1.2,
        ];
        let mut p = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                p[i + j * n] = (0..n).map(|k| a[i + k * n] * a[j + k * n]).sum::<f64>();
            }
        }
        let so = SecondOrder::new(&h, n, 3);
        assert_eq!(so.len(), 2);
        let (mut mean, mut cov) = (vec![0.0; 2], vec![0.0; 4]);
        so.terms(&p, n, &mut mean, &mut cov);
        let pm = nalgebra::DMatrix::from_column_slice(n, n, &p);
        for g1 in 0..2 {
            let h1 = h.dense(so.output(g1), n);
            assert!((mean[g1] - 0.5 * (&h1 * &pm).trace()).abs() < 1e-12);
            for g2 in 0..2 {
                let h2 = h.dense(so.output(g2), n);
                let want = 0.5 * (&h1 * &pm * &h2 * &pm).trace();
                assert!((cov[g1 + 2 * g2] - want).abs() < 1e-12, "{g1} {g2}");
            }
        }
    }
}
