//! Flat particle storage (STYLE lesson 4): per particle a sampled block and, for the marginalized
//! filters, the Gaussian `N(μ, C)` of the marginalised block, each block contiguous, all particles
//! in three `Vec<f64>` allocated once. The runner keeps two stores and swaps them: a step reads
//! each particle's ancestor from one and writes the particle to the other, so resampling costs no
//! extra copy.

use rayon::prelude::*;

/// Sizes of one particle's blocks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shape {
    /// Length of the sampled block.
    pub sampled: usize,
    /// Dimension of the marginalised Gaussian (0 for the bootstrap PF).
    pub marginal: usize,
}

/// The particles of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct Particles {
    np: usize,
    shape: Shape,
    sampled: Vec<f64>,
    mean: Vec<f64>,
    cov: Vec<f64>,
}

/// One particle's blocks, mutable.
pub struct ParticleMut<'a> {
    pub sampled: &'a mut [f64],
    pub mean: &'a mut [f64],
    pub cov: &'a mut [f64],
}

impl Particles {
    /// Zeroed storage for `np` particles.
    pub fn new(np: usize, shape: Shape) -> Self {
        let nm = shape.marginal;
        Self {
            np,
            shape,
            sampled: vec![0.0; np * shape.sampled],
            mean: vec![0.0; np * nm],
            cov: vec![0.0; np * nm * nm],
        }
    }

    pub fn len(&self) -> usize {
        self.np
    }

    pub fn is_empty(&self) -> bool {
        self.np == 0
    }

    pub fn shape(&self) -> Shape {
        self.shape
    }

    #[inline]
    pub fn sampled(&self, i: usize) -> &[f64] {
        let s = self.shape.sampled;
        &self.sampled[i * s..(i + 1) * s]
    }

    #[inline]
    pub fn mean(&self, i: usize) -> &[f64] {
        let n = self.shape.marginal;
        &self.mean[i * n..(i + 1) * n]
    }

    #[inline]
    pub fn cov(&self, i: usize) -> &[f64] {
        let n = self.shape.marginal;
        &self.cov[i * n * n..(i + 1) * n * n]
    }

    /// Particle `i`'s three blocks, mutable.
    #[inline]
    pub fn particle_mut(&mut self, i: usize) -> ParticleMut<'_> {
        particle_at(
            self.shape,
            i,
            &mut self.sampled,
            &mut self.mean,
            &mut self.cov,
        )
    }

    /// Copies particle `from` of `src` into particle `to` of `self`.
    #[inline]
    pub fn copy_from(&mut self, to: usize, src: &Particles, from: usize) {
        self.particle_mut(to).copy(src, from);
    }

    /// The particles in consecutive blocks of `per` (the last may be shorter), each writable on
    /// its own, so that blocks can be advanced on several threads. Both block sizes must be
    /// non-zero.
    pub(crate) fn blocks_mut(
        &mut self,
        per: usize,
    ) -> impl IndexedParallelIterator<Item = Block<'_>> {
        let shape = self.shape;
        let (s, n) = (shape.sampled, shape.marginal);
        assert!(per > 0 && s > 0 && n > 0, "blocks of non-empty particles");
        self.sampled
            .par_chunks_mut(per * s)
            .zip(self.mean.par_chunks_mut(per * n))
            .zip(self.cov.par_chunks_mut(per * n * n))
            .enumerate()
            .map(move |(b, ((sampled, mean), cov))| Block {
                first: b * per,
                shape,
                sampled,
                mean,
                cov,
            })
    }

    /// All the particles as one block.
    pub(crate) fn as_block(&mut self) -> Block<'_> {
        Block {
            first: 0,
            shape: self.shape,
            sampled: &mut self.sampled,
            mean: &mut self.mean,
            cov: &mut self.cov,
        }
    }
}

/// Consecutive particles `first, first + 1, …` of a [`Particles`], writable; addressed by the
/// particles' indices in the whole store.
pub(crate) struct Block<'a> {
    first: usize,
    shape: Shape,
    sampled: &'a mut [f64],
    mean: &'a mut [f64],
    cov: &'a mut [f64],
}

impl Block<'_> {
    /// Index of the block's first particle.
    pub fn first(&self) -> usize {
        self.first
    }

    /// Particle `i`'s three blocks (`i` indexes the whole store).
    #[inline]
    pub fn particle_mut(&mut self, i: usize) -> ParticleMut<'_> {
        let j = i - self.first;
        particle_at(self.shape, j, self.sampled, self.mean, self.cov)
    }

    /// Copies particle `from` of `src` into particle `to` (indexing the whole store).
    #[inline]
    pub fn copy_from(&mut self, to: usize, src: &Particles, from: usize) {
        self.particle_mut(to).copy(src, from);
    }
}

/// The blocks of the `j`-th particle of flat storage of particles of `shape`.
#[inline]
fn particle_at<'a>(
    shape: Shape,
    j: usize,
    sampled: &'a mut [f64],
    mean: &'a mut [f64],
    cov: &'a mut [f64],
) -> ParticleMut<'a> {
    let (s, n) = (shape.sampled, shape.marginal);
    ParticleMut {
        sampled: &mut sampled[j * s..(j + 1) * s],
        mean: &mut mean[j * n..(j + 1) * n],
        cov: &mut cov[j * n * n..(j + 1) * n * n],
    }
}

impl ParticleMut<'_> {
    /// Overwrites these blocks with particle `from` of `src`.
    #[inline]
    fn copy(self, src: &Particles, from: usize) {
        self.sampled.copy_from_slice(src.sampled(from));
        self.mean.copy_from_slice(src.mean(from));
        self.cov.copy_from_slice(src.cov(from));
    }
}
