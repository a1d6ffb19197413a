//! The foreign corpus: simulated records of three-storey buildings outside the filter's class, to
//! judge an identification on structures nobody tuned it for (docs/foreign.md).
//!
//! The filter's class is a planar shear chain with per-storey (and mass-proportional) damping,
//! exactly measured ground motion and white measurement noise. Each case breaks one of these
//! (and one, `in-class`, breaks none: the control): a brace coupling storeys that are not
//! neighbours, a torsional mode coupled to the sway by an eccentric mass, a hardening joint,
//! coloured measurement noise, a sensor one sample late with a gain error, a light appendage
//! tuned beside the second mode, a noisy ground sensor. A table that interacts with the
//! structure is not a case: with the table's acceleration measured as the ground motion, the
//! interaction does not reach the model (the relative motion depends on the base acceleration
//! alone), so what remains of it is the ground sensor's error — the last case.
//!
//! Every case is simulated twice, under two ground motions: one record to identify, one kept out
//! to judge the prediction. Responses are integrated by RK4 at the sample step (ü_g linearly
//! interpolated), M ẍ + C ẋ + f(x) = −M r ü_g with r the ground's influence on each degree of
//! freedom; a sensor records an absolute acceleration, a combination of the degrees of
//! freedom's (ẍ + r ü_g = −M⁻¹(C ẋ + f(x))).

use std::path::Path;

use nalgebra::{DMatrix, DVector};
use rand_distr::{Distribution, StandardNormal};

use models::dataset::{load_dir, DatasetError, LoadedDataset};

use crate::error::{bail, Result};

/// The storey stiffnesses (per unit mass of floor 1) of the corpus's base building: modes near
/// 1.9, 5.3 and 7.9 Hz, where earthquake records carry energy, with 200 Hz sampling.
pub(crate) const STIFFNESS: [f64; 3] = [1200.0, 1000.0, 800.0];

/// Rayleigh damping, this ratio in the base chain's first and third modes.
pub const DAMPING_RATIO: f64 = 0.02;

/// Measurement noise: this fraction of each clean channel's RMS (the ground sensor's too, in
/// the case that has one).
pub(crate) const NOISE_FRACTION: f64 = 0.05;

/// What a user knows of every building of the corpus: `sysid filter`'s minimal flags (the seed
/// is [`SEED`]).
pub const MINIMAL_FLAGS: [&str; 10] = [
    "--algorithm",
    "mpf-ekf2",
    "--storeys",
    "3",
    "--hysteretic",
    "none",
    "--masses",
    "1",
    "--measurement",
    "absolute",
];

/// The master seed of the corpus's noise streams and of its identifications.
pub const SEED: u64 = 49;

/// `sysid simulate` of the identification's ground motion (El Centro 1940 × 3, its default for
/// 3 storeys, 31.18 s at 200 Hz); the clean `ug` of its `truth.csv` is taken ([`clean_ground`]).
pub const GROUND: [&str; 7] = [
    "simulate",
    "--storeys",
    "3",
    "--hysteretic",
    "none",
    "--seed",
    "1",
];

/// Added to [`GROUND`] for the held-out record's ground motion: another earthquake, Loma Prieta
/// 1989, over the same duration.
pub const HELD_OUT_GROUND: [&str; 4] = ["--excitation", "loma-prieta-1989", "--duration", "31.18"];

/// A hardening joint in storey 1: spring force k·d·(1 + ε (d/d₀)²).
#[derive(Debug, Clone)]
pub struct Joint {
    pub k: f64,
    pub epsilon: f64,
    pub d0: f64,
}

/// A structure: its matrices, the ground's influence vector and what each sensor reads.
#[derive(Debug, Clone)]
pub struct Structure {
    pub m: DMatrix<f64>,
    pub c: DMatrix<f64>,
    /// The linear stiffness (storey 1's spring excluded where a [`Joint`] replaces it).
    pub k: DMatrix<f64>,
    pub joint: Option<Joint>,
    /// 1 for a degree of freedom the ground moves, 0 for a rotation.
    pub r: DVector<f64>,
    /// One row per floor sensor: its absolute acceleration is the row times the degrees of
    /// freedom's absolute accelerations.
    pub sensors: DMatrix<f64>,
}

