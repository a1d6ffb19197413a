//! Conditionally bilinear partition of the general chain for MPF-EKF2 (SPEC §5.4 and §6
//! generalised, §9; derivation in `docs/partitions.md`).
//!
//! Sampled: what enters a hysteresis law nonlinearly. For the element at storey j: the velocities
//! its drift rate depends on (`v_j`, and `v_{j−1}` for j ≥ 1 in 0-based storeys), `r_j` and `n_j`
//! (static):
//!
//! `xⁿ = [sampled velocities by storey, r_e…, n_e…]`,
//! `x^bl = [x1..xN, the other velocities by storey, k1..kN, c1..cN, (α), (β_e, γ_e)…]`
//! (for any law, [`HysteresisLaw`]: its nonlinear parameters where n is, its linear ones where
//! (β, γ) are).
//!
//! For the paper's chain this is SPEC §6 exactly (`xⁿ = [ẋ1, r1, n]`,
//! `x^bl = [x1 x2 x3 ẋ2 ẋ3 k1 k2 k3 c1 c2 c3 β γ]`). Given xⁿ, an element force
//! `F_j = k_j d_j + c_j δv_j` has at most the products `k_j·x` and `c_j·v` (bilinear), and a
//! hysteretic rate is affine in `(β, γ)`; so every map is at most bilinear in x^bl, with constant
//! Hessians (±dt/m_j, ±1/m_j, ±dt²/m_j), built once.
//!
//! With the storey+mass damping form ([`crate::structure::Damping::StoreyMass`]) α is one more
//! entry of x^bl after c: `a_j` gains `−α v_j`, bilinear (constant Hessian entry `−scale` for
//! α × v_j, e.g. `−dt` in a velocity row) when `v_j` is marginal, linear in α (Jacobian entry
//! `−scale·v_j`) when `v_j` is sampled.
//!
//! - Euler: one sampled stage (sampled velocities, then r's), `φ_bl` = Euler map of x and the
//!   marginal velocities; `Q_bl` diagonal.
//! - Symplectic: stage 0 = sampled velocities, stage 1 = r's with the *new* sampled velocities;
//!   `φ_bl`: marginal velocities `v + dt a` (bilinear), displacements `x_j + dt v_j,new` with
//!   `v_j,new` the marginal map (quadratic: Hessian `dt²·∂²a_j`) or the sampled new value
//!   (affine); `Q_bl` adds `Var(x_j) += dt² q_vel²` and `Cov(x_j, v_j) = dt q_vel²` for every
//!   marginal velocity (the same noise moves `x_j` through the new velocity).
//!
//! With coloured measurement noise ([`super::ColouredNoise`]) x^bl ends with one AR(1) state per
//! sensor, `e_i ← a e_i` (`D` entry `a − 1`, noise `(1 − a²)·share·r_i`), added to its
//! channel's observation (Jacobian entry 1): linear, so the Kalman part carries it exactly.
//!
//! With regressors ([`super::Regressors`]) x^bl ends with their coefficients β (channel-major),
//! static, each observation gaining `Σ_c β_ic s_c(k)` (Jacobian entries `s_c(k)`): linear too.
//!
//! A chain without hysteretic element samples nothing: xⁿ is empty and there are no sampled
//! stages, so the MPF-EKF2 reduces to an EKF2 (exact here: a KF with bilinear terms) on x^bl.

use super::{nlin, zero_basis, ChainCore, ChainSpecOf, ForceColumns, SpecError};
use crate::building::Building;
use crate::law::{BoucWenLaw, HysteresisLaw};
use crate::structure::ChainView;
use core_filters::linalg::{Sparse, SymEntries};
use core_filters::model::{Layout, Slot, SparseHessians};
use core_filters::real::Real;
use core_filters::rng::StreamRng;
use core_filters::smc::model::{
    ConditionallyQuadratic, Marginalised, Partition, QuadraticDims, SampledAt,
};
use core_filters::smc::rejuvenation::StaticParam;

/// Where a storey's velocity lives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Vel {
    /// Entry of xⁿ.
    Sampled(usize),
    /// Entry of x^bl.
    Marginal(usize),
}

