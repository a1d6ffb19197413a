//! Cost of one particle-filter `step` at 500 particles on models of the paper's size
//! (SPEC §5.1–5.3): the augmented Bouc–Wen state (NX = 16, NY = 3) for the bootstrap PF and the
//! MLN/Storvik partition (NU = 8, NZ = 8, NL = 4, NY = 3).
//!
//! `core-filters` cannot depend on `models`, so the three-storey chain (SPEC §1, forward Euler
//! inside the filter, §3) is restated here in its two partitions. The data are an Euler
//! simulation at θ_true under the harmonic input `3 sin(4t)` with measurement noise. Criterion's
//! throughput is in particle-steps per second (one element = one particle propagated, weighted
//! and updated). Initialisation and re-initialisation at the end of the data are not timed.

use std::time::{Duration, Instant};

use core_filters::model::{ConditionallyLinear, Layout, Slot, StateSpace};
use core_filters::particle::bootstrap::BootstrapPf;
use core_filters::particle::mlnrbpf::MlnRbpf;
use core_filters::particle::storvik::{Storvik, StorvikUpdate};
use core_filters::particle::{ParticleConfig, ParticleFilter};
use core_filters::rng::stream;
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::{SMatrix, SVector};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

const DT: f64 = 0.005;
const STEPS: usize = 2000;
const PARTICLES: usize = 500;
const THETA_TRUE: [f64; 9] = [8.0, 8.0, 8.0, 0.25, 0.25, 0.25, 2.0, 1.0, 2.0];

/// The three-storey chain with one Bouc–Wen element at the ground (SPEC §1), its known input and
/// its filter noise levels (SPEC §3).
struct Chain {
    /// Measured ground acceleration at steps 0..=STEPS.
    ug: Vec<f64>,
    /// Diagonal of R.
    r_diag: [f64; 3],
    /// Process-noise s.d. of [x1 x2 x3 ẋ1 ẋ2 ẋ3 r1].
    q_sd: [f64; 7],
}

/// Accelerations [ẍ1 ẍ2 ẍ3] at state `s = [x1 x2 x3 ẋ1 ẋ2 ẋ3 r1]`, θ = [k c β γ n].
fn accelerations(s: &[f64; 7], th: &[f64; 9], ug: f64) -> [f64; 3] {
    let [x1, x2, x3, v1, v2, v3, r1] = *s;
    let [k1, k2, k3, c1, c2, c3, ..] = *th;
    let a1 = -ug - k1 * r1 + k2 * (x2 - x1) - c1 * v1 + c2 * (v2 - v1);
    let a2 = -ug + k2 * (x1 - x2) + k3 * (x3 - x2) + c2 * (v1 - v2) + c3 * (v3 - v2);
    let a3 = -ug + k3 * (x2 - x3) + c3 * (v2 - v3);
    [a1, a2, a3]
}

/// Bouc–Wen rate ṙ1 (SPEC eq. 22).
fn bouc_wen_rate(v1: f64, r1: f64, th: &[f64; 9]) -> f64 {
    let [.., beta, gamma, n] = *th;
    let ar = r1.abs().powf(n - 1.0);
    v1 - beta * v1.abs() * ar * r1 - gamma * v1 * ar * r1.abs()
}

/// One forward-Euler step of the chain.
fn euler(s: &[f64; 7], th: &[f64; 9], ug: f64) -> [f64; 7] {
    let a = accelerations(s, th, ug);
    let rdot = bouc_wen_rate(s[3], s[6], th);
    [
        s[0] + DT * s[3],
        s[1] + DT * s[4],
        s[2] + DT * s[5],
        s[3] + DT * a[0],
        s[4] + DT * a[1],
        s[5] + DT * a[2],
        s[6] + DT * rdot,
    ]
}

fn normal<G: Rng + ?Sized>(rng: &mut G) -> f64 {
    StandardNormal.sample(rng)
}

