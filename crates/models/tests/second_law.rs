//! A second hysteresis law through the simulator and the filter partitions: the smoothed
//! elastic–perfectly-plastic law of `models::law::plastic` (`ṙ = δv − ρ ℓ |r|^m`, `ℓ = δv` while
//! loading, 0 while unloading; θ = (ρ), φ = (m)), which is one file and a `mod` line.
//!
//! Independent reference: the law equals Bouc–Wen with β = γ = ρ/2 and n = m, whose code shares
//! nothing with it but the chain; so a chain with the plastic law must simulate, and every
//! partition's staged map must step, as the Bouc–Wen chain at those values. The two evaluate the
//! same function with different operations, so they differ by rounding only: a few ulps per rate
//! evaluation, grown by at most the Lipschitz constant over the record; the tolerance 1e−9 of the
//! largest state is far above that (the record below: 8e−16 of 1.5) and far below any real
//! error (a wrong branch or exponent changes the response at O(1)).
//!
//! The derivative checks reuse the set-up of the `filtering_*` tests (`filtering_support`) and
//! their tolerances (see `filtering_derivatives.rs`: central differences of maps that are affine
//! or bilinear in the differentiated variables, round-off ≈ 1e−9, tolerance 1e−7).

use crate::filtering_support;

use core_filters::linalg::Sparse;
use core_filters::rng::{stream, StreamRng};
use core_filters::smc::model::{
    ConditionallyLinear, ConditionallyQuadratic, Partition, SampledAt, StateSpace,
};
use filtering_support::*;
use models::filtering::{
    AugmentedChain, AugmentedChainOf, ChainPriorOf, ChainSpecOf, Discretisation, MlnChainOf,
    MpfChainOf,
};
use models::integrate::simulate_rk4;
use models::law::plastic::{Plastic, PlasticLaw};
use models::law::HysteresisLaw;
use models::structure::{BoucWen, ShearChain, ShearChainOf};
use rand::Rng;

const H: f64 = 1e-5;
const TOL: f64 = 1e-7;
const POINTS: u64 = 4;
const SCHEMES: [Discretisation; 2] = [Discretisation::Euler, Discretisation::Symplectic];

/// The Bouc–Wen element equal to a plastic one.
fn as_bouc_wen(p: &Plastic) -> BoucWen {
    BoucWen {
        storey: p.storey,
        beta: p.rho / 2.0,
        gamma: p.rho / 2.0,
        n: p.m,
    }
}

