//! Sparse matrices with a structural pattern fixed by the model.
//!
//! The Jacobians of the partitioned shear chain have a handful of non-zeros per row, at positions
//! fixed by the structure (which storeys are linked, which elements are hysteretic). A model
//! writes a Jacobian entry by entry into a [`Sparse`]; the first evaluation records the pattern,
//! later ones only overwrite the values, in the same order. The Gaussian kernels then visit the
//! structural non-zeros — always the same operations, whatever the values, so that one particle
//! and a pack of particles perform identical arithmetic ([`crate::real`]).
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
}

impl<T: Real> Sparse<T> {
    /// An empty matrix that records its pattern during the first evaluation
    /// ([`Sparse::start`], then [`Sparse::add`] for every entry, then [`Sparse::finish`]).
    pub fn recording(nrows: usize, ncols: usize) -> Self {
        Self {
            nrows,
            ncols,
            rows: Vec::new(),
            cols: Vec::new(),
            values: Vec::new(),
            pos: 0,
            frozen: false,
        }
    }

    /// A matrix with the pattern of `other` (recorded already) and zero values.
    pub fn with_pattern_of<U: Real>(other: &Sparse<U>) -> Self {
        assert!(other.frozen, "the pattern has not been recorded yet");
        Self {
            nrows: other.nrows,
            ncols: other.ncols,
            rows: other.rows.clone(),
            cols: other.cols.clone(),
            values: vec![T::splat(0.0); other.rows.len()],
            pos: 0,
            frozen: true,
        }
    }

    /// A dense `nrows × ncols` pattern (every entry, column by column).
    pub fn dense(nrows: usize, ncols: usize) -> Self {
        let mut s = Self::recording(nrows, ncols);
        s.start();
        for c in 0..ncols {
            for r in 0..nrows {
                s.add(r, c, T::splat(0.0));
            }
        }
        s.finish();
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

    /// Whether the pattern is recorded.
    pub fn is_frozen(&self) -> bool {
        self.frozen
    }

    /// Begins an evaluation: the next [`Sparse::add`] writes entry 0.
    #[inline]
    pub fn start(&mut self) {
        self.pos = 0;
    }

    /// Writes the next entry. While recording, appends `(row, col)`; afterwards the model must
    /// write the same `(row, col)` sequence (checked in debug builds).
    #[inline]
    #[track_caller]
    pub fn add(&mut self, row: usize, col: usize, value: T) {
        if self.frozen {
            debug_assert!(
                self.pos < self.rows.len()
                    && self.rows[self.pos] as usize == row
                    && self.cols[self.pos] as usize == col,
                "entry {} of the pattern is not ({row}, {col})",
                self.pos
            );
            self.values[self.pos] = value;
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
        self.pos += 1;
    }

    /// Ends an evaluation; the first one fixes the pattern.
    #[inline]
    #[track_caller]
    pub fn finish(&mut self) {
        debug_assert_eq!(self.pos, self.rows.len(), "the model wrote too few entries");
        self.frozen = true;
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
        s.start();
        for c in 0..ncols {
            for r in 0..nrows {
                let v = a[r + c * nrows];
                if v != 0.0 {
                    s.add(r, c, v);
                }
            }
        }
        s.finish();
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pattern_is_recorded_once_and_values_follow() {
        let mut s = Sparse::<f64>::recording(2, 3);
        s.start();
        s.add(0, 2, 1.5);
        s.add(1, 0, -2.0);
        s.add(0, 2, 0.5);
        s.finish();
        assert_eq!(s.nnz(), 3);
        assert_eq!(s.to_dense(), vec![0.0, -2.0, 0.0, 0.0, 2.0, 0.0]);
        s.start();
        s.add(0, 2, 1.0);
        s.add(1, 0, 1.0);
        s.add(0, 2, 1.0);
        s.finish();
        let mut out = [0.0; 2];
        s.mul_add(&[1.0, 10.0, 100.0], &mut out);
        assert_eq!(out, [200.0, 1.0]);
        let d = Sparse::<f64>::dense(2, 2);
        assert_eq!(d.nnz(), 4);
    }

    #[test]
    #[should_panic(expected = "outside")]
    fn entries_outside_the_matrix_are_a_programmer_error() {
        let mut s = Sparse::<f64>::recording(2, 2);
        s.add(2, 0, 1.0);
    }
}
