//! Field data of a stiff building with default, data-scaled priors: the paper's chain time-scaled
//! ×s (k ×s², c ×s, same masses and Bouc–Wen parameters, El Centro ×3 compressed s× in time and
//! so ×s² in amplitude), absolute accelerations, only `measured.csv`. SPEC §3's priors (k median
//! 10) are s²-fold off; the priors scaled from the measured spectrum let the MPF-EKF2 identify k.

use std::fmt::Write as _;

use core_filters::rng::stream;
use identify::field::StructureSettings;
use identify::identification::{settle, Target};
use identify::pipeline::{
    identify, prior_from_data, Algorithm, FilterSettings, RunInput, HYSTERETIC_PARTICLES,
};
use identify::settings::RECOMMENDED_PARTICLES;
use models::dataset::{load_dir, LoadedDataset, MeasurementKind};
use models::excitation::GroundMotion;
use models::ground_motions::el_centro;
use models::integrate::simulate_rk4;
use models::structure::{BoucWen, ShearChain};
use rand::Rng;

/// The time-scaled chain sampled at `dt`, with 10 % RMS noise on every channel from the noise
/// stream of `noise_seed`, written as `measured.csv` into `dir`; returns the true k.
fn write_stiff_field_data(dir: &std::path::Path, scale: f64, dt: f64, noise_seed: u64) -> Vec<f64> {
    let k = vec![8.0 * scale * scale; 3];
    let chain = ShearChain::new(
        vec![1.0; 3],
        k.clone(),
        vec![0.25 * scale; 3],
        vec![BoucWen {
            storey: 0,
            beta: 2.0,
            gamma: 1.0,
            n: 2.0,
        }],
    )
    .unwrap();
    let ec = el_centro().scaled(3.0);
    let compressed = GroundMotion {
        dt: ec.dt / scale,
        acc: ec.acc.iter().map(|a| a * scale * scale).collect(),
    };
    let ug = compressed.resample_linear(dt).acc;
    let truth = match std::env::var("STIFF_TRUTH").as_deref() {
        // A measurement of the sweep: ü_g held over each sample interval (as the filter's
        // transition holds ü_g(k−1)) instead of linear, by 16 RK4 steps per sample.
        Ok("zoh") => {
            let r = 16;
            let fine: Vec<f64> = ug.iter().flat_map(|&u| std::iter::repeat_n(u, r)).collect();
            let t = simulate_rk4(&chain, &fine, dt / r as f64);
            let dim = t.state(0).len();
            let flat: Vec<f64> = (0..ug.len())
                .flat_map(|i| t.state(i * r).to_vec())
                .collect();
            models::integrate::Trajectory::from_flat(dim, dt, flat)
        }
        _ => simulate_rk4(&chain, &ug, dt),
    };
    let n = 3;
    let mut y = vec![0.0; ug.len() * n];
    for (i, row) in y.chunks_exact_mut(n).enumerate() {
        chain.relative_accelerations(truth.state(i), ug[i], row);
        row.iter_mut().for_each(|a| *a += ug[i]);
    }
    let rms = |v: &mut dyn Iterator<Item = f64>| {
        let (s, c) = v.fold((0.0, 0), |(s, c), x| (s + x * x, c + 1));
        (s / c as f64).sqrt()
    };
    let sd_ug = 0.1 * rms(&mut ug.iter().copied());
    let sd: Vec<f64> = (0..n)
        .map(|j| 0.1 * rms(&mut y.iter().skip(j).step_by(n).copied()))
        .collect();
    let mut rng = stream(noise_seed, 0, "test-noise");
    // Box–Muller from the named stream.
    let mut gauss = || -> f64 {
        let (u1, u2): (f64, f64) = (1.0 - rng.random::<f64>(), rng.random());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let mut text = String::from("t,ug,a1,a2,a3\n");
    for i in 0..ug.len() {
        write!(text, "{},{}", i as f64 * dt, ug[i] + sd_ug * gauss()).unwrap();
        for j in 0..n {
            write!(text, ",{}", y[i * n + j] + sd[j] * gauss()).unwrap();
        }
        text.push('\n');
    }
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("measured.csv"), text).unwrap();
    k
}

