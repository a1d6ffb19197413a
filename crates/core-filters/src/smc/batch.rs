//! The batch layer: runs a filter's per-particle step for one particle (`f64`) or for four
//! particles side by side in SIMD lanes ([`Pack`]), with the same results to the bit.
//!
//! Each marginalized filter writes its step once, as [`ParticleStep::advance`], generic over
//! [`Real`]; that function is the definition (it reads like the SPEC) and the test oracle. This
//! layer owns everything around it, for every filter alike:
//! - the random draws, taken particle by particle in order (all of a particle's draws at once),
//!   so that the lanes consume the stream exactly as one particle at a time would;
//! - gathering the ancestors' blocks into the lanes and scattering the results;
//! - the fallback: a lane whose straight path failed (a factorisation that needs the documented
//!   repair, a non-finite result) is redone by the `f64` step from its ancestor with the same
//!   draws, which repairs, counts and reports exactly as for a lone particle;
//! - particles with weight zero (possible with an ESS threshold) are copied, not advanced.
//!
//! Why lanes: one Gaussian update of a small marginalised block is a short chain of dependent
//! operations that leaves most of the processor idle; four independent particles fill it. For a
//! large block (hundreds of entries) one particle's update is long enough on its own, and the four
//! lanes' covariances no longer fit the caches: the batch layer then runs particles one at a time.

use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

use crate::error::FilterError;
use crate::health::Health;
use crate::linalg::pack::gather;
use crate::linalg::support::{truncate_below, LowerBound};
use crate::model::Layout;
use crate::real::{Pack, Real, PACK_LANES};
use crate::rng::StreamRng;

use super::model::{Marginalised, Partition};
use super::rejuvenation::StaticParam;
use super::runner::{Filter, StepInput, StepOutput};
use super::store::{Block, Particles, Shape};

/// Largest marginalised dimension processed in lanes: 40 storeys with a Bouc–Wen element
/// (n = 161), whose pack's covariance takes 161² × 32 bytes = 810 KiB. The limit was 48 (a pack
/// within a second-level cache of 72 KiB), but measured on this project's 2-core machine
/// (docs/performance.md, "Cost against size with three sensors") the lanes are 2.2–2.4× faster
/// than one particle at a time at n = 81 and 161 for the MPF-EKF2 (1.3–2.2× for the MLN-RBPF and
/// Storvik at n = 161): the covariance streams through the cache either way, and four particles
/// share each pass. Above 63 a particle alone has its rank-q downdates done by faer
/// (`FAER_MIN_DIM`), the lanes by plain loops: the two round differently (relative
/// differences of 1e-13 to 3e-11 measured on θ_val at n = 81 and 161).
pub const MAX_LANE_DIM: usize = 200;

/// One particle's blocks as the step sees them.
pub struct Slots<'a, T> {
    /// On entry a copy of the ancestor's sampled block (so static entries are already set); on
    /// return the new sampled block.
    pub sampled: &'a mut [T],
    /// The marginalised Gaussian `N(mean, cov)`: the ancestor's on entry, updated in place.
    pub mean: &'a mut [T],
    pub cov: &'a mut [T],
}

/// What one particle (or a pack) starts step `k` from: the measurement `y_k`, the ancestor's
/// sampled block `prev` and the particle's standard normal draws `xi`.
#[derive(Clone, Copy)]
pub struct Ancestry<'a, T> {
    pub k: usize,
    pub y: &'a [f64],
    pub prev: &'a [T],
    pub xi: &'a [T],
}

