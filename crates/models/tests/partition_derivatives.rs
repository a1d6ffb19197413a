//! Derivatives and cross-consistency of the three partitions of the Bouc–Wen chain
//! (SPEC §5.1–5.4, §6).
//!
//! Finite-difference tolerances. Every map is differentiated only along directions in which it
//! is affine (θ-entries of the Euler map and of the accelerations, the states in y) or, for the
//! MPF maps in x^bl, at most bilinear with no squared terms. A central difference is then exact
//! in exact arithmetic (its truncation error involves third derivatives along the direction,
//! which vanish), and a centred second difference is exact for bilinear maps. What remains is
//! round-off: with |f| ≲ 50 and step h the first difference errs by ≈ ε·|f|/h ≈ 1e−9 for
//! h = 1e−5, the second difference by ≈ ε·|f|/h² ≈ 1e−8 for h = 1e−3. The tolerances below
//! (1e−7 relative for Jacobians, 1e−6 for Hessians) sit two orders of magnitude above that and
//! far below any real error (a wrong entry is off by O(dt) ≈ 5e−3 or more).

use core_filters::model::{
    ConditionallyLinear, ConditionallyQuadratic, SparseHessians, StateSpace,
};
use core_filters::rng::stream;
use models::partition::{
    AugmentedChain, FilterSpec, MeasurementKind, MlnChain, MpfChain, PaperMpf,
};
use nalgebra::{DMatrix, SMatrix, SVector};
use rand::Rng;

const DT: f64 = 0.005;
const K: usize = 7; // the time step used in every evaluation (transition uses ug[6], y uses ug[7])

/// A chain point in physical terms: states and θ = [k, c, β, γ, n].
#[derive(Debug, Clone)]
struct Pt {
    x: Vec<f64>,
    v: Vec<f64>,
    r1: f64,
    theta: Vec<f64>,
}

fn random_point<G: Rng>(n: usize, rng: &mut G) -> Pt {
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.random::<f64>();
    let x = (0..n).map(|_| u(-0.5, 0.5)).collect();
    let v = (0..n).map(|_| u(-2.0, 2.0)).collect();
    // r1 away from 0 (sign random) so that the Bouc–Wen terms are far from their kink.
    let r1 = u(0.05, 0.6) * if u(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 };
    let mut theta: Vec<f64> = (0..n).map(|_| u(3.0, 15.0)).collect();
    theta.extend((0..n).map(|_| u(0.05, 1.0)));
    let beta = u(0.0, 5.0);
    theta.extend([beta, u(-beta, beta), u(1.0, 5.0)]);
    Pt { x, v, r1, theta }
}

fn spec<G: Rng>(n: usize, unit_masses: bool, kind: MeasurementKind, rng: &mut G) -> FilterSpec {
    let masses = (0..n)
        .map(|_| {
            if unit_masses {
                1.0
            } else {
                0.5 + 1.5 * rng.random::<f64>()
            }
        })
        .collect();
    let ug = (0..=K + 2)
        .map(|_| 4.0 * rng.random::<f64>() - 2.0)
        .collect();
    let rms_acc: Vec<f64> = (0..n).map(|j| 1.0 + j as f64).collect();
    let mut s = FilterSpec::from_rms(DT, masses, ug, &rms_acc, 2.0, 0.5, 0.1).unwrap();
    s.measurement = kind;
    s
}

fn aug_state<const NX: usize>(p: &Pt) -> SVector<f64, NX> {
    let mut v: Vec<f64> = p.x.iter().chain(&p.v).copied().collect();
    v.push(p.r1);
    v.extend(&p.theta);
    SVector::from_column_slice(&v)
}

fn mln_state<const NU: usize, const NZ: usize>(p: &Pt) -> (SVector<f64, NU>, SVector<f64, NZ>) {
    let mut u: Vec<f64> = p.x.iter().chain(&p.v).copied().collect();
    u.push(p.r1);
    u.push(*p.theta.last().unwrap());
    let z = &p.theta[..p.theta.len() - 1];
    (
        SVector::from_column_slice(&u),
        SVector::from_column_slice(z),
    )
}

