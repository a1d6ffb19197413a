//! Properties of the discretisations (`docs/discretisation.md`) and the validation of the spec.
//!
//! - Symplectic Euler converges to the continuous solution at first order on a smooth chain
//!   (β = γ = 0, so the hysteretic variable follows the drift): the error at a fixed time halves
//!   with dt.
//! - On a single linear storey its per-step determinant is `1 − c·dt/m` (forward Euler:
//!   `1 − c·dt/m + k·dt²/m`), to round-off.
//! - Malformed specs get errors naming the field.

use crate::filtering_support;

use core_filters::rng::stream;
use core_filters::smc::model::{Partition, StateSpace};
use filtering_support::*;
use models::building::{Building, Damping};
use models::filtering::{
    AugmentedChain, ChainSpec, Discretisation, MlnChain, MpfChain, RmsLevels, SpecError,
    SPEC_R_NOISE_FRACTION,
};
use models::integrate::simulate_rk4;
use models::sensors::{MeasurementKind, SensorError, SensorLayout};
use models::structure::{BoucWen, ShearChain};

/// A smooth excitation (m/s²).
fn ground(t: f64) -> f64 {
    3.0 * (4.0 * t).sin() + 1.5 * (9.0 * t).sin()
}

fn chain_spec(
    masses: Vec<f64>,
    hysteretic: Vec<usize>,
    ug: Vec<f64>,
    dt: f64,
    disc: Discretisation,
) -> ChainSpec {
    let n = masses.len();
    let sensors = SensorLayout::all(n, MeasurementKind::Relative).unwrap();
    let rms = RmsLevels {
        acc: vec![1.0; n],
        ug: 1.0,
        drift_velocity: vec![0.5; hysteretic.len()],
    };
    let building = Building::new(masses, hysteretic, Damping::Storey).unwrap();
    let mut s = ChainSpec::from_rms(dt, building, sensors, ug, &rms, 0.1).unwrap();
    s.discretisation = disc;
    s
}

/// The noise-free state at `t_end` from rest, stepped by `disc` at `dt`.
fn run(theta: &[f64], dt: f64, t_end: f64, disc: Discretisation) -> Vec<f64> {
    let steps = (t_end / dt).round() as usize;
    let ug: Vec<f64> = (0..=steps).map(|k| ground(k as f64 * dt)).collect();
    let aug = AugmentedChain::new(chain_spec(vec![1.0, 1.2, 0.8], vec![0], ug, dt, disc)).unwrap();
    let d = aug.noise_dim();
    let mut x = vec![0.0; d];
    x.extend_from_slice(theta);
    let mut out = x.clone();
    let xi = vec![0.0; d];
    for k in 1..=steps {
        aug.propagate(k, &x, &xi, &mut out);
        std::mem::swap(&mut x, &mut out);
    }
    x.truncate(d);
    x
}

#[test]
fn symplectic_euler_converges_at_first_order_on_a_smooth_chain() {
    // k = 8, c = 0.25 per storey; one element with β = γ = 0, n = 1: ṙ = δv, a linear chain.
    let theta = [8.0, 8.0, 8.0, 0.25, 0.25, 0.25, 0.0, 0.0, 1.0];
    let t_end: f64 = 2.0;
    // Reference: RK4 at a step 64 times finer than the finest tested (error ~ dt⁴, negligible).
    let dt_ref: f64 = 0.0025 / 64.0;
    let steps = (t_end / dt_ref).round() as usize;
    let ug: Vec<f64> = (0..=steps).map(|k| ground(k as f64 * dt_ref)).collect();
    let chain = ShearChain::new(
        vec![1.0, 1.2, 0.8],
        vec![8.0; 3],
        vec![0.25; 3],
        vec![BoucWen {
            storey: 0,
            beta: 0.0,
            gamma: 0.0,
            n: 1.0,
        }],
    )
    .unwrap();
    let truth = simulate_rk4(&chain, &ug, dt_ref);
    let reference = truth.state(steps).to_vec();
    for disc in [Discretisation::Symplectic, Discretisation::Euler] {
        let errors: Vec<f64> = [0.01, 0.005, 0.0025]
            .iter()
            .map(|&dt| {
                let x = run(&theta, dt, t_end, disc);
                x.iter()
                    .zip(&reference)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max)
            })
            .collect();
        let ratios = [errors[0] / errors[1], errors[1] / errors[2]];
        eprintln!("{disc}: errors {errors:?}, ratios {ratios:?}");
        for r in ratios {
            assert!(
                (1.8..2.2).contains(&r),
                "{disc}: error ratio {r} is not ≈ 2 (first order)"
            );
        }
    }
}