/// The building as `sysid filter --storeys 3 --hysteretic 1 --masses 1 --measurement absolute`.
fn structure() -> StructureSettings {
    StructureSettings {
        storeys: Some(3),
        hysteretic: Some(vec![1]),
        masses: Some(vec![1.0]),
        measurement: Some(MeasurementKind::Absolute),
        damping: None,
    }
}

fn input<'a>(data: &'a LoadedDataset, seed: u64) -> RunInput<'a> {
    RunInput {
        data,
        chain: None,
        experiment: "stiff",
        seed,
        run: 0,
        progress: None,
        residuals: false,
    }
}

/// Every identified k within 5 % of the truth (the goal of docs/structures.md, "Stiff
/// buildings"); `context` goes into the message.
fn assert_every_k_within_5_percent(r: &identify::record::RunRecord, k_true: &[f64], context: &str) {
    for (j, k) in k_true.iter().enumerate() {
        let rel = r.theta_val[j] / k - 1.0;
        assert!(
            rel.abs() < 0.05,
            "k{}: θ_val {} against {k} ({:+.1}%); {context}",
            j + 1,
            r.theta_val[j],
            100.0 * rel
        );
    }
}

/// A data-set directory, not yet created, inside a fresh directory under the system temp dir,
/// and the guard that removes them when dropped (also when the test panics).
fn scratch(tag: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let tmp = tempfile::Builder::new()
        .prefix(&format!("sysid-{tag}-"))
        .tempdir()
        .unwrap();
    let dir = tmp.path().join("data");
    (tmp, dir)
}

#[test]
fn a_stiff_building_is_identified_with_data_scaled_priors() {
    let (_tmp, dir) = scratch("stiff");
    let scale = 5.0;
    let k_true = write_stiff_field_data(&dir, scale, 0.005 / scale, 7);
    let data = load_dir(&dir).unwrap();
    assert!(data.meta.is_none());
    let settings = FilterSettings {
        particles: 300,
        validate: false,
        trace_every: 0,
        structure: structure(),
        ..FilterSettings::default()
    };
    let scaled = prior_from_data(&data, None, &settings).unwrap().unwrap();
    // The scaled median puts the true stiffness within one prior log-s.d.
    let off = (scaled.k_median / k_true[0]).ln();
    assert!(
        off.abs() < identify::scaled_prior::K_LOG_SD,
        "{}",
        scaled.describe()
    );
    let r = identify(&input(&data, 3), Algorithm::MpfEkf2, &settings).unwrap();
    assert!(r.failure.is_none(), "{:?}", r.failure);
    assert!(r.config["prior_from_data"]["k_median"].as_f64().is_some());
    // "Within a few percent": the paper's MPF-EKF2 errors on k are 1–3% (SPEC §8).
    assert_every_k_within_5_percent(&r, &k_true, &scaled.describe());
}

/// The realistic case: the chain time-scaled ×4 (k = 128, c = 1) sampled at 200 Hz — a stiff
/// building is not logged 4× faster — with `sysid filter`'s settings (MPF-EKF2, 500 particles in
/// 4 pooled filters, substeps "auto"). ω₁·dt = 0.028 while the highest mode's frequency error
/// is 0.05 %, so only the Bouc–Wen rule sub-steps (8 per sample). With one step per sample this
/// data set (noise seed 104, filter seed 1) gave k1 5.4 % low; with the rule 1.3 %.
#[test]
fn a_stiff_building_sampled_at_200_hz_is_sub_stepped_for_its_bouc_wen_element() {
    let (_tmp, dir) = scratch("stiff-200");
    let k_true = write_stiff_field_data(&dir, 4.0, 0.005, 104);
    let data = load_dir(&dir).unwrap();
    let settings = FilterSettings {
        validate: false,
        trace_every: 0,
        structure: structure(),
        ..FilterSettings::recommended()
    };
    let r = identify(&input(&data, 1), Algorithm::MpfEkf2, &settings).unwrap();
    assert!(r.failure.is_none(), "{:?}", r.failure);
    let h = &r.config["substeps_hysteretic"];
    let omega1_dt = h["omega1_dt"].as_f64().unwrap();
    assert!((omega1_dt - 0.0277).abs() < 0.001, "{h}");
    assert_eq!(r.config["spec"]["substeps"].as_u64(), Some(8), "{h}");
    assert_every_k_within_5_percent(&r, &k_true, &h.to_string());
}

