//! Mode shapes of the identified model against the measured operating shapes: the modal
//! assurance criterion (docs/validation.md, "Mode shapes").
//!
//! The model's shape of a mode is the undamped shape φ of its chain (`models::modal::shapes_of`,
//! `K φ = ω² M φ`) whose frequency is nearest the mode's; the measured one is the operating shape
//! ψ at the paired peak of the transfer functions by quadrature picking
//! (`spectral::operating_shape`: Im H1 per measured floor). Near a lightly damped mode ψ is φ on
//! the measured floors times one real factor, so they are compared by
//!
//!   MAC(φ, ψ) = (Σ_i φ_i ψ_i)² / (Σ_i φ_i² · Σ_i ψ_i²),
//!
//! 1 for the same shape up to scale and sign, 0 for orthogonal shapes. The 95 % interval is the
//! central 95 % of the MAC over θ drawn from the posterior as the modal intervals draw them (its
//! own stream), with the measured ψ held fixed: the model's statistical uncertainty, not the
//! Welch estimate's. With one measured channel every shape is the same (MAC ≡ 1), so no MAC is
//! reported.

use models::description::StructureDescription;
use models::modal::{shapes_of, Shape};

use super::free_run::{percentile_sorted, QuantileDraw};
use super::spectral::{operating_shape, TransferEstimate};
use super::ModePair;

/// Purpose of the random stream of the shapes' draws.
pub(crate) const SHAPES_PURPOSE: &str = "validation-shapes";

/// θ drawn for the shapes' intervals.
pub(crate) const SHAPE_DRAWS: usize = 400;

/// A MAC below this says the paired peak is not the model's mode: less than half of the measured
/// shape's squared norm lies along the model's shape (MAC = cos² of the angle between them; 0.5
/// is 45°). On the frame a frequency pairing of the 11.13 Hz mode with a 9.01 Hz bump of a sine
/// record's input gives 0.062, the particle filters' misplaced modes 0.012–0.023; the pairings
/// of the frame's MPF-EKF2 variants and of the foreign corpus 0.77–1.0.
pub const UNLIKE_MAC: f64 = 0.5;

/// MAC(φ, ψ) of two shapes of the same length; NaN when either is zero or the lengths differ.
pub fn mac(phi: &[f64], psi: &[f64]) -> f64 {
    if phi.len() != psi.len() {
        return f64::NAN;
    }
    let dot: f64 = phi.iter().zip(psi).map(|(a, b)| a * b).sum();
    let pp: f64 = phi.iter().map(|a| a * a).sum();
    let qq: f64 = psi.iter().map(|b| b * b).sum();
    if pp > 0.0 && qq > 0.0 {
        dot * dot / (pp * qq)
    } else {
        f64::NAN
    }
}

/// ψ scaled onto φ by least squares, a·ψ with a = ψᵀφ / ψᵀψ — the measured shape drawn beside
/// the model's (zeros when ψ is zero).
pub fn aligned(phi: &[f64], psi: &[f64]) -> Vec<f64> {
    let dot: f64 = phi.iter().zip(psi).map(|(a, b)| a * b).sum();
    let qq: f64 = psi.iter().map(|b| b * b).sum();
    if qq <= 0.0 {
        return vec![0.0; psi.len()];
    }
    psi.iter().map(|b| b * dot / qq).collect()
}

/// φ on the measured floors (1-based storeys; NaN for a floor φ does not have).
pub(crate) fn on_floors(phi: &[f64], floors: &[usize]) -> Vec<f64> {
    floors
        .iter()
        .map(|s| phi.get(s.wrapping_sub(1)).copied().unwrap_or(f64::NAN))
        .collect()
}

/// The index of the shape whose frequency is nearest `f_hz` (in log-frequency).
fn nearest(shapes: &[Shape], f_hz: f64) -> Option<usize> {
    shapes
        .iter()
        .enumerate()
        .filter(|(_, s)| s.frequency_hz > 0.0)
        .min_by(|(_, a), (_, b)| {
            let d = |s: &Shape| (s.frequency_hz / f_hz).ln().abs();
            d(a).total_cmp(&d(b))
        })
        .map(|(i, _)| i)
}

/// Whether shapes can be compared: two storeys or more and two measured channels or more.
pub(crate) fn comparable(d: &StructureDescription, floors: &[usize]) -> bool {
    d.storeys >= 2 && floors.len() >= 2
}

/// Fills each pair's model shape at θ's stiffnesses `k` (with `masses`) and, where it has a
/// measured peak, its operating shape from `t` and the MAC on the measured `floors`.
pub(crate) fn compare(
    pairs: &mut [ModePair],
    masses: &[f64],
    k: &[f64],
    t: Option<&TransferEstimate>,
    floors: &[usize],
) {
    let Ok(shapes) = shapes_of(masses, k) else {
        return;
    };
    for p in pairs.iter_mut() {
        let Some(r) = nearest(&shapes, p.model_hz) else {
            continue;
        };
        p.model_shape = shapes[r].phi.clone();
        let psi = t
            .zip(p.measured_hz)
            .and_then(|(t, f)| operating_shape(t, f));
        if let Some(psi) = psi {
            let m = mac(&on_floors(&p.model_shape, floors), &psi);
            p.mac = m.is_finite().then_some(m);
            p.operating_shape = psi;
        }
    }
}