/// The chain partitioned for MPF-EKF2, its elements following the law `L`.
#[derive(Debug, Clone)]
pub struct MpfChainOf<L: HysteresisLaw> {
    core: ChainCore<L>,
    symplectic: bool,
    /// Location of each storey's velocity.
    vel: Vec<Vel>,
    /// Storeys of the sampled velocities (increasing).
    sampled_vel: Vec<usize>,
    /// Storeys of the marginal velocities (increasing).
    marginal_vel: Vec<usize>,
    /// Offsets of k and c in x^bl.
    k0: usize,
    c0: usize,
    /// Offset of α in x^bl (the first entry after c; present only with mass damping).
    a0: usize,
    /// Offset of (β_0, γ_0) in x^bl.
    b0: usize,
    /// Offset of the coloured-noise states in x^bl (one per sensor, after the elements'
    /// parameters), their AR coefficient and innovation variance per transition, and their
    /// stationary variances (empty without coloured noise).
    e0: usize,
    colour_ar: f64,
    colour_q: Vec<f64>,
    colour_var: Vec<f64>,
    /// Offset of the regressors' coefficients in x^bl (after the coloured-noise states).
    g0: usize,
    stages: Vec<Vec<usize>>,
    stage_noise: Vec<Vec<f64>>,
    stage_hessians: Vec<SparseHessians>,
    marginal_hessians: SparseHessians,
    observation_hessians: SparseHessians,
    marginal_noise: SymEntries,
}

/// The Bouc–Wen chain partitioned for MPF-EKF2.
pub type MpfChain = MpfChainOf<BoucWenLaw>;

/// (xⁿ, x^bl) as a chain point.
struct View<'a, T, L: HysteresisLaw> {
    xn: &'a [T],
    m: &'a [T],
    p: &'a MpfChainOf<L>,
}

impl<T: Real, L: HysteresisLaw> ChainView<T> for View<'_, T, L> {
    #[inline(always)]
    fn x(&self, j: usize) -> T {
        self.m[j]
    }
    #[inline(always)]
    fn v(&self, j: usize) -> T {
        match self.p.vel[j] {
            Vel::Sampled(i) => self.xn[i],
            Vel::Marginal(i) => self.m[i],
        }
    }
    #[inline(always)]
    fn r(&self, e: usize) -> T {
        self.xn[self.p.r_index(e)]
    }
    #[inline(always)]
    fn k(&self, j: usize) -> T {
        self.m[self.p.k0 + j]
    }
    #[inline(always)]
    fn c(&self, j: usize) -> T {
        self.m[self.p.c0 + j]
    }
    #[inline(always)]
    fn alpha(&self) -> T {
        self.m[self.p.a0]
    }
}

/// x^bl as the variables of the force gradients: displacements, marginal velocities, θ.
impl<L: HysteresisLaw> ForceColumns for MpfChainOf<L> {
    #[inline(always)]
    fn theta(&self) -> Option<(usize, usize)> {
        Some((self.k0, self.c0))
    }
    #[inline(always)]
    fn displacements(&self) -> bool {
        true
    }
    #[inline(always)]
    fn velocity(&self, j: usize) -> Option<usize> {
        match self.vel[j] {
            Vel::Marginal(i) => Some(i),
            Vel::Sampled(_) => None,
        }
    }
    #[inline(always)]
    fn alpha(&self) -> Option<usize> {
        self.core.mass_damping().then_some(self.a0)
    }
}

