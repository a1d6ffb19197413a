//! Finite-difference tests of every Jacobian and sparse Hessian of the run-time partitions
//! (`models::filtering`), for forward and symplectic Euler, on the 7-storey chain (hysteresis at
//! storeys 1 and 4, sensors at 2, 4, 7, relative and absolute) and the paper's chain, at random
//! points; and the agreement of each partition's maps with the augmented (physical) map.
//!
//! Tolerances. Every map is differentiated along directions in which it is affine (θ in the
//! accelerations, states in y), at most bilinear (MPF maps in x^bl) or, for the symplectic
//! sensitivity, quadratic with a kink only at δv = 0 (random points stay away from it). A central
//! difference is then exact in exact arithmetic, and the difference of Jacobians is exact for
//! bilinear maps; what remains is round-off, ≈ ε·|f|/h ≈ 1e−9 for |f| ≲ 50 and h = 1e−5. The
//! tolerance 1e−7 (relative to max(1, |value|)) is two orders above that and far below any real
//! error (a wrong entry is off by O(dt) = 5e−3 or more).

use crate::filtering_support;

use core_filters::linalg::Sparse;
use core_filters::model::Slot;
use core_filters::rng::stream;
use core_filters::smc::model::{
    ConditionallyLinear, ConditionallyQuadratic, Partition, SampledAt, StateSpace,
};
use filtering_support::*;
use models::filtering::{AugmentedChain, Discretisation, MlnChain, MpfChain};
use models::structure::bouc_wen_rate;

const H: f64 = 1e-5;
const TOL: f64 = 1e-7;
const POINTS: u64 = 4;
const SCHEMES: [Discretisation; 2] = [Discretisation::Euler, Discretisation::Symplectic];

/// The augmented map's dynamic states at K (zero noise).
fn aug_next(aug: &AugmentedChain, p: &Point) -> Vec<f64> {
    let x = p.augmented();
    let mut out = vec![0.0; x.len()];
    aug.propagate(K, &x, &vec![0.0; aug.noise_dim()], &mut out);
    assert_eq!(&out[aug.noise_dim()..], &p.theta[..], "θ is copied");
    out.truncate(aug.noise_dim());
    out
}

fn aug_measure(aug: &AugmentedChain, p: &Point) -> Vec<f64> {
    let mut y = vec![0.0; aug.ny()];
    aug.measure(K, &p.augmented(), &mut y);
    y
}

/// One MLN stage at (u_prev, u_new): `f` and `F` (dense, `linked × nz`).
fn mln_stage(mln: &MlnChain, stage: usize, u_prev: &[f64], u_new: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let st = &mln.stages()[stage];
    let nz = mln.dims().nz;
    let mut f = vec![0.0; st.rows.len()];
    let mut big_f = Sparse::recording(st.linked.len(), nz);
    mln.transition(stage, K, u_prev, u_new, &mut f, &mut big_f);
    (f, big_f.to_dense())
}

/// The staged MLN map `u_k = f + F z`, noise-free; copied rows keep `u_prev`.
fn mln_step(mln: &MlnChain, u_prev: &[f64], z: &[f64]) -> Vec<f64> {
    let mut u_new = u_prev.to_vec();
    let nz = z.len();
    for (s, st) in mln.stages().iter().enumerate() {
        let (f, big_f) = mln_stage(mln, s, u_prev, &u_new);
        for (i, &row) in st.rows.iter().enumerate() {
            u_new[row] = f[i];
        }
        let nl = st.linked.len();
        for (l, &row) in st.linked.iter().enumerate() {
            u_new[row] += (0..nz).map(|c| big_f[l + c * nl] * z[c]).sum::<f64>();
        }
    }
    u_new
}