fn mpf_state<const NBL: usize>(p: &Pt) -> (SVector<f64, 3>, SVector<f64, NBL>) {
    let xn = SVector::<f64, 3>::new(p.v[0], p.r1, *p.theta.last().unwrap());
    let mut m: Vec<f64> = p.x.iter().chain(&p.v[1..]).copied().collect();
    m.extend(&p.theta[..p.theta.len() - 1]);
    (xn, SVector::from_column_slice(&m))
}

/// Maximum over entries of |a − b| / (1 + |b|).
fn rel_err<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>) -> f64 {
    a.iter()
        .zip(b.iter())
        .map(|(x, y)| (x - y).abs() / (1.0 + y.abs()))
        .fold(0.0, f64::max)
}

/// Central difference of `f` along coordinate `i` of `at`.
fn central<const D: usize, const R: usize>(
    f: impl Fn(&SVector<f64, D>) -> SVector<f64, R>,
    at: &SVector<f64, D>,
    i: usize,
    h: f64,
) -> SVector<f64, R> {
    let (mut p, mut m) = (*at, *at);
    p[i] += h;
    m[i] -= h;
    (f(&p) - f(&m)) / (2.0 * h)
}

/// Jacobian of `f` at `at` by central differences.
fn fd_jacobian<const D: usize, const R: usize>(
    f: impl Fn(&SVector<f64, D>) -> SVector<f64, R>,
    at: &SVector<f64, D>,
) -> SMatrix<f64, R, D> {
    let mut j = SMatrix::<f64, R, D>::zeros();
    for i in 0..D {
        j.set_column(i, &central(&f, at, i, 1e-5));
    }
    j
}

/// Centred second difference ∂²f/∂a∂b for every output, step h = 1e−3.
fn fd_second<const D: usize, const R: usize>(
    f: &impl Fn(&SVector<f64, D>) -> SVector<f64, R>,
    at: &SVector<f64, D>,
    a: usize,
    b: usize,
) -> SVector<f64, R> {
    let h = 1e-3;
    let shifted = |sa: f64, sb: f64| {
        let mut p = *at;
        p[a] += sa * h;
        p[b] += sb * h;
        f(&p)
    };
    (shifted(1.0, 1.0) - shifted(1.0, -1.0) - shifted(-1.0, 1.0) + shifted(-1.0, -1.0))
        / (4.0 * h * h)
}

/// Checks the dense Hessians of `hess` (R outputs) against second differences of `f` at `at`.
fn check_hessians<const D: usize, const R: usize>(
    what: &str,
    f: impl Fn(&SVector<f64, D>) -> SVector<f64, R>,
    hess: &SparseHessians,
    at: &SVector<f64, D>,
) {
    let dense: Vec<DMatrix<f64>> = (0..R).map(|o| hess.dense(o, D)).collect();
    for a in 0..D {
        for b in a..D {
            let fd = fd_second(&f, at, a, b);
            for o in 0..R {
                let exact = dense[o][(a, b)];
                assert!(
                    (fd[o] - exact).abs() <= 1e-6 * (1.0 + exact.abs()),
                    "{what}: output {o}, ({a},{b}): finite difference {} vs sparse Hessian {exact}",
                    fd[o]
                );
            }
        }
    }
}

/// f(m + δ) − f(m) − J δ − ½ Σ_o e_o δᵀ 𝓗ᵒ δ, which vanishes for a map at most quadratic in m.
fn taylor_residual<const D: usize, const R: usize>(
    f: impl Fn(&SVector<f64, D>) -> (SVector<f64, R>, SMatrix<f64, R, D>),
    hess: &SparseHessians,
    m: &SVector<f64, D>,
    delta: &SVector<f64, D>,
) -> f64 {
    let (f0, j) = f(m);
    let (f1, _) = f(&(m + delta));
    let mut second = SVector::<f64, R>::zeros();
    for e in hess.entries() {
        let w = if e.a == e.b { 0.5 } else { 1.0 };
        second[e.output] += w * e.value * delta[e.a] * delta[e.b];
    }
    let predicted = f0 + j * delta + second;
    (f1 - predicted)
        .iter()
        .zip(f1.iter())
        .map(|(r, y)| r.abs() / (1.0 + y.abs()))
        .fold(0.0, f64::max)
}