/// How `sysid filter` settles the MPF-EKF2's settings on the stiff building's data in `dir`
/// (no config unless `config`; `particles_asked` as `--particles`), and the notes it prints.
fn settled(
    data: &LoadedDataset,
    dir: &std::path::Path,
    algorithm: Algorithm,
    flags: &StructureSettings,
    config: Option<&str>,
    particles_asked: bool,
) -> (FilterSettings, Vec<String>) {
    let measured = dir.join("measured.csv");
    let target = Target {
        algorithm,
        data,
        chain: None,
        measured: &measured,
        flags,
        config,
        particles_asked,
    };
    let mut notes = Vec::new();
    let mut settings = FilterSettings::recommended();
    settings.validate = false;
    settings.trace_every = 0;
    let s = settle(&target, settings, &mut |n| notes.push(n.to_string())).unwrap();
    (s, notes)
}

/// The particle count of `sysid filter` without a config on a building with Bouc–Wen elements
/// sampled coarsely for its data-scaled first mode (`pipeline::HYSTERETIC_PARTICLES`): taken
/// only there, only when the run did not ask for a count, and said. On noise seed 304 (one of the
/// fresh data sets of docs/structures.md, "Stiff buildings") 1000 particles left k1 7.7 % low;
/// the rule's 4000 bring every k within 5 %.
#[test]
fn a_coarsely_sampled_hysteretic_building_takes_more_particles() {
    let (_tmp_dir, dir) = scratch("stiff-particles");
    let k_true = write_stiff_field_data(&dir, 4.0, 0.005, 304);
    let data = load_dir(&dir).unwrap();
    let flags = structure();
    let (chosen, notes) = settled(&data, &dir, Algorithm::MpfEkf2, &flags, None, false);
    assert_eq!((chosen.particles, chosen.pool), (HYSTERETIC_PARTICLES, 8));
    assert!(
        notes
            .iter()
            .any(|n| n.contains("4000 particles as 8 filters of 500")
                && n.contains("--particles 1000")),
        "{notes:?}"
    );
    // Not where the run asked for a count, has a config, is another filter, or the building is
    // linear.
    for (algorithm, config, asked) in [
        (Algorithm::MpfEkf2, None, true),
        (Algorithm::MpfEkf2, Some("settings.toml"), false),
        (Algorithm::MlnRbpf, None, false),
        (Algorithm::Bootstrap, None, false),
    ] {
        let (s, notes) = settled(&data, &dir, algorithm, &flags, config, asked);
        assert_eq!(
            s.particles, RECOMMENDED_PARTICLES,
            "{algorithm:?} {config:?} {asked}"
        );
        assert!(
            !notes.iter().any(|n| n.contains("particles as")),
            "{notes:?}"
        );
    }
    let linear = StructureSettings {
        hysteretic: Some(vec![]),
        ..structure()
    };
    // A linear building samples nothing: one Gaussian filter (`rules::samples_nothing`), not
    // the hysteretic rule's count.
    let (s, notes) = settled(&data, &dir, Algorithm::MpfEkf2, &linear, None, false);
    assert_eq!((s.particles, s.pool), (1, 1));
    assert!(
        notes.iter().any(|n| n.contains("one Gaussian filter"))
            && !notes.iter().any(|n| n.contains("particles as")),
        "{notes:?}"
    );
    // The filter with the settled settings: every k within 5 % (k1 −3.8 %).
    let r = identify(&input(&data, 1), Algorithm::MpfEkf2, &chosen).unwrap();
    assert!(r.failure.is_none(), "{:?}", r.failure);
    assert_eq!(r.particles, HYSTERETIC_PARTICLES);
    assert_every_k_within_5_percent(&r, &k_true, "settled by the rule");
    // The same data at the paper's rate scaled with the building (800 Hz, ω₁·dt ≈ 0.007): no
    // sub-steps, the usual count.
    let (_tmp_dir800, dir800) = scratch("stiff-particles-800");
    write_stiff_field_data(&dir800, 4.0, 0.00125, 304);
    let data800 = load_dir(&dir800).unwrap();
    let (s, _) = settled(&data800, &dir800, Algorithm::MpfEkf2, &flags, None, false);
    assert_eq!(s.particles, RECOMMENDED_PARTICLES);
}

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The measurement behind docs/structures.md ("Stiff buildings"): `sysid filter`'s settings
/// for the MPF-EKF2 on three measured storeys, as it settles them on each data set ([`settle`]:
/// 4000 particles where the Bouc–Wen rule sub-steps, unless `STIFF_PARTICLES` is set) on fresh
/// noise seeds; prints one line per data set and the mean and worst |k error|. `STIFF_SCALE` (4), `STIFF_HZ` (sampling rate; default 200·scale, the paper's rate
/// scaled), `STIFF_SEEDS` (6), `STIFF_FIRST_NOISE` (101: noise seeds 101, 102, …),
/// `STIFF_FILTER_SEED` (1), `STIFF_PARTICLES`, `STIFF_POOL`, `STIFF_SUBSTEPS` (a number or
/// `auto`), `STIFF_DISC` (the defaults of `sysid filter`), `STIFF_SETTINGS=spec` (SPEC §3's
/// settings instead), `STIFF_K_MEDIAN_AT=f` (the prior's k medians at f × the true k),
/// `STIFF_TRUTH=zoh` (ü_g held over each sample in the simulation), `STIFF_R_NOISE`
/// (`r_noise_fraction`). Run with
/// `cargo test --release -p identify --test suite field_scaled_prior -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement (minutes), not a check"]
fn stiff_sweep() {
    let scale: f64 = env("STIFF_SCALE", 4.0);
    let hz: f64 = env("STIFF_HZ", 200.0 * scale);
    let seeds: u64 = env("STIFF_SEEDS", 6);
    let first: u64 = env("STIFF_FIRST_NOISE", 101);
    let filter_seed: u64 = env("STIFF_FILTER_SEED", 1);
    let spec_settings = std::env::var("STIFF_SETTINGS").as_deref() == Ok("spec");
    // The settings of one data set: SPEC §3's, or `sysid filter`'s as settled on it, under the
    // sweep's overrides.
    let settings_for = |data: &LoadedDataset, dir: &std::path::Path| {
        let mut settings = if spec_settings {
            FilterSettings::default()
        } else {
            let asked = std::env::var("STIFF_PARTICLES").is_ok();
            settled(data, dir, Algorithm::MpfEkf2, &structure(), None, asked).0
        };
        settings.particles = env("STIFF_PARTICLES", settings.particles);
        if let Ok(v) = std::env::var("STIFF_SUBSTEPS") {
            settings.substeps = v.parse().unwrap();
        }
        if let Ok(v) = std::env::var("STIFF_DISC") {
            settings.discretisation = v.parse().unwrap();
        }
        settings.pool = env("STIFF_POOL", settings.pool);
        settings.r_noise_fraction = env("STIFF_R_NOISE", settings.r_noise_fraction);
        settings.validate = false;
        settings.trace_every = 0;
        settings.structure = structure();
        settings
    };
    let (_tmp, dir) = scratch("stiff-sweep");
    let (mut sum, mut worst, mut count) = (0.0_f64, 0.0_f64, 0);
    for noise in first..first + seeds {
        let _ = std::fs::remove_dir_all(&dir);
        let k_true = write_stiff_field_data(&dir, scale, 1.0 / hz, noise);
        let data = load_dir(&dir).unwrap();
        let mut run_settings = settings_for(&data, &dir);
        let scaled = prior_from_data(&data, None, &run_settings)
            .unwrap()
            .unwrap();
        if let Ok(f) = std::env::var("STIFF_K_MEDIAN_AT") {
            // The prior's k median at f × the true k (c scaled with it).
            let f: f64 = f.parse().unwrap();
            let mut p = scaled.prior.clone();
            for (j, pk) in p.k.iter_mut().enumerate() {
                if let models::priors::Prior::LogNormal { median, .. } = pk {
                    *median = f * k_true[j];
                }
            }
            for pc in p.c.iter_mut() {
                if let models::priors::Prior::LogNormal { median, .. } = pc {
                    *median *= f * k_true[0] / scaled.k_median;
                }
            }
            run_settings.prior = Some(p);
        }
        let t = std::time::Instant::now();
        let r = identify(
            &input(&data, filter_seed),
            Algorithm::MpfEkf2,
            &run_settings,
        )
        .unwrap();
        let errs: Vec<f64> = (0..3).map(|j| r.theta_val[j] / k_true[j] - 1.0).collect();
        for e in &errs {
            sum += e.abs();
            worst = worst.max(e.abs());
            count += 1;
        }
        println!(
            "scale {scale} {hz} Hz noise {noise}: k_median {:.1} ω₁ {:.2}, {} particles, substeps {}, \
             k = {:?} ({}) sd {} c = {:?} {:.0} s{}",
            scaled.k_median,
            scaled.omega1,
            r.particles,
            r.config["spec"]["substeps"].as_u64().unwrap_or(1),
            r.theta_val[..3]
                .iter()
                .map(|v| (v * 10.0).round() / 10.0)
                .collect::<Vec<_>>(),
            errs.iter()
                .map(|e| format!("{:+.1}%", 100.0 * e))
                .collect::<Vec<_>>()
                .join(" "),
            (0..3)
                .map(|j| format!("{:.1}%", 100.0 * r.theta_sd_final[j] / k_true[j]))
                .collect::<Vec<_>>()
                .join(" "),
            r.theta_val[3..]
                .iter()
                .map(|v| (v * 1000.0).round() / 1000.0)
                .collect::<Vec<_>>(),
            t.elapsed().as_secs_f64(),
            r.failure
                .map(|f| format!(" FAILURE {f}"))
                .unwrap_or_default()
        );
    }
    println!(
        "scale {scale} {hz} Hz: mean |k error| {:.1} %, worst {:.1} % over {seeds} data sets",
        100.0 * sum / count as f64,
        100.0 * worst
    );
}

