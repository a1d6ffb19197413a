//! The four particle filters of `core_filters::smc` on the general shear chain at run-time
//! dimensions (issue "any building"): every algorithm for several storey counts and sparse
//! sensors, a 40-storey run inside a thread-pool worker, and the exactness of the marginalised
//! blocks on the chain (the MLN-RBPF's Gaussian is the Kalman filter of the parameters given its
//! sampled path; the MPF-EKF2 is the Kalman filter of a linear chain).

use core_filters::rng::stream;
use core_filters::smc::bootstrap::BootstrapPf;
use core_filters::smc::mlnrbpf::MlnRbpf;
use core_filters::smc::model::{ConditionallyLinear, Marginalised};
use core_filters::smc::mpf::MpfEkf2;
use core_filters::smc::storvik::{Storvik, StorvikUpdate};
use core_filters::smc::{run, Filter, Observer, Posterior, SmcConfig, StepInfo};
use models::building::{Building, Damping};
use models::filtering::{
    AugmentedChain, ChainSpec, ColouredNoise, Discretisation, MlnChain, MpfChain, Regressors,
    RmsLevels,
};
use models::ground_motions::el_centro;
use models::integrate::simulate_rk4;
use models::sensors::{MeasurementKind, SensorLayout};
use models::structure::{BoucWen, ShearChain};
use nalgebra::{DMatrix, DVector};
use rand_distr::{Distribution, StandardNormal};

/// A data set on the chain: k = 8, c = 0.25, unit masses, Bouc–Wen (β 2, γ 1, n 2) at the
/// 0-based `hysteretic` storeys, El Centro × 3 for `seconds`, relative accelerations at the
/// 1-based `sensors` with 10% noise. Returns the spec (SPEC §3 noise from the clean RMS) and `y`.
fn chain_data(
    n: usize,
    hysteretic: &[usize],
    sensors: &[usize],
    seconds: f64,
    discretisation: Discretisation,
) -> (ChainSpec, Vec<f64>) {
    let dt = 0.005;
    let ug = el_centro()
        .scaled(3.0)
        .resample_linear(dt)
        .truncated(seconds)
        .acc;
    let bw = hysteretic
        .iter()
        .map(|&s| BoucWen {
            storey: s,
            beta: 2.0,
            gamma: 1.0,
            n: 2.0,
        })
        .collect();
    let chain = ShearChain::new(vec![1.0; n], vec![8.0; n], vec![0.25; n], bw).unwrap();
    let traj = simulate_rk4(&chain, &ug, dt);
    let layout = SensorLayout::new(n, sensors, MeasurementKind::Relative).unwrap();
    let mut acc = vec![0.0; n];
    let mut clean = Vec::new();
    for (k, &u) in ug.iter().enumerate() {
        chain.relative_accelerations(traj.state(k), u, &mut acc);
        clean.push(
            layout
                .storeys()
                .iter()
                .map(|&j| acc[j])
                .collect::<Vec<f64>>(),
        );
    }
    let rms = |v: &mut dyn Iterator<Item = f64>| {
        let (s, c) = v.fold((0.0, 0usize), |(s, c), x| (s + x * x, c + 1));
        (s / c as f64).sqrt()
    };
    let acc_rms: Vec<f64> = (0..sensors.len())
        .map(|i| rms(&mut clean.iter().map(|r| r[i])))
        .collect();
    let ug_rms = rms(&mut ug.iter().copied());
    let drift: Vec<f64> = hysteretic
        .iter()
        .map(|&s| {
            rms(&mut (0..ug.len()).map(|k| {
                let st = traj.state(k);
                st[n + s] - if s == 0 { 0.0 } else { st[n + s - 1] }
            }))
        })
        .collect();
    let mut rng = stream(11, 0, "test-data");
    let mut noisy = |x: f64, sd: f64| {
        let e: f64 = StandardNormal.sample(&mut rng);
        x + sd * e
    };
    let ug_meas: Vec<f64> = ug.iter().map(|&u| noisy(u, 0.1 * ug_rms)).collect();
    let mut y = Vec::new();
    for row in clean.iter().skip(1) {
        for (i, a) in row.iter().enumerate() {
            y.push(noisy(*a, 0.1 * acc_rms[i]));
        }
    }
    let rms = RmsLevels {
        acc: acc_rms,
        ug: ug_rms,
        drift_velocity: drift,
    };
    let building = Building::new(vec![1.0; n], hysteretic.to_vec(), Damping::Storey).unwrap();
    let mut spec = ChainSpec::from_rms(dt, building, layout, ug_meas, &rms, 0.1).unwrap();
    spec.discretisation = discretisation;
    (spec, y)
}

