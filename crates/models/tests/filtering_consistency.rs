//! The run-time partitions agree with the truth simulator and with themselves when evaluated for
//! a SIMD pack of four particles; their layouts follow SPEC §5.2 and §6. (Their agreement with the
//! earlier compile-time partitions of the paper's chain was checked to 1e-13 before those were
//! retired; the full reproduction gave the same θ_val to 6.2e-11.)

use crate::filtering_support;

use core_filters::linalg::Sparse;
use core_filters::model::Slot;
use core_filters::real::{Pack, Real};
use core_filters::rng::stream;
use core_filters::smc::model::{
    ConditionallyLinear, ConditionallyQuadratic, Partition, SampledAt, StateSpace,
};
use filtering_support::*;
use models::filtering::{AugmentedChain, Discretisation, MlnChain, MpfChain};
use models::integrate::simulate_rk4;
use models::sensors::MeasurementKind;
use models::structure::Damping;

fn propagate(aug: &AugmentedChain, k: usize, x: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; x.len()];
    aug.propagate(k, x, &vec![0.0; aug.noise_dim()], &mut out);
    out
}

#[test]
fn augmented_maps_are_the_truth_simulator_stepped_by_each_scheme() {
    for case in cases().into_iter().chain(damped_cases()) {
        let mut rng = stream(21, 0, case.name);
        for _ in 0..4 {
            let p = random_point(&case, &mut rng);
            let ch = shear_chain(&case, &p);
            let s = p.states();
            let (n, d) = (case.n(), s.len());
            let ug = spec(&case, Discretisation::Euler).ug;
            let mut ds = vec![0.0; d];
            ch.rhs(&s, ug[K - 1], &mut ds);
            // Forward Euler: s + dt g(s), bit for bit.
            let aug = AugmentedChain::new(spec(&case, Discretisation::Euler)).unwrap();
            let euler: Vec<f64> = (0..d).map(|i| s[i] + DT * ds[i]).collect();
            assert_eq!(
                &propagate(&aug, K, &p.augmented())[..d],
                &euler[..],
                "{}",
                case.name
            );
            // Symplectic: v' = v + dt a(s); x' = x + dt v'; r' = r + dt ṙ(δv', r).
            let aug = AugmentedChain::new(spec(&case, Discretisation::Symplectic)).unwrap();
            let mut s2 = s.clone();
            for j in 0..n {
                s2[n + j] = s[n + j] + DT * ds[n + j];
            }
            let mut ds2 = vec![0.0; d];
            ch.rhs(&s2, ug[K - 1], &mut ds2);
            let mut want = s2.clone();
            for j in 0..n {
                want[j] = s[j] + DT * s2[n + j];
            }
            for i in 2 * n..d {
                want[i] = s[i] + DT * ds2[i];
            }
            assert_eq!(
                &propagate(&aug, K, &p.augmented())[..d],
                &want[..],
                "{}",
                case.name
            );
        }
        // RK4 from rest over the whole excitation: the truth integrator, bit for bit.
        let p = random_point(&case, &mut rng);
        let aug = AugmentedChain::new(spec(&case, Discretisation::Rk4)).unwrap();
        let ug = aug.spec().ug.clone();
        let truth = simulate_rk4(&shear_chain(&case, &p), &ug, DT);
        let mut x = p.with_states(&vec![0.0; p.states().len()]).augmented();
        for k in 1..ug.len() {
            x = propagate(&aug, k, &x);
            assert_eq!(
                &x[..truth.dim()],
                truth.state(k),
                "{} RK4 step {k}",
                case.name
            );
        }
    }
}