/// How the records are measured.
#[derive(Debug, Clone, Default)]
pub struct Sensing {
    /// AR(1) coefficient of the measurement noise (0: white).
    pub ar: f64,
    /// Floor 3's sensor one sample late, its gain × (1 + this).
    pub lag_gain: Option<f64>,
    /// The ground sensor's noise, as a fraction of the ground motion's RMS (0: exact).
    pub ground_noise: f64,
}

/// One case of the corpus.
#[derive(Debug, Clone)]
pub struct Case {
    /// Short name (a directory name).
    pub name: &'static str,
    /// What it breaks of the filter's class.
    pub about: &'static str,
    pub structure: Structure,
    pub sensing: Sensing,
}

/// The shear chain's stiffness matrix of storey stiffnesses `k` (storey j links floor j − 1 to
/// floor j; floor 0 is the ground).
pub fn chain(k: &[f64]) -> DMatrix<f64> {
    let n = k.len();
    let mut m = DMatrix::zeros(n, n);
    for j in 0..n {
        m[(j, j)] += k[j];
        if j > 0 {
            m[(j - 1, j - 1)] += k[j];
            m[(j, j - 1)] -= k[j];
            m[(j - 1, j)] -= k[j];
        }
    }
    m
}

/// Rayleigh damping a₀ M + a₁ K with damping ratio `z` at circular frequencies w1 and w2.
pub fn rayleigh(m: &DMatrix<f64>, k: &DMatrix<f64>, z: f64, (w1, w2): (f64, f64)) -> DMatrix<f64> {
    m * (2.0 * z * w1 * w2 / (w1 + w2)) + k * (2.0 * z / (w1 + w2))
}

/// The lowest and highest circular frequencies of stiffness `k` with unit masses.
pub fn band(k: &DMatrix<f64>) -> (f64, f64) {
    let e = k.clone().symmetric_eigen().eigenvalues;
    let (lo, hi) = e
        .iter()
        .fold((f64::INFINITY, 0.0_f64), |(l, h), &v| (l.min(v), h.max(v)));
    (lo.sqrt(), hi.sqrt())
}

/// The base chain's lowest and highest circular frequencies (unit masses).
fn base_band() -> (f64, f64) {
    band(&chain(&STIFFNESS))
}

/// The mass and stiffness of a unit-mass structure of stiffness `base` with a mass `mass` on
/// 0-based floor `floor`, its spring tuned to circular frequency `w`: one more degree of freedom,
/// unmeasured.
pub fn with_mass_on(
    base: &DMatrix<f64>,
    floor: usize,
    mass: f64,
    w: f64,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = base.nrows();
    let ka = mass * w * w;
    let mut k = DMatrix::zeros(n + 1, n + 1);
    k.view_mut((0, 0), (n, n)).copy_from(base);
    for (a, b, s) in [
        (floor, floor, ka),
        (n, n, ka),
        (floor, n, -ka),
        (n, floor, -ka),
    ] {
        k[(a, b)] += s;
    }
    let mut m = DMatrix::identity(n + 1, n + 1);
    m[(n, n)] = mass;
    (m, k)
}

/// A planar three-storey building of mass matrix `m` and stiffness `k`, floors measured.
fn planar(m: DMatrix<f64>, k: DMatrix<f64>) -> Structure {
    let n = m.nrows();
    let (w1, w3) = base_band();
    Structure {
        c: rayleigh(&m, &k, DAMPING_RATIO, (w1, w3)),
        sensors: DMatrix::identity(3, n),
        r: DVector::from_element(n, 1.0),
        m,
        k,
        joint: None,
    }
}