#[test]
fn symplectic_step_has_determinant_one_minus_c_dt_over_m() {
    let (k, c, dt) = (8.0, 0.25, 0.005);
    for m in [1.0, 1.7] {
        for disc in [Discretisation::Symplectic, Discretisation::Euler] {
            let aug = AugmentedChain::new(chain_spec(vec![m], vec![], vec![0.3, -0.2], dt, disc))
                .unwrap();
            let map = |s: &[f64]| {
                let x = [s[0], s[1], k, c];
                let mut out = [0.0; 4];
                aug.propagate(1, &x, &[0.0, 0.0], &mut out);
                out[..2].to_vec()
            };
            // The map is affine in (x, v): a central difference is exact up to round-off.
            let (_, j) = fd_jacobian(&map, &[0.1, -0.4], 1e-2);
            let det = j[0] * j[3] - j[2] * j[1];
            let want = match disc {
                Discretisation::Symplectic => 1.0 - c * dt / m,
                _ => 1.0 - c * dt / m + k * dt * dt / m,
            };
            close(det, want, 1e-12, &format!("{disc} determinant, m = {m}"));
            if disc == Discretisation::Symplectic {
                // First-order agreement with the continuous contraction e^{−c dt/m}.
                assert!((det - (-c * dt / m).exp()).abs() < (c * dt / m).powi(2));
            }
        }
    }
}

#[track_caller]
fn names_field(err: impl std::fmt::Display, field: &str) {
    let msg = err.to_string();
    assert!(
        msg.contains(field),
        "message {msg:?} does not name {field:?}"
    );
}

