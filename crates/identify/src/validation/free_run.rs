//! The free run: the identified building simulated from rest under the measured ground motion
//! with the toolkit's own simulator ([`models::integrate`], the equations of
//! [`models::structure::ShearChain`]), and its fit to every measured channel.
//!
//! - fit = 100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖) per channel (the system-identification convention: 100 %
//!   is a perfect prediction, 0 % is no better than the channel's mean, it can be negative);
//! - NRMSE = RMSE / RMS(y) per channel (SPEC §7, the measured channel in place of the truth).
//!
//! The band comes from θ drawn from the run's posterior as the record summarises it
//! ([`QuantileDraw`]).

use models::description::StructureDescription;
use models::ground_between::GroundBetween;
use models::integrate::{
    simulate_adaptive, simulate_linear_exact, simulate_rk4, IntegrateError, Tolerance,
};
use models::sensors::MeasurementKind;
use models::structure::{ShearChain, StructureError};
use rand::Rng;
use thiserror::Error;

use crate::observe::ParamIntervals;
pub use crate::record::validation::Integrator;

/// The free run's integrator of a building with hysteretic elements: adaptive, tighter than the
/// SPEC §7 validation default so that the integration error (relative ~10⁻⁸) is far below any
/// fit difference worth reporting.
const FREE_RUN_ADAPTIVE: Integrator = Integrator::Adaptive(Tolerance {
    rtol: 1e-8,
    atol: 1e-12,
});

/// The free run's integrator for `chain`: the exact solution where the building is linear (no
/// hysteretic element; the solution the adaptive integrator approaches, about 70 times cheaper:
/// the adaptive runs were 40 % of the README frame command's CPU time, docs/performance.md,
/// "The free run of a linear building"), the adaptive one otherwise.
pub(crate) fn free_run_integrator(chain: &ShearChain) -> Integrator {
    if chain.elements().is_empty() {
        Integrator::ExactLinear
    } else {
        FREE_RUN_ADAPTIVE
    }
}