/// Sway and twist: floors j = 0..3 have x_j (sway) and θ_j (rotation times the radius of
/// gyration, so both are lengths). The mass centre sits `e` (a fraction of the radius of
/// gyration) from the stiffness centre, coupling the two; the sensors sit at the floor's edge,
/// one radius of gyration from the stiffness centre, reading ẍ + θ̈.
fn torsional(e: f64, twist_ratio: f64) -> Structure {
    let ks = chain(&STIFFNESS);
    let mut k = DMatrix::zeros(6, 6);
    k.view_mut((0, 0), (3, 3)).copy_from(&ks);
    k.view_mut((3, 3), (3, 3)).copy_from(&(&ks * twist_ratio));
    // Mass at offset e: in the stiffness centre's coordinates the mass matrix couples x and θ.
    let mut m = DMatrix::identity(6, 6);
    for j in 0..3 {
        m[(j, j + 3)] = e;
        m[(j + 3, j)] = e;
        m[(j + 3, j + 3)] = 1.0 + e * e;
    }
    let (w1, w3) = base_band();
    let mut r = DVector::zeros(6);
    r.rows_mut(0, 3).fill(1.0);
    let mut sensors = DMatrix::zeros(3, 6);
    for j in 0..3 {
        sensors[(j, j)] = 1.0;
        sensors[(j, j + 3)] = 1.0;
    }
    Structure {
        c: rayleigh(&m, &k, DAMPING_RATIO, (w1, w3)),
        m,
        k,
        joint: None,
        r,
        sensors,
    }
}

/// The corpus (every case's structure and sensing; the joint's d₀ is set by [`calibrate_joint`]).
pub fn cases() -> Vec<Case> {
    let base = chain(&STIFFNESS);
    let eye = DMatrix::identity(3, 3);
    let (app_m, app_k) = with_appendage(&base);
    let case = |name, about, structure, sensing| Case {
        name,
        about,
        structure,
        sensing,
    };
    vec![
        case(
            "in-class",
            "a shear chain with Rayleigh damping and white noise: the filter's own class",
            planar(eye.clone(), base.clone()),
            Sensing::default(),
        ),
        case(
            "brace",
            "a brace couples floors 1 and 3 (non-shear stiffness, a quarter of storey 3's)",
            planar(eye.clone(), braced(&base)),
            Sensing::default(),
        ),
        case(
            "torsion",
            "an eccentric mass (10 % of the radius of gyration) couples a twist to the sway; \
             sensors at the floors' edge",
            torsional(0.1, 1.4),
            Sensing::default(),
        ),
        case(
            "joint",
            "storey 1's spring hardens: +50 % stiffness at the linear response's peak drift",
            jointed(&eye, &base),
            Sensing::default(),
        ),
        case(
            "coloured-noise",
            "measurement noise AR(1) with coefficient 0.95 (same variance)",
            planar(eye.clone(), base.clone()),
            Sensing {
                ar: 0.95,
                ..Sensing::default()
            },
        ),
        case(
            "sensor-lag-gain",
            "floor 3's sensor reads one sample late, its gain 5 % high",
            planar(eye.clone(), base.clone()),
            Sensing {
                lag_gain: Some(0.05),
                ..Sensing::default()
            },
        ),
        case(
            "appendage",
            "a 5 % mass on floor 3 tuned 5 % below the second mode (a fourth, unmeasured DOF)",
            planar(app_m, app_k),
            Sensing::default(),
        ),
        case(
            "ground-noise",
            "the ground sensor is noisy too (5 % of the ground motion's RMS)",
            planar(eye, base),
            Sensing {
                ground_noise: NOISE_FRACTION,
                ..Sensing::default()
            },
        ),
    ]
}