#[test]
fn process_noise_is_added_as_documented() {
    let case = &cases()[0];
    let sp = spec(case, Discretisation::Symplectic);
    let aug = AugmentedChain::new(sp.clone()).unwrap();
    let p = random_point(case, &mut stream(22, 0, "noise"));
    let x = p.augmented();
    let n = case.n();
    let xi: Vec<f64> = (0..aug.noise_dim()).map(|i| 0.3 + 0.1 * i as f64).collect();
    let mut out = vec![0.0; x.len()];
    aug.propagate(K, &x, &xi, &mut out);
    let clean = propagate(&aug, K, &x);
    // The velocity draw moves the displacement through the new velocity.
    for j in 0..n {
        close(
            out[n + j] - clean[n + j],
            sp.q_vel * xi[n + j],
            1e-9,
            "v noise",
        );
        close(
            out[j] - clean[j],
            sp.q_disp * xi[j] + DT * sp.q_vel * xi[n + j],
            1e-9,
            "x noise",
        );
    }
    assert_eq!(
        &out[aug.noise_dim()..],
        &x[aug.noise_dim()..],
        "θ carries no noise"
    );
}

fn pack(vs: &[Vec<f64>]) -> Vec<Pack> {
    (0..vs[0].len())
        .map(|i| Pack::from_lanes(|b| vs[b][i]))
        .collect()
}

#[track_caller]
fn same_lanes(p: &[Pack], s: &[Vec<f64>], what: &str) {
    for (b, sb) in s.iter().enumerate() {
        assert_eq!(p.len(), sb.len());
        for (i, v) in sb.iter().enumerate() {
            assert_eq!(
                p[i].lane(b).to_bits(),
                v.to_bits(),
                "{what}: lane {b} entry {i}"
            );
        }
    }
}

