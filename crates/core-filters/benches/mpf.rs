//! Throughput of one MPF-EKF2 step (SPEC §5.4) at 500 particles on the paper's partition sizes
//! (NN = 3, ND = 2, NBL = 13, NY = 3) with the Hessian sparsity of SPEC §6.
//!
//! `core-filters` cannot depend on the `models` crate, so the three-storey Bouc–Wen chain in its
//! MPF-EKF2 partition is restated here ([`chain`]); the integration tests of the filter reuse it.
//! Criterion reports the throughput in particle-steps per second ("elements").

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use core_filters::particle::mpf::{MpfEkf2, MpfKernel};
use core_filters::particle::{ParticleConfig, ParticleFilter};
use core_filters::rng::stream;

/// The three-storey chain of SPEC §1 in the MPF-EKF2 partition of SPEC §5.4 with the exact
/// derivatives of SPEC §6, forward Euler with step `dt`, and a synthetic data set.
pub mod chain {
    use core_filters::model::{ConditionallyQuadratic, Layout, Slot, SparseHessians};
    use nalgebra::{SMatrix, SVector, Vector3};
    use rand::Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// x^bl indices (SPEC §6).
    pub const X1: usize = 0;
    pub const X2: usize = 1;
    pub const X3: usize = 2;
    pub const V2: usize = 3;
    pub const V3: usize = 4;
    pub const K1: usize = 5;
    pub const K2: usize = 6;
    pub const K3: usize = 7;
    pub const C1: usize = 8;
    pub const C2: usize = 9;
    pub const C3: usize = 10;
    pub const BETA: usize = 11;
    pub const GAMMA: usize = 12;

    /// θ_true = [k1 k2 k3 c1 c2 c3 β γ n] (SPEC §1).
    pub const THETA_TRUE: [f64; 9] = [8.0, 8.0, 8.0, 0.25, 0.25, 0.25, 2.0, 1.0, 2.0];

    pub type Bl = SVector<f64, 13>;
    pub type Xn = SVector<f64, 3>;

    #[derive(Debug, Clone)]
    pub struct ChainModel {
        pub dt: f64,
        /// Measured ground acceleration `ug[k]`, k = 0..=K.
        pub ug: Vec<f64>,
        pub sampled_sd: SVector<f64, 2>,
        pub marginal_sd: Bl,
        pub r: SMatrix<f64, 3, 3>,
        sampled_hess: SparseHessians,
        marginal_hess: SparseHessians,
        observation_hess: SparseHessians,
    }

    /// `−β|ẋ1||r1|^(n−1) r1` and `−ẋ1|r1|^n`: the Bouc–Wen coefficients of β and γ (SPEC eq. 22).
    fn bouc_wen_terms(v1: f64, r1: f64, n: f64) -> (f64, f64) {
        let ar = r1.abs();
        (-v1.abs() * ar.powf(n - 1.0) * r1, -v1 * ar.powf(n))
    }

    /// The three sparse Hessian sets of SPEC §6 (sampled ψₙ, marginal φ_bl, observation) for the
    /// three-storey chain with unit masses and time step `dt`.
    pub fn spec6_hessians(dt: f64) -> (SparseHessians, SparseHessians, SparseHessians) {
        let mut sampled = SparseHessians::new();
        for (a, b, v) in [(K2, X2, dt), (K2, X1, -dt), (C2, V2, dt)] {
            sampled.push(0, a, b, v);
        }
        let mut marginal = SparseHessians::new();
        for (a, b, v) in [
            (K2, X1, dt),
            (K2, X2, -dt),
            (K3, X3, dt),
            (K3, X2, -dt),
            (C2, V2, -dt),
            (C3, V3, dt),
            (C3, V2, -dt),
        ] {
            marginal.push(3, a, b, v);
        }
        for (a, b, v) in [(K3, X2, dt), (K3, X3, -dt), (C3, V2, dt), (C3, V3, -dt)] {
            marginal.push(4, a, b, v);
        }
        let mut obs = SparseHessians::new();
        for (a, b, v) in [(K2, X2, 1.0), (K2, X1, -1.0), (C2, V2, 1.0)] {
            obs.push(0, a, b, v);
        }
        for (a, b, v) in [
            (K2, X1, 1.0),
            (K2, X2, -1.0),
            (K3, X3, 1.0),
            (K3, X2, -1.0),
            (C2, V2, -1.0),
            (C3, V3, 1.0),
            (C3, V2, -1.0),
        ] {
            obs.push(1, a, b, v);
        }
        for (a, b, v) in [(K3, X2, 1.0), (K3, X3, -1.0), (C3, V2, 1.0), (C3, V3, -1.0)] {
            obs.push(2, a, b, v);
        }
        (sampled, marginal, obs)
    }