impl<L: HysteresisLaw> MpfChainOf<L> {
    /// Validates the spec, builds the index maps, the stages and the constant Hessians; Euler
    /// and symplectic only (RK4 is not bilinear in x^bl given xⁿ).
    pub fn new(spec: ChainSpecOf<L>) -> Result<Self, SpecError> {
        let core = ChainCore::new(spec)?;
        let (n, ne) = (core.n, core.ne);
        let symplectic = core.symplectic("MPF-EKF2")?;
        let mut sampled = vec![false; n];
        for &j in core.spec.building.hysteretic() {
            sampled[j] = true;
            if j > 0 {
                sampled[j - 1] = true;
            }
        }
        let sampled_vel: Vec<usize> = (0..n).filter(|&j| sampled[j]).collect();
        let marginal_vel: Vec<usize> = (0..n).filter(|&j| !sampled[j]).collect();
        let mut vel = vec![Vel::Sampled(0); n];
        for (i, &j) in sampled_vel.iter().enumerate() {
            vel[j] = Vel::Sampled(i);
        }
        for (i, &j) in marginal_vel.iter().enumerate() {
            vel[j] = Vel::Marginal(n + i);
        }
        let nvm = marginal_vel.len();
        let nvs = sampled_vel.len();
        let na = core.spec.building.damping().extra_parameters();
        let (k0, c0, a0, b0) = (n + nvm, 2 * n + nvm, 3 * n + nvm, 3 * n + nvm + na);
        let e0 = b0 + L::NLIN * ne;
        let (mut colour_ar, mut colour_q, mut colour_var) = (1.0, Vec::new(), Vec::new());
        if let Some(c) = core.spec.coloured_noise {
            for r in &core.spec.r_diag {
                let var = c.share * r;
                let (ar, q) = c.per_transition(core.substeps, var);
                colour_ar = ar;
                colour_q.push(q);
                colour_var.push(var);
            }
        }
        let g0 = e0 + colour_var.len();
        let mut me = Self {
            core,
            symplectic,
            vel,
            sampled_vel,
            marginal_vel,
            k0,
            c0,
            a0,
            b0,
            e0,
            colour_ar,
            colour_q,
            colour_var,
            g0,
            stages: Vec::new(),
            stage_noise: Vec::new(),
            stage_hessians: Vec::new(),
            marginal_hessians: SparseHessians::new(),
            observation_hessians: SparseHessians::new(),
            marginal_noise: SymEntries::new(),
        };
        let dt = me.core.dt;
        let (q_vel, q_disp) = (me.core.q_vel, me.core.q_disp);
        // Sampled stages, their noise and Hessians (velocity rows: dt·∂²a_j; r rows affine).
        let mut vel_hessians = SparseHessians::new();
        for (i, &j) in me.sampled_vel.iter().enumerate() {
            me.push_acceleration_hessian(&mut vel_hessians, i, j, dt);
        }
        let r_entries: Vec<usize> = (nvs..nvs + ne).collect();
        if ne > 0 {
            if symplectic {
                me.stages = vec![(0..nvs).collect(), r_entries];
                me.stage_noise = vec![vec![q_vel; nvs], me.core.q_r.clone()];
                me.stage_hessians = vec![vel_hessians, SparseHessians::new()];
            } else {
                me.stages = vec![(0..nvs + ne).collect()];
                let mut q = vec![q_vel; nvs];
                q.extend_from_slice(&me.core.q_r);
                me.stage_noise = vec![q];
                me.stage_hessians = vec![vel_hessians];
            }
        }
        // φ_bl Hessians and Q_bl.
        let mut mh = SparseHessians::new();
        let mut q = SymEntries::new();
        for j in 0..n {
            q.push(j, j, q_disp * q_disp);
        }
        for (i, &j) in me.marginal_vel.clone().iter().enumerate() {
            let vi = n + i;
            me.push_acceleration_hessian(&mut mh, vi, j, dt);
            q.push(vi, vi, q_vel * q_vel);
            if symplectic {
                me.push_acceleration_hessian(&mut mh, j, j, dt * dt);
                q.push(j, j, dt * dt * q_vel * q_vel);
                q.push(j, vi, dt * q_vel * q_vel);
            }
        }
        for (i, qe) in me.colour_q.iter().enumerate() {
            q.push(e0 + i, e0 + i, *qe);
        }
        me.marginal_hessians = mh;
        me.marginal_noise = q;
        let mut oh = SparseHessians::new();
        for (i, &s) in me.core.sensors.clone().iter().enumerate() {
            me.push_acceleration_hessian(&mut oh, i, s, 1.0);
        }
        me.observation_hessians = oh;
        Ok(me)
    }

    pub fn spec(&self) -> &ChainSpecOf<L> {
        &self.core.spec
    }

    #[inline]
    fn nvs(&self) -> usize {
        self.sampled_vel.len()
    }

    /// Index of r_e in xⁿ.
    #[inline]
    fn r_index(&self, e: usize) -> usize {
        self.sampled_vel.len() + e
    }