#[test]
fn pack_evaluation_is_the_scalar_evaluation_of_each_lane() {
    // Both damping forms (the MLN partition refuses the storey+mass form).
    for case in cases().into_iter().chain(damped_cases()) {
        for disc in [Discretisation::Euler, Discretisation::Symplectic] {
            let mpf = MpfChain::new(spec(&case, disc)).unwrap();
            let aug = AugmentedChain::new(spec(&case, disc)).unwrap();
            let mut rng = stream(24, 0, case.name);
            let pts: Vec<Point> = (0..4).map(|_| random_point(&case, &mut rng)).collect();
            let what = format!("{} {disc}", case.name);
            // MLN.
            if !case.damping.has_mass_term() {
                let mln = MlnChain::new(spec(&case, disc)).unwrap();
                let d = mln.dims();
                let uz: Vec<(Vec<f64>, Vec<f64>)> = pts
                    .iter()
                    .map(|p| split(&mln.layout(), p, d.nu, d.nz))
                    .collect();
                let us: Vec<Vec<f64>> = uz.iter().map(|x| x.0.clone()).collect();
                let zs: Vec<Vec<f64>> = uz.iter().map(|x| x.1.clone()).collect();
                let u_new: Vec<Vec<f64>> = pts
                    .iter()
                    .zip(&us)
                    .map(|(p, u)| {
                        let mut v = u.clone();
                        let next = propagate(&aug, K, &p.augmented());
                        v[..aug.noise_dim()].copy_from_slice(&next[..aug.noise_dim()]);
                        v
                    })
                    .collect();
                let (up, zp, unp) = (pack(&us), pack(&zs), pack(&u_new));
                for (s, st) in mln.stages().iter().enumerate() {
                    let mut fp = vec![Pack::splat(0.0); st.rows.len()];
                    let mut big_fp = Sparse::<Pack>::recording(st.linked.len(), d.nz);
                    mln.transition(s, K, &up, &unp, &mut fp, &mut big_fp);
                    let (mut fs, mut big_fs) = (Vec::new(), Vec::new());
                    for b in 0..4 {
                        let mut f = vec![0.0; st.rows.len()];
                        let mut big_f = Sparse::<f64>::recording(st.linked.len(), d.nz);
                        mln.transition(s, K, &us[b], &u_new[b], &mut f, &mut big_f);
                        fs.push(f);
                        big_fs.push(big_f.values().to_vec());
                    }
                    same_lanes(&fp, &fs, &format!("{what}: MLN f"));
                    same_lanes(big_fp.values(), &big_fs, &format!("{what}: MLN F"));
                }
                let mut sp = Sparse::<Pack>::recording(d.nu, d.nz);
                mln.transition_sensitivity(K, &up, &unp, &zp, &mut sp);
                let mut hp = vec![Pack::splat(0.0); d.ny];
                let mut big_hp = Sparse::<Pack>::recording(d.ny, d.nz);
                mln.observation(K, &up, &mut hp, &mut big_hp);
                let mut jp = Sparse::<Pack>::recording(d.ny, d.nu);
                mln.observation_jacobian_u(K, &up, &zp, &mut jp);
                let (mut ss, mut hs, mut big_hs, mut js) = (vec![], vec![], vec![], vec![]);
                for b in 0..4 {
                    let mut s = Sparse::<f64>::recording(d.nu, d.nz);
                    mln.transition_sensitivity(K, &us[b], &u_new[b], &zs[b], &mut s);
                    ss.push(s.values().to_vec());
                    let mut h = vec![0.0; d.ny];
                    let mut big_h = Sparse::<f64>::recording(d.ny, d.nz);
                    mln.observation(K, &us[b], &mut h, &mut big_h);
                    hs.push(h);
                    big_hs.push(big_h.values().to_vec());
                    let mut j = Sparse::<f64>::recording(d.ny, d.nu);
                    mln.observation_jacobian_u(K, &us[b], &zs[b], &mut j);
                    js.push(j.values().to_vec());
                }
                same_lanes(sp.values(), &ss, &format!("{what}: MLN sensitivity"));
                same_lanes(&hp, &hs, &format!("{what}: MLN h"));
                same_lanes(big_hp.values(), &big_hs, &format!("{what}: MLN H"));
                same_lanes(jp.values(), &js, &format!("{what}: MLN J_u"));
            }

            // MPF.
            let qd = mpf.dims();
            let xm: Vec<(Vec<f64>, Vec<f64>)> = pts
                .iter()
                .map(|p| split(&mpf.layout(), p, qd.nn, qd.nbl))
                .collect();
            let xns: Vec<Vec<f64>> = xm.iter().map(|x| x.0.clone()).collect();
            let ms: Vec<Vec<f64>> = xm.iter().map(|x| x.1.clone()).collect();
            // Some new sampled values (any values serve for the comparison).
            let xn_new: Vec<Vec<f64>> = xns
                .iter()
                .map(|x| x.iter().map(|v| 0.9 * v + 0.01).collect())
                .collect();
            let (xp, xnp, mp) = (pack(&xns), pack(&xn_new), pack(&ms));
            for (s, entries) in mpf.sampled_stages().iter().enumerate() {
                let mut vp = vec![Pack::splat(0.0); entries.len()];
                let mut jp = Sparse::<Pack>::recording(entries.len(), qd.nbl);
                let at = SampledAt {
                    stage: s,
                    k: K,
                    prev: &xp,
                    new: &xnp,
                    m: &mp,
                };
                mpf.sampled_dynamics(at, &mut vp, &mut jp);
                let (mut vs, mut jss) = (vec![], vec![]);
                for b in 0..4 {
                    let mut v = vec![0.0; entries.len()];
                    let mut j = Sparse::<f64>::recording(entries.len(), qd.nbl);
                    let at = SampledAt {
                        stage: s,
                        k: K,
                        prev: &xns[b],
                        new: &xn_new[b],
                        m: &ms[b],
                    };
                    mpf.sampled_dynamics(at, &mut v, &mut j);
                    vs.push(v);
                    jss.push(j.values().to_vec());
                }
                same_lanes(&vp, &vs, &format!("{what}: MPF ψ {s}"));
                same_lanes(jp.values(), &jss, &format!("{what}: MPF ψ Jacobian {s}"));
            }
            let mut vp = vec![Pack::splat(0.0); qd.nbl];
            let mut dp = Sparse::<Pack>::recording(qd.nbl, qd.nbl);
            mpf.marginal_dynamics(K, &xp, &xnp, &mp, &mut vp, &mut dp);
            let mut yp = vec![Pack::splat(0.0); qd.ny];
            let mut ojp = Sparse::<Pack>::recording(qd.ny, qd.nbl);
            ConditionallyQuadratic::observation(&mpf, K, &xnp, &mp, &mut yp, &mut ojp);
            let (mut vs, mut ds, mut ys, mut ojs) = (vec![], vec![], vec![], vec![]);
            for b in 0..4 {
                let mut v = vec![0.0; qd.nbl];
                let mut dm = Sparse::<f64>::recording(qd.nbl, qd.nbl);
                mpf.marginal_dynamics(K, &xns[b], &xn_new[b], &ms[b], &mut v, &mut dm);
                vs.push(v);
                ds.push(dm.values().to_vec());
                let mut y = vec![0.0; qd.ny];
                let mut oj = Sparse::<f64>::recording(qd.ny, qd.nbl);
                ConditionallyQuadratic::observation(&mpf, K, &xn_new[b], &ms[b], &mut y, &mut oj);
                ys.push(y);
                ojs.push(oj.values().to_vec());
            }
            same_lanes(&vp, &vs, &format!("{what}: MPF φ_bl"));
            same_lanes(dp.values(), &ds, &format!("{what}: MPF D"));
            same_lanes(&yp, &ys, &format!("{what}: MPF y"));
            same_lanes(ojp.values(), &ojs, &format!("{what}: MPF y Jacobian"));
        }
    }
}