    impl ChainModel {
        pub fn new(dt: f64, ug: Vec<f64>) -> Self {
            let (sampled_hess, marginal_hess, observation_hess) = spec6_hessians(dt);
            // Noise levels of SPEC §3 for RMS(ü_g) ≈ 2.1 and RMS(ẋ1) ≈ 0.5 (the harmonic input).
            let vel = dt * 0.1 * 2.1;
            let sampled_sd = SVector::<f64, 2>::new(vel, dt * 0.05 * 0.5);
            let mut marginal_sd = Bl::zeros();
            marginal_sd[X1] = 1e-6;
            marginal_sd[X2] = 1e-6;
            marginal_sd[X3] = 1e-6;
            marginal_sd[V2] = vel;
            marginal_sd[V3] = vel;
            let r = SMatrix::<f64, 3, 3>::from_diagonal(&Vector3::new(0.2, 0.25, 0.3));
            Self {
                dt,
                ug,
                sampled_sd,
                marginal_sd,
                r,
                sampled_hess,
                marginal_hess,
                observation_hess,
            }
        }

        /// Relative accelerations ẍ1, ẍ2, ẍ3 at `(xⁿ, x^bl)` with input `ug` (SPEC §6).
        fn accelerations(ug: f64, xn: &Xn, m: &Bl) -> Vector3<f64> {
            let (v1, r1) = (xn[0], xn[1]);
            Vector3::new(
                -ug - m[K1] * r1 + m[K2] * (m[X2] - m[X1]) - m[C1] * v1 + m[C2] * (m[V2] - v1),
                -ug + m[K2] * (m[X1] - m[X2])
                    + m[K3] * (m[X3] - m[X2])
                    + m[C2] * (v1 - m[V2])
                    + m[C3] * (m[V3] - m[V2]),
                -ug + m[K3] * (m[X2] - m[X3]) + m[C3] * (m[V2] - m[V3]),
            )
        }

        /// Jacobian of [`Self::accelerations`] w.r.t. x^bl.
        fn accelerations_jac(xn: &Xn, m: &Bl) -> SMatrix<f64, 3, 13> {
            let (v1, r1) = (xn[0], xn[1]);
            let mut j = SMatrix::<f64, 3, 13>::zeros();
            j[(0, X1)] = -m[K2];
            j[(0, X2)] = m[K2];
            j[(0, V2)] = m[C2];
            j[(0, K1)] = -r1;
            j[(0, K2)] = m[X2] - m[X1];
            j[(0, C1)] = -v1;
            j[(0, C2)] = m[V2] - v1;
            j[(1, X1)] = m[K2];
            j[(1, X2)] = -m[K2] - m[K3];
            j[(1, X3)] = m[K3];
            j[(1, V2)] = -m[C2] - m[C3];
            j[(1, V3)] = m[C3];
            j[(1, K2)] = m[X1] - m[X2];
            j[(1, K3)] = m[X3] - m[X2];
            j[(1, C2)] = v1 - m[V2];
            j[(1, C3)] = m[V3] - m[V2];
            j[(2, X2)] = m[K3];
            j[(2, X3)] = -m[K3];
            j[(2, V2)] = m[C3];
            j[(2, V3)] = -m[C3];
            j[(2, K3)] = m[X2] - m[X3];
            j[(2, C3)] = m[V2] - m[V3];
            j
        }