    /// Index of n_e (the element's first nonlinear parameter) in xⁿ.
    #[inline]
    fn n_index(&self, e: usize) -> usize {
        self.sampled_vel.len() + self.core.ne + L::NNONLIN * e
    }

    /// Index of β_e (the element's first linear parameter) in x^bl (γ_e follows).
    #[inline]
    fn beta_index(&self, e: usize) -> usize {
        self.b0 + L::NLIN * e
    }

    /// Pushes the constant Hessian of `scale · F_j` w.r.t. x^bl as output `out`:
    /// `k_j × x_j`, `k_j × x_{j−1}` (linear element) and `c_j × v` for marginal velocities.
    fn push_force_hessian(&self, h: &mut SparseHessians, out: usize, j: usize, scale: f64) {
        if self.core.spec.building.element_at(j).is_none() {
            h.push(out, self.k0 + j, j, scale);
            if j > 0 {
                h.push(out, self.k0 + j, j - 1, -scale);
            }
        }
        if let Vel::Marginal(i) = self.vel[j] {
            h.push(out, self.c0 + j, i, scale);
        }
        if j > 0 {
            if let Vel::Marginal(i) = self.vel[j - 1] {
                h.push(out, self.c0 + j, i, -scale);
            }
        }
    }

    /// Pushes the Hessian of `scale · a_j`, `a_j = ground + (F_{j+1} − F_j)/m_j` (`− α v_j`
    /// with mass damping: `−scale` at α × v_j for a marginal v_j).
    fn push_acceleration_hessian(&self, h: &mut SparseHessians, out: usize, j: usize, scale: f64) {
        let s = scale * self.core.inv_mass[j];
        self.push_force_hessian(h, out, j, -s);
        if j + 1 < self.core.n {
            self.push_force_hessian(h, out, j + 1, s);
        }
        if self.core.mass_damping() {
            if let Vel::Marginal(i) = self.vel[j] {
                h.push(out, self.a0, i, -scale);
            }
        }
    }

    /// Writes `scale · ∂a_j/∂x^bl` at the point into row `row`.
    #[inline]
    fn write_acceleration_gradient<T: Real>(
        &self,
        out: &mut Sparse<T>,
        row: usize,
        j: usize,
        p: &View<'_, T, L>,
        scale: T,
    ) {
        self.core
            .write_acceleration_gradient(out, row, j, p, self, scale);
    }

    /// Returns `r_e + dt (g₀ + β g₁ + γ g₂)` at drift velocity `dv` and writes its row of the
    /// Jacobian (`dt g₁`, `dt g₂` at β_e, γ_e; generally `dt g_i` at the law's linear parameters).
    #[inline]
    fn write_r_map<T: Real>(
        &self,
        e: usize,
        dv: T,
        xn_prev: &[T],
        m: &[T],
        row: usize,
        jac: &mut Sparse<T>,
    ) -> T {
        let dt = T::splat(self.core.dt);
        let mut g = zero_basis();
        let i0 = self.n_index(e);
        let phi = &xn_prev[i0..i0 + L::NNONLIN];
        let r = xn_prev[self.r_index(e)];
        self.core.law.basis(dv, r, phi, &mut g[..1 + nlin::<L>()]);
        let b = self.beta_index(e);
        let mut rate = g[0];
        for i in 0..L::NLIN {
            jac.add(row, b + i, dt * g[1 + i]);
            rate += m[b + i] * g[1 + i];
        }
        r + dt * rate
    }
}

impl<L: HysteresisLaw> Partition for MpfChainOf<L> {
    /// Zero states, each n_e drawn from its prior (SPEC §3).
    fn sample_initial(&self, rng: &mut StreamRng, xn: &mut [f64]) {
        self.core.sample_initial(rng, xn, |e| self.n_index(e));
    }

    fn measurement_cov(&self) -> Vec<f64> {
        self.core.measurement_cov()
    }

    /// Each element's n, with the support of its prior.
    fn static_params(&self) -> Vec<StaticParam> {
        self.core.static_params(|e| self.n_index(e))
    }