#[test]
fn layouts_follow_spec_sections_5_2_and_6() {
    use Slot::{Marginal as M, Sampled as S};
    let case = paper_case(MeasurementKind::Relative);
    let mpf = MpfChain::new(spec(&case, Discretisation::Symplectic)).unwrap();
    let l = mpf.layout();
    // SPEC §6: xⁿ = [ẋ1, r1, n]; x^bl = [x1 x2 x3 ẋ2 ẋ3 k1 k2 k3 c1 c2 c3 β γ].
    assert_eq!(l.states, [M(0), M(1), M(2), S(0), M(3), M(4), S(1)]);
    assert_eq!(
        l.params,
        [M(5), M(6), M(7), M(8), M(9), M(10), M(11), M(12), S(2)]
    );
    assert_eq!(
        l.param_names,
        ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"]
    );
    assert_eq!(mpf.sampled_stages(), [vec![0], vec![1]]);
    let mln = MlnChain::new(spec(&case, Discretisation::Euler)).unwrap();
    let l = mln.layout();
    assert_eq!(
        l.params,
        [M(0), M(1), M(2), M(3), M(4), M(5), M(6), M(7), S(7)]
    );
    assert_eq!(mln.stages()[0].linked, [3, 4, 5, 6]);

    // 7 storeys, elements at 1 and 4: sampled velocities v1, v3, v4.
    let case = &cases()[0];
    let mpf = MpfChain::new(spec(case, Discretisation::Euler)).unwrap();
    let l = mpf.layout();
    assert_eq!(l.state_names[14..], ["r1", "r4"]);
    assert_eq!(
        &l.states[7..],
        [S(0), M(7), S(1), S(2), M(8), M(9), M(10), S(3), S(4)]
    );
    assert_eq!(
        l.param_names[14..],
        ["beta1", "gamma1", "n1", "beta4", "gamma4", "n4"]
    );
    assert_eq!(l.params[14..], [M(25), M(26), S(5), M(27), M(28), S(6)]);
    assert_eq!(mpf.dims().nbl, 29);
    let mln = MlnChain::new(spec(case, Discretisation::Symplectic)).unwrap();
    assert_eq!(mln.stages()[0].rows, (7..14).collect::<Vec<_>>());
    assert_eq!(mln.stages()[1].rows, [0, 1, 2, 3, 4, 5, 6, 14, 15]);
    assert_eq!(mln.stages()[1].linked, [14, 15]);

    // The 10-storey example of docs/partitions.md: elements at 1 and 6, sensors at 1, 3, 6, 10.
    let case = Case {
        name: "10 storeys",
        masses: vec![1.0; 10],
        hysteretic: vec![0, 5],
        sensors: vec![1, 3, 6, 10],
        kind: MeasurementKind::Relative,
        damping: Damping::Storey,
    };
    let mpf = MpfChain::new(spec(&case, Discretisation::Euler)).unwrap();
    assert_eq!((mpf.dims().nn, mpf.dims().nbl, mpf.dims().ny), (7, 41, 4));
    let l = mpf.layout();
    let sampled: Vec<&str> = l
        .state_names
        .iter()
        .zip(&l.states)
        .filter(|(_, s)| matches!(s, S(_)))
        .map(|(n, _)| n.as_str())
        .collect();
    assert_eq!(sampled, ["v1", "v5", "v6", "r1", "r6"]);
    let mln = MlnChain::new(spec(&case, Discretisation::Euler)).unwrap();
    assert_eq!((mln.dims().nu, mln.dims().nz), (24, 24));

    // A linear chain: nothing sampled by the MPF-EKF2, no n in the MLN partition.
    let case = Case {
        name: "linear",
        masses: vec![1.0; 4],
        hysteretic: vec![],
        sensors: vec![2, 4],
        kind: MeasurementKind::Absolute,
        damping: Damping::Storey,
    };
    let mpf = MpfChain::new(spec(&case, Discretisation::Symplectic)).unwrap();
    assert_eq!((mpf.dims().nn, mpf.dims().nbl), (0, 16));
    assert!(mpf.sampled_stages().is_empty());
    let mln = MlnChain::new(spec(&case, Discretisation::Symplectic)).unwrap();
    assert_eq!((mln.dims().nu, mln.dims().nz), (8, 8));
    assert_eq!(mln.stages()[1].linked, Vec::<usize>::new());
}