// ----------------------------------------------------------------------------------------------
// MLN-RBPF / Storvik partition

fn check_mln<
    const NX: usize,
    const NU: usize,
    const NZ: usize,
    const NL: usize,
    const NY: usize,
>(
    n: usize,
    points: usize,
    seed: u64,
) {
    let mut rng = stream(seed, 0, "partition-derivatives");
    for case in 0..points {
        let kind = if case % 2 == 0 {
            MeasurementKind::Relative
        } else {
            MeasurementKind::Absolute
        };
        let s = spec(n, false, kind, &mut rng);
        let aug = AugmentedChain::<NX, NY>::new(s.clone()).unwrap();
        let mln = MlnChain::<NU, NZ, NL, NY>::new(s).unwrap();
        let p = random_point(n, &mut rng);
        let xa = aug_state::<NX>(&p);
        let (u, z) = mln_state::<NU, NZ>(&p);
        let theta0 = 2 * n + 1;
        let linked = mln.linked_rows();

        // F (all rows) and H against central differences of the augmented map in z.
        let (_, fl) = mln.transition(K, &u);
        let (_, hm) = mln.observation(K, &u);
        for i in 0..NZ {
            let col = central(|x| aug.propagate(K, x), &xa, theta0 + i, 1e-5);
            for r in 0..NU - 1 {
                // u row r is augmented row r for the states; the n row (NU−1) is copied.
                let exact = linked
                    .iter()
                    .position(|&l| l == r)
                    .map_or(0.0, |li| fl[(li, i)]);
                assert!(
                    (col[r] - exact).abs() <= 1e-7 * (1.0 + exact.abs()),
                    "N={n} case {case}: dF[{r}]/dz[{i}] fd {} vs {exact}",
                    col[r]
                );
            }
            let ycol = central(|x| aug.measure(K, x), &xa, theta0 + i, 1e-5);
            for r in 0..NY {
                let exact = hm[(r, i)];
                assert!(
                    (ycol[r] - exact).abs() <= 1e-7 * (1.0 + exact.abs()),
                    "N={n} case {case}: H[{r}][{i}] fd {} vs {exact}",
                    ycol[r]
                );
            }
        }

        // J_u = ∂/∂u [H(u) z + h(u)] against central differences of the MLN measurement itself.
        let y_of_u = |uu: &SVector<f64, NU>| {
            let (h, hh) = mln.observation(K, uu);
            h + hh * z
        };
        let ju = mln.observation_jacobian_u(K, &u, &z);
        let fd = fd_jacobian(y_of_u, &u);
        let err = rel_err(&ju, &fd);
        assert!(
            err <= 1e-7,
            "N={n} case {case}: J_u error {err}\n{ju}\n{fd}"
        );
        assert!(
            ju.column(NU - 1).iter().all(|&v| v == 0.0),
            "n column of J_u"
        );
    }
}

#[test]
fn mln_jacobians_match_finite_differences_n3() {
    check_mln::<16, 8, 8, 4, 3>(3, 200, 1);
}

#[test]
fn mln_jacobians_match_finite_differences_n5() {
    check_mln::<24, 12, 12, 6, 5>(5, 100, 2);
}

// ----------------------------------------------------------------------------------------------
// MPF-EKF2 partition