fn config(np: usize) -> SmcConfig {
    SmcConfig {
        particles: np,
        resampling: Default::default(),
        rejuvenation: None,
    }
}

#[derive(Default)]
struct Last(Vec<f64>, usize);
impl Observer for Last {
    fn on_step(&mut self, _info: &StepInfo, p: &Posterior) {
        self.0 = p.param_mean.clone();
        self.1 += 1;
    }
}

fn filters(spec: &ChainSpec) -> Vec<Box<dyn Filter>> {
    let mut out: Vec<Box<dyn Filter>> = vec![
        Box::new(MlnRbpf::new(MlnChain::new(spec.clone()).unwrap())),
        Box::new(Storvik::new(
            MlnChain::new(spec.clone()).unwrap(),
            StorvikUpdate::Linearised,
        )),
        Box::new(Storvik::new(
            MlnChain::new(spec.clone()).unwrap(),
            StorvikUpdate::Exact,
        )),
        Box::new(MpfEkf2::new(MpfChain::new(spec.clone()).unwrap())),
    ];
    if let Ok(aug) = AugmentedChain::new(spec.clone()) {
        out.push(Box::new(BootstrapPf::new(aug)));
    }
    out
}

#[test]
fn every_algorithm_runs_for_one_four_and_ten_storeys_with_sparse_sensors() {
    let cases: [(usize, &[usize], &[usize]); 3] = [
        (1, &[0], &[1]),
        (4, &[0, 2], &[2, 4]),
        (10, &[0, 5], &[1, 3, 6, 10]),
    ];
    for (n, hyst, sensors) in cases {
        for disc in [Discretisation::Euler, Discretisation::Symplectic] {
            let (spec, y) = chain_data(n, hyst, sensors, 1.0, disc);
            for mut f in filters(&spec) {
                let mut last = Last::default();
                let s = run(
                    f.as_mut(),
                    &config(40),
                    &y,
                    sensors.len(),
                    &mut stream(3, n as u64, "chain"),
                    &mut last,
                );
                assert!(
                    s.failure.is_none(),
                    "{} N={n} {disc:?}: {:?}",
                    f.name(),
                    s.failure
                );
                assert_eq!(last.1, y.len() / sensors.len());
                assert!(last.0.iter().all(|v| v.is_finite()), "{} N={n}", f.name());
                assert_eq!(last.0.len(), 2 * n + 3 * hyst.len());
            }
        }
    }
}

#[test]
fn forty_storeys_run_inside_a_thread_pool_worker() {
    let sensors: Vec<usize> = (1..=40).collect();
    let (spec, y) = chain_data(40, &[0], &sensors, 0.03, Discretisation::Euler);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let done = pool.install(|| {
        let mut out = Vec::new();
        for mut f in [
            Box::new(MlnRbpf::new(MlnChain::new(spec.clone()).unwrap())) as Box<dyn Filter>,
            Box::new(MpfEkf2::new(MpfChain::new(spec.clone()).unwrap())),
        ] {
            let mut last = Last::default();
            let s = run(
                f.as_mut(),
                &config(8),
                &y,
                40,
                &mut stream(1, 0, "40"),
                &mut last,
            );
            out.push((f.name(), s.failure.is_none(), last.1));
        }
        out
    });
    for (name, ok, steps) in done {
        assert!(ok, "{name}");
        assert_eq!(steps, y.len() / 40, "{name}");
    }
}

/// Keeps every step's posterior (one particle: the particle itself).
#[derive(Default)]
struct Steps(Vec<(Posterior, StepInfo)>);
impl Observer for Steps {
    fn on_step(&mut self, info: &StepInfo, p: &Posterior) {
        self.0.push((p.clone(), *info));
    }
}