/// A filter's per-particle step, written once for one particle or a pack of particles.
pub trait ParticleStep: Sync + Send {
    /// Short algorithm name (`mln-rbpf`, `storvik`, `mpf-ekf2`).
    fn name(&self) -> &'static str;
    /// The model the step reads.
    type Model: Marginalised;
    fn model(&self) -> &Self::Model;
    /// Where θ and the physical states live in a particle (the model's).
    fn layout(&self) -> Layout {
        self.model().layout()
    }
    /// The static entries of the sampled block and their supports (the model's,
    /// [`super::model::Partition::static_params`]).
    fn static_params(&self) -> Vec<StaticParam> {
        self.model().static_params()
    }
    /// Draws one particle's sampled block and Gaussian from the model's prior.
    fn initialise(
        &self,
        rng: &mut StreamRng,
        sampled: &mut [f64],
        mean: &mut [f64],
        cov: &mut [f64],
    ) {
        self.model().sample_initial(rng, sampled);
        self.model().marginal_prior(rng, mean, cov);
    }
    /// The entries of the marginalised block held to their physical support after every step
    /// (`linalg::support`): the model's by default.
    fn lower_bounds(&self) -> Vec<LowerBound> {
        self.model().lower_bounds()
    }
    /// A failure of the whole step, before any particle moves (e.g. an `R` that could not be
    /// factorised); none by default.
    fn check(&self, _k: usize) -> Result<(), FilterError> {
        Ok(())
    }
    /// The step's scratch for one number type (allocated once).
    type Scratch<T: Real>: Send;
    /// The first Jacobian of `scratch` that its model wrote off the sparsity pattern it declared
    /// at set-up (`Sparse::pattern_broken`), if any: the step's numbers are then
    /// wrong and the run ends with [`FilterError::JacobianPattern`].
    fn broken_pattern<T: Real>(scratch: &Self::Scratch<T>) -> Option<&'static str>;
    /// Allocates the scratch.
    fn scratch<T: Real>(&self) -> Self::Scratch<T>;
    /// Sizes of a particle's blocks.
    fn shape(&self) -> Shape;
    /// Standard normal draws per particle and step.
    fn draws(&self) -> usize;
    /// Advances one particle (or a pack) from step `k − 1` to `k` ([`Ancestry`]), `slots` being
    /// the particle's blocks (module docs). Returns `log p(y_k | particle)` and the lanes whose
    /// straight path was valid. With `T = f64` the step takes the documented repairs (counted in
    /// `health`) and the mask is false only when the particle has no result.
    fn advance<T: Real>(
        &self,
        from: Ancestry<'_, T>,
        slots: Slots<'_, T>,
        scratch: &mut Self::Scratch<T>,
        health: &mut Health,
    ) -> (T, T::Mask);
}

/// Smallest marginalised dimension at which one filter advances its particles in blocks on
/// several threads (the rayon pool it runs in). Below it a particle-step costs a microsecond or
/// two and the pooled filters already fill the cores (`identify::pool`); from 10 storeys with a
/// Bouc–Wen element (n = 41, 11 µs a particle-step) a step of 125 particles is long enough that
/// sharing it costs nothing measurable (docs/performance.md, "Particle blocks in parallel").
pub const PARALLEL_MIN_DIM: usize = 32;

/// Whether a marginalized filter of particles of `shape` advances them in blocks on the threads
/// of the pool it runs in ([`PARALLEL_MIN_DIM`]).
pub(crate) fn shares_steps(shape: Shape) -> bool {
    shape.marginal >= PARALLEL_MIN_DIM && shape.sampled > 0
}

/// The particles that go through the step together: four in lanes, else one.
fn group_size(lanes: bool) -> usize {
    if lanes {
        PACK_LANES
    } else {
        1
    }
}

/// Particles per block when `np` particles are shared by `threads` threads: whole groups, one
/// block per thread.
fn block_size(lanes: bool, np: usize, threads: usize) -> usize {
    let group = group_size(lanes);
    np.div_ceil(group).div_ceil(threads.max(1)).max(1) * group
}

/// Whether particles of this shape go through the step in lanes when lanes are asked for.
fn lanes_fit(shape: Shape) -> bool {
    shape.marginal <= MAX_LANE_DIM
}

/// How many blocks a filter with the default lanes (lanes where they
/// pay) advances side by side for `np` particles on `threads` threads: 1 when it does not share
/// its steps (`shares_steps`) or has too few particles to fill two blocks.
pub fn blocks(shape: Shape, np: usize, threads: usize) -> usize {
    if !shares_steps(shape) {
        return 1;
    }
    np.div_ceil(block_size(lanes_fit(shape), np, threads))
        .max(1)
}

/// The buffers of the batch layer for one filter: the draws of every particle of a step, and one
/// `Worker` per block of particles advanced side by side.
pub(crate) struct Batch<S: ParticleStep> {
    lanes: bool,
    parallel: bool,
    workers: Vec<Worker<S>>,
    /// The draws of every particle of the step, particle after particle.
    draws: Vec<f64>,
}

