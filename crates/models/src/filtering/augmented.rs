//! Augmented-state partition for the bootstrap PF (SPEC §5.1), any chain, three schemes.
//!
//! x = [x1..xN, v1..vN, r_e…, θ] with θ = [k, c, (α), (β_e, γ_e, n_e)…] (for any law, its
//! parameters per element); θ is static (no draw).
//! The mass-proportional damping α (the storey+mass form) is one more static entry of θ.
//! `noise_dim = 2N + E`: one standard normal draw per displacement, velocity and r.
//!
//! - Euler: `x' = x + dt v + q_disp ξ`, `v' = v + dt a(x, v, r; θ, ü_g(k−1)) + q_vel ξ`,
//!   `r' = r + dt ṙ(δv, r) + q_r ξ`.
//! - Symplectic: `v'` first (as Euler), then `x' = x + dt v' + q_disp ξ` and
//!   `r' = r + dt ṙ(δv', r) + q_r ξ` with the new velocities (noise included).
//! - RK4: one classical RK4 step of the continuous equations (`ü_g` linear inside the step, as
//!   `crate::integrate::simulate_rk4`), then the same additive noise.
//!
//! With `substeps = M > 1` ([`ChainSpecOf::substeps`]) one transition between two samples is `M`
//! of these steps with `dt/M` on the interpolated `ü_g`, each with its own draws
//! (`noise_dim = M (2N + E)`), and the measurement at sample k reads the grid at `kM`.

use super::{ChainCore, ChainSpecOf, Discretisation, SpecError};
use crate::building::Building;
use crate::law::{BoucWenLaw, HysteresisLaw};
use crate::structure::{ChainView, StateView};
use core_filters::model::{Layout, Slot};
use core_filters::rng::StreamRng;
use core_filters::smc::model::{Partition, StateSpace};
use std::cell::RefCell;

/// The chain as one augmented state (SPEC §5.1), its elements following the law `L`.
#[derive(Debug, Clone)]
pub struct AugmentedChainOf<L: HysteresisLaw> {
    core: ChainCore<L>,
    /// Process-noise s.d. of the 2N + E dynamic entries (per filter step).
    noise_sd: Vec<f64>,
}

/// The Bouc–Wen chain as one augmented state.
pub type AugmentedChain = AugmentedChainOf<BoucWenLaw>;

thread_local! {
    /// The state between sub-steps (`substeps > 1`), grown once per thread.
    static SUBSTEP_SCRATCH: RefCell<Vec<f64>> = const { RefCell::new(Vec::new()) };
}

thread_local! {
    /// RK4 stage buffers (5 × (2N + E)), grown once per thread.
    static RK4_SCRATCH: RefCell<Vec<f64>> = const { RefCell::new(Vec::new()) };
}

impl<L: HysteresisLaw> AugmentedChainOf<L> {
    /// Validates the spec; every discretisation is supported.
    pub fn new(spec: ChainSpecOf<L>) -> Result<Self, SpecError> {
        let core = ChainCore::new(spec)?;
        core.no_gaussian_extras("bootstrap PF")?;
        let (n, ne) = (core.n, core.ne);
        let mut noise_sd = vec![core.q_disp; n];
        noise_sd.extend(std::iter::repeat_n(core.q_vel, n));
        noise_sd.extend_from_slice(&core.q_r);
        debug_assert_eq!(noise_sd.len(), 2 * n + ne);
        Ok(Self { core, noise_sd })
    }

    pub fn spec(&self) -> &ChainSpecOf<L> {
        &self.core.spec
    }

    /// Number of dynamic entries 2N + E.
    fn dyn_dim(&self) -> usize {
        2 * self.core.n + self.core.ne
    }

    /// The dynamic part `s = [x, v, r]` and θ of an augmented state as a chain point.
    #[inline]
    fn view<'a>(&self, s: &'a [f64], th: &'a [f64]) -> StateView<'a> {
        let n = self.core.n;
        StateView {
            s,
            n,
            k: &th[..n],
            c: &th[n..2 * n],
            alpha: self.core.theta_alpha().map_or(0.0, |t| th[t]),
        }
    }