#[test]
fn a_chain_with_the_plastic_law_simulates_as_bouc_wen_with_beta_equal_gamma() {
    let (masses, k, c) = (
        vec![1.0, 1.2, 0.9],
        vec![8.0, 7.0, 6.0],
        vec![0.25, 0.2, 0.2],
    );
    let elements = vec![
        Plastic {
            storey: 0,
            rho: 16.0,
            m: 2.0,
        },
        Plastic {
            storey: 2,
            rho: 125.0,
            m: 3.0,
        },
    ];
    let plastic = ShearChainOf::<PlasticLaw>::with_elements(
        masses.clone(),
        k.clone(),
        c.clone(),
        elements.clone(),
    )
    .unwrap();
    let bw = ShearChain::new(masses, k, c, elements.iter().map(as_bouc_wen).collect()).unwrap();
    assert_eq!(
        plastic.theta_names(),
        ["k1", "k2", "k3", "c1", "c2", "c3", "rho1", "m1", "rho3", "m3"]
    );
    assert_eq!(plastic.with_theta(&plastic.theta()).unwrap(), plastic);

    // 12 s of a harmonic ground motion (SPEC §2's harmonic preset's a = 3 m/s², ω = 4 rad/s).
    let dt = 0.005;
    let ug: Vec<f64> = (0..2400)
        .map(|i| 3.0 * (4.0 * i as f64 * dt).sin())
        .collect();
    let traj = simulate_rk4(&plastic, &ug, dt);
    let reference = simulate_rk4(&bw, &ug, dt);
    let scale = reference
        .as_flat()
        .iter()
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    let diff = traj
        .as_flat()
        .iter()
        .zip(reference.as_flat())
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(scale > 0.1, "the chain moves: {scale}");
    assert!(
        diff <= 1e-9 * scale,
        "plastic against Bouc–Wen: {diff:e} of {scale}"
    );

    // Each element reaches its plastic plateau and never passes the yield value ρ^(−1/m).
    for (e, el) in elements.iter().enumerate() {
        let r_y = plastic.saturation(e).unwrap();
        assert_eq!(r_y, el.rho.powf(-1.0 / el.m));
        let i = plastic.r_index(e);
        let max_r = traj.rows().fold(0.0_f64, |m, s| m.max(s[i].abs()));
        assert!(max_r <= r_y * (1.0 + 1e-9), "element {e}: {max_r} > {r_y}");
        assert!(max_r >= 0.9 * r_y, "element {e} yields: {max_r} of {r_y}");
    }

    // Unloading is elastic: where δv·r < 0 the simulator's rate of r is δv, to the bit; while
    // loading it is δv(1 − ρ|r|^m).
    let n = 3;
    let (mut unloading, mut loading) = (0, 0);
    let mut d = vec![0.0; plastic.dim()];
    for s in traj.rows() {
        plastic.rhs(s, 0.0, &mut d);
        for (e, el) in elements.iter().enumerate() {
            let j = el.storey;
            let dv = s[n + j] - if j == 0 { 0.0 } else { s[n + j - 1] };
            let r = s[2 * n + e];
            if dv * r < 0.0 {
                assert_eq!(d[2 * n + e].to_bits(), dv.to_bits());
                unloading += 1;
            } else if dv * r > 0.0 {
                let want = dv * (1.0 - el.rho * r.abs().powf(el.m));
                assert!((d[2 * n + e] - want).abs() <= 1e-14 * (1.0 + want.abs()));
                loading += 1;
            }
        }
    }
    assert!(unloading > 500 && loading > 500, "{unloading} {loading}");
}

/// The spec of `filtering_support::spec` with the plastic law's default prior.
fn plastic_spec(case: &Case, disc: Discretisation) -> ChainSpecOf<PlasticLaw> {
    let s = spec(case, disc);
    let mut prior = ChainPriorOf::<PlasticLaw>::paper(case.n(), &case.hysteretic);
    prior.alpha = s.prior.alpha;
    ChainSpecOf {
        dt: s.dt,
        building: s.building,
        sensors: s.sensors,
        ug: s.ug,
        q_disp: s.q_disp,
        q_vel: s.q_vel,
        q_r: s.q_r,
        r_diag: s.r_diag,
        prior,
        marginal_prior: s.marginal_prior,
        discretisation: s.discretisation,
        substeps: s.substeps,
        physical_support: false,
        coloured_noise: None,
        ground_between: Default::default(),
        regressors: None,
    }
}

/// A random point of `filtering_support::random_point` with the plastic law's parameters
/// (ρ ∈ [0.5, 6], m ∈ [1, 5]) per element, and the same point in Bouc–Wen's θ.
fn random_plastic_point(case: &Case, rng: &mut StreamRng) -> (Point, Point) {
    let p = random_point(case, rng);
    let e0 = p.theta.len() - 3 * case.ne();
    let mut plastic = p.clone();
    let mut bw = p;
    plastic.theta.truncate(e0);
    bw.theta.truncate(e0);
    for _ in 0..case.ne() {
        let rho = 0.5 + 5.5 * rng.random::<f64>();
        let m = 1.0 + 4.0 * rng.random::<f64>();
        plastic.theta.extend([rho, m]);
        bw.theta.extend([rho / 2.0, rho / 2.0, m]);
    }
    (plastic, bw)
}

fn aug_next<L: HysteresisLaw>(aug: &AugmentedChainOf<L>, p: &Point) -> Vec<f64> {
    let x = p.augmented();
    let mut out = vec![0.0; x.len()];
    aug.propagate(K, &x, &vec![0.0; aug.noise_dim()], &mut out);
    out.truncate(aug.noise_dim());
    out
}