/// What every worker reads in a step: the filter's per-particle step, the step's input, every
/// particle's draws (particle after particle) and whether particles go four at a time.
struct StepContext<'c, 'i, S> {
    step: &'c S,
    input: &'c StepInput<'i>,
    draws: &'c [f64],
    lanes: bool,
}

/// What one worker writes: its block of consecutive particles and their log-weights.
struct BlockOut<'b, 'p> {
    block: Block<'p>,
    log_w: &'b mut [f64],
}

impl BlockOut<'_, '_> {
    /// The log-weight of particle `i` (indexing the whole store).
    fn log_w(&mut self, i: usize) -> &mut f64 {
        &mut self.log_w[i - self.block.first()]
    }
}

/// What one thread needs to advance a block of particles: the scratch of the `f64` step and of
/// the pack, the pack's blocks, and the repairs counted in the current step.
struct Worker<S: ParticleStep> {
    scalar: S::Scratch<f64>,
    packed: S::Scratch<Pack>,
    prev: Vec<Pack>,
    sampled: Vec<Pack>,
    mean: Vec<Pack>,
    cov: Vec<Pack>,
    xi: Vec<Pack>,
    /// Repairs of the current step, added to the filter's once the step is over.
    health: Health,
}

impl<S: ParticleStep> Batch<S> {
    /// Buffers for `step`; lanes are used when the marginalised dimension is at most
    /// [`MAX_LANE_DIM`] and `lanes` is asked for; blocks of particles go to several threads from
    /// [`PARALLEL_MIN_DIM`] on.
    pub fn new(step: &S, lanes: bool) -> Self {
        let shape = step.shape();
        let use_lanes = lanes && lanes_fit(shape);
        Self {
            lanes: use_lanes,
            parallel: shares_steps(shape),
            workers: vec![Worker::new(step, use_lanes)],
            draws: Vec::new(),
        }
    }

    /// Whether particles go through the step four at a time.
    pub fn uses_lanes(&self) -> bool {
        self.lanes
    }

    /// Whether blocks of particles are advanced on several threads.
    pub fn uses_blocks(&self) -> bool {
        self.parallel
    }

    /// [`ParticleStep::broken_pattern`] of every worker's one-particle and pack scratch.
    fn broken_pattern(&self) -> Option<&'static str> {
        self.workers
            .iter()
            .find_map(|w| S::broken_pattern(&w.scalar).or_else(|| S::broken_pattern(&w.packed)))
    }

    /// Particles per block for `np` particles: one block per thread of the pool the step runs
    /// in (one block when the filter does not share its steps).
    fn block_size(&self, np: usize) -> usize {
        let threads = if self.parallel {
            rayon::current_num_threads()
        } else {
            1
        };
        block_size(self.lanes, np, threads)
    }

    /// Sizes the buffers for `np` particles in the pool the run is in (set-up: a step then
    /// allocates nothing unless the pool grew).
    fn prepare(&mut self, step: &S, np: usize) {
        self.draws.resize(np * step.draws(), 0.0);
        let blocks = np.div_ceil(self.block_size(np)).max(1);
        while self.workers.len() < blocks {
            self.workers.push(Worker::new(step, self.lanes));
        }
    }

    /// One step of every particle (the contract of [`super::Filter::step`]). The draws are taken
    /// first, particle after particle, so the stream is consumed as one particle at a time would
    /// consume it; a particle's result depends only on its ancestor and its draws, and blocks
    /// start at whole groups, so the particles come out the same to the bit whatever the number
    /// of blocks or threads.
    pub fn step(
        &mut self,
        step: &S,
        input: &StepInput<'_>,
        out: &mut StepOutput<'_>,
        rng: &mut StreamRng,
        health: &mut Health,
    ) {
        let np = out.log_w.len();
        self.prepare(step, np);
        let nd = step.draws();
        for v in &mut self.draws[..np * nd] {
            *v = StandardNormal.sample(rng);
        }
        let per = self.block_size(np);
        let blocks = np.div_ceil(per).max(1);
        let cx = StepContext {
            step,
            input,
            draws: &self.draws[..],
            lanes: self.lanes,
        };
        if blocks == 1 {
            let mut out = BlockOut {
                block: out.dst.as_block(),
                log_w: out.log_w,
            };
            self.workers[0].advance(&cx, &mut out);
        } else {
            out.dst
                .blocks_mut(per)
                .zip(out.log_w.par_chunks_mut(per))
                .zip(self.workers.par_iter_mut())
                .for_each(|((block, log_w), worker)| {
                    worker.advance(&cx, &mut BlockOut { block, log_w })
                });
        }
        for w in &mut self.workers[..blocks] {
            health.absorb(&w.health);
            w.health = Health::default();
        }
    }
}