/// The chain's stiffness with a brace from the ground floor's top to the roof: floors 1 and 3
/// coupled directly, by a quarter of storey 3's stiffness.
fn braced(base: &DMatrix<f64>) -> DMatrix<f64> {
    let mut braced = base.clone();
    let kb = 0.25 * STIFFNESS[2];
    for (a, b, s) in [(0, 0, kb), (2, 2, kb), (0, 2, -kb), (2, 0, -kb)] {
        braced[(a, b)] += s;
    }
    braced
}

/// The mass and stiffness of the chain with a 5 % mass on floor 3 tuned 5 % below the second
/// mode: a fourth degree of freedom, unmeasured.
fn with_appendage(base: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut w2 = base
        .clone()
        .symmetric_eigen()
        .eigenvalues
        .as_slice()
        .to_vec();
    w2.sort_by(f64::total_cmp);
    with_mass_on(base, 2, 0.05, 0.95 * w2[1].sqrt())
}

/// The chain with storey 1's linear spring replaced by a hardening joint (+50 % stiffness at
/// the drift d₀, set later by [`calibrate_joint`]).
fn jointed(eye: &DMatrix<f64>, base: &DMatrix<f64>) -> Structure {
    let mut jointed = planar(eye.clone(), base.clone());
    let mut k_lin = base.clone();
    k_lin[(0, 0)] -= STIFFNESS[0];
    jointed.k = k_lin;
    jointed.joint = Some(Joint {
        k: STIFFNESS[0],
        epsilon: 0.5,
        d0: 1.0,
    });
    jointed
}

/// The restoring force f(x) = K x (+ the joint's spring on floor 0's drift).
fn restoring(s: &Structure, x: &DVector<f64>) -> DVector<f64> {
    let mut f = &s.k * x;
    if let Some(j) = &s.joint {
        let d = x[0];
        f[0] += j.k * d * (1.0 + j.epsilon * (d / j.d0).powi(2));
    }
    f
}

/// Integrates the structure under `ug` from rest by RK4 at `dt`, handing each sample's
/// displacements and the degrees of freedom's absolute accelerations to `visit`.
fn integrate(
    s: &Structure,
    ug: &[f64],
    dt: f64,
    mut visit: impl FnMut(&DVector<f64>, DVector<f64>),
) {
    let minv =
        s.m.clone()
            .try_inverse()
            .expect("the corpus's mass matrices are positive definite");
    // Absolute accelerations of the degrees of freedom, and ẍ (relative) for the integration.
    let absolute = |x: &DVector<f64>, v: &DVector<f64>| -> DVector<f64> {
        -(&minv * (&s.c * v + restoring(s, x)))
    };
    let rel = |x: &DVector<f64>, v: &DVector<f64>, u: f64| absolute(x, v) - &s.r * u;
    let n = s.m.nrows();
    let (mut x, mut v) = (DVector::zeros(n), DVector::zeros(n));
    for i in 0..ug.len() {
        visit(&x, absolute(&x, &v));
        if i + 1 == ug.len() {
            break;
        }
        let (u0, u1) = (ug[i], ug[i + 1]);
        let um = 0.5 * (u0 + u1);
        let k1v = rel(&x, &v, u0);
        let (x2, v2) = (&x + &v * (dt / 2.0), &v + &k1v * (dt / 2.0));
        let k2v = rel(&x2, &v2, um);
        let (x3, v3) = (&x + &v2 * (dt / 2.0), &v + &k2v * (dt / 2.0));
        let k3v = rel(&x3, &v3, um);
        let (x4, v4) = (&x + &v3 * dt, &v + &k3v * dt);
        let k4v = rel(&x4, &v4, u1);
        x += (&v + &v2 * 2.0 + &v3 * 2.0 + &v4) * (dt / 6.0);
        v += (&k1v + &k2v * 2.0 + &k3v * 2.0 + &k4v) * (dt / 6.0);
    }
}