fn check_mpf<const NBL: usize, const NY: usize>(n: usize, points: usize, seed: u64) {
    let mut rng = stream(seed, 0, "partition-derivatives");
    for case in 0..points {
        let kind = if case % 2 == 0 {
            MeasurementKind::Relative
        } else {
            MeasurementKind::Absolute
        };
        let mpf = MpfChain::<NBL, NY>::new(spec(n, false, kind, &mut rng)).unwrap();
        let p = random_point(n, &mut rng);
        let (xn, m) = mpf_state::<NBL>(&p);

        let psi = |mm: &SVector<f64, NBL>| mpf.sampled_dynamics(K, &xn, mm);
        let phi = |mm: &SVector<f64, NBL>| mpf.marginal_dynamics(K, &xn, mm);
        let obs = |mm: &SVector<f64, NBL>| mpf.observation(K, &xn, mm);

        // Jacobians.
        let err = rel_err(&psi(&m).1, &fd_jacobian(|mm| psi(mm).0, &m));
        assert!(err <= 1e-7, "N={n} case {case}: ψₙ Jacobian error {err}");
        let err = rel_err(&phi(&m).1, &fd_jacobian(|mm| phi(mm).0, &m));
        assert!(err <= 1e-7, "N={n} case {case}: φ_bl Jacobian error {err}");
        let err = rel_err(&obs(&m).1, &fd_jacobian(|mm| obs(mm).0, &m));
        assert!(
            err <= 1e-7,
            "N={n} case {case}: observation Jacobian error {err}"
        );

        // Hessians (a handful of points suffices: they are constant; the sweep is O(NBL²)).
        if case < 20 {
            check_hessians("ψₙ", |mm| psi(mm).0, mpf.sampled_hessians(), &m);
            check_hessians("φ_bl", |mm| phi(mm).0, mpf.marginal_hessians(), &m);
            check_hessians("y", |mm| obs(mm).0, mpf.observation_hessians(), &m);
        }

        // Exact bilinearity: the second-order Taylor expansion with the sparse Hessians
        // reproduces the map at a far-away point (δ of order one in every entry).
        let delta = SVector::<f64, NBL>::from_fn(|_, _| 2.0 * rng.random::<f64>() - 1.0);
        for (what, r) in [
            (
                "ψₙ",
                taylor_residual(psi, mpf.sampled_hessians(), &m, &delta),
            ),
            (
                "φ_bl",
                taylor_residual(phi, mpf.marginal_hessians(), &m, &delta),
            ),
            (
                "y",
                taylor_residual(obs, mpf.observation_hessians(), &m, &delta),
            ),
        ] {
            assert!(r <= 1e-12, "N={n} case {case}: {what} Taylor residual {r}");
        }
    }
}

#[test]
fn mpf_jacobians_and_hessians_match_finite_differences_n3() {
    check_mpf::<13, 3>(3, 200, 3);
}

#[test]
fn mpf_jacobians_and_hessians_match_finite_differences_n5() {
    check_mpf::<21, 5>(5, 100, 4);
}

#[test]
fn mpf_jacobians_and_hessians_match_finite_differences_n1() {
    check_mpf::<5, 1>(1, 50, 5);
}

/// The Taylor check can fail: dropping one observation Hessian entry leaves a residual of
/// order |δ_a δ_b| = 0.25.
#[test]
fn taylor_check_detects_a_missing_hessian_entry() {
    let mut rng = stream(6, 0, "partition-derivatives");
    let mpf = PaperMpf::new(spec(3, true, MeasurementKind::Relative, &mut rng)).unwrap();
    let p = random_point(3, &mut rng);
    let (xn, m) = mpf_state::<13>(&p);
    let mut truncated = SparseHessians::new();
    for e in &mpf.observation_hessians().entries()[1..] {
        truncated.push(e.output, e.a, e.b, e.value);
    }
    let delta = SVector::<f64, 13>::from_element(0.5);
    let r = taylor_residual(|mm| mpf.observation(K, &xn, mm), &truncated, &m, &delta);
    assert!(r > 1e-3, "residual {r} should expose the missing entry");
}

// ----------------------------------------------------------------------------------------------
// SPEC §6 for the paper's chain

