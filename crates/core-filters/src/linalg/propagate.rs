//! The EKF2 propagate of SPEC §4 for a Jacobian close to the identity, on run-time dimensions and
//! generic over [`Real`]:
//!
//! `m ← φ(m) + ½ tr(𝓗ⁱ P)`,  `P ← J P Jᵀ + ½ tr(𝓗ⁱ P 𝓗^{i'} P) + Q`,  `J = I + D`.
//!
//! The marginalised transition of the shear chain is the identity on the parameters and near the
//! identity on the states (SPEC §6), so `D` has a few entries per state row. With `A = (I + D) P`
//! and `J P Jᵀ = A (I + D)ᵀ`, only the entries of `D` are visited: `2 n nnz(D)` instead of
//! `2 n³`. `Q` is a constant symmetric matrix given by its entries (diagonal, plus the
//! displacement–velocity covariances of a semi-implicit discretisation).

use crate::real::Real;

use super::second_order::SecondOrder;
use super::sparse::Sparse;

/// A constant symmetric matrix by its lower-triangle entries `(row ≥ col, value)`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SymEntries {
    entries: Vec<(usize, usize, f64)>,
}

impl SymEntries {
    pub fn new() -> Self {
        Self::default()
    }

    /// A diagonal matrix.
    pub fn diagonal(d: &[f64]) -> Self {
        let mut s = Self::new();
        for (i, v) in d.iter().enumerate() {
            if *v != 0.0 {
                s.push(i, i, *v);
            }
        }
        s
    }

    /// Adds `value` at `(row, col)` and, off the diagonal, at `(col, row)`.
    pub fn push(&mut self, row: usize, col: usize, value: f64) {
        let (r, c) = if row >= col { (row, col) } else { (col, row) };
        self.entries.push((r, c, value));
    }

    pub fn entries(&self) -> &[(usize, usize, f64)] {
        &self.entries
    }

    /// `p += self` on an `n × n` column-major matrix.
    #[inline]
    pub fn add_to<T: Real>(&self, p: &mut [T], n: usize) {
        for &(r, c, v) in &self.entries {
            p[r + c * n] += T::splat(v);
            if r != c {
                p[c + r * n] += T::splat(v);
            }
        }
    }

    /// The dense matrix (column-major).
    pub fn to_dense(&self, n: usize) -> Vec<f64> {
        let mut d = vec![0.0; n * n];
        self.add_to(&mut d, n);
        d
    }
}

/// Scratch of [`ekf2_propagate_near_identity`] (allocated once).
#[derive(Debug, Clone)]
pub struct PropagateScratch<T> {
    a: Vec<T>,
    mean2: Vec<T>,
    cov2: Vec<T>,
}

impl<T: Real> PropagateScratch<T> {
    pub fn new(n: usize, hess: &SecondOrder) -> Self {
        let k = hess.len();
        Self {
            a: vec![T::splat(0.0); n * n],
            mean2: vec![T::splat(0.0); k],
            cov2: vec![T::splat(0.0); k * k],
        }
    }
}

/// What stays the same at every propagate of a model: `φ`'s constant Hessians and `Q`.
#[derive(Debug, Clone)]
pub struct Propagation {
    pub hess: SecondOrder,
    pub q: SymEntries,
}

/// EKF2 propagate with `J = I + D` (module docs). `value` = φ(m); `d` = `J − I` at `m` (`n × n`
/// sparse); the Hessian terms use `P` before propagation. `p` is left exactly symmetric.
#[inline]
pub fn ekf2_propagate_near_identity<T: Real>(
    m: &mut [T],
    p: &mut [T],
    n: usize,
    value: &[T],
    d: &Sparse<T>,
    constant: &Propagation,
    scratch: &mut PropagateScratch<T>,
) {
    let Propagation { hess, q } = constant;
    let k = hess.len();
    if k > 0 {
        hess.terms(p, n, &mut scratch.mean2, &mut scratch.cov2);
    }
    // A = (I + D) P: row r of A gains D[r, c] · (row c of P).
    let a = &mut scratch.a;
    a[..n * n].copy_from_slice(&p[..n * n]);
    for e in 0..d.nnz() {
        let (r, c, v) = d.entry(e);
        for j in 0..n {
            a[r + j * n] += v * p[c + j * n];
        }
    }
    // P = A (I + D)ᵀ: column r gains D[r, c] · (column c of A).
    p[..n * n].copy_from_slice(&a[..n * n]);
    for e in 0..d.nnz() {
        let (r, c, v) = d.entry(e);
        for i in 0..n {
            p[i + r * n] += v * a[i + c * n];
        }
    }
    q.add_to(p, n);
    m[..n].copy_from_slice(&value[..n]);
    for g in 0..k {
        let og = hess.output(g);
        m[og] += scratch.mean2[g];
        for h in 0..k {
            p[og + hess.output(h) * n] += scratch.cov2[g + h * k];
        }
    }
    // Symmetrise (round-off only).
    let half = T::splat(0.5);
    for c in 0..n {
        for r in (c + 1)..n {
            let v = half * (p[r + c * n] + p[c + r * n]);
            p[r + c * n] = v;
            p[c + r * n] = v;
        }
    }
}