/// One MLN stage at (u_prev, u_new): `f` and `F` (dense, `linked × nz`).
fn mln_stage<L: HysteresisLaw>(
    mln: &MlnChainOf<L>,
    stage: usize,
    u_prev: &[f64],
    u_new: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let st = &mln.stages()[stage];
    let mut f = vec![0.0; st.rows.len()];
    let mut big_f = Sparse::recording(st.linked.len(), mln.dims().nz);
    mln.transition(stage, K, u_prev, u_new, &mut f, &mut big_f);
    (f, big_f.to_dense())
}

/// The staged MLN map `u_k = f + F z`, noise-free; copied rows keep `u_prev`.
fn mln_step<L: HysteresisLaw>(mln: &MlnChainOf<L>, u_prev: &[f64], z: &[f64]) -> Vec<f64> {
    let mut u_new = u_prev.to_vec();
    for (s, st) in mln.stages().iter().enumerate() {
        let (f, big_f) = mln_stage(mln, s, u_prev, &u_new);
        for (i, &row) in st.rows.iter().enumerate() {
            u_new[row] = f[i];
        }
        let nl = st.linked.len();
        for (l, &row) in st.linked.iter().enumerate() {
            u_new[row] += (0..z.len()).map(|c| big_f[l + c * nl] * z[c]).sum::<f64>();
        }
    }
    u_new
}

/// One MPF sampled stage: values and dense Jacobian in x^bl.
fn mpf_stage<L: HysteresisLaw>(
    mpf: &MpfChainOf<L>,
    stage: usize,
    xn_prev: &[f64],
    xn_new: &[f64],
    m: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let rows = mpf.sampled_stages()[stage].len();
    let mut value = vec![0.0; rows];
    let mut jac = Sparse::recording(rows, mpf.dims().nbl);
    let at = SampledAt {
        stage,
        k: K,
        prev: xn_prev,
        new: xn_new,
        m,
    };
    mpf.sampled_dynamics(at, &mut value, &mut jac);
    (value, jac.to_dense())
}

/// The noise-free staged MPF step: (xⁿ_k, m_k).
fn mpf_step<L: HysteresisLaw>(mpf: &MpfChainOf<L>, xn: &[f64], m: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut xn_new = xn.to_vec();
    for (s, entries) in mpf.sampled_stages().iter().enumerate() {
        let (value, _) = mpf_stage(mpf, s, xn, &xn_new, m);
        for (i, &e) in entries.iter().enumerate() {
            xn_new[e] = value[i];
        }
    }
    let nbl = mpf.dims().nbl;
    let mut m_new = vec![0.0; nbl];
    let mut d = Sparse::recording(nbl, nbl);
    mpf.marginal_dynamics(K, xn, &xn_new, m, &mut m_new, &mut d);
    (xn_new, m_new)
}

