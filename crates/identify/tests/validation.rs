//! Validation without the truth (docs/validation.md): the free run against independently
//! simulated data of a known structure, with and without noise of a known level; the measured
//! transfer-function peaks against the known modes; the posterior band.

use identify::validation::{self, free_run, spectral};
use models::dataset::{generate, DatasetConfig, LoadedDataset};
use models::description::StructureDescription;
use models::sensors::MeasurementKind;

/// A data set of `preset` with no noise (the truth of the data generator, RK4 at dt), its
/// description and θ_true.
fn clean(
    preset: &str,
    hysteretic: Option<Vec<usize>>,
    kind: MeasurementKind,
) -> (LoadedDataset, StructureDescription, Vec<f64>) {
    let mut config = DatasetConfig::from_preset(preset, 3).unwrap();
    config.noise_fraction = 0.0;
    config.duration = Some(12.0);
    config.measurement = kind;
    config.hysteretic = hysteretic;
    let data = generate(&config).unwrap();
    let loaded = data.to_loaded();
    let meta = loaded.meta.clone().unwrap();
    (loaded, meta.structure().unwrap(), meta.theta_true)
}

#[test]
fn the_free_run_with_the_true_theta_fits_noise_free_data_perfectly() {
    for (preset, hyst, kind) in [
        ("paper-3dof", None, MeasurementKind::Relative),
        ("building-chain", Some(vec![]), MeasurementKind::Absolute),
    ] {
        let (data, d, theta) = clean(preset, hyst, kind);
        // The data generator's own scheme (RK4, one step per sample): the same arithmetic, so the
        // fit is 100 % to round-off.
        let chain = free_run::chain_of(&d, &theta).unwrap();
        let y = free_run::simulate_channels(
            &chain,
            &data.ug_meas,
            data.dt,
            &data.sensors,
            kind,
            free_run::Integrator::Rk4,
        )
        .unwrap();
        for (c, yc) in y.iter().enumerate() {
            let measured: Vec<f64> = (0..data.len()).map(|k| data.y(k)[c]).collect();
            let fit = free_run::fit_percent(&measured, yc);
            assert!((fit - 100.0).abs() < 1e-9, "{preset} a{c}: fit {fit}");
        }
        let f = validation::free_run(
            &d,
            &data,
            &theta,
            None,
            0,
            validation::prediction::ErrorBand::Without,
            validation::DiscrepancyUse::Without,
        )
        .unwrap();
        assert_eq!(f.channels.len(), data.channels);
        // The free run's adaptive integrator (tolerance 1e-8) differs from the data's RK4 by
        // RK4's own truncation error: a phase error of about T·ω·(ω·dt)⁴/120 per mode, 3e-8 rad
        // for the paper's chain (ω ≤ 3.5 rad/s, T = 12 s, dt = 5 ms) but 0.2 rad for the third
        // mode of the stiff building chain (ω ≈ 80 rad/s): there only RK4 against RK4 is exact.
        if preset != "paper-3dof" {
            continue;
        }
        for c in &f.channels {
            assert!(
                c.fit_percent > 100.0 - 1e-3 && c.fit_percent <= 100.0,
                "{preset} {}: fit {}",
                c.channel,
                c.fit_percent
            );
            assert!(c.nrmse < 1e-5, "{preset} {}: NRMSE {}", c.channel, c.nrmse);
        }
        assert!(f.band.is_none() && f.band_error.is_some());
    }
}