/// With one particle, the MLN-RBPF's Gaussian over z is the Kalman filter of the static z whose
/// measurements are the particle's own linked rows (through F) and y (through H), for forward
/// and symplectic Euler, on a 10-storey chain with two hysteretic storeys and four sensors.
#[test]
fn mln_rbpf_gaussian_is_the_kalman_filter_of_z_given_its_path() {
    for disc in [Discretisation::Euler, Discretisation::Symplectic] {
        let sensors = [2, 4, 7, 10];
        let (spec, y) = chain_data(10, &[0, 4], &sensors, 0.5, disc);
        let model = MlnChain::new(spec.clone()).unwrap();
        let dims = model.dims();
        let mut steps = Steps::default();
        let mut f = MlnRbpf::new(model.clone());
        let s = run(
            &mut f,
            &config(1),
            &y,
            4,
            &mut stream(2, 0, "path"),
            &mut steps,
        );
        assert!(s.failure.is_none());
        // Reassemble the particle's path u_k = [x, v, r, n] from the one-particle posterior.
        let layout = f.layout().clone();
        let n_idx: Vec<usize> = layout
            .param_names
            .iter()
            .enumerate()
            .filter(|(_, n)| n.starts_with('n'))
            .map(|(i, _)| i)
            .collect();
        let path: Vec<Vec<f64>> = steps
            .0
            .iter()
            .map(|(p, _)| {
                let mut u = p.state_mean.clone();
                u.extend(n_idx.iter().map(|&i| p.param_mean[i]));
                u
            })
            .collect();
        assert_eq!(path[0].len(), dims.nu);
        // The Kalman filter of z on that path, from the model's own maps.
        let nz = dims.nz;
        let mut mean = vec![0.0; nz];
        let mut cov = vec![0.0; nz * nz];
        model.marginal_prior(&mut stream(0, 0, "unused"), &mut mean, &mut cov);
        let mut m = DVector::from_vec(mean);
        let mut p = DMatrix::from_vec(nz, nz, cov);
        let r = DMatrix::from_vec(
            4,
            4,
            spec.r_diag
                .iter()
                .enumerate()
                .fold(vec![0.0; 16], |mut a, (i, v)| {
                    a[i + 4 * i] = *v;
                    a
                }),
        );
        let sd = model.process_noise_sd().to_vec();
        let mut u_prev = vec![0.0; dims.nu];
        // u_0: the prior's x, v, r are zero; n is the particle's own (static).
        let n_first = &path[0][dims.nu - n_idx.len()..];
        u_prev[dims.nu - n_idx.len()..].copy_from_slice(n_first);
        let update = |m: &mut DVector<f64>,
                      p: &mut DMatrix<f64>,
                      j: &DMatrix<f64>,
                      resid: &DVector<f64>,
                      s_add: &DMatrix<f64>|
         -> f64 {
            let s = j * &*p * j.transpose() + s_add;
            let chol = s.clone().cholesky().expect("SPD");
            let k = &*p * j.transpose() * chol.inverse();
            *m += &k * resid;
            *p = &*p - &k * &s * k.transpose();
            let q = resid.len() as f64;
            -0.5 * (resid.transpose() * chol.solve(resid))[0]
                - 0.5 * s.determinant().ln()
                - 0.5 * q * (2.0 * std::f64::consts::PI).ln()
        };
        for (kk, u_k) in path.iter().enumerate() {
            let k = kk + 1;
            for (st, stage) in model.stages().iter().enumerate() {
                let mut fv = vec![0.0; dims.nu];
                let mut fm = core_filters::linalg::Sparse::<f64>::recording(stage.linked.len(), nz);
                fm.evaluate(|j| model.transition(st, k, &u_prev, u_k, &mut fv, j));
                let fd = DMatrix::from_vec(stage.linked.len(), nz, fm.to_dense());
                let resid = DVector::from_iterator(
                    stage.linked.len(),
                    stage.linked.iter().map(|&row| {
                        let pos = stage.rows.iter().position(|r| *r == row).unwrap();
                        u_k[row] - fv[pos]
                    }),
                ) - &fd * &m;
                let q_l = DMatrix::from_diagonal(&DVector::from_iterator(
                    stage.linked.len(),
                    stage.linked.iter().map(|&row| sd[row] * sd[row]),
                ));
                update(&mut m, &mut p, &fd, &resid, &q_l);
            }
            let mut h = vec![0.0; 4];
            let mut hm = core_filters::linalg::Sparse::<f64>::recording(4, nz);
            hm.evaluate(|j| model.observation(k, u_k, &mut h, j));
            let hd = DMatrix::from_vec(4, nz, hm.to_dense());
            let resid = DVector::from_iterator(4, (0..4).map(|j| y[kk * 4 + j] - h[j])) - &hd * &m;
            let ll = update(&mut m, &mut p, &hd, &resid, &r);
            let (post, info) = &steps.0[kk];
            assert!(
                (info.loglik_increment - ll).abs() < 1e-7 * ll.abs().max(1.0),
                "{disc:?} k={k}: {} vs {ll}",
                info.loglik_increment
            );
            // z's slots: every parameter except the n's.
            let mut zi = 0;
            for (j, name) in layout.param_names.iter().enumerate() {
                if name.starts_with('n') {
                    continue;
                }
                let (fm, fsd) = (post.param_mean[j], post.param_sd[j]);
                let (km, ksd) = (m[zi], p[(zi, zi)].max(0.0).sqrt());
                assert!(
                    (fm - km).abs() < 1e-7 * (1.0 + km.abs()),
                    "{disc:?} k={k} {name}: {fm} vs {km}"
                );
                assert!(
                    (fsd - ksd).abs() < 1e-6 * (1.0 + ksd),
                    "{disc:?} k={k} {name} sd: {fsd} vs {ksd}"
                );
                zi += 1;
            }
            u_prev = u_k.clone();
        }
    }
}