#[test]
fn mpf_hessians_equal_spec_section_6_for_three_unit_storeys() {
    let mut rng = stream(7, 0, "partition-derivatives");
    let mpf = PaperMpf::new(spec(3, true, MeasurementKind::Relative, &mut rng)).unwrap();
    // x^bl index: 0 x1, 1 x2, 2 x3, 3 ẋ2, 4 ẋ3, 5 k1, 6 k2, 7 k3, 8 c1, 9 c2, 10 c3, 11 β, 12 γ.
    let (x1, x2, x3, v2, v3, k2, k3, c2, c3) = (0, 1, 2, 3, 4, 6, 7, 9, 10);
    let d = DT;
    // (output, a, b, value) exactly as listed in SPEC §6.
    let phi = [
        (3, k2, x1, d),
        (3, k2, x2, -d),
        (3, k3, x3, d),
        (3, k3, x2, -d),
        (3, c2, v2, -d),
        (3, c3, v3, d),
        (3, c3, v2, -d),
        (4, k3, x2, d),
        (4, k3, x3, -d),
        (4, c3, v2, d),
        (4, c3, v3, -d),
    ];
    let psi = [(0, k2, x2, d), (0, k2, x1, -d), (0, c2, v2, d)];
    let y = [
        (0, k2, x2, 1.0),
        (0, k2, x1, -1.0),
        (0, c2, v2, 1.0),
        (1, k2, x1, 1.0),
        (1, k2, x2, -1.0),
        (1, k3, x3, 1.0),
        (1, k3, x2, -1.0),
        (1, c2, v2, -1.0),
        (1, c3, v3, 1.0),
        (1, c3, v2, -1.0),
        (2, k3, x2, 1.0),
        (2, k3, x3, -1.0),
        (2, c3, v2, 1.0),
        (2, c3, v3, -1.0),
    ];
    let normalise = |h: &SparseHessians| {
        let mut v: Vec<(usize, usize, usize, f64)> = h
            .entries()
            .iter()
            .map(|e| (e.output, e.a.min(e.b), e.a.max(e.b), e.value))
            .collect();
        v.sort_by_key(|p| (p.0, p.1, p.2));
        v
    };
    let expected = |list: &[(usize, usize, usize, f64)]| {
        let mut h = SparseHessians::new();
        for &(o, a, b, v) in list {
            h.push(o, a, b, v);
        }
        normalise(&h)
    };
    assert_eq!(normalise(mpf.marginal_hessians()), expected(&phi));
    assert_eq!(normalise(mpf.sampled_hessians()), expected(&psi));
    assert_eq!(normalise(mpf.observation_hessians()), expected(&y));
}

// ----------------------------------------------------------------------------------------------
// Cross-consistency of the three partitions

fn check_consistency<
    const NX: usize,
    const NU: usize,
    const NZ: usize,
    const NL: usize,
    const NBL: usize,
    const NY: usize,
