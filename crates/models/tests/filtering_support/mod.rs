//! Shared set-up of the `filtering_*` tests: chains, specs, random points and the conversion of
//! a physical point (states, θ) into each partition's storage through its `Layout`.
#![allow(dead_code)]

use core_filters::model::{Layout, Slot};
use core_filters::rng::{stream, StreamRng};
use models::building::Building;
use models::filtering::{ChainSpec, Discretisation, RmsLevels};
use models::priors::Prior;
use models::sensors::{MeasurementKind, SensorLayout};
use models::structure::{Damping, ShearChain};
use rand::Rng;

pub const DT: f64 = 0.005;
/// The step used in every evaluation (transition uses ug[K−1], y uses ug[K]).
pub const K: usize = 7;

/// A chain description for the tests (0-based hysteretic storeys, 1-based sensors).
#[derive(Debug, Clone)]
pub struct Case {
    pub name: &'static str,
    pub masses: Vec<f64>,
    pub hysteretic: Vec<usize>,
    pub sensors: Vec<usize>,
    pub kind: MeasurementKind,
    /// Damping form (θ gains α after c with [`Damping::StoreyMass`]).
    pub damping: Damping,
}

impl Case {
    pub fn n(&self) -> usize {
        self.masses.len()
    }
    pub fn ne(&self) -> usize {
        self.hysteretic.len()
    }
    /// The case's building with damping form `damping`.
    pub fn building(&self, damping: Damping) -> Building {
        Building::new(self.masses.clone(), self.hysteretic.clone(), damping).unwrap()
    }
}

/// The 7-storey chain with hysteresis at storeys 1 and 4 and sensors at 2, 4, 7 (non-unit
/// masses), relative and absolute; the paper's 3-storey chain; a linear 4-storey chain.
pub fn cases() -> Vec<Case> {
    let masses7 = vec![1.0, 1.3, 0.8, 1.1, 0.9, 1.2, 0.7];
    vec![
        Case {
            name: "7-storey relative",
            masses: masses7.clone(),
            hysteretic: vec![0, 3],
            sensors: vec![2, 4, 7],
            kind: MeasurementKind::Relative,
            damping: Damping::Storey,
        },
        Case {
            name: "7-storey absolute",
            masses: masses7,
            hysteretic: vec![0, 3],
            sensors: vec![2, 4, 7],
            kind: MeasurementKind::Absolute,
            damping: Damping::Storey,
        },
        paper_case(MeasurementKind::Relative),
        Case {
            name: "4-storey linear",
            masses: vec![1.0, 0.9, 1.1, 1.2],
            hysteretic: vec![],
            sensors: vec![2, 4],
            kind: MeasurementKind::Absolute,
            damping: Damping::Storey,
        },
    ]
}

/// The cases of [`cases`] with mass-proportional damping as well (storey+mass form).
pub fn damped_cases() -> Vec<Case> {
    cases()
        .into_iter()
        .map(|c| Case {
            damping: Damping::StoreyMass,
            ..c
        })
        .collect()
}

pub fn paper_case(kind: MeasurementKind) -> Case {
    Case {
        name: "paper 3-storey",
        masses: vec![1.0; 3],
        hysteretic: vec![0],
        sensors: vec![1, 2, 3],
        kind,
        damping: Damping::Storey,
    }
}

/// A valid spec for `case` with random-looking but fixed noise levels and excitation.
pub fn spec(case: &Case, disc: Discretisation) -> ChainSpec {
    let mut rng = stream(99, 0, "filtering-tests-spec");
    let sensors = SensorLayout::new(case.n(), &case.sensors, case.kind).unwrap();
    let ug: Vec<f64> = (0..=K + 2)
        .map(|_| 4.0 * rng.random::<f64>() - 2.0)
        .collect();
    let rms = RmsLevels {
        acc: (0..case.sensors.len()).map(|i| 1.0 + i as f64).collect(),
        ug: 3.0,
        drift_velocity: (0..case.ne()).map(|e| 0.5 + 0.1 * e as f64).collect(),
    };
    let storey = case.building(Damping::Storey);
    let mut s = ChainSpec::from_rms(DT, storey, sensors, ug, &rms, 0.1).unwrap();
    s.discretisation = disc;
    if case.damping.has_mass_term() {
        s.building = case.building(case.damping);
        s.prior.alpha = Some(Prior::LogNormal {
            median: 0.5,
            log_sd: 0.7,
        });
    }
    s
}

/// A physical point: states and θ = [k, c, (α), (β, γ, n)…].
#[derive(Debug, Clone)]
pub struct Point {
    pub x: Vec<f64>,
    pub v: Vec<f64>,
    pub r: Vec<f64>,
    pub theta: Vec<f64>,
}

impl Point {
    /// `[x, v, r]`.
    pub fn states(&self) -> Vec<f64> {
        let mut s = self.x.clone();
        s.extend(&self.v);
        s.extend(&self.r);
        s
    }