/// The storey+mass damping form: α sits right after c in θ and in x^bl (marginal, like c) for
/// the MPF-EKF2, is one more static entry of the bootstrap PF's augmented state, and is refused
/// by name by the MLN-RBPF/Storvik partition.
#[test]
fn mass_damping_layouts_and_refusal() {
    use Slot::{Marginal as M, Sampled as S};
    let case = damped_cases()
        .into_iter()
        .find(|c| c.name == "paper 3-storey")
        .unwrap();
    for disc in [Discretisation::Euler, Discretisation::Symplectic] {
        let mpf = MpfChain::new(spec(&case, disc)).unwrap();
        let l = mpf.layout();
        assert_eq!(
            l.param_names,
            ["k1", "k2", "k3", "c1", "c2", "c3", "alpha", "beta", "gamma", "n"]
        );
        // x^bl = [x1 x2 x3 v2 v3 k1 k2 k3 c1 c2 c3 α β γ]: α at 11, β, γ after it.
        assert_eq!(
            l.params,
            [
                M(5),
                M(6),
                M(7),
                M(8),
                M(9),
                M(10),
                M(11),
                M(12),
                M(13),
                S(2)
            ]
        );
        assert_eq!((mpf.dims().nn, mpf.dims().nbl), (3, 14));
        let aug = AugmentedChain::new(spec(&case, disc)).unwrap();
        assert_eq!(aug.layout().param_names, l.param_names);
        assert_eq!(aug.dim(), 7 + 10);
        let err = MlnChain::new(spec(&case, disc)).unwrap_err();
        assert!(
            matches!(
                err,
                models::filtering::SpecError::DampingUnsupported {
                    damping: Damping::StoreyMass,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("damping"), "{err}");
    }
    // The form and α's prior must agree, named by field.
    let mut bad = spec(&case, Discretisation::Euler);
    bad.prior.alpha = None;
    let err = MpfChain::new(bad).unwrap_err().to_string();
    assert!(err.contains("prior.alpha"), "{err}");
    let mut bad = spec(
        &paper_case(MeasurementKind::Relative),
        Discretisation::Euler,
    );
    bad.prior.alpha = Some(models::priors::Prior::Fixed { value: 0.1 });
    let err = MpfChain::new(bad).unwrap_err().to_string();
    assert!(err.contains("prior.alpha"), "{err}");
}