impl<S: ParticleStep> Worker<S> {
    fn new(step: &S, lanes: bool) -> Self {
        let shape = step.shape();
        let z = Pack::splat(0.0);
        let n = |len: usize| if lanes { vec![z; len] } else { Vec::new() };
        Self {
            scalar: step.scratch(),
            packed: step.scratch(),
            prev: n(shape.sampled),
            sampled: n(shape.sampled),
            mean: n(shape.marginal),
            cov: n(shape.marginal * shape.marginal),
            xi: n(step.draws()),
            health: Health::default(),
        }
    }

    /// Advances the particles of `out`, group after group: the groups one worker would form
    /// over the whole store, since a block starts at a whole group.
    fn advance(&mut self, cx: &StepContext<'_, '_, S>, out: &mut BlockOut<'_, '_>) {
        let group = group_size(cx.lanes);
        let end = out.block.first() + out.log_w.len();
        let mut first = out.block.first();
        while first < end {
            let count = group.min(end - first);
            if cx.lanes && count > 1 {
                self.pack_group(cx, out, first, count);
            } else {
                for i in first..first + count {
                    self.one(cx, out, i);
                }
            }
            first += count;
        }
    }

    /// Particle `i` through the `f64` step, with its draws.
    fn one(&mut self, cx: &StepContext<'_, '_, S>, out: &mut BlockOut<'_, '_>, i: usize) {
        let StepInput {
            k,
            y,
            src,
            ancestors,
        } = *cx.input;
        let a = ancestors[i];
        out.block.copy_from(i, src, a);
        if *out.log_w(i) == f64::NEG_INFINITY {
            return;
        }
        let nd = cx.step.draws();
        let d = out.block.particle_mut(i);
        let (ll, ok) = cx.step.advance(
            Ancestry {
                k,
                y,
                prev: src.sampled(a),
                xi: &cx.draws[i * nd..(i + 1) * nd],
            },
            Slots {
                sampled: d.sampled,
                mean: d.mean,
                cov: d.cov,
            },
            &mut self.scalar,
            &mut self.health,
        );
        *out.log_w(i) += if ok { ll } else { f64::NAN };
    }

    /// The `count ≤ 4` particles from `first` on in lanes (lanes past `count` repeat the group's
    /// first particle and are discarded).
    fn pack_group(
        &mut self,
        cx: &StepContext<'_, '_, S>,
        out: &mut BlockOut<'_, '_>,
        first: usize,
        count: usize,
    ) {
        let StepInput {
            k,
            y,
            src,
            ancestors,
        } = *cx.input;
        let nd = cx.step.draws();
        let particle = |b: usize| first + if b < count { b } else { 0 };
        gather(
            &mut self.prev,
            std::array::from_fn(|b| src.sampled(ancestors[particle(b)])),
        );
        self.sampled.copy_from_slice(&self.prev);
        gather(
            &mut self.mean,
            std::array::from_fn(|b| src.mean(ancestors[particle(b)])),
        );
        gather(
            &mut self.cov,
            std::array::from_fn(|b| src.cov(ancestors[particle(b)])),
        );
        gather(
            &mut self.xi,
            std::array::from_fn(|b| &cx.draws[particle(b) * nd..(particle(b) + 1) * nd]),
        );
        let (ll, ok) = cx.step.advance(
            Ancestry {
                k,
                y,
                prev: &self.prev,
                xi: &self.xi,
            },
            Slots {
                sampled: &mut self.sampled,
                mean: &mut self.mean,
                cov: &mut self.cov,
            },
            &mut self.packed,
            &mut self.health,
        );
        for b in 0..count {
            let i = first + b;
            if *out.log_w(i) == f64::NEG_INFINITY {
                out.block.copy_from(i, src, ancestors[i]);
            } else if Pack::mask_lane(ok, b) {
                let d = out.block.particle_mut(i);
                for (o, v) in d.sampled.iter_mut().zip(&self.sampled) {
                    *o = v.lane(b);
                }
                for (o, v) in d.mean.iter_mut().zip(&self.mean) {
                    *o = v.lane(b);
                }
                for (o, v) in d.cov.iter_mut().zip(&self.cov) {
                    *o = v.lane(b);
                }
                *out.log_w(i) += ll.lane(b);
            } else {
                self.one(cx, out, i);
            }
        }
    }
}