    fn layout(&self) -> Layout {
        let (n, ne) = (self.core.n, self.core.ne);
        let mut params: Vec<Slot> = (0..n).map(|j| Slot::Marginal(self.k0 + j)).collect();
        params.extend((0..n).map(|j| Slot::Marginal(self.c0 + j)));
        if self.core.mass_damping() {
            params.push(Slot::Marginal(self.a0));
        }
        self.core
            .push_element_slots(&mut params, |e| self.beta_index(e), |e| self.n_index(e));
        let mut states: Vec<Slot> = (0..n).map(Slot::Marginal).collect();
        states.extend(self.vel.iter().map(|v| match *v {
            Vel::Sampled(i) => Slot::Sampled(i),
            Vel::Marginal(i) => Slot::Marginal(i),
        }));
        states.extend((0..ne).map(|e| Slot::Sampled(self.r_index(e))));
        self.core.layout(params, states)
    }
}

impl<L: HysteresisLaw> ConditionallyQuadratic for MpfChainOf<L> {
    fn dims(&self) -> QuadraticDims {
        let (n, ne) = (self.core.n, self.core.ne);
        QuadraticDims {
            nn: self.nvs() + ne + L::NNONLIN * ne,
            nbl: 3 * n
                + self.marginal_vel.len()
                + self.core.spec.building.damping().extra_parameters()
                + L::NLIN * ne
                + self.colour_var.len()
                + self
                    .core
                    .spec
                    .regressors
                    .as_ref()
                    .map_or(0, |r| r.prior_sd.len()),
            ny: self.core.sensors.len(),
        }
    }

    fn sampled_stages(&self) -> &[Vec<usize>] {
        &self.stages
    }

    /// ψ of stage `at.stage` (module docs) at `(xⁿ_{k−1}, m)` with ü_g,meas(k−1).
    fn sampled_dynamics<T: Real>(
        &self,
        at: SampledAt<'_, T>,
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        let SampledAt {
            stage,
            k,
            prev: xn_prev,
            new: xn_new,
            m,
        } = at;
        let dt = T::splat(self.core.dt);
        let ground = T::splat(self.core.transition_ground(k));
        let p = View {
            xn: xn_prev,
            m,
            p: self,
        };
        let nvs = self.nvs();
        let hyst = self.core.spec.building.hysteretic();
        let velocities = |value: &mut [T], jac: &mut Sparse<T>| {
            for (i, &j) in self.sampled_vel.iter().enumerate() {
                value[i] = xn_prev[i] + dt * self.core.spec.building.acceleration(&p, j, ground);
                self.write_acceleration_gradient(jac, i, j, &p, dt);
            }
        };
        match (self.symplectic, stage) {
            (false, 0) => {
                velocities(value, jac);
                for (e, &j) in hyst.iter().enumerate() {
                    let dv = Building::drift_velocity(&p, j);
                    value[nvs + e] = self.write_r_map(e, dv, xn_prev, m, nvs + e, jac);
                }
            }
            (true, 0) => velocities(value, jac),
            (true, 1) => {
                let q = View {
                    xn: xn_new,
                    m,
                    p: self,
                };
                for (e, &j) in hyst.iter().enumerate() {
                    let dv = Building::drift_velocity(&q, j);
                    value[e] = self.write_r_map(e, dv, xn_prev, m, e, jac);
                }
            }
            _ => panic!("no stage {stage}"),
        }
    }

    fn sampled_hessians(&self, stage: usize) -> &SparseHessians {
        &self.stage_hessians[stage]
    }

    fn sampled_noise_sd(&self, stage: usize) -> &[f64] {
        &self.stage_noise[stage]
    }