#[test]
fn the_partitions_with_the_plastic_law_pass_the_derivative_checks() {
    for case in cases() {
        for disc in SCHEMES {
            let what = format!("{} {disc}", case.name);
            let aug = AugmentedChainOf::new(plastic_spec(&case, disc)).unwrap();
            let aug_bw = AugmentedChain::new(spec(&case, disc)).unwrap();
            let mln = MlnChainOf::new(plastic_spec(&case, disc)).unwrap();
            let mpf = MpfChainOf::new(plastic_spec(&case, disc)).unwrap();
            let (n, ne) = (case.n(), case.ne());
            let dyn_dim = 2 * n + ne;
            // One linear and one nonlinear parameter per element.
            assert_eq!(mln.dims().nz, 2 * n + ne, "{what}");
            assert_eq!(mln.dims().nu, 2 * n + 2 * ne, "{what}");
            // Against Bouc–Wen's partition: one marginal entry less per element (ρ for β, γ),
            // the same sampled block (m for n).
            let mpf_bw = models::filtering::MpfChain::new(spec(&case, disc)).unwrap();
            assert_eq!(mpf.dims().nbl + ne, mpf_bw.dims().nbl, "{what}");
            assert_eq!(mpf.dims().nn, mpf_bw.dims().nn, "{what}");
            let mut rng = stream(17, 0, case.name);
            for _ in 0..POINTS {
                let (p, p_bw) = random_plastic_point(&case, &mut rng);
                // The physical map: the plastic chain's is the Bouc–Wen chain's.
                let next = aug_next(&aug, &p);
                close_all(
                    &next,
                    &aug_next(&aug_bw, &p_bw),
                    1e-12,
                    &format!("{what}: augmented"),
                );

                // MLN-RBPF / Storvik: staged map, F of each stage and the path sensitivity.
                let layout = mln.layout();
                let d = mln.dims();
                let (u, z) = split(&layout, &p, d.nu, d.nz);
                let point_at = |z: &[f64]| join(&layout, &u, z, n);
                let u_next = mln_step(&mln, &u, &z);
                close_all(
                    &u_next[..dyn_dim],
                    &next,
                    1e-12,
                    &format!("{what}: f + F z"),
                );
                assert_eq!(&u_next[dyn_dim..], &u[dyn_dim..], "{what}: m copied");
                let mut u_new = u.clone();
                u_new[..dyn_dim].copy_from_slice(&next);
                for (s, st) in mln.stages().iter().enumerate() {
                    let (_, big_f) = mln_stage(&mln, s, &u, &u_new);
                    let stage_map = |z: &[f64]| -> Vec<f64> {
                        let q = point_at(z);
                        let full = aug_next(&aug, &q);
                        st.linked
                            .iter()
                            .map(|&row| {
                                if disc == Discretisation::Symplectic && s == 1 {
                                    // r rows with the new velocities held fixed.
                                    let e = row - 2 * n;
                                    let j = case.hysteretic[e];
                                    let dv =
                                        u_new[n + j] - if j > 0 { u_new[n + j - 1] } else { 0.0 };
                                    let t = 2 * n + 2 * e;
                                    let (rho, m) = (q.theta[t], q.theta[t + 1]);
                                    u[row] + DT * PlasticLaw.rate(dv, u[row], &[rho], &[m])
                                } else {
                                    full[row]
                                }
                            })
                            .collect()
                    };
                    let (_, fd) = fd_jacobian(&stage_map, &z, H);
                    close_all(&big_f, &fd, TOL, &format!("{what}: F of stage {s}"));
                }
                let mut big_s = Sparse::recording(d.nu, d.nz);
                mln.transition_sensitivity(K, &u, &u_next, &z, &mut big_s);
                let path = |z: &[f64]| {
                    let mut full = aug_next(&aug, &point_at(z));
                    full.extend(std::iter::repeat_n(0.0, ne));
                    full
                };
                let (_, fd) = fd_jacobian(&path, &z, H);
                close_all(&big_s.to_dense(), &fd, TOL, &format!("{what}: sensitivity"));

                // MPF-EKF2: staged step and ψ's Jacobian in x^bl for every stage.
                let layout = mpf.layout();
                let d = mpf.dims();
                let (xn, m) = split(&layout, &p, d.nn, d.nbl);
                let (xn_new, m_new) = mpf_step(&mpf, &xn, &m);
                let after = join(&layout, &xn_new, &m_new, n);
                close_all(&after.states(), &next, 1e-12, &format!("{what}: MPF step"));
                assert_eq!(after.theta, p.theta, "{what}: parameters unchanged");
                for s in 0..mpf.sampled_stages().len() {
                    let (_, jac) = mpf_stage(&mpf, s, &xn, &xn_new, &m);
                    let value = |m: &[f64]| mpf_stage(&mpf, s, &xn, &xn_new, m).0;
                    let (_, fd) = fd_jacobian(&value, &m, H);
                    close_all(&jac, &fd, TOL, &format!("{what}: ψ stage {s}"));
                }
            }
        }
    }
}