/// A marginalized particle filter as the runner sees it: a per-particle step ([`ParticleStep`])
/// and the batch layer that runs it. The MLN-RBPF, Storvik and the MPF-EKF2 are this adapter
/// around their own step.
pub struct Marginalized<S: ParticleStep> {
    step: S,
    batch: Batch<S>,
    layout: Layout,
    statics: Vec<StaticParam>,
    /// The model's physical support, enforced after the batch step (not inside it, so the
    /// per-particle step stays the SPEC's and the lanes stay equal to it).
    bounds: Vec<LowerBound>,
    health: Health,
}

impl<S: ParticleStep> Marginalized<S> {
    /// The filter of `step`; `lanes = false` runs every particle through the `f64` step (the
    /// reference the lanes are tested against).
    pub(crate) fn from_step(step: S, lanes: bool) -> Self {
        Self {
            layout: step.layout(),
            statics: step.static_params(),
            bounds: step.lower_bounds(),
            batch: Batch::new(&step, lanes),
            step,
            health: Health::default(),
        }
    }

    /// The per-particle step.
    pub fn particle_step(&self) -> &S {
        &self.step
    }

    /// Whether particles go through the step four at a time.
    pub fn uses_lanes(&self) -> bool {
        self.batch.uses_lanes()
    }

    /// Whether blocks of particles are advanced on several threads ([`PARALLEL_MIN_DIM`]).
    pub fn uses_blocks(&self) -> bool {
        self.batch.uses_blocks()
    }

    /// The filter with blocks of particles on several threads (`true`) or one thread (`false`)
    /// whatever its size; the particles are the same either way (tested).
    pub fn with_blocks(mut self, on: bool) -> Self {
        self.batch.parallel = on && self.step.shape().sampled > 0;
        self
    }
}

impl<S: ParticleStep> Filter for Marginalized<S> {
    fn name(&self) -> &'static str {
        self.step.name()
    }

    fn layout(&self) -> &Layout {
        &self.layout
    }

    fn static_params(&self) -> &[StaticParam] {
        &self.statics
    }

    fn shape(&self) -> Shape {
        self.step.shape()
    }

    fn initialise(&mut self, rng: &mut StreamRng, particles: &mut Particles) {
        self.health = Health::default();
        self.batch.prepare(&self.step, particles.len());
        for i in 0..particles.len() {
            let p = particles.particle_mut(i);
            self.step.initialise(rng, p.sampled, p.mean, p.cov);
        }
    }

    fn step(
        &mut self,
        input: &StepInput<'_>,
        out: &mut StepOutput<'_>,
        rng: &mut StreamRng,
    ) -> Result<(), FilterError> {
        let k = input.k;
        self.step.check(k)?;
        self.batch
            .step(&self.step, input, out, rng, &mut self.health);
        if !self.bounds.is_empty() {
            for i in 0..out.log_w.len() {
                if out.log_w[i].is_finite() {
                    let p = out.dst.particle_mut(i);
                    let n = truncate_below(p.mean, p.cov, &self.bounds);
                    self.health.truncated += n as u64;
                }
            }
        }
        // Checked once per step: the flags are sticky, so a single wrong write is not missed.
        match self.batch.broken_pattern() {
            Some(which) => Err(FilterError::JacobianPattern { step: k, which }),
            None => Ok(()),
        }
    }

    fn health(&self) -> Health {
        self.health
    }

    fn lower_bounds(&self) -> &[LowerBound] {
        &self.bounds
    }
}