        /// One noise-free Euler step of the full model (truth simulation at the filter's
        /// discretisation): returns `(xⁿ_k, x^bl_k)`.
        pub fn euler(&self, k: usize, xn: &Xn, m: &Bl) -> (Xn, Bl) {
            let (psi, _) = self.sampled_dynamics(k, xn, m);
            let (phi, _) = self.marginal_dynamics(k, xn, m);
            (Xn::new(psi[0], psi[1], xn[2]), phi)
        }
    }

    impl ConditionallyQuadratic<3, 2, 13, 3> for ChainModel {
        fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> Xn {
            // Zero initial states; n ~ U(1, 5) (SPEC §3).
            Xn::new(0.0, 0.0, 1.0 + 4.0 * rng.random::<f64>())
        }

        fn sample_marginal_prior<G: Rng + ?Sized>(
            &self,
            _rng: &mut G,
        ) -> (Bl, SMatrix<f64, 13, 13>) {
            // Moment-matched Gaussian prior of SPEC §3; initial states exactly zero.
            let mut m = Bl::zeros();
            let mut var = Bl::zeros();
            for j in [K1, K2, K3] {
                m[j] = 10.46;
                var[j] = 3.21 * 3.21;
            }
            for j in [C1, C2, C3] {
                m[j] = 0.453;
                var[j] = 0.242 * 0.242;
            }
            m[BETA] = 10.0 / 3.0;
            var[BETA] = 25.0 / 18.0;
            var[GAMMA] = 25.0 / 6.0;
            (m, SMatrix::from_diagonal(&var))
        }

        fn sampled_dynamics(
            &self,
            k: usize,
            xn: &Xn,
            m: &Bl,
        ) -> (SVector<f64, 2>, SMatrix<f64, 2, 13>) {
            let dt = self.dt;
            let (v1, r1, n) = (xn[0], xn[1], xn[2]);
            let a = Self::accelerations(self.ug[k - 1], xn, m)[0];
            let (tb, tg) = bouc_wen_terms(v1, r1, n);
            let value =
                SVector::<f64, 2>::new(v1 + dt * a, r1 + dt * (v1 + m[BETA] * tb + m[GAMMA] * tg));
            let ja = Self::accelerations_jac(xn, m);
            let mut jac = SMatrix::<f64, 2, 13>::zeros();
            for c in 0..13 {
                jac[(0, c)] = dt * ja[(0, c)];
            }
            jac[(1, BETA)] = dt * tb;
            jac[(1, GAMMA)] = dt * tg;
            (value, jac)
        }

        fn marginal_dynamics(&self, k: usize, xn: &Xn, m: &Bl) -> (Bl, SMatrix<f64, 13, 13>) {
            let dt = self.dt;
            let a = Self::accelerations(self.ug[k - 1], xn, m);
            let ja = Self::accelerations_jac(xn, m);
            let mut value = *m;
            value[X1] += dt * xn[0];
            value[X2] += dt * m[V2];
            value[X3] += dt * m[V3];
            value[V2] += dt * a[1];
            value[V3] += dt * a[2];
            let mut jac = SMatrix::<f64, 13, 13>::identity();
            jac[(X2, V2)] = dt;
            jac[(X3, V3)] = dt;
            for c in 0..13 {
                jac[(V2, c)] += dt * ja[(1, c)];
                jac[(V3, c)] += dt * ja[(2, c)];
            }
            (value, jac)
        }

        fn observation(&self, k: usize, xn: &Xn, m: &Bl) -> (Vector3<f64>, SMatrix<f64, 3, 13>) {
            (
                Self::accelerations(self.ug[k], xn, m),
                Self::accelerations_jac(xn, m),
            )
        }

        fn sampled_hessians(&self) -> &SparseHessians {
            &self.sampled_hess
        }

        fn marginal_hessians(&self) -> &SparseHessians {
            &self.marginal_hess
        }

        fn observation_hessians(&self) -> &SparseHessians {
            &self.observation_hess
        }

