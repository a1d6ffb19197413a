//! The `building-chain` preset (docs/scaling.md): modal periods and damping ratios against the
//! closed form of a uniform chain, and the accuracy of the data's RK4 integration at its
//! stiffness (ω_N·dt ≈ 0.45 at dt = 0.005 s, against ≈ 0.03 for the paper's chain).

use models::integrate::simulate_rk4;
use models::preset::{uniform_chain_omega, Preset, BUILDING_K, BUILDING_ZETA1};

/// Eigenvalues of M⁻¹K for a fixed-free chain with unit masses and equal springs `k`, by the
/// Jacobi method on the symmetric tridiagonal matrix (small N only).
fn chain_eigenvalues(k: f64, n: usize) -> Vec<f64> {
    let mut a = vec![vec![0.0; n]; n];
    for i in 0..n {
        a[i][i] = if i + 1 < n { 2.0 * k } else { k };
        if i + 1 < n {
            a[i][i + 1] = -k;
            a[i + 1][i] = -k;
        }
    }
    for _ in 0..100 {
        let mut off = 0.0;
        for p in 0..n {
            for q in p + 1..n {
                off += a[p][q] * a[p][q];
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
                for r in 0..n {
                    let (arp, arq) = (a[r][p], a[r][q]);
                    a[r][p] = c * arp - s * arq;
                    a[r][q] = s * arp + c * arq;
                }
                for r in 0..n {
                    let (apr, aqr) = (a[p][r], a[q][r]);
                    a[p][r] = c * apr - s * aqr;
                    a[q][r] = s * apr + c * aqr;
                }
            }
        }
        if off < 1e-20 {
            break;
        }
    }
    let mut ev: Vec<f64> = (0..n).map(|i| a[i][i]).collect();
    ev.sort_by(f64::total_cmp);
    ev
}

#[test]
fn periods_and_damping_follow_the_closed_form() {
    for n in [3usize, 5, 10] {
        let chain = Preset::building_chain(n).unwrap();
        let ev = chain_eigenvalues(BUILDING_K, n);
        for (i, lambda) in ev.iter().enumerate() {
            let closed = uniform_chain_omega(BUILDING_K, 1.0, n, i + 1);
            assert!(
                (lambda.sqrt() - closed).abs() < 1e-8 * closed,
                "N = {n}, mode {}: {} vs {closed}",
                i + 1,
                lambda.sqrt()
            );
        }
        // Stiffness-proportional dampers: ζ_1 = (c/k) ω₁ / 2 is the preset's 2 %.
        let w1 = ev[0].sqrt();
        let zeta1 = chain.damping()[0] / chain.stiffness()[0] * w1 / 2.0;
        assert!(
            (zeta1 - BUILDING_ZETA1).abs() < 1e-12,
            "N = {n}: ζ₁ = {zeta1}"
        );
    }
    // T₁ ≈ 0.1 N s over the study's sizes.
    for (n, t1) in [
        (3, 0.316),
        (5, 0.494),
        (10, 0.940),
        (20, 1.834),
        (40, 3.623),
    ] {
        let t = 2.0 * std::f64::consts::PI / uniform_chain_omega(BUILDING_K, 1.0, n, 1);
        assert!((t - t1).abs() < 2e-3, "N = {n}: T₁ = {t}");
    }
}

#[test]
fn rk4_at_the_data_step_matches_half_the_step() {
    // The truth of a data set is RK4 at the data's dt. At the building's stiffness, compare it
    // with RK4 at dt/2 (the same excitation, interpolated) at the common samples.
    for n in [3usize, 40] {
        let p = Preset::from_name("building-chain", Some(n)).unwrap();
        let ug = p.ground_motion();
        let coarse = simulate_rk4(&p.chain, &ug.acc, p.dt);
        let fine_ug = ug.resample_linear(p.dt / 2.0);
        let fine = simulate_rk4(&p.chain, &fine_ug.acc, p.dt / 2.0);
        let dim = coarse.state(0).len();
        let (mut err2, mut ref2) = (0.0f64, 0.0f64);
        for k in 0..coarse.len().min(fine.len() / 2) {
            let (a, b) = (coarse.state(k), fine.state(2 * k));
            for i in 0..dim {
                err2 += (a[i] - b[i]).powi(2);
                ref2 += b[i] * b[i];
            }
        }
        let rel = (err2 / ref2).sqrt();
        eprintln!("N = {n}: relative RMS difference dt vs dt/2 = {rel:.2e}");
        assert!(rel < 1e-3, "N = {n}: {rel}");
    }
}

/// Tall `building-chain`s: their overdamped top modes decay faster than one RK4 step per sample
/// can follow (130 storeys diverged at dt = 0.005 s). The data are integrated with the sub-steps
/// [`rk4_substeps`] gives; chains up to 121 storeys keep one step (their data are unchanged) and
/// the integration agrees with adaptive Dormand–Prince across the documented range.
#[test]
fn tall_building_chains_are_integrated_stably_to_200_storeys() {
    use models::integrate::{
        fastest_damping_rate, rk4_substeps, simulate_adaptive, simulate_rk4_substeps, Tolerance,
    };
    let dt = 0.005;
    for n in [3, 5, 10, 20, 40, 80, 120, 121] {
        assert_eq!(
            rk4_substeps(&Preset::building_chain(n).unwrap(), dt),
            1,
            "{n}"
        );
    }
    let ug: Vec<f64> = models::ground_motions::paper_default()
        .acc
        .iter()
        .take(401)
        .map(|a| a * 50.0 / 3.0)
        .collect();
    for (n, expected_substeps) in [(130, 2), (200, 2)] {
        let chain = Preset::building_chain(n).unwrap();
        let m = rk4_substeps(&chain, dt);
        assert_eq!(m, expected_substeps, "{n} storeys");
        assert!(fastest_damping_rate(&chain) * dt / m as f64 <= 2.78);
        // One step per sample diverges (the failure this guards against) …
        let single = simulate_rk4(&chain, &ug, dt);
        assert!(
            single
                .as_flat()
                .iter()
                .any(|v| !v.is_finite() || v.abs() > 1e6),
            "{n} storeys: one RK4 step per sample did not diverge"
        );
        // … the sub-stepped integration stays bounded and agrees with Dormand–Prince.
        let rk = simulate_rk4_substeps(&chain, &ug, dt, m);
        let tol = Tolerance {
            rtol: 1e-8,
            atol: 1e-11,
        };
        let dp = simulate_adaptive(&chain, &ug, dt, tol).unwrap();
        let scale = dp.as_flat().iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let err = rk
            .as_flat()
            .iter()
            .zip(dp.as_flat())
            .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        assert!(
            err <= 1e-3 * scale,
            "{n} storeys: RK4 × {m} differs from Dormand–Prince by {err:e} (scale {scale:e})"
        );
    }
    // One sub-step is simulate_rk4 itself, bit for bit.
    let paper = Preset::building_chain(3).unwrap();
    assert_eq!(
        simulate_rk4_substeps(&paper, &ug, dt, 1),
        simulate_rk4(&paper, &ug, dt)
    );
}