/// The chain, and noisy measurements y_1..y_STEPS simulated at θ_true.
fn chain_and_data() -> (Chain, Vec<SVector<f64, 3>>) {
    let ug: Vec<f64> = (0..=STEPS)
        .map(|k| 3.0 * (4.0 * k as f64 * DT).sin())
        .collect();
    let mut s = [0.0; 7];
    let (mut clean, mut v1_sq) = (Vec::with_capacity(STEPS), 0.0);
    for k in 1..=STEPS {
        s = euler(&s, &THETA_TRUE, ug[k - 1]);
        v1_sq += s[3] * s[3];
        clean.push(accelerations(&s, &THETA_TRUE, ug[k]));
    }
    let rms = |f: &dyn Fn(usize) -> f64| {
        ((0..STEPS).map(|k| f(k).powi(2)).sum::<f64>() / STEPS as f64).sqrt()
    };
    let rms_ug = rms(&|k| ug[k]);
    let rms_v1 = (v1_sq / STEPS as f64).sqrt();
    let mut r_diag = [0.0; 3];
    for (i, r) in r_diag.iter_mut().enumerate() {
        *r = (0.1 * rms(&|k| clean[k][i])).powi(2) + (0.1 * rms_ug).powi(2);
    }
    let vel = DT * 0.1 * rms_ug;
    let q_sd = [1e-6, 1e-6, 1e-6, vel, vel, vel, DT * 0.05 * rms_v1];
    let mut rng = stream(1, 0, "bench-data");
    let ys = clean
        .iter()
        .map(|a| SVector::<f64, 3>::from_fn(|i, _| a[i] + r_diag[i].sqrt() * normal(&mut rng)))
        .collect();
    (Chain { ug, r_diag, q_sd }, ys)
}

/// Names of θ and of the states; `params` says where each of the nine parameters lives.
fn layout(params: Vec<Slot>) -> Layout {
    let names = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"];
    let states = ["x1", "x2", "x3", "v1", "v2", "v3", "r1"];
    Layout {
        param_names: names.iter().map(|s| s.to_string()).collect(),
        params,
        state_names: states.iter().map(|s| s.to_string()).collect(),
        states: (0..7).map(Slot::Sampled).collect(),
    }
}

fn sample_theta<G: Rng + ?Sized>(rng: &mut G) -> [f64; 9] {
    let mut th = [0.0; 9];
    for t in &mut th[0..3] {
        *t = 10.0 * (0.3 * normal(rng)).exp();
    }
    for t in &mut th[3..6] {
        *t = 0.4 * (0.5 * normal(rng)).exp();
    }
    th[6] = 5.0 * rng.random::<f64>().sqrt();
    th[7] = th[6] * (2.0 * rng.random::<f64>() - 1.0);
    th[8] = 1.0 + 4.0 * rng.random::<f64>();
    th
}

/// Augmented state x = [x1 x2 x3 ẋ1 ẋ2 ẋ3 r1 | k1 k2 k3 c1 c2 c3 β γ n] (SPEC §5.1).
struct Augmented(Chain);

impl StateSpace<16, 3> for Augmented {
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, 16> {
        let th = sample_theta(rng);
        SVector::from_fn(|i, _| if i < 7 { 0.0 } else { th[i - 7] })
    }
    fn propagate(&self, k: usize, x: &SVector<f64, 16>) -> SVector<f64, 16> {
        let s: [f64; 7] = std::array::from_fn(|i| x[i]);
        let th: [f64; 9] = std::array::from_fn(|i| x[7 + i]);
        let s = euler(&s, &th, self.0.ug[k - 1]);
        let mut out = *x;
        out.fixed_rows_mut::<7>(0).copy_from_slice(&s);
        out
    }
    fn process_noise_sd(&self) -> SVector<f64, 16> {
        SVector::from_fn(|i, _| if i < 7 { self.0.q_sd[i] } else { 0.0 })
    }
    fn measure(&self, k: usize, x: &SVector<f64, 16>) -> SVector<f64, 3> {
        let s: [f64; 7] = std::array::from_fn(|i| x[i]);
        let th: [f64; 9] = std::array::from_fn(|i| x[7 + i]);
        SVector::from(accelerations(&s, &th, self.0.ug[k]))
    }
    fn measurement_cov(&self) -> SMatrix<f64, 3, 3> {
        SMatrix::from_diagonal(&SVector::from(self.0.r_diag))
    }
    fn layout(&self) -> Layout {
        layout((7..16).map(Slot::Sampled).collect())
    }
}