        fn sampled_noise_sd(&self) -> SVector<f64, 2> {
            self.sampled_sd
        }

        fn marginal_noise_sd(&self) -> Bl {
            self.marginal_sd
        }

        fn measurement_cov(&self) -> SMatrix<f64, 3, 3> {
            self.r
        }

        fn layout(&self) -> Layout {
            let names = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"];
            let mut params: Vec<Slot> = (K1..=GAMMA).map(Slot::Marginal).collect();
            params.push(Slot::Sampled(2));
            Layout {
                param_names: names.iter().map(|s| s.to_string()).collect(),
                params,
                state_names: ["x1", "x2", "x3", "v1", "v2", "v3", "r1"]
                    .iter()
                    .map(|s| s.to_string())
                    .collect(),
                states: vec![
                    Slot::Marginal(X1),
                    Slot::Marginal(X2),
                    Slot::Marginal(X3),
                    Slot::Sampled(0),
                    Slot::Marginal(V2),
                    Slot::Marginal(V3),
                    Slot::Sampled(1),
                ],
            }
        }
    }

    /// A harmonic input `3 sin(4t)` (SPEC §2, preset `paper-3dof-harmonic`), the noise-free Euler
    /// response at θ_true, and measurements with noise of covariance `R`: `(model, ys)` with
    /// `ys[k−1] = y_k`, k = 1..=steps.
    pub fn dataset(steps: usize, seed: u64) -> (ChainModel, Vec<Vector3<f64>>) {
        let dt = 0.005;
        let ug: Vec<f64> = (0..=steps)
            .map(|k| 3.0 * (4.0 * k as f64 * dt).sin())
            .collect();
        let model = ChainModel::new(dt, ug);
        let mut bl = Bl::zeros();
        for (j, t) in (K1..=GAMMA).zip(THETA_TRUE) {
            bl[j] = t;
        }
        let mut xn = Xn::new(0.0, 0.0, THETA_TRUE[8]);
        let mut rng = core_filters::rng::stream(seed, 0, "bench-data");
        let r_sd = model.r.map(f64::sqrt);
        let mut ys = Vec::with_capacity(steps);
        for k in 1..=steps {
            (xn, bl) = model.euler(k, &xn, &bl);
            let clean = ChainModel::accelerations(model.ug[k], &xn, &bl);
            let noise = Vector3::from_fn(|i, _| {
                r_sd[(i, i)]
                    * <StandardNormal as Distribution<f64>>::sample(&StandardNormal, &mut rng)
            });
            ys.push(clean + noise);
        }
        (model, ys)
    }
}

const PARTICLES: usize = 500;
const STEPS: usize = 6000;
const WARM_UP: usize = 200;

fn bench_step(c: &mut Criterion) {
    let (model, ys) = chain::dataset(STEPS, 11);
    let mut group = c.benchmark_group("mpf-ekf2");
    group.throughput(Throughput::Elements(PARTICLES as u64));
    for kernel in [MpfKernel::Sparse, MpfKernel::Dense] {
        let config = ParticleConfig {
            particles: PARTICLES,
            ..ParticleConfig::default()
        };
        let mut filter = MpfEkf2::new(model.clone(), config).with_kernel(kernel);
        let mut rng = stream(5, 0, "filter/mpf-ekf2");
        let restart = |f: &mut MpfEkf2<chain::ChainModel, 3, 2, 13, 3>, rng: &mut _| {
            f.initialise(rng);
            for k in 1..=WARM_UP {
                f.step(k, &ys[k - 1], rng).expect("warm-up step");
            }
        };
        restart(&mut filter, &mut rng);
        let mut k = WARM_UP;
        group.bench_function(format!("step/{PARTICLES}/{kernel:?}"), |b| {
            b.iter(|| {
                k += 1;
                if k > STEPS {
                    // Rare: start the data set again (the warm-up is timed, a negligible share).
                    restart(&mut filter, &mut rng);
                    k = WARM_UP + 1;
                }
                filter.step(k, &ys[k - 1], &mut rng).expect("step")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