#[test]
fn malformed_specs_get_errors_naming_the_field() {
    let case = &cases()[0];
    let good = spec(case, Discretisation::Euler);
    good.validate().unwrap();
    let check = |f: &dyn Fn(&mut ChainSpec), field: &str| {
        let mut s = good.clone();
        f(&mut s);
        let err = s.validate().expect_err(field);
        names_field(&err, field);
        // The partitions refuse it with the same error.
        assert_eq!(AugmentedChain::new(s.clone()).unwrap_err(), err);
        assert_eq!(MpfChain::new(s).unwrap_err(), err);
    };
    // The building is validated when built: it cannot reach a spec malformed.
    let masses = good.building.masses().to_vec();
    for (hysteretic, field) in [(vec![0, 7], "hysteretic"), (vec![3, 0], "hysteretic")] {
        let err = Building::new(masses.clone(), hysteretic, Damping::Storey).unwrap_err();
        names_field(SpecError::from(err), field);
    }
    let mut zero = masses.clone();
    zero[2] = 0.0;
    let err = Building::new(zero, vec![0, 3], Damping::Storey).unwrap_err();
    names_field(SpecError::from(err), "masses");
    // A building of another storey count than the sensor layout and the prior.
    check(
        &|s| s.building = Building::new(vec![1.0; 6], vec![0, 3], Damping::Storey).unwrap(),
        "masses",
    );
    check(&|s| s.q_r.pop().map(drop).unwrap_or(()), "q_r");
    check(&|s| s.r_diag.push(1.0), "r_diag");
    check(&|s| s.dt = -0.1, "dt");
    check(&|s| s.ug[3] = f64::NAN, "ug");
    check(&|s| s.q_vel = f64::INFINITY, "q_vel");
    check(
        &|s| s.prior.k[0] = models::priors::Prior::Fixed { value: -1.0 },
        "prior",
    );

    // Sensor layouts: storey 0, a storey listed twice, out of range, unsorted.
    let kind = MeasurementKind::Relative;
    for (storeys, want) in [
        (vec![0, 2], SensorError::StoreyZero),
        (vec![2, 2, 7], SensorError::Duplicate { storey: 2 }),
        (
            vec![2, 8],
            SensorError::OutOfRange {
                storey: 8,
                storeys: 7,
            },
        ),
        (
            vec![4, 2],
            SensorError::Unsorted {
                before: 4,
                after: 2,
            },
        ),
    ] {
        let err = SensorLayout::new(7, &storeys, kind).unwrap_err();
        assert_eq!(err, want);
        names_field(SpecError::from(err), "sensors");
    }
    // A layout made for another chain, and one read from a file with storey 0.
    let mut s = good.clone();
    s.sensors = SensorLayout::new(5, &[1, 2], kind).unwrap();
    names_field(s.validate().unwrap_err(), "masses");
    let json = serde_json::to_string(&good)
        .unwrap()
        .replace(r#""storeys":[2,4,7]"#, r#""storeys":[0,4,7]"#);
    names_field(
        serde_json::from_str::<ChainSpec>(&json).unwrap_err(),
        "sensors",
    );
    let back: ChainSpec = serde_json::from_str(&serde_json::to_string(&good).unwrap()).unwrap();
    assert_eq!(back, good);

    // RMS values of the wrong length, and RK4 for the marginalised partitions.
    let rms = RmsLevels {
        acc: vec![1.0; 2],
        ug: 1.0,
        drift_velocity: vec![0.5; 2],
    };
    let err = ChainSpec::from_rms(
        DT,
        good.building.clone(),
        good.sensors.clone(),
        good.ug.clone(),
        &rms,
        0.1,
    )
    .unwrap_err();
    names_field(err, "rms.acc");
    let mut s = good.clone();
    s.discretisation = Discretisation::Rk4;
    names_field(MlnChain::new(s.clone()).unwrap_err(), "discretisation");
    names_field(MpfChain::new(s.clone()).unwrap_err(), "discretisation");
    AugmentedChain::new(s).unwrap();
}

#[test]
fn from_rms_follows_spec_section_3_for_both_measurement_kinds() {
    let rms = RmsLevels {
        acc: vec![2.0, 3.0],
        ug: 5.0,
        drift_velocity: vec![0.6],
    };
    for kind in [MeasurementKind::Relative, MeasurementKind::Absolute] {
        let sensors = SensorLayout::new(4, &[1, 3], kind).unwrap();
        let s = ChainSpec::from_rms(
            0.005,
            Building::new(vec![1.0; 4], vec![2], Damping::Storey).unwrap(),
            sensors,
            vec![0.0; 5],
            &rms,
            0.1,
        )
        .unwrap();
        assert_eq!(s.q_disp, 1e-6);
        close(s.q_vel, 0.005 * 0.1 * 5.0, 1e-15, "q_vel");
        close(s.q_r[0], 0.005 * 0.05 * 0.6, 1e-15, "q_r");
        // The process noise of r as another fraction: the SPEC's leaves it bit for bit, a tenth
        // scales it by a tenth, a non-positive or non-finite fraction is refused by name.
        let mut t = s.clone();
        t.set_r_noise_fraction(SPEC_R_NOISE_FRACTION).unwrap();
        assert_eq!(t.q_r[0].to_bits(), s.q_r[0].to_bits());
        t.set_r_noise_fraction(0.005).unwrap();
        close(t.q_r[0], 0.005 * 0.005 * 0.6, 1e-16, "q_r at 0.005");
        for bad in [0.0, -0.05, f64::NAN, f64::INFINITY] {
            names_field(t.set_r_noise_fraction(bad).unwrap_err(), "r_noise_fraction");
        }
        let excitation = if kind == MeasurementKind::Relative {
            0.25
        } else {
            0.0
        };
        close(s.r_diag[0], 0.04 + excitation, 1e-14, "R_11");
        close(s.r_diag[1], 0.09 + excitation, 1e-14, "R_22");
        assert_eq!(s.prior.names()[8..], ["beta", "gamma", "n"]);
        let mut rng = stream(1, 0, "t");
        let aug = AugmentedChain::new(s).unwrap();
        let mut x = vec![1.0; aug.dim()];
        aug.sample_initial(&mut rng, &mut x);
        assert!(x[..9].iter().all(|&v| v == 0.0) && x[9..].iter().all(|v| v.is_finite()));
    }
}

#[test]
fn marginal_priors_follow_spec_section_3_for_every_partition() {
    use core_filters::smc::model::{ConditionallyLinear, ConditionallyQuadratic, Marginalised};
    use models::filtering::MarginalPrior;
    let case = &cases()[0];
    let mut s = spec(case, Discretisation::Euler);
    s.prior.fix("k3", 8.0).unwrap();
    let (mean, var) = s.prior.moments();
    let mut rng = stream(5, 0, "priors");
    for per_particle in [false, true] {
        if per_particle {
            s.marginal_prior = MarginalPrior::PerParticle { rel_sd: 0.1 };
        }
        let mln = MlnChain::new(s.clone()).unwrap();
        let mpf = MpfChain::new(s.clone()).unwrap();
        // θ index of every marginal entry, from the layouts.
        for (layout, nm, which) in [
            (mln.layout(), mln.dims().nz, "mln"),
            (mpf.layout(), mpf.dims().nbl, "mpf"),
        ] {
            let mut mu = vec![0.0; nm];
            let mut cov = vec![0.0; nm * nm];
            if which == "mln" {
                mln.marginal_prior(&mut rng, &mut mu, &mut cov);
            } else {
                mpf.marginal_prior(&mut rng, &mut mu, &mut cov);
            }
            let mut is_param = vec![false; nm];
            for (t, slot) in layout.params.iter().enumerate() {
                if let core_filters::model::Slot::Marginal(i) = *slot {
                    is_param[i] = true;
                    let v = cov[i + i * nm];
                    if per_particle {
                        let want = if var[t] > 0.0 {
                            (0.1 * mu[i]).powi(2)
                        } else {
                            0.0
                        };
                        close(v, want, 1e-15, &format!("{which} per-particle var {t}"));
                    } else {
                        assert_eq!((mu[i], v), (mean[t], var[t]), "{which} θ {t}");
                    }
                }
            }
            // States start exactly at zero; the covariance is diagonal.
            for i in 0..nm {
                if !is_param[i] {
                    assert_eq!((mu[i], cov[i + i * nm]), (0.0, 0.0), "{which} state {i}");
                }
                for j in 0..nm {
                    if i != j {
                        assert_eq!(cov[i + j * nm], 0.0);
                    }
                }
            }
            let core_filters::model::Slot::Marginal(k3) = layout.params[2] else {
                panic!("k3 is marginal")
            };
            assert_eq!((mu[k3], cov[k3 + k3 * nm]), (8.0, 0.0), "{which}: k3 fixed");
        }
        let mut u = vec![1.0; mln.dims().nu];
        mln.sample_initial(&mut rng, &mut u);
        assert!(
            u[..16].iter().all(|&v| v == 0.0) && u[16..].iter().all(|v| (1.0..5.0).contains(v))
        );
        let mut xn = vec![1.0; mpf.dims().nn];
        mpf.sample_initial(&mut rng, &mut xn);
        assert!(
            xn[..5].iter().all(|&v| v == 0.0) && xn[5..].iter().all(|v| (1.0..5.0).contains(v))
        );
    }
}

/// `substeps = M`: one transition of the augmented chain is M steps of the same chain on a grid
/// M times finer (`dt/M`, ü_g linear between samples, process-noise s.d. over √M), each with its
/// own slice of the draws, and the measurement at sample k is the fine chain's at index kM — for
/// every scheme. The other partitions refuse what they do not support, naming the field.
#[test]
fn substeps_are_the_same_chain_on_a_finer_grid() {
    let (dt, m, steps) = (0.01, 4usize, 30usize);
    let ug: Vec<f64> = (0..=steps).map(|k| ground(k as f64 * dt)).collect();
    let fine_ug: Vec<f64> = (0..=steps * m)
        .map(|kf| {
            let (k, s) = (kf / m, kf % m);
            match s {
                0 => ug[k],
                _ => ug[k] + (ug[k + 1] - ug[k]) * (s as f64 / m as f64),
            }
        })
        .collect();
    let theta = [8.0, 9.0, 7.0, 0.25, 0.3, 0.2, 2.0, 1.0, 2.0];
    for disc in [
        Discretisation::Euler,
        Discretisation::Symplectic,
        Discretisation::Rk4,
    ] {
        let mut coarse = chain_spec(vec![1.0, 1.2, 0.8], vec![0], ug.clone(), dt, disc);
        coarse.substeps = m;
        let mut fine = chain_spec(
            vec![1.0, 1.2, 0.8],
            vec![0],
            fine_ug.clone(),
            dt / m as f64,
            disc,
        );
        let root = (m as f64).sqrt();
        fine.q_disp = coarse.q_disp / root;
        fine.q_vel = coarse.q_vel / root;
        fine.q_r = coarse.q_r.iter().map(|q| q / root).collect();
        let (c, f) = (
            AugmentedChain::new(coarse).unwrap(),
            AugmentedChain::new(fine).unwrap(),
        );
        let d = f.noise_dim();
        assert_eq!(c.noise_dim(), m * d, "{disc:?}");
        let mut rng = stream(3, 0, "substeps");
        let mut x = vec![0.0; d];
        x.extend_from_slice(&theta);
        let mut xf = x.clone();
        let (mut out, mut tmp) = (x.clone(), x.clone());
        let (mut yc, mut yf) = (vec![0.0; 3], vec![0.0; 3]);
        for k in 1..=steps {
            let xi: Vec<f64> = (0..m * d)
                .map(|_| {
                    rand_distr::Distribution::<f64>::sample(&rand_distr::StandardNormal, &mut rng)
                })
                .collect();
            c.propagate(k, &x, &xi, &mut out);
            std::mem::swap(&mut x, &mut out);
            for s in 0..m {
                f.propagate((k - 1) * m + s + 1, &xf, &xi[s * d..(s + 1) * d], &mut tmp);
                std::mem::swap(&mut xf, &mut tmp);
            }
            c.measure(k, &x, &mut yc);
            f.measure(k * m, &xf, &mut yf);
            for (i, (a, b)) in x.iter().zip(&xf).chain(yc.iter().zip(&yf)).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-12 * (1.0 + b.abs()),
                    "{disc:?} k={k} entry {i}: {a} vs {b}"
                );
            }
        }
        assert!(
            x[..d].iter().any(|v| v.abs() > 1e-3),
            "{disc:?}: the chain moved"
        );
    }
    // The MLN-RBPF/Storvik partition has one transition per sample; out-of-range counts are
    // refused by every partition.
    let mut spec = chain_spec(
        vec![1.0; 3],
        vec![0],
        ug.clone(),
        dt,
        Discretisation::Symplectic,
    );
    spec.substeps = 2;
    assert!(MpfChain::new(spec.clone()).is_ok());
    let e = MlnChain::new(spec.clone()).unwrap_err();
    assert!(matches!(e, SpecError::SubstepsUnsupported { .. }), "{e}");
    assert!(e.to_string().contains("substeps"), "{e}");
    for bad in [0, models::filtering::MAX_SUBSTEPS + 1] {
        spec.substeps = bad;
        let e = AugmentedChain::new(spec.clone()).unwrap_err();
        assert!(
            matches!(
                e,
                SpecError::Invalid {
                    field: "substeps",
                    ..
                }
            ),
            "{bad}: {e}"
        );
    }
}