/// MLN/Storvik partition (SPEC §5.2): u = [x1 x2 x3 ẋ1 ẋ2 ẋ3 r1 n], z = [k1 k2 k3 c1 c2 c3 β γ],
/// linked rows ẋ1 ẋ2 ẋ3 r1.
struct Mln(Chain);

impl Mln {
    #[allow(non_snake_case)]
    fn H(u: &SVector<f64, 8>) -> SMatrix<f64, 3, 8> {
        let (x1, x2, x3, v1, v2, v3, r1) = (u[0], u[1], u[2], u[3], u[4], u[5], u[6]);
        let mut h = SMatrix::<f64, 3, 8>::zeros();
        h[(0, 0)] = -r1;
        h[(0, 1)] = x2 - x1;
        h[(0, 3)] = -v1;
        h[(0, 4)] = v2 - v1;
        h[(1, 1)] = x1 - x2;
        h[(1, 2)] = x3 - x2;
        h[(1, 4)] = v1 - v2;
        h[(1, 5)] = v3 - v2;
        h[(2, 2)] = x2 - x3;
        h[(2, 5)] = v2 - v3;
        h
    }
}

impl ConditionallyLinear<8, 8, 4, 3> for Mln {
    fn sample_initial<G: Rng + ?Sized>(&self, rng: &mut G) -> SVector<f64, 8> {
        let mut u = SVector::zeros();
        u[7] = 1.0 + 4.0 * rng.random::<f64>();
        u
    }
    fn sample_marginal_prior<G: Rng + ?Sized>(
        &self,
        _rng: &mut G,
    ) -> (SVector<f64, 8>, SMatrix<f64, 8, 8>) {
        // Moment-matched prior (SPEC §3).
        let mean = SVector::from([10.46, 10.46, 10.46, 0.453, 0.453, 0.453, 10.0 / 3.0, 0.0]);
        let var = SVector::from([
            3.21f64.powi(2),
            3.21f64.powi(2),
            3.21f64.powi(2),
            0.242f64.powi(2),
            0.242f64.powi(2),
            0.242f64.powi(2),
            25.0 / 18.0,
            25.0 / 6.0,
        ]);
        (mean, SMatrix::from_diagonal(&var))
    }
    fn linked_rows(&self) -> [usize; 4] {
        [3, 4, 5, 6]
    }
    fn transition(&self, k: usize, u: &SVector<f64, 8>) -> (SVector<f64, 8>, SMatrix<f64, 4, 8>) {
        let ug = self.0.ug[k - 1];
        let f = SVector::from([
            u[0] + DT * u[3],
            u[1] + DT * u[4],
            u[2] + DT * u[5],
            u[3] - DT * ug,
            u[4] - DT * ug,
            u[5] - DT * ug,
            u[6] + DT * u[3],
            u[7],
        ]);
        let mut fl = SMatrix::<f64, 4, 8>::zeros();
        fl.fixed_rows_mut::<3>(0).copy_from(&(Self::H(u) * DT));
        let (v1, r1, n) = (u[3], u[6], u[7]);
        let ar = r1.abs().powf(n - 1.0);
        fl[(3, 6)] = -DT * v1.abs() * ar * r1;
        fl[(3, 7)] = -DT * v1 * ar * r1.abs();
        (f, fl)
    }
    fn process_noise_sd(&self) -> SVector<f64, 8> {
        SVector::from_fn(|i, _| if i < 7 { self.0.q_sd[i] } else { 0.0 })
    }
    fn observation(&self, k: usize, u: &SVector<f64, 8>) -> (SVector<f64, 3>, SMatrix<f64, 3, 8>) {
        (SVector::repeat(-self.0.ug[k]), Self::H(u))
    }
    fn observation_jacobian_u(
        &self,
        _k: usize,
        _u: &SVector<f64, 8>,
        z: &SVector<f64, 8>,
    ) -> SMatrix<f64, 3, 8> {
        let (k1, k2, k3, c1, c2, c3) = (z[0], z[1], z[2], z[3], z[4], z[5]);
        let mut j = SMatrix::<f64, 3, 8>::zeros();
        j[(0, 0)] = -k2;
        j[(0, 1)] = k2;
        j[(0, 3)] = -c1 - c2;
        j[(0, 4)] = c2;
        j[(0, 6)] = -k1;
        j[(1, 0)] = k2;
        j[(1, 1)] = -k2 - k3;
        j[(1, 2)] = k3;
        j[(1, 3)] = c2;
        j[(1, 4)] = -c2 - c3;
        j[(1, 5)] = c3;
        j[(2, 1)] = k3;
        j[(2, 2)] = -k3;
        j[(2, 4)] = c3;
        j[(2, 5)] = -c3;
        j
    }
    fn measurement_cov(&self) -> SMatrix<f64, 3, 3> {
        SMatrix::from_diagonal(&SVector::from(self.0.r_diag))
    }
    fn layout(&self) -> Layout {
        layout(
            (0..8)
                .map(Slot::Marginal)
                .chain([Slot::Sampled(7)])
                .collect(),
        )
    }
}