/// Failures of a free run; each says what was wrong.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FreeRunError {
    #[error(
        "θ has {found} entries; a building of {storeys} storeys with {elements} Bouc–Wen \
         element(s) has {expected} (k1..kN, c1..cN, alpha with the storey+mass damping form, \
         then β, γ, n per element)"
    )]
    ThetaLength {
        found: usize,
        expected: usize,
        storeys: usize,
        elements: usize,
    },
    #[error("θ is not a valid structure: {0}")]
    Structure(#[from] StructureError),
    #[error("the free-run integration failed: {0}")]
    Integrate(#[from] IntegrateError),
    #[error("channel a{storey}: the building has only {storeys} storeys")]
    Channel { storey: usize, storeys: usize },
    #[error("the record has {0} samples; at least 2 are needed")]
    TooShort(usize),
}

crate::error::domain_error!(FreeRunError);

/// The chain of building `d` with parameters θ = `[k1..kN, c1..cN, (α), (β, γ, n) per
/// element]` (α with the storey+mass damping form of `d`).
pub fn chain_of(d: &StructureDescription, theta: &[f64]) -> Result<ShearChain, FreeRunError> {
    let building = d.building().map_err(StructureError::from)?;
    let (n, elements) = (building.storeys(), building.hysteretic().len());
    let expected = 2 * n + building.damping().extra_parameters() + 3 * elements;
    if theta.len() != expected {
        return Err(FreeRunError::ThetaLength {
            found: theta.len(),
            expected,
            storeys: n,
            elements,
        });
    }
    Ok(ShearChain::from_theta(&building, theta)?)
}

/// The accelerations the channels of 1-based storeys `sensors` record (`kind`) when `chain`
/// starts from rest under ground acceleration `ug` sampled at `dt`: one vector per channel.
/// Computed exactly as the data generator computes its clean channels
/// ([`models::dataset::generate`]): relative accelerations from the states, plus ü_g for
/// absolute ones.
pub fn simulate_channels(
    chain: &ShearChain,
    ug: &[f64],
    dt: f64,
    sensors: &[usize],
    kind: MeasurementKind,
    integrator: Integrator,
) -> Result<Vec<Vec<f64>>, FreeRunError> {
    simulate_channels_between(
        chain,
        ug,
        dt,
        sensors,
        kind,
        integrator,
        GroundBetween::Linear,
    )
}

/// Sub-intervals per sample interval of a free run whose ground motion is band-limited between
/// samples: the integrators then interpolate linearly only within a sub-interval, which keeps
/// sinc²(f·dt/8) ≥ 0.987 of the input's amplitude up to the Nyquist frequency (1 − 0.995 at
/// 0.3 of the sampling rate, where linear interpolation between the samples keeps 0.74).
pub const BAND_LIMITED_REFINE: usize = 8;

/// [`simulate_channels`] with `ug` reconstructed between its samples as `between` says: linear
/// (SPEC §2), or band-limited on a grid [`BAND_LIMITED_REFINE`] times finer, the building
/// integrated on it and read at the sample times.
pub fn simulate_channels_between(
    chain: &ShearChain,
    ug: &[f64],
    dt: f64,
    sensors: &[usize],
    kind: MeasurementKind,
    integrator: Integrator,
    between: GroundBetween,
) -> Result<Vec<Vec<f64>>, FreeRunError> {
    let n = chain.storeys();
    if let Some(&s) = sensors.iter().find(|&&s| s == 0 || s > n) {
        return Err(FreeRunError::Channel {
            storey: s,
            storeys: n,
        });
    }
    if ug.len() < 2 {
        return Err(FreeRunError::TooShort(ug.len()));
    }
    let every = match between {
        GroundBetween::Linear => 1,
        GroundBetween::BandLimited => BAND_LIMITED_REFINE,
    };
    // The record itself when nothing is refined (no copy per free run or band draw).
    let fine: std::borrow::Cow<[f64]> = match every {
        1 => std::borrow::Cow::Borrowed(ug),
        _ => std::borrow::Cow::Owned(models::ground_between::refine(ug, dt, every, between)),
    };
    let h = dt / every as f64;
    let traj = match integrator {
        Integrator::Adaptive(tol) => simulate_adaptive(chain, &fine, h, tol)?,
        Integrator::ExactLinear => simulate_linear_exact(chain, &fine, h)?,
        Integrator::Rk4 => {
            let t = simulate_rk4(chain, &fine, h);
            if let Some(k) = t.rows().position(|r| r.iter().any(|v| !v.is_finite())) {
                return Err(IntegrateError::NonFinite { t: k as f64 * h }.into());
            }
            t
        }
    };
    let mut all = vec![0.0; n];
    let mut out = vec![Vec::with_capacity(ug.len()); sensors.len()];
    for (k, &u) in ug.iter().enumerate().take(traj.len().div_ceil(every)) {
        chain.relative_accelerations(traj.state(k * every), u, &mut all);
        for (ch, &s) in out.iter_mut().zip(sensors) {
            let mut y = all[s - 1];
            if kind == MeasurementKind::Absolute {
                y += u;
            }
            ch.push(y);
        }
    }
    Ok(out)
}

/// fit = 100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖) in % (NaN when y is constant).
pub fn fit_percent(y: &[f64], yhat: &[f64]) -> f64 {
    let n = y.len().min(yhat.len());
    if n == 0 {
        return f64::NAN;
    }
    let mean = y[..n].iter().sum::<f64>() / n as f64;
    let (mut num, mut den) = (0.0, 0.0);
    for k in 0..n {
        num += (y[k] - yhat[k]).powi(2);
        den += (y[k] - mean).powi(2);
    }
    if den > 0.0 {
        100.0 * (1.0 - (num / den).sqrt())
    } else {
        f64::NAN
    }
}

/// NRMSE = RMSE(y − ŷ) / RMS(y) (SPEC §7).
pub fn nrmse(y: &[f64], yhat: &[f64]) -> f64 {
    let n = y.len().min(yhat.len());
    let (mut num, mut den) = (0.0, 0.0);
    for k in 0..n {
        num += (y[k] - yhat[k]).powi(2);
        den += y[k] * y[k];
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else {
        f64::NAN
    }
}

/// Percentile `p` ∈ [0, 1] of sorted values, linear between order statistics.
pub(crate) fn percentile_sorted(sorted: &[f64], p: f64) -> f64 {
    match sorted.len() {
        0 => f64::NAN,
        1 => sorted[0],
        m => {
            let x = p.clamp(0.0, 1.0) * (m - 1) as f64;
            let i = (x.floor() as usize).min(m - 2);
            let f = x - i as f64;
            sorted[i] + f * (sorted[i + 1] - sorted[i])
        }
    }
}

/// Draws of θ from the posterior as a run record summarises it.
///
/// A record holds, per parameter, the central 50, 90 and 95 % credible intervals of the final
/// posterior (for marginalised parameters a Gaussian mixture over the particles, for sampled
/// ones the weighted particle sample): six quantiles, 2.5, 5, 25, 75, 95 and 97.5 %. A draw
/// takes u in (0.025, 0.975) and returns the quantile function interpolated linearly between
/// these six points — a distribution with the record's own quantiles (skewness included, no
/// Gaussian or log-normal shape assumed). The 2.5 % tails on each side are left out (draws stay
/// inside the 95 % interval), as is stated wherever the band is shown.
///
/// The parameters are drawn together through a Gaussian copula of the record's posterior
/// correlation matrix ([`QuantileDraw::with_correlation`]): z ~ N(0, R), u_j = 0.025 +
/// 0.95 Φ(z_j). A posterior constrains combinations of parameters (a mode's frequency) far more
/// than each alone (neighbouring stiffnesses); drawn independently, the draws leave that ridge
/// and the band shows a spread the data exclude. A record without correlations (written before
/// they were recorded) is drawn independently, u ~ U(0.025, 0.975), and says so.
///
/// A run that is one Gaussian filter has a posterior the record states exactly: N(θ_val, Σ),
/// restricted to where k, c and α are physical ([`QuantileDraw::with_gaussian`]). Its draws come
/// from that Gaussian itself, kept where every parameter lies inside its recorded 95 % interval
/// (which the truncation at zero holds ≥ 0). The copula cannot stand in for it there: each
/// marginal truncated at zero alone moves up, while the data fix a combination (a mode's damping
/// c₁/m₁ + α, a ridge of the Gaussian) far better than any one of them — coupled quantile by
/// quantile, every truncated parameter's shift adds up along the ridge, and a mode's drawn
/// damping ratios excluded the value θ_val gives.
#[derive(Debug, Clone)]
pub struct QuantileDraw {
    /// Per parameter, (probability, quantile) increasing in both.
    tables: Vec<Vec<(f64, f64)>>,
    /// The lower Cholesky factor of the correlation matrix, when the draws are correlated.
    chol: Option<nalgebra::DMatrix<f64>>,
    /// The posterior's mean and s.d. when it is one Gaussian (with `chol`, its covariance).
    gaussian: Option<(Vec<f64>, Vec<f64>)>,
    /// θ of another record: per parameter the between-part spread added to each draw, with its
    /// t distribution (none: nothing added).
    between: Vec<Option<(Between, rand_distr::StudentT<f64>)>>,
}

/// One parameter's between-part spread as a draw adds it ([`QuantileDraw::with_between`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Between {
    /// The between-part s.d. τ (0: nothing added).
    pub tau: f64,
    /// The parts that gave τ (the shift is τ times Student's t on `parts − 2` degrees of
    /// freedom); fewer than 3 add nothing.
    pub parts: usize,
    /// Whether the parameter is held ≥ 0 (k, c, α).
    pub bounded: bool,
}

impl Between {
    /// Nothing added.
    pub const NONE: Between = Between {
        tau: 0.0,
        parts: 0,
        bounded: false,
    };
}

/// Tries of a draw from the joint Gaussian before it falls back to the copula: an acceptance
/// below 1/1000 means the Gaussian is not the posterior the intervals describe.
const GAUSSIAN_TRIES: usize = 1000;

/// Tries of a physical between-record shift of one parameter before it is left out.
const BETWEEN_TRIES: usize = 1000;

impl QuantileDraw {
    /// From the record's intervals, in the order of `names`; an error names the parameter whose
    /// intervals are missing or inconsistent.
    pub fn new(names: &[String], credible: &[ParamIntervals]) -> Result<Self, String> {
        let tables = names
            .iter()
            .map(|name| {
                let p = credible
                    .iter()
                    .find(|p| &p.parameter == name)
                    .ok_or_else(|| format!("{name}: the record holds no credible intervals"))?;
                if let Some(e) = &p.error {
                    return Err(format!("{name}: no credible intervals ({e})"));
                }
                let get = |level: f64| {
                    p.at(level).map(|c| (c.lo, c.hi)).ok_or_else(|| {
                        format!(
                            "{name}: the record holds no {:.0} % interval",
                            level * 100.0
                        )
                    })
                };
                let (l95, h95) = get(0.95)?;
                let (l90, h90) = get(0.90)?;
                let (l50, h50) = get(0.50)?;
                let t = vec![
                    (0.025, l95),
                    (0.05, l90),
                    (0.25, l50),
                    (0.75, h50),
                    (0.95, h90),
                    (0.975, h95),
                ];
                if t.iter().any(|(_, q)| !q.is_finite()) || t.windows(2).any(|w| w[1].1 < w[0].1) {
                    return Err(format!(
                        "{name}: the credible intervals are not finite and nested"
                    ));
                }
                Ok(t)
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            tables,
            chol: None,
            gaussian: None,
            between: Vec::new(),
        })
    }

    /// The same marginals drawn through the Gaussian copula of `correlation` (one row per
    /// parameter, in the order of [`QuantileDraw::new`]'s `names`). An empty matrix, one of
    /// another size or one that is not a correlation matrix (no Cholesky factor even with a
    /// diagonal of 1 + 10⁻⁸, after round-off) leaves the draws independent:
    /// [`QuantileDraw::correlated`] says which.
    pub fn with_correlation(mut self, correlation: &[Vec<f64>]) -> Self {
        let n = self.tables.len();
        if n == 0 || correlation.len() != n || correlation.iter().any(|r| r.len() != n) {
            return self;
        }
        let r = nalgebra::DMatrix::from_fn(n, n, |a, b| {
            // Symmetrised: the record's rows are written from one triangle, but a hand-edited
            // record need not be.
            0.5 * (correlation[a][b] + correlation[b][a]) + if a == b { 1e-8 } else { 0.0 }
        });
        if r.iter().all(|v| v.is_finite()) {
            self.chol = r.cholesky().map(|c| c.l());
        }
        self
    }

    /// Whether the draws follow the posterior's correlations (else they are independent).
    pub fn correlated(&self) -> bool {
        self.chol.is_some()
    }

    /// The draws taken from the Gaussian N(`mean`, D R D) itself (D = diag(`sd`), R the
    /// correlation matrix of [`QuantileDraw::with_correlation`]), kept where every parameter lies
    /// inside its 95 % interval: the posterior of a run that is one Gaussian filter, whose
    /// intervals are that Gaussian's truncated at the physical bounds. Without a correlation
    /// matrix, or with a mean or s.d. that is not finite or of another length, the draws stay
    /// the copula's ([`QuantileDraw::gaussian`] says which).
    pub fn with_gaussian(mut self, mean: &[f64], sd: &[f64]) -> Self {
        let n = self.tables.len();
        let finite = |v: &[f64]| v.len() == n && v.iter().all(|x| x.is_finite());
        if self.chol.is_some() && finite(mean) && finite(sd) && sd.iter().all(|&s| s >= 0.0) {
            self.gaussian = Some((mean.to_vec(), sd.to_vec()));
        }
        self
    }

    /// Whether the draws come from the posterior's joint Gaussian (else from the copula).
    pub fn gaussian(&self) -> bool {
        self.gaussian.is_some()
    }

    /// θ of **another** record of the structure rather than of this one: each draw from the
    /// posterior is shifted by δ_j = τ_j·t_j (t_j Student's t on `parts − 2` degrees of freedom,
    /// independent between parameters), the random-effects prediction of a new part's θ whose
    /// quantiles the widened intervals state (`crate::spread`). The shift is added to a joint
    /// draw, not built into the marginals: the posterior's ridges stay where the data put them
    /// within the record, and move as a whole between records. A shift that takes a parameter
    /// held ≥ 0 below zero is drawn again (`BETWEEN_TRIES` times, then that parameter's shift is
    /// left out): the shifts are the random effects restricted to a physical structure.
    /// `between` has one entry per parameter (another length: nothing is added,
    /// [`QuantileDraw::shifted`] says which).
    pub fn with_between(mut self, between: &[Between]) -> Self {
        if between.len() == self.tables.len()
            && between.iter().all(|b| b.tau.is_finite() && b.tau >= 0.0)
        {
            self.between = between
                .iter()
                .map(|b| {
                    let t = (b.tau > 0.0 && b.parts >= 3)
                        .then(|| rand_distr::StudentT::new((b.parts - 2) as f64).ok())
                        .flatten();
                    t.map(|t| (*b, t))
                })
                .collect();
        }
        self
    }

    /// Whether the draws are of another record (shifted by the between-part spread).
    pub fn shifted(&self) -> bool {
        self.between.iter().any(Option::is_some)
    }

    /// Whether every entry of `theta` lies inside its parameter's 95 % interval.
    fn inside(&self, theta: &[f64]) -> bool {
        self.tables.iter().zip(theta).all(|(t, &x)| {
            let (lo, hi) = (t[0].1, t[t.len() - 1].1);
            lo <= x && x <= hi
        })
    }

    /// One θ: of this record, shifted to another's when [`QuantileDraw::with_between`] says so.
    pub fn draw<R: Rng + ?Sized>(&self, rng: &mut R) -> Vec<f64> {
        let mut theta = self.draw_posterior(rng);
        for (x, (b, t)) in theta
            .iter_mut()
            .zip(&self.between)
            .filter_map(|(x, b)| b.as_ref().map(|b| (x, b)))
        {
            for _ in 0..BETWEEN_TRIES {
                let shifted = *x + b.tau * rng.sample::<f64, _>(*t);
                if !b.bounded || shifted >= 0.0 {
                    *x = shifted;
                    break;
                }
            }
        }
        theta
    }

    /// One θ of the record's own posterior.
    fn draw_posterior<R: Rng + ?Sized>(&self, rng: &mut R) -> Vec<f64> {
        if let (Some((mean, sd)), Some(l)) = (&self.gaussian, &self.chol) {
            let n = self.tables.len();
            for _ in 0..GAUSSIAN_TRIES {
                let e = nalgebra::DVector::from_fn(n, |_, _| {
                    rng.sample::<f64, _>(rand_distr::StandardNormal)
                });
                let z = l * e;
                let theta: Vec<f64> = (0..n).map(|j| mean[j] + sd[j] * z[j]).collect();
                if self.inside(&theta) {
                    return theta;
                }
            }
        }
        let u: Vec<f64> = match &self.chol {
            None => (0..self.tables.len())
                .map(|_| 0.025 + 0.95 * rng.random::<f64>())
                .collect(),
            Some(l) => {
                let e = nalgebra::DVector::from_fn(self.tables.len(), |_, _| {
                    rng.sample::<f64, _>(rand_distr::StandardNormal)
                });
                (l * e)
                    .iter()
                    .map(|&z| 0.025 + 0.95 * core_filters::credible::normal_cdf(z))
                    .collect()
            }
        };
        self.tables
            .iter()
            .zip(u)
            .map(|(t, u)| {
                let i = t
                    .windows(2)
                    .position(|w| u <= w[1].0)
                    .unwrap_or(t.len() - 2);
                let ((p0, q0), (p1, q1)) = (t[i], t[i + 1]);
                q0 + (q1 - q0) * (u - p0) / (p1 - p0)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core_filters::credible::CredibleInterval;

    #[test]
    fn fit_and_nrmse_follow_their_definitions() {
        let y = [1.0, -1.0, 1.0, -1.0];
        assert_eq!(fit_percent(&y, &y), 100.0);
        assert_eq!(fit_percent(&y, &[0.0; 4]), 0.0);
        assert!((fit_percent(&y, &[0.5, -0.5, 0.5, -0.5]) - 50.0).abs() < 1e-12);
        assert!((nrmse(&y, &[0.5, -0.5, 0.5, -0.5]) - 0.5).abs() < 1e-12);
        assert!(fit_percent(&[2.0; 3], &[2.0; 3]).is_nan());
    }

    #[test]
    fn quantile_draws_reproduce_the_recorded_quantiles() {
        // Intervals of a skewed distribution; the empirical quantiles of many draws must match
        // them within a few binomial standard errors of the quantile level.
        let ci = |level: f64, lo: f64, hi: f64| CredibleInterval { level, lo, hi };
        let p = ParamIntervals {
            parameter: "k1".into(),
            shape: crate::observe::PosteriorShape::GaussianMixture,
            intervals: vec![ci(0.5, 9.0, 11.0), ci(0.9, 8.0, 14.0), ci(0.95, 7.5, 16.0)],
            error: None,
            mc_se: None,
        };
        let q = QuantileDraw::new(&["k1".into()], &[p]).unwrap();
        let mut rng = core_filters::rng::stream(1, 0, "test");
        let m = 20_000;
        let mut v: Vec<f64> = (0..m).map(|_| q.draw(&mut rng)[0]).collect();
        v.sort_by(f64::total_cmp);
        // Among draws (restricted to [2.5 %, 97.5 %]) the level p sits at (p − 0.025)/0.95.
        for (p, want) in [(0.05, 8.0), (0.25, 9.0), (0.75, 11.0), (0.95, 14.0)] {
            let r = (p - 0.025) / 0.95;
            let se = (r * (1.0 - r) / m as f64).sqrt();
            let below = v.partition_point(|x| *x < want) as f64 / m as f64;
            assert!((below - r).abs() < 4.0 * se, "{p}: {below} vs {r}");
        }
        assert!(v[0] >= 7.5 && v[m - 1] <= 16.0);
        let missing = QuantileDraw::new(&["c1".into()], &[]).unwrap_err();
        assert!(missing.contains("c1"), "{missing}");
    }

    /// θ of another record: each draw is the posterior's shifted by τ·t on parts − 2 degrees of
    /// freedom. With a posterior narrow beside τ the draws' quantiles are Student's t's, scaled
    /// by τ about the posterior (the share of draws below each within 4 binomial standard
    /// errors); a parameter held ≥ 0 is never drawn below 0; an entry per parameter is needed,
    /// and τ = 0 or fewer than 3 parts shift nothing.
    #[test]
    fn another_records_draws_add_the_between_part_spread() {
        let ci = |level: f64, lo: f64, hi: f64| CredibleInterval { level, lo, hi };
        let param = |name: &str, centre: f64, w: f64| ParamIntervals {
            parameter: name.into(),
            shape: crate::observe::PosteriorShape::GaussianMixture,
            intervals: vec![
                ci(0.5, centre - w, centre + w),
                ci(0.9, centre - 2.0 * w, centre + 2.0 * w),
                ci(0.95, centre - 3.0 * w, centre + 3.0 * w),
            ],
            error: None,
            mc_se: None,
        };
        let names: Vec<String> = vec!["k1".into(), "c1".into()];
        let credible = [param("k1", 100.0, 0.01), param("c1", 0.05, 0.01)];
        let between = [
            Between {
                tau: 5.0,
                parts: 8,
                bounded: true,
            },
            Between {
                tau: 1.0,
                parts: 8,
                bounded: true,
            },
        ];
        let q = QuantileDraw::new(&names, &credible)
            .unwrap()
            .with_between(&between);
        assert!(q.shifted());
        let mut rng = core_filters::rng::stream(1, 0, "test");
        let m = 20_000;
        let draws: Vec<Vec<f64>> = (0..m).map(|_| q.draw(&mut rng)).collect();
        let mut k1: Vec<f64> = draws.iter().map(|d| d[0]).collect();
        k1.sort_by(f64::total_cmp);
        // Student's t on 6 degrees of freedom: its 75, 95 and 97.5 % points (tables).
        for (p, t) in [(0.75, 0.7176), (0.95, 1.9432), (0.975, 2.4469)] {
            for (share, x) in [(p, 100.0 + 5.0 * t), (1.0 - p, 100.0 - 5.0 * t)] {
                let se = (share * (1.0 - share) / m as f64).sqrt();
                let below = k1.partition_point(|v| *v < x) as f64 / m as f64;
                assert!((below - share).abs() < 4.0 * se, "{x}: {below} vs {share}");
            }
        }
        // c1: τ twenty times its value; held ≥ 0, and shifted far beyond its own interval.
        assert!(draws.iter().all(|d| d[1] >= 0.0));
        let beyond = draws.iter().filter(|d| d[1] > 0.08).count();
        assert!(
            beyond > m / 4,
            "{beyond} of {m} beyond the posterior's 95 %"
        );
        // Nothing to add: the record's own posterior, draw for draw.
        let own = QuantileDraw::new(&names, &credible).unwrap();
        for nothing in [
            vec![between[0]],
            vec![Between::NONE, Between::NONE],
            vec![
                Between {
                    parts: 2,
                    ..between[0]
                },
                Between::NONE,
            ],
        ] {
            let q = QuantileDraw::new(&names, &credible)
                .unwrap()
                .with_between(&nothing);
            assert!(!q.shifted());
            let (mut a, mut b) = (
                core_filters::rng::stream(2, 0, "test"),
                core_filters::rng::stream(2, 0, "test"),
            );
            for _ in 0..100 {
                assert_eq!(q.draw(&mut a), own.draw(&mut b));
            }
        }
    }

    /// With a correlation matrix the draws keep each parameter's recorded quantiles and take the
    /// matrix's correlation: the normal scores Φ⁻¹((u − 0.025)/0.95) of the draws' levels u
    /// correlate as asked, within a few Monte-Carlo standard errors; a matrix that is not a
    /// correlation matrix leaves the draws independent, and says so.
    #[test]
    fn correlated_draws_keep_the_quantiles_and_take_the_correlation() {
        let ci = |level: f64, lo: f64, hi: f64| CredibleInterval { level, lo, hi };
        let param = |name: &str, scale: f64| ParamIntervals {
            parameter: name.into(),
            shape: crate::observe::PosteriorShape::GaussianMixture,
            intervals: vec![
                ci(0.5, 9.0 * scale, 11.0 * scale),
                ci(0.9, 8.0 * scale, 14.0 * scale),
                ci(0.95, 7.5 * scale, 16.0 * scale),
            ],
            error: None,
            mc_se: None,
        };
        let names: Vec<String> = vec!["k1".into(), "k2".into()];
        let credible = [param("k1", 1.0), param("k2", 2.0)];
        let rho = 0.9;
        let q = QuantileDraw::new(&names, &credible)
            .unwrap()
            .with_correlation(&[vec![1.0, rho], vec![rho, 1.0]]);
        assert!(q.correlated());
        let mut rng = core_filters::rng::stream(1, 0, "test");
        let m = 20_000;
        let draws: Vec<Vec<f64>> = (0..m).map(|_| q.draw(&mut rng)).collect();
        // Marginals: the recorded quantiles, as independent draws have them.
        for (j, scale) in [(0, 1.0), (1, 2.0)] {
            let mut v: Vec<f64> = draws.iter().map(|d| d[j]).collect();
            v.sort_by(f64::total_cmp);
            for (p, want) in [(0.05, 8.0), (0.25, 9.0), (0.75, 11.0), (0.95, 14.0)] {
                let r = (p - 0.025) / 0.95;
                let se = (r * (1.0 - r) / m as f64).sqrt();
                let below = v.partition_point(|x| *x < want * scale) as f64 / m as f64;
                assert!((below - r).abs() < 4.0 * se, "{j} at {p}: {below} vs {r}");
            }
        }
        // The level of a draw, back through the piecewise-linear quantile function, then its
        // normal score.
        let table = [
            (0.025, 7.5),
            (0.05, 8.0),
            (0.25, 9.0),
            (0.75, 11.0),
            (0.95, 14.0),
            (0.975, 16.0),
        ];
        let score = |x: f64| {
            let i = table.windows(2).position(|w| x <= w[1].1).unwrap_or(4);
            let ((p0, q0), (p1, q1)) = (table[i], table[i + 1]);
            let u = p0 + (p1 - p0) * (x - q0) / (q1 - q0);
            inverse_normal_cdf((u - 0.025) / 0.95)
        };
        let (a, b): (Vec<f64>, Vec<f64>) = draws
            .iter()
            .map(|d| (score(d[0]), score(d[1] / 2.0)))
            .unzip();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let (ma, mb) = (mean(&a), mean(&b));
        let cov: f64 = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - ma) * (y - mb))
            .sum::<f64>()
            / m as f64;
        let sd = |v: &[f64], mv: f64| {
            (v.iter().map(|x| (x - mv).powi(2)).sum::<f64>() / m as f64).sqrt()
        };
        let r = cov / (sd(&a, ma) * sd(&b, mb));
        // s.e. of a sample correlation: (1 − ρ²)/√m.
        let se = (1.0 - rho * rho) / (m as f64).sqrt();
        assert!(
            (r - rho).abs() < 4.0 * se,
            "correlation {r} against {rho} (s.e. {se})"
        );
        // Not a correlation matrix: independent draws.
        let q = QuantileDraw::new(&names, &credible)
            .unwrap()
            .with_correlation(&[vec![1.0, 2.0], vec![2.0, 1.0]]);
        assert!(!q.correlated());
        let q = QuantileDraw::new(&names, &credible)
            .unwrap()
            .with_correlation(&[]);
        assert!(!q.correlated());
    }

    /// A one-Gaussian posterior on a ridge near zero — the data fix c1 + α (one storey) while
    /// each alone is poorly known, so each marginal interval is its Gaussian's truncated at zero:
    /// its draws come from the Gaussian itself, inside every 95 % interval, and keep the ridge
    /// (the sum's spread the Gaussian's, around θ_val's sum). Through the copula of the truncated
    /// marginals the same record's sum moved up off the ridge, past θ_val's — why the joint draw
    /// exists. The reference is the Gaussian restricted to the 95 % box, drawn by brute force on
    /// another stream; tolerances 4 Monte-Carlo standard errors.
    #[test]
    fn a_one_gaussian_posterior_is_drawn_from_its_gaussian_and_keeps_its_ridge() {
        let (mean, sd, rho) = ([0.3, 0.3], [0.5, 0.5], -0.98);
        // The Gaussian N(m, s²) truncated at zero: its quantile at level p.
        let truncated = |m: f64, s: f64, p: f64| {
            let below = core_filters::credible::normal_cdf(-m / s);
            m + s * inverse_normal_cdf(below + p * (1.0 - below))
        };
        let ci = |m: f64, s: f64, level: f64| CredibleInterval {
            level,
            lo: truncated(m, s, (1.0 - level) / 2.0),
            hi: truncated(m, s, (1.0 + level) / 2.0),
        };
        let names: Vec<String> = vec!["c1".into(), "alpha".into()];
        let credible: Vec<ParamIntervals> = names
            .iter()
            .enumerate()
            .map(|(j, name)| ParamIntervals {
                parameter: name.clone(),
                shape: crate::observe::PosteriorShape::GaussianMixture,
                intervals: [0.5, 0.9, 0.95].map(|l| ci(mean[j], sd[j], l)).to_vec(),
                error: None,
                mc_se: None,
            })
            .collect();
        let box95: Vec<(f64, f64)> = credible
            .iter()
            .map(|p| p.at(0.95).map(|c| (c.lo, c.hi)).unwrap())
            .collect();
        let correlation = [vec![1.0, rho], vec![rho, 1.0]];
        let copula = QuantileDraw::new(&names, &credible)
            .unwrap()
            .with_correlation(&correlation);
        let joint = copula.clone().with_gaussian(&mean, &sd);
        assert!(joint.gaussian() && !copula.gaussian());
        // Not finite, or of another length: the copula's draws.
        assert!(!copula.clone().with_gaussian(&[0.3], &sd).gaussian());
        assert!(!copula
            .clone()
            .with_gaussian(&mean, &[f64::NAN, 0.5])
            .gaussian());
        let m = 20_000;
        let sums = |q: &QuantileDraw, rng: &mut core_filters::rng::StreamRng| {
            let mut v: Vec<f64> = (0..m)
                .map(|_| {
                    let t = q.draw(rng);
                    for (x, (lo, hi)) in t.iter().zip(&box95) {
                        assert!(lo <= x && x <= hi, "{x} outside [{lo}, {hi}]");
                    }
                    t[0] + t[1]
                })
                .collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let mut rng = core_filters::rng::stream(1, 0, "test");
        let drawn = sums(&joint, &mut rng);
        // The reference: N(m, Σ) by its own Cholesky factor, kept inside the box.
        let mut rng = core_filters::rng::stream(2, 0, "test");
        let mut reference = Vec::with_capacity(m);
        while reference.len() < m {
            let (e1, e2): (f64, f64) = (
                rng.sample(rand_distr::StandardNormal),
                rng.sample(rand_distr::StandardNormal),
            );
            let a = mean[0] + sd[0] * e1;
            let b = mean[1] + sd[1] * (rho * e1 + (1.0 - rho * rho).sqrt() * e2);
            let inside = |x: f64, (lo, hi): (f64, f64)| lo <= x && x <= hi;
            if inside(a, box95[0]) && inside(b, box95[1]) {
                reference.push(a + b);
            }
        }
        let mean_of = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let sd_of = |v: &[f64]| {
            let mv = mean_of(v);
            (v.iter().map(|x| (x - mv).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
        };
        let se = sd_of(&reference) * (2.0 / m as f64).sqrt();
        assert!(
            (mean_of(&drawn) - mean_of(&reference)).abs() < 4.0 * se,
            "the sum's mean {} against the reference's {} (s.e. {se})",
            mean_of(&drawn),
            mean_of(&reference)
        );
        // The ridge: the Gaussian's sum has s.d. √(s₁² + s₂² + 2ρ s₁ s₂) = 0.1 around 0.6.
        let ridge = (sd[0] * sd[0] + sd[1] * sd[1] + 2.0 * rho * sd[0] * sd[1]).sqrt();
        assert!((sd_of(&drawn) - sd_of(&reference)).abs() < 0.05 * ridge);
        let (lo, hi) = (
            percentile_sorted(&drawn, 0.025),
            percentile_sorted(&drawn, 0.975),
        );
        assert!(lo < 0.6 && 0.6 < hi, "[{lo}, {hi}] misses θ_val's sum 0.6");
        // The copula's sum left the ridge: its central 95 % excludes θ_val's sum.
        let mut rng = core_filters::rng::stream(1, 0, "test");
        let off = sums(&copula, &mut rng);
        let lo = percentile_sorted(&off, 0.025);
        assert!(lo > 0.6, "the copula's sum {lo} stayed on the ridge");
    }

    /// Φ⁻¹ by bisection on [`core_filters::credible::normal_cdf`] (tests only).
    fn inverse_normal_cdf(p: f64) -> f64 {
        let (mut lo, mut hi) = (-10.0, 10.0);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if core_filters::credible::normal_cdf(mid) < p {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}