/// Each pair's shape interval per storey and MAC interval over `SHAPE_DRAWS` θ drawn from `q` on
/// the stream (seed, run, `SHAPES_PURPOSE`): a draw's shape is the one nearest the pair's mode
/// in frequency, scaled onto the θ_val shape by least squares (so that sign and scale match). A
/// pair keeps no interval when fewer than half the draws give a shape.
pub(crate) fn intervals(
    pairs: &mut [ModePair],
    d: &StructureDescription,
    q: &QuantileDraw,
    (seed, run): (u64, u64),
    floors: &[usize],
) {
    let n = d.storeys;
    let mut rng = core_filters::rng::stream(seed, run, SHAPES_PURPOSE);
    let mut shape_draws: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); n]; pairs.len()];
    let mut mac_draws: Vec<Vec<f64>> = vec![Vec::new(); pairs.len()];
    for _ in 0..SHAPE_DRAWS {
        let theta = q.draw(&mut rng);
        let Some(Ok(shapes)) = theta.get(..n).map(|k| shapes_of(&d.masses, k)) else {
            continue;
        };
        for (i, p) in pairs.iter().enumerate() {
            if p.model_shape.len() != n {
                continue;
            }
            let Some(r) = nearest(&shapes, p.model_hz) else {
                continue;
            };
            let phi = &shapes[r].phi;
            let dot: f64 = phi.iter().zip(&p.model_shape).map(|(a, b)| a * b).sum();
            let norm: f64 = phi.iter().map(|a| a * a).sum();
            if !(norm > 0.0 && dot.is_finite()) {
                continue;
            }
            for (j, v) in phi.iter().enumerate() {
                shape_draws[i][j].push(v * dot / norm);
            }
            if !p.operating_shape.is_empty() {
                let m = mac(&on_floors(phi, floors), &p.operating_shape);
                if m.is_finite() {
                    mac_draws[i].push(m);
                }
            }
        }
    }
    let central = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        [percentile_sorted(v, 0.025), percentile_sorted(v, 0.975)]
    };
    for ((p, shapes), macs) in pairs.iter_mut().zip(&mut shape_draws).zip(&mut mac_draws) {
        if shapes.first().is_some_and(|s| 2 * s.len() >= SHAPE_DRAWS) {
            p.model_shape_95 = shapes.iter_mut().map(central).collect();
        }
        if 2 * macs.len() >= SHAPE_DRAWS {
            p.mac_95 = Some(central(macs));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mac_is_one_for_a_scaled_shape_and_zero_for_an_orthogonal_one() {
        let phi = [0.45, 0.8, 1.0];
        let psi: Vec<f64> = phi.iter().map(|p| -3.0 * p).collect();
        assert!((mac(&phi, &psi) - 1.0).abs() < 1e-12);
        let back = aligned(&phi, &psi);
        for (a, b) in back.iter().zip(&phi) {
            assert!((a - b).abs() < 1e-12, "{back:?}");
        }
        // Orthogonal: φ·χ = 0.45 − 1.6 + 1.15 = 0.
        assert!(mac(&phi, &[1.0, -2.0, 1.15]).abs() < 1e-12);
        // In between, by hand: φ·ψ = 0.45 + 0.4 + 0.9 = 1.75; |φ|² = 1.8425, |ψ|² = 2.06.
        let mixed = [1.0, 0.5, 0.9];
        let m = mac(&phi, &mixed);
        let want = 1.75f64.powi(2) / (1.8425 * 2.06);
        assert!((m - want).abs() < 1e-12, "{m} vs {want}");
        assert!((mac(&mixed, &phi) - m).abs() < 1e-15);
        // The aligned shape is the least-squares one: its residual is orthogonal to ψ.
        let a = aligned(&phi, &mixed);
        let r: f64 = phi
            .iter()
            .zip(&a)
            .zip(&mixed)
            .map(|((p, a), m)| (p - a) * m)
            .sum();
        assert!(r.abs() < 1e-12);
        assert!(mac(&phi, &[0.0; 3]).is_nan());
        assert!(mac(&phi, &mixed[..2]).is_nan());
        assert_eq!(aligned(&phi, &[0.0; 3]), vec![0.0; 3]);
    }

    /// The record's intervals of a 3-storey θ = (k, c) with each k's 95 % interval ±`spread`
    /// of its value (c fixed), as a posterior to draw from.
    fn posterior(theta: &[f64], spread: f64) -> QuantileDraw {
        use crate::observe::{ParamIntervals, PosteriorShape};
        use core_filters::credible::CredibleInterval;
        let names: Vec<String> = ["k1", "k2", "k3", "c1", "c2", "c3"]
            .map(String::from)
            .into();
        let intervals: Vec<ParamIntervals> = names
            .iter()
            .zip(theta)
            .enumerate()
            .map(|(i, (n, &v))| {
                let w = if i < 3 { spread } else { 0.0 };
                ParamIntervals {
                    parameter: n.clone(),
                    shape: PosteriorShape::GaussianMixture,
                    intervals: [(0.5, 0.35), (0.9, 0.85), (0.95, 1.0)]
                        .iter()
                        .map(|&(level, f)| CredibleInterval {
                            level,
                            lo: v * (1.0 - w * f),
                            hi: v * (1.0 + w * f),
                        })
                        .collect(),
                    error: None,
                    mc_se: None,
                }
            })
            .collect();
        QuantileDraw::new(&names, &intervals).unwrap()
    }

    #[test]
    fn the_shapes_intervals_collapse_on_a_point_posterior_and_hold_the_value_otherwise() {
        use models::description::StructureDescription;
        use models::sensors::MeasurementKind;
        let d = StructureDescription {
            storeys: 3,
            masses: vec![1.0, 1.0, 1.2],
            hysteretic: vec![],
            sensors: vec![1, 2, 3],
            measurement: MeasurementKind::Absolute,
            damping: Default::default(),
            ground_between: Default::default(),
        };
        let theta = [3000.0, 3100.0, 3800.0, 0.1, 0.1, 0.8];
        let modes = models::modal::modes_of(&d.masses, &theta[..3], &theta[3..]).unwrap();
        // "Measured" shapes: the truth's with one floor off by 5 % of the largest component.
        let truth = shapes_of(&d.masses, &theta[..3]).unwrap();
        let mut pairs: Vec<ModePair> = modes
            .modes
            .iter()
            .enumerate()
            .map(|(i, m)| ModePair {
                mode: i + 1,
                model_hz: m.frequency_hz,
                damping_ratio: m.damping_ratio,
                measured_hz: Some(m.frequency_hz),
                difference_percent: Some(0.0),
                excitation_db: Some(0.0),
                model_hz_95: None,
                damping_ratio_95: None,
                model_shape: truth[i].phi.clone(),
                model_shape_95: Vec::new(),
                operating_shape: truth[i]
                    .phi
                    .iter()
                    .enumerate()
                    .map(|(j, v)| 2.0 * v + if j == 0 { 0.1 } else { 0.0 })
                    .collect(),
                mac: None,
                mac_95: None,
            })
            .collect();
        for p in &mut pairs {
            p.mac = Some(mac(&p.model_shape, &p.operating_shape));
        }
        let floors = [1, 2, 3];
        let mut point = pairs.clone();
        intervals(&mut point, &d, &posterior(&theta, 0.0), (1, 0), &floors);
        for p in &point {
            let [lo, hi] = p.mac_95.unwrap();
            assert!((lo - p.mac.unwrap()).abs() < 1e-12 && (hi - lo).abs() < 1e-12);
            for ([lo, hi], v) in p.model_shape_95.iter().zip(&p.model_shape) {
                assert!((lo - v).abs() < 1e-12 && (hi - v).abs() < 1e-12);
            }
        }
        // k within ±10 %: intervals of some width that hold θ_val's shape and MAC, the same
        // for the same (seed, run).
        let mut wide = pairs.clone();
        intervals(&mut wide, &d, &posterior(&theta, 0.1), (1, 0), &floors);
        let mut again = pairs.clone();
        intervals(&mut again, &d, &posterior(&theta, 0.1), (1, 0), &floors);
        assert_eq!(wide, again);
        for p in &wide {
            let [lo, hi] = p.mac_95.unwrap();
            let m = p.mac.unwrap();
            assert!(
                lo <= m && m <= hi && hi - lo > 1e-4,
                "mode {}: {m} in [{lo}, {hi}]",
                p.mode
            );
            for ([lo, hi], v) in p.model_shape_95.iter().zip(&p.model_shape) {
                assert!(
                    *lo <= v + 1e-12 && v - 1e-12 <= *hi,
                    "mode {}: {v} in [{lo}, {hi}]",
                    p.mode
                );
            }
            assert!(p.model_shape_95.iter().any(|[lo, hi]| hi - lo > 1e-3));
        }
    }

    #[test]
    fn measured_floors_pick_the_shapes_components() {
        let phi = [0.3, 0.7, 1.0];
        assert_eq!(on_floors(&phi, &[1, 3]), vec![0.3, 1.0]);
        assert!(on_floors(&phi, &[4])[0].is_nan());
        assert!(on_floors(&phi, &[0])[0].is_nan());
    }
}