    /// φ_bl (module docs) and `D = ∂φ_bl/∂x^bl − I`.
    fn marginal_dynamics<T: Real>(
        &self,
        k: usize,
        xn_prev: &[T],
        xn_new: &[T],
        m: &[T],
        value: &mut [T],
        d: &mut Sparse<T>,
    ) {
        let n = self.core.n;
        let dt = T::splat(self.core.dt);
        let ground = T::splat(self.core.transition_ground(k));
        let p = View {
            xn: xn_prev,
            m,
            p: self,
        };
        value.copy_from_slice(m);
        for (i, &j) in self.marginal_vel.iter().enumerate() {
            let vi = n + i;
            value[vi] = m[vi] + dt * self.core.spec.building.acceleration(&p, j, ground);
            self.write_acceleration_gradient(d, vi, j, &p, dt);
        }
        for j in 0..n {
            match (self.vel[j], self.symplectic) {
                (Vel::Sampled(i), false) => value[j] = m[j] + dt * xn_prev[i],
                (Vel::Sampled(i), true) => value[j] = m[j] + dt * xn_new[i],
                (Vel::Marginal(vi), false) => {
                    value[j] = m[j] + dt * m[vi];
                    d.add(j, vi, dt);
                }
                (Vel::Marginal(vi), true) => {
                    value[j] = m[j] + dt * value[vi];
                    d.add(j, vi, dt);
                    self.write_acceleration_gradient(d, j, j, &p, dt * dt);
                }
            }
        }
        let a = self.colour_ar;
        for i in self.e0..self.e0 + self.colour_var.len() {
            value[i] = T::splat(a) * m[i];
            d.add(i, i, T::splat(a - 1.0));
        }
    }

    fn marginal_hessians(&self) -> &SparseHessians {
        &self.marginal_hessians
    }

    fn marginal_noise(&self) -> &SymEntries {
        &self.marginal_noise
    }

    /// Accelerations at the sensor storeys at `(xⁿ_k, m)` with ü_g,meas(k).
    fn observation<T: Real>(
        &self,
        k: usize,
        xn: &[T],
        m: &[T],
        value: &mut [T],
        jac: &mut Sparse<T>,
    ) {
        let ground = T::splat(self.core.measurement_ground(k));
        let p = View { xn, m, p: self };
        for (i, &s) in self.core.sensors.iter().enumerate() {
            value[i] = self.core.spec.building.acceleration(&p, s, ground);
            self.write_acceleration_gradient(jac, i, s, &p, T::splat(1.0));
            if !self.colour_var.is_empty() {
                value[i] += m[self.e0 + i];
                jac.add(i, self.e0 + i, T::splat(1.0));
            }
            if let Some(r) = &self.core.spec.regressors {
                // The columns are on the samples' grid; k is on the model's.
                let sample = k / self.core.substeps;
                let first = self.g0 + i * r.columns.len();
                for (c, column) in r.columns.iter().enumerate() {
                    let s = T::splat(column[sample]);
                    value[i] += m[first + c] * s;
                    jac.add(i, first + c, s);
                }
            }
        }
    }

    fn observation_hessians(&self) -> &SparseHessians {
        &self.observation_hessians
    }

    /// [`ChainSpecOf::substeps`]: the model's grid is `dt/substeps`.
    fn substeps(&self) -> usize {
        self.core.substeps
    }
}

impl<L: HysteresisLaw> Marginalised for MpfChainOf<L> {
    fn lower_bounds(&self) -> Vec<core_filters::linalg::LowerBound> {
        self.core.lower_bounds(&self.layout().params)
    }

    /// States exactly zero (variance 0); k, c, (α), β, γ from θ's Gaussian prior (SPEC §3).
    fn marginal_prior(&self, rng: &mut StreamRng, mean: &mut [f64], cov: &mut [f64]) {
        let n = self.core.n;
        let nbl = self.dims().nbl;
        let (m, v) = self.core.theta_prior(rng);
        mean.fill(0.0);
        cov.fill(0.0);
        let mut set = |i: usize, t: usize| {
            mean[i] = m[t];
            cov[i + i * nbl] = v[t];
        };
        for j in 0..n {
            set(self.k0 + j, j);
            set(self.c0 + j, n + j);
        }
        if let Some(t) = self.core.theta_alpha() {
            set(self.a0, t);
        }
        for e in 0..self.core.ne {
            let t = self.core.theta_element(e);
            for i in 0..L::NLIN {
                set(self.beta_index(e) + i, t + i);
            }
        }
        if let Some(r) = &self.core.spec.regressors {
            for (j, sd) in r.prior_sd.iter().enumerate() {
                cov[(self.g0 + j) * (nbl + 1)] = sd * sd;
            }
        }
        // The coloured noise starts from its stationary distribution.
        for (i, var) in self.colour_var.iter().enumerate() {
            cov[(self.e0 + i) * (nbl + 1)] = *var;
        }
    }
}