>(
    n: usize,
    seed: u64,
) {
    let mut rng = stream(seed, 0, "partition-consistency");
    for case in 0..100 {
        let kind = if case % 2 == 0 {
            MeasurementKind::Relative
        } else {
            MeasurementKind::Absolute
        };
        let s = spec(n, case % 3 == 0, kind, &mut rng);
        let aug = AugmentedChain::<NX, NY>::new(s.clone()).unwrap();
        let mln = MlnChain::<NU, NZ, NL, NY>::new(s.clone()).unwrap();
        let mpf = MpfChain::<NBL, NY>::new(s).unwrap();
        let p = random_point(n, &mut rng);
        let close = |a: f64, b: f64, what: &str| {
            assert!(
                (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                "N={n} case {case}: {what}: {a} vs {b}"
            );
        };

        // Augmented Euler step: the reference.
        let next = aug.propagate(K, &aug_state::<NX>(&p));
        let y_aug = aug.measure(K, &aug_state::<NX>(&p));

        // MLN: f + F z on the linked rows.
        let (u, z) = mln_state::<NU, NZ>(&p);
        let (f, fl) = mln.transition(K, &u);
        let fz = fl * z;
        let mut u_next = f;
        for (li, &row) in mln.linked_rows().iter().enumerate() {
            u_next[row] += fz[li];
        }
        for i in 0..2 * n + 1 {
            close(u_next[i], next[i], &format!("MLN state {i}"));
        }
        close(u_next[2 * n + 1], next[4 * n + 3], "MLN n");
        let (h, hm) = mln.observation(K, &u);
        let y_mln = h + hm * z;

        // MPF: ψₙ for (ẋ1, r1), φ_bl for the rest.
        let (xn, m) = mpf_state::<NBL>(&p);
        let (psi, _) = mpf.sampled_dynamics(K, &xn, &m);
        let (phi, _) = mpf.marginal_dynamics(K, &xn, &m);
        close(psi[0], next[n], "MPF v1");
        close(psi[1], next[2 * n], "MPF r1");
        for j in 0..n {
            close(phi[j], next[j], &format!("MPF x{}", j + 1));
        }
        for j in 1..n {
            close(phi[n + j - 1], next[n + j], &format!("MPF v{}", j + 1));
        }
        for i in 0..2 * n + 2 {
            close(phi[2 * n - 1 + i], p.theta[i], "MPF parameters unchanged");
        }
        let (y_mpf, _) = mpf.observation(K, &xn, &m);

        for i in 0..n {
            close(y_mln[i], y_aug[i], "MLN measurement");
            close(y_mpf[i], y_aug[i], "MPF measurement");
        }
    }
}

#[test]
fn partitions_agree_on_next_state_and_measurement_n3() {
    check_consistency::<16, 8, 8, 4, 13, 3>(3, 10);
}

#[test]
fn partitions_agree_on_next_state_and_measurement_n5() {
    check_consistency::<24, 12, 12, 6, 21, 5>(5, 11);
}

#[test]
fn partitions_agree_on_next_state_and_measurement_n1() {
    check_consistency::<8, 4, 4, 2, 5, 1>(1, 12);
}

/// The augmented map against the equations of SPEC §1 written out by hand (3 storeys, unit
/// masses), forward Euler with ü_g,meas(k−1) and relative measurements with ü_g,meas(k).
#[test]
fn augmented_chain_matches_spec_section_1_equations() {
    let mut rng = stream(13, 0, "partition-consistency");
    for _ in 0..100 {
        let s = spec(3, true, MeasurementKind::Relative, &mut rng);
        let (g_prev, g_now) = (s.ug[K - 1], s.ug[K]);
        let aug = AugmentedChain::<16, 3>::new(s).unwrap();
        let p = random_point(3, &mut rng);
        let [x1, x2, x3] = [p.x[0], p.x[1], p.x[2]];
        let [v1, v2, v3] = [p.v[0], p.v[1], p.v[2]];
        let r1 = p.r1;
        let t = &p.theta;
        let (k1, k2, k3, c1, c2, c3, beta, gamma, nn) =
            (t[0], t[1], t[2], t[3], t[4], t[5], t[6], t[7], t[8]);
        let acc = |g: f64| {
            [
                -g - k1 * r1 + k2 * (x2 - x1) - c1 * v1 + c2 * (v2 - v1),
                -g + k2 * (x1 - x2) + k3 * (x3 - x2) + c2 * (v1 - v2) + c3 * (v3 - v2),
                -g + k3 * (x2 - x3) + c3 * (v2 - v3),
            ]
        };
        let rdot =
            v1 - beta * v1.abs() * r1.abs().powf(nn - 1.0) * r1 - gamma * v1 * r1.abs().powf(nn);
        let a = acc(g_prev);
        let expected = [
            x1 + DT * v1,
            x2 + DT * v2,
            x3 + DT * v3,
            v1 + DT * a[0],
            v2 + DT * a[1],
            v3 + DT * a[2],
            r1 + DT * rdot,
        ];
        let xa = aug_state::<16>(&p);
        let next = aug.propagate(K, &xa);
        for i in 0..7 {
            assert!((next[i] - expected[i]).abs() <= 1e-12 * (1.0 + expected[i].abs()));
        }
        for i in 7..16 {
            assert_eq!(next[i], xa[i], "θ is static");
        }
        let y = aug.measure(K, &xa);
        let ye = acc(g_now);
        for i in 0..3 {
            assert!((y[i] - ye[i]).abs() <= 1e-12 * (1.0 + ye[i].abs()));
        }
    }
}

/// Masses divide the element forces: doubling every mass halves the net force per unit mass.
#[test]
fn masses_scale_the_accelerations() {
    let mut rng = stream(14, 0, "partition-consistency");
    let s1 = spec(3, true, MeasurementKind::Absolute, &mut rng);
    let mut s2 = s1.clone();
    s2.masses = vec![2.0; 3];
    let a1 = AugmentedChain::<16, 3>::new(s1).unwrap();
    let a2 = AugmentedChain::<16, 3>::new(s2).unwrap();
    let p = random_point(3, &mut rng);
    let xa = aug_state::<16>(&p);
    let (y1, y2) = (a1.measure(K, &xa), a2.measure(K, &xa));
    for i in 0..3 {
        assert!((y2[i] - 0.5 * y1[i]).abs() <= 1e-12 * (1.0 + y1[i].abs()));
        assert!(y1[i].abs() > 1e-3, "the check needs a non-zero force");
    }
}

// ----------------------------------------------------------------------------------------------
// The maps are called per particle per step: they must not allocate.

struct CountingAllocator;

thread_local! {
    static ALLOCATIONS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

// SAFETY: every call is forwarded unchanged to the system allocator; the counter is a
// thread-local `Cell` with a const initialiser, so counting itself never allocates.
unsafe impl std::alloc::GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: std::alloc::Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        unsafe { std::alloc::System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: std::alloc::Layout) {
        unsafe { std::alloc::System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

fn allocations() -> usize {
    ALLOCATIONS.with(|c| c.get())
}

#[test]
fn map_evaluations_do_not_allocate() {
    let mut rng = stream(15, 0, "partition-allocations");
    let s = spec(3, false, MeasurementKind::Relative, &mut rng);
    let aug = AugmentedChain::<16, 3>::new(s.clone()).unwrap();
    let mln = MlnChain::<8, 8, 4, 3>::new(s.clone()).unwrap();
    let mpf = PaperMpf::new(s).unwrap();
    let p = random_point(3, &mut rng);
    let xa = aug_state::<16>(&p);
    let (u, z) = mln_state::<8, 8>(&p);
    let (xn, m) = mpf_state::<13>(&p);
    let before = allocations();
    let mut sink = 0.0;
    for k in 1..=K {
        sink += aug.propagate(k, &xa).sum() + aug.measure(k, &xa).sum();
        sink += aug.process_noise_sd().sum() + aug.measurement_cov().sum();
        let (f, fl) = mln.transition(k, &u);
        let (h, hm) = mln.observation(k, &u);
        sink += f.sum() + fl.sum() + h.sum() + hm.sum();
        sink += mln.observation_jacobian_u(k, &u, &z).sum() + mln.process_noise_sd().sum();
        sink += mln.linked_rows().iter().sum::<usize>() as f64;
        let (a, ja) = mpf.sampled_dynamics(k, &xn, &m);
        let (b, jb) = mpf.marginal_dynamics(k, &xn, &m);
        let (c, jc) = mpf.observation(k, &xn, &m);
        sink += a.sum() + ja.sum() + b.sum() + jb.sum() + c.sum() + jc.sum();
        sink += mpf.sampled_hessians().entries().len() as f64;
        sink += mpf.sampled_noise_sd().sum() + mpf.marginal_noise_sd().sum();
    }
    let after = allocations();
    assert!(sink.is_finite());
    assert_eq!(
        after - before,
        0,
        "map evaluations allocated {} times",
        after - before
    );
    // The counter works: a Vec allocates.
    let v = std::hint::black_box(vec![1.0_f64; 4]);
    assert!(allocations() > after && v.len() == 4);
}