    /// The augmented vector `[x, v, r, θ]`.
    pub fn augmented(&self) -> Vec<f64> {
        let mut s = self.states();
        s.extend(&self.theta);
        s
    }

    /// Value of a named quantity (as in `Layout` names).
    pub fn physical(&self) -> Vec<f64> {
        self.augmented()
    }

    /// The point whose states are `s = [x, v, r]`, with θ of `self`.
    pub fn with_states(&self, s: &[f64]) -> Point {
        let n = self.x.len();
        Point {
            x: s[..n].to_vec(),
            v: s[n..2 * n].to_vec(),
            r: s[2 * n..].to_vec(),
            theta: self.theta.clone(),
        }
    }
}

/// Random states and θ: n in [1, 5], β > 0, |γ| ≤ β, random signs, r away from 0.
pub fn random_point(case: &Case, rng: &mut StreamRng) -> Point {
    let n = case.n();
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.random::<f64>();
    let x = (0..n).map(|_| u(-0.5, 0.5)).collect();
    let v = (0..n).map(|_| u(-2.0, 2.0)).collect();
    let r = (0..case.ne())
        .map(|_| u(0.05, 0.6) * if u(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 })
        .collect();
    let mut theta: Vec<f64> = (0..n).map(|_| u(3.0, 15.0)).collect();
    theta.extend((0..n).map(|_| u(0.05, 1.0)));
    if case.damping.has_mass_term() {
        theta.push(u(0.1, 2.0));
    }
    for _ in 0..case.ne() {
        let beta = u(0.1, 5.0);
        theta.extend([beta, u(-beta, beta), u(1.0, 5.0)]);
    }
    Point { x, v, r, theta }
}

/// The truth simulator's chain at θ of `p`.
pub fn shear_chain(case: &Case, p: &Point) -> ShearChain {
    ShearChain::from_theta(&case.building(case.damping), &p.theta).unwrap()
}

/// Splits a point into a partition's (sampled, marginal) vectors through its layout; entries the
/// layout does not name (none for these partitions) stay 0.
pub fn split(
    layout: &Layout,
    p: &Point,
    n_sampled: usize,
    n_marginal: usize,
) -> (Vec<f64>, Vec<f64>) {
    let mut s = vec![0.0; n_sampled];
    let mut m = vec![0.0; n_marginal];
    let states = p.states();
    let slots = layout.states.iter().zip(&states);
    let params = layout.params.iter().zip(&p.theta);
    for (slot, &value) in slots.chain(params) {
        match *slot {
            Slot::Sampled(i) => s[i] = value,
            Slot::Marginal(i) => m[i] = value,
        }
    }
    (s, m)
}

/// Reads the physical states `[x, v, r]` back from a partition's vectors.
pub fn states_of(layout: &Layout, sampled: &[f64], marginal: &[f64]) -> Vec<f64> {
    layout
        .states
        .iter()
        .map(|slot| match *slot {
            Slot::Sampled(i) => sampled[i],
            Slot::Marginal(i) => marginal[i],
        })
        .collect()
}

/// `|a − b| ≤ tol · max(1, |a|, |b|)`.
#[track_caller]
pub fn close(a: f64, b: f64, tol: f64, what: &str) {
    let scale = 1f64.max(a.abs()).max(b.abs());
    assert!(
        (a - b).abs() <= tol * scale,
        "{what}: {a} vs {b} (diff {:e})",
        (a - b).abs()
    );
}

/// Element-wise [`close`] of two slices.
#[track_caller]
pub fn close_all(a: &[f64], b: &[f64], tol: f64, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        close(*x, *y, tol, &format!("{what} [{i}]"));
    }
}

/// Central finite-difference Jacobian (column-major, `m × n`) of `f` at `x`.
pub fn fd_jacobian(f: &dyn Fn(&[f64]) -> Vec<f64>, x: &[f64], h: f64) -> (usize, Vec<f64>) {
    let m = f(x).len();
    let mut jac = vec![0.0; m * x.len()];
    let mut xp = x.to_vec();
    for c in 0..x.len() {
        xp[c] = x[c] + h;
        let fp = f(&xp);
        xp[c] = x[c] - h;
        let fm = f(&xp);
        xp[c] = x[c];
        for r in 0..m {
            jac[r + c * m] = (fp[r] - fm[r]) / (2.0 * h);
        }
    }
    (m, jac)
}

/// The point whose states and θ are read from a partition's vectors through its layout
/// (the inverse of [`split`]).
pub fn join(layout: &Layout, sampled: &[f64], marginal: &[f64], n: usize) -> Point {
    let get = |slot: &Slot| match *slot {
        Slot::Sampled(i) => sampled[i],
        Slot::Marginal(i) => marginal[i],
    };
    let states: Vec<f64> = layout.states.iter().map(get).collect();
    let theta: Vec<f64> = layout.params.iter().map(get).collect();
    Point {
        x: states[..n].to_vec(),
        v: states[n..2 * n].to_vec(),
        r: states[2 * n..].to_vec(),
        theta,
    }
}