#[test]
fn mln_maps_jacobians_and_sensitivity_match_the_physics() {
    for case in cases() {
        for disc in SCHEMES {
            let mln = MlnChain::new(spec(&case, disc)).unwrap();
            let aug = AugmentedChain::new(spec(&case, disc)).unwrap();
            let d = mln.dims();
            let layout = mln.layout();
            let (n, ne) = (case.n(), case.ne());
            let dyn_dim = 2 * n + ne;
            let mut rng = stream(7, 0, case.name);
            for _ in 0..POINTS {
                let p = random_point(&case, &mut rng);
                let (u, z) = split(&layout, &p, d.nu, d.nz);
                let what = format!("{} {disc}", case.name);
                // z ↦ point with the states and n's of u.
                let point_at = |z: &[f64]| join(&layout, &u, z, n);

                // The staged map equals the augmented map; n rows are copied.
                let u_next = mln_step(&mln, &u, &z);
                close_all(
                    &u_next[..dyn_dim],
                    &aug_next(&aug, &p),
                    1e-12,
                    &format!("{what}: f + F z"),
                );
                assert_eq!(&u_next[dyn_dim..], &u[dyn_dim..], "n copied");

                // F of each stage: central differences of the stage's physical map in z.
                let u_new = aug_next(&aug, &p);
                let mut u_new_full = u.clone();
                u_new_full[..dyn_dim].copy_from_slice(&u_new);
                for (s, st) in mln.stages().iter().enumerate() {
                    let (_, big_f) = mln_stage(&mln, s, &u, &u_new_full);
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
                                    let t = 2 * n + 3 * e;
                                    u[row]
                                        + DT * bouc_wen_rate(
                                            dv,
                                            u[row],
                                            q.theta[t],
                                            q.theta[t + 1],
                                            q.theta[t + 2],
                                        )
                                } else {
                                    full[row]
                                }
                            })
                            .collect()
                    };
                    let (_, fd) = fd_jacobian(&stage_map, &z, H);
                    close_all(&big_f, &fd, TOL, &format!("{what}: F of stage {s}"));
                }

                // Sensitivity ∂u_k/∂z along the path: the augmented map as a function of z.
                let mut big_s = Sparse::recording(d.nu, d.nz);
                mln.transition_sensitivity(K, &u, &u_next, &z, &mut big_s);
                let path = |z: &[f64]| {
                    let mut full = aug_next(&aug, &point_at(z));
                    full.extend(std::iter::repeat_n(0.0, ne));
                    full
                };
                let (_, fd) = fd_jacobian(&path, &z, H);
                close_all(&big_s.to_dense(), &fd, TOL, &format!("{what}: sensitivity"));

                // Observation: h + H z equals the measurement; H and J_u by differences.
                let mut h = vec![0.0; d.ny];
                let mut big_h = Sparse::recording(d.ny, d.nz);
                mln.observation(K, &u, &mut h, &mut big_h);
                let mut y = h.clone();
                big_h.mul_add(&z, &mut y);
                close_all(
                    &y,
                    &aug_measure(&aug, &p),
                    1e-12,
                    &format!("{what}: h + H z"),
                );
                let (_, fd) = fd_jacobian(&|z: &[f64]| aug_measure(&aug, &point_at(z)), &z, H);
                close_all(&big_h.to_dense(), &fd, TOL, &format!("{what}: H"));
                let mut ju = Sparse::recording(d.ny, d.nu);
                mln.observation_jacobian_u(K, &u, &z, &mut ju);
                let (_, fd) = fd_jacobian(
                    &|u: &[f64]| aug_measure(&aug, &join(&layout, u, &z, n)),
                    &u,
                    H,
                );
                close_all(&ju.to_dense(), &fd, TOL, &format!("{what}: J_u"));
            }
        }
    }
}