/// Standard normal by Box–Muller.
fn normal(rng: &mut impl rand::Rng) -> f64 {
    let u: f64 = 1.0 - rng.random::<f64>();
    let v: f64 = rng.random::<f64>();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

#[test]
fn the_fit_on_data_with_known_noise_is_the_value_the_noise_level_predicts() {
    // Noise of s.d. σ = 0.1·RMS(clean) added to every channel (the excitation stays clean, so
    // the free run at θ_true reproduces the clean channels): y − ŷ = e, and
    // fit = 100·(1 − ‖e‖/‖y − ȳ‖) with ‖e‖ ≈ σ√K (s.d. σ/√2, K samples).
    let (mut data, d, theta) = clean("paper-3dof", None, MeasurementKind::Relative);
    let k = data.len();
    let m = data.channels;
    let mut rng = core_filters::rng::stream(11, 0, "test-noise");
    let mut sigma = vec![0.0; m];
    for (c, s) in sigma.iter_mut().enumerate() {
        let rms = ((0..k).map(|i| data.y(i)[c].powi(2)).sum::<f64>() / k as f64).sqrt();
        *s = 0.1 * rms;
    }
    for row in data.y_meas.chunks_exact_mut(m) {
        for (v, s) in row.iter_mut().zip(&sigma) {
            *v += s * normal(&mut rng);
        }
    }
    let f = validation::free_run(
        &d,
        &data,
        &theta,
        None,
        0,
        validation::prediction::ErrorBand::Without,
        validation::DiscrepancyUse::Without,
    )
    .unwrap();
    for (c, ch) in f.channels.iter().enumerate() {
        let y: Vec<f64> = (0..k).map(|i| data.y(i)[c]).collect();
        let mean = y.iter().sum::<f64>() / k as f64;
        let dev = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
        let expected = 100.0 * (1.0 - sigma[c] * (k as f64).sqrt() / dev);
        let se = 100.0 * sigma[c] / (2.0_f64.sqrt() * dev);
        assert!(
            (ch.fit_percent - expected).abs() < 4.0 * se,
            "{}: fit {} against {expected} ± {se}",
            ch.channel,
            ch.fit_percent
        );
        // NRMSE ≈ σ/RMS(y), RMS(y)² = RMS(clean)² + σ² = 101 σ².
        let want = 1.0 / 101.0_f64.sqrt();
        let se_n = want / (2.0 * k as f64).sqrt();
        assert!(
            (ch.nrmse - want).abs() < 4.0 * se_n + 1e-3 * want,
            "{}: NRMSE {} against {want}",
            ch.channel,
            ch.nrmse
        );
    }
}

#[test]
fn measured_transfer_peaks_sit_at_the_modes_of_a_known_linear_building() {
    // A lightly damped linear 3-storey building (unit masses, k = 2000, c = 0.5: ζ = 0.25 %,
    // 0.7 %, 1.0 %) simulated by the toolkit's RK4 under El Centro × 50 at dt = 5 ms, absolute
    // accelerations with 10 % noise on every channel and on the ground: the Welch peaks of the
    // measured floor/ground transfer functions sit at its damped frequencies within two bins.
    let chain =
        models::structure::ShearChain::new(vec![1.0; 3], vec![2000.0; 3], vec![0.5; 3], vec![])
            .unwrap();
    let dt = 0.005;
    // SPEC §2's El Centro × 3 at 5 ms, scaled to × 50.
    let ug = models::ground_motions::paper_default()
        .scaled(50.0 / 3.0)
        .acc;
    let truth = models::integrate::simulate_rk4(&chain, &ug, dt);
    let k = ug.len();
    let mut rng = core_filters::rng::stream(5, 0, "test-noise");
    let mut all = vec![0.0; 3];
    let mut y = vec![0.0; 3 * k];
    for i in 0..k {
        chain.relative_accelerations(truth.state(i), ug[i], &mut all);
        for c in 0..3 {
            y[3 * i + c] = all[c] + ug[i];
        }
    }
    let rms = |v: &mut dyn Iterator<Item = f64>| {
        let (s, n) = v.fold((0.0, 0), |(s, n), x| (s + x * x, n + 1));
        (s / n as f64).sqrt()
    };
    let sd: Vec<f64> = (0..3)
        .map(|c| 0.1 * rms(&mut y.iter().skip(c).step_by(3).copied()))
        .collect();
    let sd_ug = 0.1 * rms(&mut ug.iter().copied());
    for (i, v) in y.iter_mut().enumerate() {
        *v += sd[i % 3] * normal(&mut rng);
    }
    let ug_meas: Vec<f64> = ug.iter().map(|u| u + sd_ug * normal(&mut rng)).collect();
    let data = LoadedDataset {
        dt,
        t: (0..k).map(|i| i as f64 * dt).collect(),
        ug_meas,
        y_meas: y,
        channels: 3,
        sensors: vec![1, 2, 3],
        truth: None,
        meta: None,
    };
    let d = StructureDescription {
        storeys: 3,
        masses: vec![1.0; 3],
        hysteretic: vec![],
        sensors: vec![1, 2, 3],
        measurement: MeasurementKind::Absolute,
        damping: Default::default(),
        ground_between: Default::default(),
    };
    let theta = chain.theta();
    let m = validation::modal(&d, &data, &theta);
    assert!(m.errors.is_empty(), "{:?}", m.errors);
    assert_eq!(m.modes.len(), 3);
    assert_eq!(m.pairs.len(), 3);
    for p in &m.pairs {
        let measured = p.measured_hz.expect("a peak per mode");
        let damped = m.modes[p.mode - 1].damped_hz;
        assert!(
            (measured - damped).abs() < 2.0 * m.resolution_hz,
            "mode {}: peak {measured} Hz, model {damped} Hz (resolution {}); peaks {:?}",
            p.mode,
            m.resolution_hz,
            m.peaks
        );
    }
    let text = validation::summary(None, Some(&m));
    assert!(
        text.contains("mode") && text.contains("measured [Hz]") && text.contains("MAC"),
        "{text}"
    );
    // The measured operating shapes (quadrature picking) are the building's mode shapes: MAC
    // with the true θ's at least 0.99 on every mode (measured 1.0000, 0.9994, 0.9937 on this
    // fixed record; the third mode, the least excited, is the most contaminated by the others).
    for p in &m.pairs {
        let mac = p.mac.expect("a MAC per paired mode");
        assert!(mac >= 0.99, "mode {}: MAC {mac}", p.mode);
        assert_eq!(p.model_shape.len(), 3);
        assert_eq!(p.operating_shape.len(), 3);
        assert!(
            p.mac_95.is_none() && p.model_shape_95.is_empty(),
            "no draws here"
        );
    }
    // A building whose stiffness falls with height (6000, 2000, 700) has other shapes: paired
    // with the same peaks, every mode agrees less (measured 0.87, 0.53, 0.67).
    let other = [6000.0, 2000.0, 700.0, 0.5, 0.5, 0.5];
    let w = validation::modal(&d, &data, &other);
    for (p, q) in m.pairs.iter().zip(&w.pairs) {
        let mac = q.mac.expect("a MAC per paired mode");
        assert!(mac < p.mac.unwrap() - 0.1, "mode {}: {mac}", q.mode);
    }
    assert!(w.pairs.iter().filter_map(|p| p.mac).fold(1.0, f64::min) < 0.6);
}

#[test]
fn the_band_is_reproducible_and_collapses_on_a_point_posterior() {
    use core_filters::credible::CredibleInterval;
    use identify::observe::{ParamIntervals, PosteriorShape};
    let (data, d, theta) = clean("paper-3dof", None, MeasurementKind::Relative);
    let names = ["k1", "k2", "k3", "c1", "c2", "c3", "beta", "gamma", "n"].map(String::from);
    let intervals = |spread: f64| -> Vec<ParamIntervals> {
        names
            .iter()
            .zip(&theta)
            .map(|(n, &v)| ParamIntervals {
                parameter: n.clone(),
                shape: PosteriorShape::GaussianMixture,
                intervals: [(0.5, 0.5), (0.9, 1.0), (0.95, 1.3)]
                    .iter()
                    .map(|&(level, w)| CredibleInterval {
                        level,
                        lo: v * (1.0 - spread * w),
                        hi: v * (1.0 + spread * w),
                    })
                    .collect(),
                error: None,
                mc_se: None,
            })
            .collect()
    };
    // A point posterior: every draw is θ, the band's fits are the fit.
    let q = free_run::QuantileDraw::new(&names, &intervals(0.0)).unwrap();
    let f = validation::free_run(
        &d,
        &data,
        &theta,
        Some((&q, 1, 0)),
        5,
        validation::prediction::ErrorBand::Without,
        validation::DiscrepancyUse::Without,
    )
    .unwrap();
    for c in &f.channels {
        let p = c.fit_draws.as_ref().unwrap();
        assert!(p.iter().all(|x| (x - c.fit_percent).abs() < 1e-9), "{p:?}");
    }
    // A spread posterior: the same band for the same (seed, run), another for another seed,
    // and the free run at θ inside it almost everywhere.
    let q = free_run::QuantileDraw::new(&names, &intervals(0.05)).unwrap();
    let a = validation::free_run(
        &d,
        &data,
        &theta,
        Some((&q, 1, 0)),
        20,
        validation::prediction::ErrorBand::Without,
        validation::DiscrepancyUse::Without,
    )
    .unwrap();
    let b = validation::free_run(
        &d,
        &data,
        &theta,
        Some((&q, 1, 0)),
        20,
        validation::prediction::ErrorBand::Without,
        validation::DiscrepancyUse::Without,
    )
    .unwrap();
    let c = validation::free_run(
        &d,
        &data,
        &theta,
        Some((&q, 2, 0)),
        20,
        validation::prediction::ErrorBand::Without,
        validation::DiscrepancyUse::Without,
    )
    .unwrap();
    assert_eq!(a, b);
    assert_ne!(a.band_lo, c.band_lo);
    assert_eq!(a.band.as_ref().unwrap().valid, 20);
    let p = a.channels[0].fit_draws.as_ref().unwrap();
    assert!(p[0] < p[1] && p[1] < p[2] && p[2] < 100.0, "{p:?}");
}

#[test]
fn bad_inputs_are_refused_with_a_reason() {
    let (data, d, theta) = clean("paper-3dof", None, MeasurementKind::Relative);
    let e = validation::free_run(
        &d,
        &data,
        &theta[..5],
        None,
        0,
        validation::prediction::ErrorBand::Without,
        validation::DiscrepancyUse::Without,
    )
    .unwrap_err();
    assert!(e.to_string().contains("θ has 5 entries"), "{e}");
    let mut bad = theta.clone();
    bad[4] = -1.0;
    let e = validation::free_run(
        &d,
        &data,
        &bad,
        None,
        0,
        validation::prediction::ErrorBand::Without,
        validation::DiscrepancyUse::Without,
    )
    .unwrap_err();
    assert!(e.to_string().contains("damping"), "{e}");
    let chain = free_run::chain_of(&d, &theta).unwrap();
    let e = free_run::simulate_channels(
        &chain,
        &data.ug_meas,
        data.dt,
        &[4],
        MeasurementKind::Relative,
        free_run::Integrator::Rk4,
    )
    .unwrap_err();
    assert!(e.to_string().contains("a4"), "{e}");
    let e = spectral::welch_h1(&data.ug_meas[..50], &[], data.dt).unwrap_err();
    assert!(e.to_string().contains("too short"), "{e}");
    let zero = vec![0.0; 1000];
    let e = spectral::welch_h1(&zero, std::slice::from_ref(&zero), 0.01).unwrap_err();
    assert!(e.to_string().contains("zero"), "{e}");
}

#[test]
fn modes_pair_with_the_nearest_peak_and_never_with_a_far_one() {
    use models::modal::Mode;
    use spectral::Peak;
    let mode = |f: f64| Mode {
        frequency_hz: f,
        damped_hz: f,
        damping_ratio: 0.01,
    };
    let peak = |f: f64| Peak {
        frequency_hz: f,
        magnitude: 1.0,
    };
    // A spurious peak at 46 Hz and a missing one near 16 Hz; a mode below two bins.
    let modes = [mode(0.05), mode(3.7), mode(11.0), mode(15.5)];
    let peaks = [peak(3.68), peak(11.13), peak(46.0)];
    let p = validation::pair(&modes, &peaks, 0.06, &[]);
    let got: Vec<Option<f64>> = p.iter().map(|q| q.measured_hz).collect();
    assert_eq!(got, [None, Some(3.68), Some(11.13), None]);
    assert!((p[1].difference_percent.unwrap() - 100.0 * (3.7 - 3.68) / 3.68).abs() < 1e-12);
    let text = validation::summary(
        None,
        Some(&validation::ModalComparison {
            modes: modes.to_vec(),
            peaks: peaks.to_vec(),
            pairs: p,
            resolution_hz: 0.06,
            ..Default::default()
        }),
    );
    assert!(
        text.contains("below resolution") && text.contains("no peak near"),
        "{text}"
    );
    assert!(text.contains("without a model mode: 46.000 Hz"), "{text}");

    // A record whose ground motion does not reach the second mode (45 dB below its strongest
    // frequency, as a 2 Hz sine leaves the frame's 11 Hz mode): a bump of the input's spectrum at
    // 13 Hz, within the pairing ratio, is not taken for it.
    let modes = [mode(3.7), mode(11.0)];
    let peaks = [peak(3.68), peak(13.0)];
    let p = validation::pair(&modes, &peaks, 0.06, &[Some(-5.0), Some(-45.0)]);
    let got: Vec<Option<f64>> = p.iter().map(|q| q.measured_hz).collect();
    assert_eq!(got, [Some(3.68), None]);
    assert_eq!(p[1].excitation_db, Some(-45.0));
    let text = validation::summary(
        None,
        Some(&validation::ModalComparison {
            modes: modes.to_vec(),
            peaks: peaks.to_vec(),
            pairs: p,
            resolution_hz: 0.06,
            ..Default::default()
        }),
    );
    assert!(text.contains("not excited (-45 dB)"), "{text}");
    assert!(text.contains("without a model mode: 13.000 Hz"), "{text}");
    // Excited (−20 dB): paired as before.
    let mut p = validation::pair(&modes, &peaks, 0.06, &[Some(-5.0), Some(-20.0)]);
    assert_eq!(p[1].measured_hz, Some(13.0));
    // Paired by frequency but of another shape (MAC 0.062, as the frame's 11.13 Hz mode with a
    // bump of a sine record's input): the summary says the peak is not that mode; a MAC of 0.5
    // or more is not flagged.
    p[0].mac = Some(0.999);
    p[1].mac = Some(0.062);
    let mut m = validation::ModalComparison {
        modes: modes.to_vec(),
        peaks: peaks.to_vec(),
        pairs: p,
        resolution_hz: 0.06,
        ..Default::default()
    };
    let text = validation::summary(None, Some(&m));
    assert!(
        text.contains("not the same shape: mode 2 (MAC 0.062)") && !text.contains("mode 1 (MAC"),
        "{text}"
    );
    assert!(text.contains("MAC 95 %"), "{text}");
    m.pairs[1].mac = Some(0.5);
    assert!(!validation::summary(None, Some(&m)).contains("not the same shape"));
}

/// The modal intervals of a one-storey building against its closed form: the natural frequency
/// √(k/m)/2π is increasing in k and the damping ratio c/(2√(km)) increasing in c and decreasing
/// in k, so the central 95 % of each over the band's draws lies between their values at the ends
/// of k's and c's 95 % intervals, holds the value at θ_val, and is reproduced by its seed.
#[test]
fn modal_intervals_of_one_storey_against_the_closed_form() {
    use core_filters::credible::{CredibleInterval, STANDARD_LEVELS};
    use identify::observe::{ParamIntervals, PosteriorShape};
    use identify::validation::free_run::QuantileDraw;
    use identify::validation::modal_intervals;
    let (k, c, m) = (600.0_f64, 1.0_f64, 1.0_f64);
    let names = vec!["k1".to_string(), "c1".to_string()];
    // Symmetric intervals of half-widths 2 %, 5 %, 10 % of the value at 50, 90, 95 %.
    let credible: Vec<ParamIntervals> = [k, c]
        .iter()
        .zip(&names)
        .map(|(&v, name)| ParamIntervals {
            parameter: name.clone(),
            shape: PosteriorShape::GaussianMixture,
            intervals: STANDARD_LEVELS
                .iter()
                .zip([0.02, 0.05, 0.10])
                .map(|(&level, h)| CredibleInterval {
                    level,
                    lo: v * (1.0 - h),
                    hi: v * (1.0 + h),
                })
                .collect(),
            error: None,
            mc_se: None,
        })
        .collect();
    let q = QuantileDraw::new(&names, &credible).unwrap();
    let building =
        models::building::Building::new(vec![m], vec![], models::structure::Damping::Storey)
            .unwrap();
    let d = models::description::StructureDescription::of(
        &building,
        vec![1],
        models::sensors::MeasurementKind::Absolute,
    );
    let got = modal_intervals(&d, &q, 5, 0, 1);
    let (f, z) = got[0].expect("every draw is under-damped");
    let freq = |k: f64| (k / m).sqrt() / std::f64::consts::TAU;
    let ratio = |k: f64, c: f64| c / (2.0 * (k * m).sqrt());
    assert!(
        freq(0.9 * k) <= f[0] && f[0] < freq(k) && freq(k) < f[1] && f[1] <= freq(1.1 * k),
        "{f:?}"
    );
    assert!(
        ratio(1.1 * k, 0.9 * c) <= z[0] && z[0] < ratio(k, c),
        "{z:?}"
    );
    assert!(
        ratio(k, c) < z[1] && z[1] <= ratio(0.9 * k, 1.1 * c),
        "{z:?}"
    );
    assert_eq!(
        modal_intervals(&d, &q, 5, 0, 1),
        got,
        "the same seed, the same intervals"
    );
}

/// A stiff one-storey building (22 Hz, ζ 0.5 %) recorded at 120 Hz under a band-limited ground
/// motion (a tapered sum of sines up to 45 Hz; the truth integrated exactly on a grid 32 times
/// finer, where the input is the sum itself): the free run with the ground motion band-limited
/// between samples (what field data get) predicts the recorded absolute acceleration to the
/// integration's accuracy; linear between samples it misses by the input's attenuation near the
/// mode (docs/validation.md, "The ground between its samples").
#[test]
fn a_recorded_ground_motion_is_reconstructed_band_limited_between_its_samples() {
    use models::ground_between::GroundBetween;
    let (dt, n, fine) = (1.0 / 120.0, 2400usize, 32usize);
    let duration = (n - 1) as f64 * dt;
    let sines = [
        (3.1, 1.0, 0.3),
        (11.7, 0.7, 1.1),
        (21.6, 0.5, 2.0),
        (27.9, 0.4, 0.7),
    ];
    let ug_at = |t: f64| {
        let taper = (std::f64::consts::PI * t / duration).sin().powi(2);
        taper
            * sines
                .iter()
                .map(|(f, a, p)| a * (2.0 * std::f64::consts::PI * f * t + p).sin())
                .sum::<f64>()
    };
    let ug: Vec<f64> = (0..n).map(|k| ug_at(k as f64 * dt)).collect();
    let ug_fine: Vec<f64> = (0..(n - 1) * fine + 1)
        .map(|i| ug_at(i as f64 * dt / fine as f64))
        .collect();
    let k1 = (2.0 * std::f64::consts::PI * 22.0f64).powi(2);
    let c1 = 2.0 * 0.005 * k1.sqrt();
    let chain = models::structure::ShearChain::new(vec![1.0], vec![k1], vec![c1], vec![]).unwrap();
    let truth_fine = free_run::simulate_channels(
        &chain,
        &ug_fine,
        dt / fine as f64,
        &[1],
        MeasurementKind::Absolute,
        free_run::Integrator::ExactLinear,
    )
    .unwrap();
    let truth: Vec<f64> = truth_fine[0].iter().step_by(fine).copied().collect();
    assert_eq!(truth.len(), n);
    let fit = |between| {
        let y = free_run::simulate_channels_between(
            &chain,
            &ug,
            dt,
            &[1],
            MeasurementKind::Absolute,
            free_run::Integrator::ExactLinear,
            between,
        )
        .unwrap();
        free_run::fit_percent(&truth, &y[0])
    };
    let (band_limited, linear) = (fit(GroundBetween::BandLimited), fit(GroundBetween::Linear));
    // Within a sub-interval of dt/8 the input is still linear: sinc²(21.6/960) keeps 0.9983 of
    // the resonant component's amplitude, about a 0.2-point fit.
    assert!(band_limited > 99.5, "band-limited {band_limited}");
    assert!(linear < 95.0, "linear {linear}");
}