/// Without hysteresis and with every stiffness and damping fixed, the chain is linear-Gaussian in
/// its states: the MPF-EKF2 (nothing sampled; all states marginalised) is the Kalman filter of
/// the states, built here from the equations of motion (SPEC §3), on a 10-storey chain with four
/// sensors — for forward and semi-implicit Euler, with one transition per sample and with three
/// (`substeps`: the Kalman filter predicts three times with dt/3, ü_g interpolated linearly and a
/// third of the process-noise variance, then updates once) — and with the storey+mass damping
/// form, α fixed: `C` gains `αM` (unit masses here). With coloured measurement noise the Kalman
/// filter's state gains one AR(1) state per sensor (`e ← a e + w`, a = ρ^(1/M) per transition,
/// Var w = (1 − a²)·share·r, started at its stationary variance), added to its channel, and the
/// white part is (1 − share)·r. With regressors the state gains their coefficients (static, their
/// prior's variance at the start) and each channel's row of the observation matrix the columns'
/// values at the sample.
#[test]
fn mpf_ekf2_is_the_kalman_filter_of_a_linear_chain() {
    for disc in [Discretisation::Euler, Discretisation::Symplectic] {
        for substeps in [1, 3] {
            mpf_ekf2_against_kalman(disc, substeps, None, None, false);
        }
        mpf_ekf2_against_kalman(disc, 1, Some(0.7), None, false);
        let colour = ColouredNoise {
            rho: 0.9,
            share: 0.6,
        };
        mpf_ekf2_against_kalman(disc, 1, None, Some(colour), false);
        mpf_ekf2_against_kalman(disc, 3, Some(0.7), Some(colour), true);
        mpf_ekf2_against_kalman(disc, 1, None, None, true);
    }
}

/// A, Q, C, b and P of a Kalman filter, to grow together.
type KalmanMatrices<'a> = (
    &'a mut DMatrix<f64>,
    &'a mut DMatrix<f64>,
    &'a mut DMatrix<f64>,
    &'a mut DVector<f64>,
    &'a mut DMatrix<f64>,
);