/// The stiff sweep's data sets written under `STIFF_OUT` (one directory per noise seed, as
/// [`stiff_sweep`] makes them: `STIFF_SCALE`, `STIFF_HZ`, `STIFF_SEEDS`, `STIFF_FIRST_NOISE`),
/// to identify with `sysid filter` as a user would — its plan as settled and chosen, which the
/// sweep's settled settings do not include. Run with `STIFF_OUT=dir cargo test --release -p
/// identify --test suite write_stiff_data_sets -- --ignored`.
#[test]
#[ignore = "writes data sets for a measurement, not a check"]
fn write_stiff_data_sets() {
    let out = std::path::PathBuf::from(std::env::var("STIFF_OUT").expect("STIFF_OUT"));
    let scale: f64 = env("STIFF_SCALE", 4.0);
    let hz: f64 = env("STIFF_HZ", 200.0 * scale);
    let (seeds, first): (u64, u64) = (env("STIFF_SEEDS", 6), env("STIFF_FIRST_NOISE", 101));
    for noise in first..first + seeds {
        let dir = out.join(format!("noise-{noise}"));
        let k = write_stiff_field_data(&dir, scale, 1.0 / hz, noise);
        std::fs::write(dir.join("k_true.txt"), format!("{k:?}\n")).unwrap();
    }
}