/// Times `iters` consecutive steps, cycling through the data; (re-)initialisation is not timed.
fn time_steps<F: ParticleFilter<3>>(
    filter: &mut F,
    ys: &[SVector<f64, 3>],
    k: &mut usize,
    iters: u64,
) -> Duration {
    let mut rng = stream(2, *k as u64, "bench-filter");
    let mut total = Duration::ZERO;
    for _ in 0..iters {
        if *k == 0 || *k > ys.len() {
            filter.initialise(&mut rng);
            *k = 1;
        }
        let start = Instant::now();
        let r = filter.step(*k, &ys[*k - 1], &mut rng);
        total += start.elapsed();
        // A failed run starts again from the prior.
        *k = if r.is_ok() { *k + 1 } else { 0 };
    }
    total
}

fn bench_steps(c: &mut Criterion) {
    let cfg = ParticleConfig {
        particles: PARTICLES,
        ..ParticleConfig::default()
    };
    let mut group = c.benchmark_group("particle-step");
    group.throughput(Throughput::Elements(PARTICLES as u64));

    let (chain, ys) = chain_and_data();
    let mut pf = BootstrapPf::new(Augmented(chain), cfg);
    let mut k = 0;
    group.bench_function("bootstrap/nx16", |b| {
        b.iter_custom(|n| time_steps(&mut pf, &ys, &mut k, n))
    });

    let (chain, ys) = chain_and_data();
    let mut pf = MlnRbpf::new(Mln(chain), cfg);
    let mut k = 0;
    group.bench_function("mln-rbpf/nu8-nz8", |b| {
        b.iter_custom(|n| time_steps(&mut pf, &ys, &mut k, n))
    });

    for update in [StorvikUpdate::Linearised, StorvikUpdate::Exact] {
        let (chain, ys) = chain_and_data();
        let mut pf = Storvik::with_update(Mln(chain), cfg, update);
        let mut k = 0;
        group.bench_function(format!("storvik-{}/nu8-nz8", update.name()), |b| {
            b.iter_custom(|n| time_steps(&mut pf, &ys, &mut k, n))
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(4));
    targets = bench_steps
}
criterion_main!(benches);
