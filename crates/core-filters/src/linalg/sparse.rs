//! Sparse matrices with a structural pattern fixed by the model.
//!
//! The Jacobians of the partitioned shear chain have a handful of non-zeros per row, at positions
//! fixed by the structure (which storeys are linked, which elements are hysteretic). A model
//! writes a Jacobian entry by entry into a [`Sparse`], inside the one bracket
//! [`Sparse::evaluate`] that the filters call: the first evaluation records the pattern, later
//! ones only overwrite the values, in the same order. The Gaussian kernels then visit the
//! structural non-zeros — always the same operations, whatever the values, so that one particle
//! and a pack of particles perform identical arithmetic ([`crate::real`]).
//!
//! A model whose pattern depended on the values would make those kernels compute with entries at
//! the wrong places. So every build checks each write against the recorded pattern (two integer
//! comparisons per entry, against arrays already in cache): a write off the pattern changes no
//! value and marks the matrix (`Sparse::pattern_broken`), which the filters report as the
//! typed error [`crate::FilterError::JacobianPattern`]. A wrong pattern is an error, never a
//! wrong number.
//!
//! An entry may be listed more than once (contributions add up), which lets a model write a
//! derivative as the sum of the terms of its equations.

use crate::real::Real;

/// An `nrows × ncols` matrix given by a list of `(row, col, value)` entries in a fixed order.
#[derive(Debug, Clone, PartialEq)]
pub struct Sparse<T> {
    nrows: usize,
    ncols: usize,
    rows: Vec<u32>,
    cols: Vec<u32>,
    values: Vec<T>,
    /// Next entry to be written.
    pos: usize,
    /// Whether the pattern is complete (after the first evaluation).
    frozen: bool,
    /// Whether an evaluation wrote another `(row, col)` sequence than the recorded one (sticky).
    broken: bool,
}

impl<T: Real> Sparse<T> {
    /// An empty matrix that records its pattern during its first [`Sparse::evaluate`].
    pub fn recording(nrows: usize, ncols: usize) -> Self {
        Self {
            nrows,
            ncols,
            rows: Vec::new(),
            cols: Vec::new(),
            values: Vec::new(),
            pos: 0,
            frozen: false,
            broken: false,
        }
    }

    /// A matrix with the pattern of `other` (recorded already) and zero values.
    pub(crate) fn with_pattern_of<U: Real>(other: &Sparse<U>) -> Self {
        assert!(other.frozen, "the pattern has not been recorded yet");
        Self {
            nrows: other.nrows,
            ncols: other.ncols,
            rows: other.rows.clone(),
            cols: other.cols.clone(),
            values: vec![T::splat(0.0); other.rows.len()],
            pos: 0,
            frozen: true,
            broken: false,
        }
    }

    /// A dense `nrows × ncols` pattern (every entry, column by column).
    pub fn dense(nrows: usize, ncols: usize) -> Self {
        let mut s = Self::recording(nrows, ncols);
        s.evaluate(|s| {
            for c in 0..ncols {
                for r in 0..nrows {
                    s.add(r, c, T::splat(0.0));
                }
            }
        });
        s
    }

    pub fn nrows(&self) -> usize {
        self.nrows
    }

    pub fn ncols(&self) -> usize {
        self.ncols
    }

    /// Number of entries (structural non-zeros, repeats included).
    pub fn nnz(&self) -> usize {
        self.rows.len()
    }

    /// Whether some evaluation wrote another `(row, col)` sequence than the recorded pattern
    /// (an entry off the pattern, too many or too few entries). Sticky: the filters check it once
    /// per step and end the run with [`crate::FilterError::JacobianPattern`].
    #[inline]
    pub(crate) fn pattern_broken(&self) -> bool {
        self.broken
    }

    /// Evaluates the matrix: `write` adds every entry with [`Sparse::add`], in order. The first
    /// evaluation records the pattern; every later one must write the same `(row, col)`
    /// sequence, which is checked here and in [`Sparse::add`] in every build (module docs).
    #[inline]
    pub fn evaluate(&mut self, write: impl FnOnce(&mut Self)) {
        self.pos = 0;
        write(self);
        if self.frozen {
            self.broken |= self.pos != self.rows.len();
        } else {
            self.frozen = true;
        }
    }

    /// Writes the next entry (inside [`Sparse::evaluate`]). While recording, appends
    /// `(row, col)`; afterwards an entry that is not the next one of the pattern is not written
    /// and marks the matrix as broken.
    // Always inlined: the models call it once per Jacobian entry in every particle's step; as a
    // call (with the pattern check of every build) it was part of the MLN-RBPF's slowdown
    // across the renovation (docs/performance.md, "Speed across builds").
    #[inline(always)]
    #[track_caller]
    pub fn add(&mut self, row: usize, col: usize, value: T) {
        let p = self.pos;
        self.pos += 1;
        if self.frozen {
            if p < self.rows.len() && self.rows[p] as usize == row && self.cols[p] as usize == col {
                self.values[p] = value;
            } else {
                self.broken = true;
            }
        } else {
            assert!(
                row < self.nrows && col < self.ncols,
                "entry ({row}, {col}) outside {}×{}",
                self.nrows,
                self.ncols
            );
            self.rows.push(row as u32);
            self.cols.push(col as u32);
            self.values.push(value);
        }
    }