/// Evaluates the MPF map of one stage: values and dense Jacobian (`rows × nbl`).
fn mpf_stage(
    mpf: &MpfChain,
    stage: usize,
    xn_prev: &[f64],
    xn_new: &[f64],
    m: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let rows = mpf.sampled_stages()[stage].len();
    let nbl = mpf.dims().nbl;
    let mut value = vec![0.0; rows];
    let mut jac = Sparse::recording(rows, nbl);
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

fn mpf_marginal(
    mpf: &MpfChain,
    xn_prev: &[f64],
    xn_new: &[f64],
    m: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let nbl = mpf.dims().nbl;
    let mut value = vec![0.0; nbl];
    let mut d = Sparse::recording(nbl, nbl);
    mpf.marginal_dynamics(K, xn_prev, xn_new, m, &mut value, &mut d);
    let mut jac = d.to_dense();
    for i in 0..nbl {
        jac[i + i * nbl] += 1.0;
    }
    (value, jac)
}

fn mpf_observation(mpf: &MpfChain, xn: &[f64], m: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let d = mpf.dims();
    let mut value = vec![0.0; d.ny];
    let mut jac = Sparse::recording(d.ny, d.nbl);
    mpf.observation(K, xn, m, &mut value, &mut jac);
    (value, jac.to_dense())
}

/// The noise-free staged MPF step: (xⁿ_k, m_k).
fn mpf_step(mpf: &MpfChain, xn: &[f64], m: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut xn_new = xn.to_vec();
    for (s, entries) in mpf.sampled_stages().iter().enumerate() {
        let (value, _) = mpf_stage(mpf, s, xn, &xn_new, m);
        for (i, &e) in entries.iter().enumerate() {
            xn_new[e] = value[i];
        }
    }
    let (m_new, _) = mpf_marginal(mpf, xn, &xn_new, m);
    (xn_new, m_new)
}

/// Checks a constant Hessian list against central differences of a Jacobian function of m.
fn check_hessians(
    jac_of: &dyn Fn(&[f64]) -> Vec<f64>,
    hess: &core_filters::model::SparseHessians,
    outputs: usize,
    m: &[f64],
    what: &str,
) {
    let nbl = m.len();
    let mut mp = m.to_vec();
    // d/dm_a of J[i, b] = H_i[b, a].
    for a in 0..nbl {
        mp[a] = m[a] + 1e-3;
        let jp = jac_of(&mp);
        mp[a] = m[a] - 1e-3;
        let jm = jac_of(&mp);
        mp[a] = m[a];
        for i in 0..outputs {
            let dense = hess.dense(i, nbl);
            for b in 0..nbl {
                let fd = (jp[i + b * outputs] - jm[i + b * outputs]) / 2e-3;
                close(
                    dense[(b, a)],
                    fd,
                    1e-9,
                    &format!("{what}: Hessian {i} ({b}, {a})"),
                );
            }
        }
    }
}

#[test]
fn mpf_maps_jacobians_and_hessians_match_the_physics() {
    // Both damping forms: with storey+mass, α × v_j is one more bilinear term (or linear in α
    // for a sampled v_j).
    for case in cases().into_iter().chain(damped_cases()) {
        for disc in SCHEMES {
            let mpf = MpfChain::new(spec(&case, disc)).unwrap();
            let aug = AugmentedChain::new(spec(&case, disc)).unwrap();
            let d = mpf.dims();
            let layout = mpf.layout();
            let n = case.n();
            let mut rng = stream(8, 0, case.name);
            for _ in 0..POINTS {
                let p = random_point(&case, &mut rng);
                let (xn, m) = split(&layout, &p, d.nn, d.nbl);
                let what = format!("{} {disc}", case.name);

                // The staged maps equal the augmented map; parameters and n are unchanged.
                let (xn_new, m_new) = mpf_step(&mpf, &xn, &m);
                let next = join(&layout, &xn_new, &m_new, n);
                close_all(
                    &next.states(),
                    &aug_next(&aug, &p),
                    1e-12,
                    &format!("{what}: staged step"),
                );
                assert_eq!(next.theta, p.theta, "{what}: parameters and n unchanged");

                // ψ of each stage: Jacobian and Hessians by differences in m.
                for s in 0..mpf.sampled_stages().len() {
                    let (_, jac) = mpf_stage(&mpf, s, &xn, &xn_new, &m);
                    let value = |m: &[f64]| mpf_stage(&mpf, s, &xn, &xn_new, m).0;
                    let (_, fd) = fd_jacobian(&value, &m, H);
                    close_all(&jac, &fd, TOL, &format!("{what}: ψ stage {s}"));
                    let rows = mpf.sampled_stages()[s].len();
                    let jac_of = |m: &[f64]| mpf_stage(&mpf, s, &xn, &xn_new, m).1;
                    check_hessians(
                        &jac_of,
                        mpf.sampled_hessians(s),
                        rows,
                        &m,
                        &format!("{what}: ψ stage {s}"),
                    );
                }

                // φ_bl: D + I and the Hessians.
                let (_, jac) = mpf_marginal(&mpf, &xn, &xn_new, &m);
                let (_, fd) =
                    fd_jacobian(&|m: &[f64]| mpf_marginal(&mpf, &xn, &xn_new, m).0, &m, H);
                close_all(&jac, &fd, TOL, &format!("{what}: D + I"));
                let jac_of = |m: &[f64]| mpf_marginal(&mpf, &xn, &xn_new, m).1;
                check_hessians(
                    &jac_of,
                    mpf.marginal_hessians(),
                    d.nbl,
                    &m,
                    &format!("{what}: φ_bl"),
                );

                // Observation at (xⁿ_k, m): the augmented measurement; Jacobian and Hessians.
                let (y, jac) = mpf_observation(&mpf, &xn, &m);
                close_all(&y, &aug_measure(&aug, &p), 1e-12, &format!("{what}: y"));
                let (_, fd) = fd_jacobian(&|m: &[f64]| mpf_observation(&mpf, &xn, m).0, &m, H);
                close_all(&jac, &fd, TOL, &format!("{what}: observation Jacobian"));
                let jac_of = |m: &[f64]| mpf_observation(&mpf, &xn, m).1;
                check_hessians(
                    &jac_of,
                    mpf.observation_hessians(),
                    d.ny,
                    &m,
                    &format!("{what}: y"),
                );
            }
        }
    }
}

/// The process noise of each partition is the augmented map's noise given what the partition
/// samples: `Q_bl` = covariance of the marginal entries' noise with the sampled entries' draws
/// held fixed (for symplectic Euler the velocity draw also moves the displacement).
#[test]
fn noise_levels_are_the_augmented_noise_seen_by_each_partition() {
    for case in cases() {
        for disc in SCHEMES {
            let aug = AugmentedChain::new(spec(&case, disc)).unwrap();
            let mpf = MpfChain::new(spec(&case, disc)).unwrap();
            let mln = MlnChain::new(spec(&case, disc)).unwrap();
            let what = format!("{} {disc}", case.name);
            let mut rng = stream(9, 0, case.name);
            let p = random_point(&case, &mut rng);
            let x = p.augmented();
            let nd = aug.noise_dim();
            // The noise map is affine in ξ: its Jacobian by differences.
            let next = |xi: &[f64]| {
                let mut out = vec![0.0; x.len()];
                aug.propagate(K, &x, xi, &mut out);
                out[..nd].to_vec()
            };
            let (_, g) = fd_jacobian(&next, &vec![0.0; nd], 1.0);
            // MPF: sampled draws are the ξ of the states in xⁿ.
            let layout = mpf.layout();
            let (nn, nbl) = (mpf.dims().nn, mpf.dims().nbl);
            let mut q = vec![0.0; nbl * nbl];
            mpf.marginal_noise().add_to(&mut q, nbl);
            let mut expected = vec![0.0; nbl * nbl];
            let sampled_xi: Vec<bool> = layout
                .states
                .iter()
                .map(|s| matches!(s, Slot::Sampled(_)))
                .collect();
            for (a, sa) in layout.states.iter().enumerate() {
                for (b, sb) in layout.states.iter().enumerate() {
                    if let (Slot::Marginal(i), Slot::Marginal(j)) = (*sa, *sb) {
                        expected[i + j * nbl] = (0..nd)
                            .filter(|&c| !sampled_xi[c])
                            .map(|c| g[a + c * nd] * g[b + c * nd])
                            .sum();
                    }
                }
            }
            close_all(&q, &expected, 1e-12, &format!("{what}: Q_bl"));
            // Sampled stage noise: the s.d. of each sampled entry's own draw.
            for (s, entries) in mpf.sampled_stages().iter().enumerate() {
                for (i, &e) in entries.iter().enumerate() {
                    let a = layout
                        .states
                        .iter()
                        .position(|sl| *sl == Slot::Sampled(e))
                        .unwrap();
                    close(
                        mpf.sampled_noise_sd(s)[i],
                        g[a + a * nd],
                        1e-12,
                        &format!("{what}: Qn"),
                    );
                }
            }
            assert!(nn >= case.ne());
            // MLN: each dynamic row's own draw, zero for the n rows.
            let sd = mln.process_noise_sd();
            for a in 0..nd {
                close(sd[a], g[a + a * nd], 1e-12, &format!("{what}: MLN noise"));
            }
            assert!(sd[nd..].iter().all(|&v| v == 0.0));
        }
    }
}