fn mpf_ekf2_against_kalman(
    disc: Discretisation,
    substeps: usize,
    alpha: Option<f64>,
    colour: Option<ColouredNoise>,
    regress: bool,
) {
    let n = 10;
    let sensors = [1, 4, 8, 10];
    let (mut spec, y) = chain_data(n, &[], &sensors, 0.5, disc);
    spec.substeps = substeps;
    spec.coloured_noise = colour;
    if regress {
        // Two known signals, each channel with its own coefficients (prior s.d. 0.3, 0.1).
        let len = spec.ug.len();
        let columns = vec![
            (0..len).map(|k| (0.13 * k as f64).sin()).collect(),
            (0..len).map(|k| (0.041 * k as f64).cos() * 2.0).collect(),
        ];
        spec.regressors = Some(Regressors {
            columns,
            prior_sd: [0.3, 0.1].repeat(4),
        });
    }
    if colour.is_some() || regress {
        // Only the MPF-EKF2 has a Gaussian part to carry the coloured noise or coefficients.
        for err in [
            AugmentedChain::new(spec.clone()).err(),
            MlnChain::new(spec.clone()).err(),
        ] {
            let msg = err.expect("refused").to_string();
            let field = if colour.is_some() {
                "coloured_noise"
            } else {
                "regressors"
            };
            assert!(msg.contains(field) && msg.contains("MPF-EKF2"), "{msg}");
        }
    }
    if let Some(a) = alpha {
        spec.building = spec.building.with_damping(Damping::StoreyMass);
        spec.prior.alpha = Some(models::priors::Prior::Fixed { value: a });
    }
    for j in 1..=n {
        spec.prior.fix(&format!("k{j}"), 8.0).unwrap();
        spec.prior.fix(&format!("c{j}"), 0.25).unwrap();
    }
    let mut f = MpfEkf2::new(MpfChain::new(spec.clone()).unwrap());
    let mut steps = Steps::default();
    let s = run(
        &mut f,
        &config(1),
        &y,
        4,
        &mut stream(4, 0, "lin"),
        &mut steps,
    );
    assert!(s.failure.is_none());
    // x_k = A x_{k−1} + b ü_g(k−1) + w, y_k = C x_k + d ü_g(k) + η, x = [x1..xN, v1..vN], on the
    // grid of step h = dt/M.
    let m_sub = substeps as f64;
    let h = spec.dt / m_sub;
    let mut kmat = DMatrix::<f64>::zeros(n, n);
    let mut cmat = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        // Element j links storey j−1 (or the ground) to storey j.
        for (mat, v) in [(&mut kmat, 8.0), (&mut cmat, 0.25)] {
            mat[(j, j)] += v;
            if j > 0 {
                mat[(j - 1, j - 1)] += v;
                mat[(j, j - 1)] -= v;
                mat[(j - 1, j)] -= v;
            }
        }
        cmat[(j, j)] += alpha.unwrap_or(0.0);
    }
    let mut acc = DMatrix::<f64>::zeros(n, 2 * n);
    acc.view_mut((0, 0), (n, n)).copy_from(&(-&kmat));
    acc.view_mut((0, n), (n, n)).copy_from(&(-&cmat));
    // Velocity rows: v' = v + h (acc·x − ü_g) + w_v.
    let mut vrows = acc.clone() * h;
    for j in 0..n {
        vrows[(j, n + j)] += 1.0;
    }
    let mut a = DMatrix::<f64>::identity(2 * n, 2 * n);
    a.view_mut((n, 0), (n, 2 * n)).copy_from(&vrows);
    // Ground input of one step, per unit ü_g.
    let mut b = DVector::<f64>::zeros(2 * n);
    let (qd, qv) = (spec.q_disp.powi(2) / m_sub, spec.q_vel.powi(2) / m_sub);
    let mut q = DMatrix::<f64>::zeros(2 * n, 2 * n);
    for j in 0..n {
        b[n + j] = -h;
        q[(j, j)] = qd;
        q[(n + j, n + j)] = qv;
    }
    match disc {
        Discretisation::Euler => {
            for j in 0..n {
                a[(j, n + j)] += h;
            }
        }
        _ => {
            // x' = x + h v' (the new velocity, its noise included).
            let mut xr = DMatrix::<f64>::identity(n, 2 * n);
            xr += &vrows * h;
            a.view_mut((0, 0), (n, 2 * n)).copy_from(&xr);
            for j in 0..n {
                b[j] = -h * h;
                q[(j, j)] = qd + h * h * qv;
                q[(j, n + j)] = h * qv;
                q[(n + j, j)] = h * qv;
            }
        }
    }
    let fine = |kf: usize| {
        let (k0, s) = (kf / substeps, kf % substeps);
        if s == 0 {
            spec.ug[k0]
        } else {
            spec.ug[k0] + (spec.ug[k0 + 1] - spec.ug[k0]) * s as f64 / m_sub
        }
    };
    let mut c = DMatrix::from_fn(4, 2 * n, |i, jj| acc[(sensors[i] - 1, jj)]);
    let mut r = DMatrix::from_diagonal(&DVector::from_vec(spec.r_diag.clone()));
    let mut p = DMatrix::<f64>::zeros(2 * n, 2 * n);
    // Appends `extra` zero states to the Kalman filter's matrices.
    let grow = |(a, q, c, b, p): KalmanMatrices<'_>, extra: usize| {
        let d = a.nrows() + extra;
        let padded = |old: &DMatrix<f64>, rows: usize| {
            let mut g = DMatrix::<f64>::zeros(rows, d);
            g.view_mut((0, 0), old.shape()).copy_from(old);
            g
        };
        *a = padded(a, d);
        *q = padded(q, d);
        *c = padded(c, 4);
        *p = padded(p, d);
        *b = b.clone().resize_vertically(d, 0.0);
    };
    if let Some(col) = colour {
        // x = [x, v, e1..e4].
        let ar = col.rho.powf(1.0 / m_sub);
        grow((&mut a, &mut q, &mut c, &mut b, &mut p), 4);
        for i in 0..4 {
            let var = col.share * spec.r_diag[i];
            a[(2 * n + i, 2 * n + i)] = ar;
            q[(2 * n + i, 2 * n + i)] = (1.0 - ar * ar) * var;
            c[(i, 2 * n + i)] = 1.0;
            p[(2 * n + i, 2 * n + i)] = var;
        }
        r *= 1.0 - col.share;
    }
    // x = [.., β (channel-major: 4 channels × 2 columns)].
    let reg = spec.regressors.clone();
    if let Some(rg) = &reg {
        let d0 = a.nrows();
        grow((&mut a, &mut q, &mut c, &mut b, &mut p), 8);
        for j in 0..8 {
            a[(d0 + j, d0 + j)] = 1.0;
            p[(d0 + j, d0 + j)] = rg.prior_sd[j] * rg.prior_sd[j];
        }
    }
    let beta0 = a.nrows() - if reg.is_some() { 8 } else { 0 };
    let observation_at = |k: usize| {
        let mut ck = c.clone();
        if let Some(rg) = &reg {
            for i in 0..4 {
                for (col, values) in rg.columns.iter().enumerate() {
                    ck[(i, beta0 + 2 * i + col)] = values[k];
                }
            }
        }
        ck
    };
    let mut m = DVector::<f64>::zeros(a.nrows());
    for (kk, (post, info)) in steps.0.iter().enumerate() {
        let k = kk + 1;
        for kf in (k - 1) * substeps + 1..=k * substeps {
            m = &a * &m + &b * fine(kf - 1);
            p = &a * &p * a.transpose() + &q;
        }
        let c = observation_at(k);
        let yhat = &c * &m - DVector::from_element(4, spec.ug[k]);
        let resid = DVector::from_iterator(4, (0..4).map(|j| y[kk * 4 + j])) - yhat;
        let s_cov = &c * &p * c.transpose() + &r;
        let chol = s_cov.clone().cholesky().unwrap();
        let gain = &p * c.transpose() * chol.inverse();
        m += &gain * &resid;
        p = &p - &gain * &s_cov * gain.transpose();
        let ll = -0.5 * (resid.transpose() * chol.solve(&resid))[0]
            - 0.5 * s_cov.determinant().ln()
            - 2.0 * (2.0 * std::f64::consts::PI).ln();
        let ctx = format!(
            "{disc:?}, substeps {substeps}, α {alpha:?}, {colour:?}, regressors {regress}, k={k}"
        );
        assert!(
            (info.loglik_increment - ll).abs() < 1e-7 * ll.abs().max(1.0),
            "{ctx}: {} vs {ll}",
            info.loglik_increment
        );
        for j in 0..2 * n {
            assert!(
                (post.state_mean[j] - m[j]).abs() < 1e-7 * (1.0 + m[j].abs()),
                "{ctx} state {j}: {} vs {}",
                post.state_mean[j],
                m[j]
            );
            assert!(
                (post.state_sd[j] - p[(j, j)].max(0.0).sqrt()).abs() < 1e-7,
                "{ctx} sd {j}"
            );
        }
    }
}