    /// Entry `e`: `(row, col, value)`.
    #[inline(always)]
    pub fn entry(&self, e: usize) -> (usize, usize, T) {
        (self.rows[e] as usize, self.cols[e] as usize, self.values[e])
    }

    /// The values, in pattern order.
    #[inline]
    pub fn values(&self) -> &[T] {
        &self.values
    }

    /// Mutable values, in pattern order (for gathering packs).
    #[inline]
    pub fn values_mut(&mut self) -> &mut [T] {
        &mut self.values
    }

    /// `out += A x` (`x` of length `ncols`, `out` of length `nrows`).
    #[inline]
    pub fn mul_add(&self, x: &[T], out: &mut [T]) {
        for e in 0..self.nnz() {
            let (r, c, v) = self.entry(e);
            out[r] += v * x[c];
        }
    }

    /// The dense matrix (column-major), for tests and diagnostics.
    pub fn to_dense(&self) -> Vec<T> {
        let mut d = vec![T::splat(0.0); self.nrows * self.ncols];
        for e in 0..self.nnz() {
            let (r, c, v) = self.entry(e);
            d[r + c * self.nrows] += v;
        }
        d
    }
}

impl Sparse<f64> {
    /// The non-zero entries of a dense column-major `nrows × ncols` matrix, column by column
    /// (the small dense matrices of the Kalman steps of [`crate::kalman`]). A NaN is kept: it is
    /// not zero.
    pub fn nonzeros_of(a: &[f64], nrows: usize, ncols: usize) -> Self {
        let mut s = Self::recording(nrows, ncols);
        s.evaluate(|s| {
            for c in 0..ncols {
                for r in 0..nrows {
                    let v = a[r + c * nrows];
                    if v != 0.0 {
                        s.add(r, c, v);
                    }
                }
            }
        });
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes `entries` as one evaluation.
    fn write(s: &mut Sparse<f64>, entries: &[(usize, usize, f64)]) {
        s.evaluate(|s| {
            for &(r, c, v) in entries {
                s.add(r, c, v);
            }
        });
    }

    #[test]
    fn pattern_is_recorded_once_and_values_follow() {
        let mut s = Sparse::<f64>::recording(2, 3);
        write(&mut s, &[(0, 2, 1.5), (1, 0, -2.0), (0, 2, 0.5)]);
        assert_eq!(s.nnz(), 3);
        assert_eq!(s.to_dense(), vec![0.0, -2.0, 0.0, 0.0, 2.0, 0.0]);
        write(&mut s, &[(0, 2, 1.0), (1, 0, 1.0), (0, 2, 1.0)]);
        let mut out = [0.0; 2];
        s.mul_add(&[1.0, 10.0, 100.0], &mut out);
        assert_eq!(out, [200.0, 1.0]);
        assert!(!s.pattern_broken());
        let d = Sparse::<f64>::dense(2, 2);
        assert_eq!(d.nnz(), 4);
    }

    /// Every way of leaving the recorded pattern marks the matrix (in release builds too) and
    /// writes no value at a wrong place.
    #[test]
    fn a_write_off_the_pattern_is_reported_never_used() {
        let recorded = [(0, 2, 1.5), (1, 0, -2.0)];
        let wrong: [&[(usize, usize, f64)]; 4] = [
            &[(0, 2, 7.0), (1, 1, 7.0)],              // another column
            &[(1, 0, 7.0), (0, 2, 7.0)],              // another order
            &[(0, 2, 7.0)],                           // too few
            &[(0, 2, 7.0), (1, 0, 7.0), (1, 0, 7.0)], // too many
        ];
        for entries in wrong {
            let mut s = Sparse::<f64>::recording(2, 3);
            write(&mut s, &recorded);
            write(&mut s, entries);
            assert!(s.pattern_broken(), "{entries:?} not detected");
            assert_eq!(s.nnz(), 2);
            assert_eq!(
                s.to_dense()[3],
                0.0,
                "(1, 1) is not in the pattern: never written"
            );
            // Sticky: a correct evaluation afterwards does not clear it.
            write(&mut s, &recorded);
            assert!(s.pattern_broken());
        }
    }

    #[test]
    #[should_panic(expected = "outside")]
    fn entries_outside_the_matrix_are_a_programmer_error() {
        let mut s = Sparse::<f64>::recording(2, 2);
        s.add(2, 0, 1.0);
    }
}