/// The clean absolute accelerations at the sensors (channels × samples) under `ug`, from rest.
pub fn respond(s: &Structure, ug: &[f64], dt: f64) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::with_capacity(ug.len()); s.sensors.nrows()];
    integrate(s, ug, dt, |_, a| {
        for (ch, ai) in out.iter_mut().zip((&s.sensors * a).iter()) {
            ch.push(*ai);
        }
    });
    out
}

/// Sets the joint's d₀ to the peak storey-1 drift of the same building with a linear spring
/// under `ug`, so that the spring is ε stiffer at that drift whatever the record's amplitude.
pub fn calibrate_joint(case: &mut Case, ug: &[f64], dt: f64) {
    let Some(joint) = case.structure.joint.clone() else {
        return;
    };
    let mut linear = case.structure.clone();
    linear.joint = None;
    linear.k[(0, 0)] += joint.k;
    let mut peak = 0.0_f64;
    integrate(&linear, ug, dt, |x, _| peak = peak.max(x[0].abs()));
    if let Some(j) = case.structure.joint.as_mut() {
        j.d0 = peak.max(f64::MIN_POSITIVE);
    }
}

/// One measured record: the ground channel and the floor channels as the sensors read them.
pub struct Record {
    pub ug: Vec<f64>,
    pub clean: Vec<Vec<f64>>,
    pub measured: Vec<Vec<f64>>,
}

/// Adds the case's measurement errors to the clean response (`rng`: the record's own stream).
pub fn measure<R: rand::Rng>(
    sensing: &Sensing,
    ug: &[f64],
    clean: Vec<Vec<f64>>,
    rng: &mut R,
) -> Record {
    let rms = |x: &[f64]| (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    let mut measured = clean.clone();
    for (j, ch) in measured.iter_mut().enumerate() {
        let s = NOISE_FRACTION * rms(&clean[j]) * (1.0 - sensing.ar * sensing.ar).sqrt();
        let mut e = 0.0;
        for v in ch.iter_mut() {
            let xi: f64 = StandardNormal.sample(rng);
            e = sensing.ar * e + s * xi;
            *v += e;
        }
        if let (2, Some(g)) = (j, sensing.lag_gain) {
            let late: Vec<f64> = std::iter::once(0.0)
                .chain(ch.iter().copied())
                .take(ch.len())
                .map(|v| v * (1.0 + g))
                .collect();
            *ch = late;
        }
    }
    let sg = sensing.ground_noise * rms(ug);
    let ug = ug
        .iter()
        .map(|&u| {
            let xi: f64 = StandardNormal.sample(rng);
            u + sg * xi
        })
        .collect();
    Record {
        ug,
        clean,
        measured,
    }
}

/// Writes `record` as a field data set (`measured.csv` of floors 1 to 3) in `dir`.
pub fn write(record: &Record, dt: f64, dir: &Path) -> Result<(), DatasetError> {
    let k = record.ug.len();
    let channels = record.measured.len();
    let mut y = Vec::with_capacity(k * channels);
    for i in 0..k {
        for ch in &record.measured {
            y.push(ch[i]);
        }
    }
    LoadedDataset {
        dt,
        t: (0..k).map(|i| i as f64 * dt).collect(),
        ug_meas: record.ug.clone(),
        y_meas: y,
        channels,
        sensors: (1..=channels).collect(),
        truth: None,
        meta: None,
    }
    .write_measured_dir(dir)
}

/// The clean ground motion and time step of a data set `sysid simulate` wrote (its
/// `truth.csv`; the measured `ug` would add the simulator's own noise to every case). A data set
/// without the truth (field data) is refused: its ground motion is not clean.
pub fn clean_ground(dir: &Path) -> Result<(Vec<f64>, f64)> {
    let data = load_dir(dir)?;
    match data.truth {
        Some(t) => Ok((t.ug_clean, data.dt)),
        None => bail!(
            "{}: no truth.csv: the corpus needs a simulated, noise-free ground motion",
            dir.display()
        ),
    }
}

/// fit = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) %, as `sysid validate` scores a free run.
pub use identify::validation::free_run::fit_percent as fit;