    /// `(θ_lin, φ)` of element `e` from θ.
    #[inline]
    fn element_params<'a>(&self, th: &'a [f64], e: usize) -> (&'a [f64], &'a [f64]) {
        let b = self.core.theta_element(e);
        (&th[b..b + L::NLIN], &th[b + L::NLIN..b + L::NPARAMS])
    }

    /// The continuous right-hand side of the dynamic part with ground term `ground = −ü_g`.
    fn rhs(&self, s: &[f64], th: &[f64], ground: f64, ds: &mut [f64]) {
        let n = self.core.n;
        let view = self.view(s, th);
        ds[..n].copy_from_slice(&s[n..2 * n]);
        self.core
            .spec
            .building
            .accelerations(&view, ground, &mut ds[n..2 * n]);
        for (e, &j) in self.core.spec.building.hysteretic().iter().enumerate() {
            let (lin, phi) = self.element_params(th, e);
            let dv = Building::drift_velocity(&view, j);
            ds[2 * n + e] = self.core.law.rate(dv, view.r(e), lin, phi);
        }
    }

    fn propagate_euler(&self, k: usize, x: &[f64], xi: &[f64], out: &mut [f64]) {
        let dt = self.core.dt;
        let d = self.dyn_dim();
        let (s, th) = x.split_at(d);
        self.rhs(s, th, self.core.transition_ground(k), &mut out[..d]);
        for i in 0..d {
            out[i] = s[i] + dt * out[i] + self.noise_sd[i] * xi[i];
        }
    }

    fn propagate_symplectic(&self, k: usize, x: &[f64], xi: &[f64], out: &mut [f64]) {
        let (n, dt) = (self.core.n, self.core.dt);
        let d = self.dyn_dim();
        let (s, th) = x.split_at(d);
        let view = self.view(s, th);
        let ground = self.core.transition_ground(k);
        self.core
            .spec
            .building
            .accelerations(&view, ground, &mut out[n..2 * n]);
        for j in 0..n {
            out[n + j] = s[n + j] + dt * out[n + j] + self.noise_sd[n + j] * xi[n + j];
        }
        for j in 0..n {
            out[j] = s[j] + dt * out[n + j] + self.noise_sd[j] * xi[j];
        }
        // r with the new velocities: a view whose velocities are those of `out`.
        for (e, &j) in self.core.spec.building.hysteretic().iter().enumerate() {
            let (lin, phi) = self.element_params(th, e);
            let dv = if j == 0 {
                out[n]
            } else {
                out[n + j] - out[n + j - 1]
            };
            let i = 2 * n + e;
            let rate = self.core.law.rate(dv, s[i], lin, phi);
            out[i] = s[i] + dt * rate + self.noise_sd[i] * xi[i];
        }
    }

    fn propagate_rk4(&self, k: usize, x: &[f64], xi: &[f64], out: &mut [f64]) {
        let dt = self.core.dt;
        let d = self.dyn_dim();
        let (s, th) = x.split_at(d);
        let (u0, u1) = (self.core.ug[k - 1], self.core.ug[k]);
        let um = 0.5 * (u0 + u1);
        RK4_SCRATCH.with(|cell| {
            let mut buf = cell.borrow_mut();
            if buf.len() < 5 * d {
                buf.resize(5 * d, 0.0);
            }
            let (k1, rest) = buf.split_at_mut(d);
            let (k2, rest) = rest.split_at_mut(d);
            let (k3, rest) = rest.split_at_mut(d);
            let (k4, rest) = rest.split_at_mut(d);
            let tmp = &mut rest[..d];
            self.rhs(s, th, -u0, k1);
            for i in 0..d {
                tmp[i] = s[i] + 0.5 * dt * k1[i];
            }
            self.rhs(tmp, th, -um, k2);
            for i in 0..d {
                tmp[i] = s[i] + 0.5 * dt * k2[i];
            }
            self.rhs(tmp, th, -um, k3);
            for i in 0..d {
                tmp[i] = s[i] + dt * k3[i];
            }
            self.rhs(tmp, th, -u1, k4);
            for i in 0..d {
                out[i] = s[i]
                    + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
                    + self.noise_sd[i] * xi[i];
            }
        });
    }

    /// One step of the filter's grid to index `k` (θ copied).
    #[inline]
    fn step(&self, k: usize, x: &[f64], xi: &[f64], out: &mut [f64]) {
        let d = self.dyn_dim();
        match self.core.spec.discretisation {
            Discretisation::Euler => self.propagate_euler(k, x, xi, out),
            Discretisation::Symplectic => self.propagate_symplectic(k, x, xi, out),
            Discretisation::Rk4 => self.propagate_rk4(k, x, xi, out),
        }
        out[d..].copy_from_slice(&x[d..]);
    }
}

impl<L: HysteresisLaw> Partition for AugmentedChainOf<L> {
    /// Zero states, θ drawn from its prior (SPEC §3).
    fn sample_initial(&self, rng: &mut StreamRng, x: &mut [f64]) {
        let d = self.dyn_dim();
        x[..d].fill(0.0);
        self.core.spec.prior.sample_into(rng, &mut x[d..]);
    }

    fn measurement_cov(&self) -> Vec<f64> {
        self.core.measurement_cov()
    }

    fn layout(&self) -> Layout {
        let d = self.dyn_dim();
        let params = (0..self.core.theta_mean.len())
            .map(|i| Slot::Sampled(d + i))
            .collect();
        self.core
            .layout(params, (0..d).map(Slot::Sampled).collect())
    }
}

impl<L: HysteresisLaw> StateSpace for AugmentedChainOf<L> {
    fn dim(&self) -> usize {
        self.dyn_dim() + self.core.theta_mean.len()
    }

    fn ny(&self) -> usize {
        self.core.sensors.len()
    }

    fn noise_dim(&self) -> usize {
        self.dyn_dim() * self.core.substeps
    }

    /// The transition to step k with ü_g,meas(k−1) (and ü_g,meas(k) inside an RK4 step); θ copied.
    fn propagate(&self, k: usize, x: &[f64], xi: &[f64], out: &mut [f64]) {
        let m = self.core.substeps;
        if m == 1 {
            self.step(k, x, xi, out);
        } else {
            let d = self.dyn_dim();
            // Grid indices (k−1)M+1 ..= kM, draws d at a time.
            SUBSTEP_SCRATCH.with(|cell| {
                let mut buf = cell.borrow_mut();
                buf.resize(x.len(), 0.0);
                buf.copy_from_slice(x);
                for s in 0..m {
                    if s > 0 {
                        buf.copy_from_slice(out);
                    }
                    let kf = (k - 1) * m + s + 1;
                    self.step(kf, &buf, &xi[s * d..(s + 1) * d], out);
                }
            });
        }
    }

    /// Accelerations at the sensor storeys with ü_g,meas(k) (relative or absolute, SPEC §2).
    fn measure(&self, k: usize, x: &[f64], out: &mut [f64]) {
        let k = k * self.core.substeps;
        let d = self.dyn_dim();
        let (s, th) = x.split_at(d);
        let view = self.view(s, th);
        let ground = self.core.measurement_ground(k);
        for (o, &j) in out.iter_mut().zip(&self.core.sensors) {
            *o = self.core.spec.building.acceleration(&view, j, ground);
        }
    }
}
