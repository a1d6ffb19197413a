//! A reference posterior of θ for one data set, by particle marginal Metropolis–Hastings
//! ([`core_filters::pmmh`]), to compare the online filters' posteriors with (SPEC §9
//! "Calibration").
//!
//! Why it is a reference: its correctness does not rest on the online filters' approximations.
//! The chain targets the exact posterior `p(θ | y_{1:K})` of the filters' own state-space model
//! (same discretisation, same process and measurement noise, SPEC §3), for any particle count,
//! because the likelihood estimate it uses is unbiased:
//!
//! - with θ fixed, the MPF-EKF2's marginalised block is exactly linear-Gaussian given the sampled
//!   states (every bilinear term of SPEC §5.4 is a product with a θ entry of zero variance, so its
//!   second-order terms vanish and the EKF2 update is the Kalman filter): the MPF-EKF2 run on a
//!   point-mass prior is an exact Rao–Blackwellised particle filter, whose likelihood estimate is
//!   unbiased;
//! - the bootstrap PF on a point-mass prior is the textbook unbiased estimator (higher variance).
//!
//! No path degeneracy of static parameters, no artificial dynamics, no Gaussian approximation
//! of the parameter posterior: the chain sees θ only through the likelihood.
//!
//! The prior is SPEC §3's (lognormal k, c; uniform triangle (β, γ); uniform n), not the online
//! filters' moment-matched Gaussian for their marginalised block; with 8 s of data the likelihood
//! dominates both. The chain moves in unconstrained coordinates: `ln θ` for lognormal priors,
//! a logistic map onto the interval of uniform priors and onto the (β, γ) triangle
//! (`β = β_max σ(a)`, `γ = β (2σ(b) − 1)`), with the Jacobians in the log-prior.

use crate::error::{bail, Result};
use core_filters::pmmh::{effective_sample_size, pmmh, PmmhChain, PmmhConfig, Target};
use core_filters::resampling::{ResamplePolicy, Scheme};
use core_filters::rng::StreamRng;
use core_filters::smc::runner::NoObserver;
use core_filters::smc::{run, SmcConfig};
use models::filtering::{ChainPrior, ChainSpec};
use models::priors::{BetaGammaPrior, Prior};
use serde::{Deserialize, Serialize};

use identify::pipeline::{build_filter, Algorithm, FilterSettings};

pub mod comparison;
pub mod posterior;
mod record;
pub(crate) use comparison::compare_files;
pub use comparison::{
    compare, goal_rows, information_limit, reference_covers, Comparison, DataSetRuns, GoalRow,
    LimitRow, GOAL_MARGIN,
};
pub use record::{chain_warnings, ReferenceRecord};

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// `ln σ(x) = −ln(1 + e^{−x})`, without overflow for any finite x (`ln(1 − σ(x)) = ln σ(−x)`).
fn log_sigmoid(x: f64) -> f64 {
    let z = -x;
    -(z.max(0.0) + (-z.abs()).exp().ln_1p())
}

/// One free coordinate of the chain and the parameter(s) it moves.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Coordinate {
    /// θ_i = exp(u), ln θ_i ~ N(ln median, log_sd²).
    Log {
        index: usize,
        median: f64,
        log_sd: f64,
    },
    /// θ_i = lo + (hi − lo) σ(u).
    Interval { index: usize, lo: f64, hi: f64 },
    /// (β, γ) at (index, index + 1) on the triangle: two coordinates (a, b).
    Triangle { index: usize, beta_max: f64 },
}

/// The map between θ (constrained, with fixed entries) and the chain's free coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct ThetaMap {
    coordinates: Vec<Coordinate>,
    /// θ with the fixed entries filled in (the free ones are overwritten by [`ThetaMap::theta`]).
    base: Vec<f64>,
    dim: usize,
}

impl ThetaMap {
    /// The map of a chain prior; fails on a prior PMMH cannot use (a triangle with β or γ
    /// fixed alone).
    pub fn new(prior: &ChainPrior) -> Result<Self> {
        let n = prior.n_storeys();
        let mut base = vec![0.0; prior.len()];
        let mut coordinates = Vec::new();
        let mut scalar = |index: usize, p: &Prior, base: &mut Vec<f64>| match *p {
            Prior::LogNormal { median, log_sd } if log_sd > 0.0 => {
                coordinates.push(Coordinate::Log {
                    index,
                    median,
                    log_sd,
                })
            }
            Prior::LogNormal { median, .. } => base[index] = median,
            Prior::Uniform { lo, hi } => coordinates.push(Coordinate::Interval { index, lo, hi }),
            Prior::Fixed { value } => base[index] = value,
        };
        for (j, p) in prior.k.iter().enumerate() {
            scalar(j, p, &mut base);
        }
        for (j, p) in prior.c.iter().enumerate() {
            scalar(n + j, p, &mut base);
        }
        let mut triangles = Vec::new();
        for (e, el) in prior.elements.iter().enumerate() {
            let i = 2 * n + 3 * e;
            match el.beta_gamma {
                BetaGammaPrior::Triangle { beta_max } => triangles.push((i, beta_max)),
                BetaGammaPrior::Fixed { beta, gamma } => {
                    base[i] = beta;
                    base[i + 1] = gamma;
                }
                other => bail!(
                    "the reference posterior needs β and γ both free or both fixed, got {other:?}"
                ),
            }
            scalar(i + 2, &el.n, &mut base);
        }
        coordinates.extend(
            triangles
                .into_iter()
                .map(|(index, beta_max)| Coordinate::Triangle { index, beta_max }),
        );
        let dim = coordinates
            .iter()
            .map(|c| {
                if matches!(c, Coordinate::Triangle { .. }) {
                    2
                } else {
                    1
                }
            })
            .sum();
        Ok(Self {
            coordinates,
            base,
            dim,
        })
    }

    /// Number of free coordinates.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// θ(u).
    pub fn theta(&self, u: &[f64]) -> Vec<f64> {
        let mut theta = self.base.clone();
        let mut k = 0;
        for c in &self.coordinates {
            match *c {
                Coordinate::Log { index, .. } => {
                    theta[index] = u[k].exp();
                    k += 1;
                }
                Coordinate::Interval { index, lo, hi } => {
                    theta[index] = lo + (hi - lo) * sigmoid(u[k]);
                    k += 1;
                }
                Coordinate::Triangle { index, beta_max } => {
                    let beta = beta_max * sigmoid(u[k]);
                    theta[index] = beta;
                    theta[index + 1] = beta * (2.0 * sigmoid(u[k + 1]) - 1.0);
                    k += 2;
                }
            }
        }
        theta
    }

    /// u(θ) for the free entries of `theta` (inside the support).
    pub(crate) fn unconstrained(&self, theta: &[f64]) -> Vec<f64> {
        let logit = |p: f64| (p / (1.0 - p)).ln();
        let mut u = Vec::with_capacity(self.dim);
        for c in &self.coordinates {
            match *c {
                Coordinate::Log { index, .. } => u.push(theta[index].ln()),
                Coordinate::Interval { index, lo, hi } => {
                    u.push(logit((theta[index] - lo) / (hi - lo)))
                }
                Coordinate::Triangle { index, beta_max } => {
                    let beta = theta[index];
                    u.push(logit(beta / beta_max));
                    u.push(logit(0.5 * (theta[index + 1] / beta + 1.0)));
                }
            }
        }
        u
    }

    /// `log p(u)` up to a constant: the prior of θ(u) times `|dθ/du|`.
    pub fn log_prior(&self, u: &[f64]) -> f64 {
        let mut lp = 0.0;
        let mut k = 0;
        for c in &self.coordinates {
            match *c {
                Coordinate::Log { median, log_sd, .. } => {
                    // ln θ = u is N(ln median, log_sd²): the Jacobian is already in this form.
                    let z = (u[k] - median.ln()) / log_sd;
                    lp += -0.5 * z * z;
                    k += 1;
                }
                Coordinate::Interval { .. } => {
                    // Uniform θ: density of u is σ(u)(1 − σ(u)) up to (hi − lo).
                    lp += log_sigmoid(u[k]) + log_sigmoid(-u[k]);
                    k += 1;
                }
                Coordinate::Triangle { .. } => {
                    // Uniform on the triangle: |J| = β_max σ(a)(1 − σ(a)) · 2β σ(b)(1 − σ(b)),
                    // β = β_max σ(a); constants dropped.
                    let (a, b) = (u[k], u[k + 1]);
                    lp += 2.0 * log_sigmoid(a) + log_sigmoid(-a) + log_sigmoid(b) + log_sigmoid(-b);
                    k += 2;
                }
            }
        }
        lp
    }

    /// Name-free list of the θ indices each coordinate moves (for reporting).
    pub(crate) fn free_indices(&self) -> Vec<usize> {
        let mut out = Vec::new();
        for c in &self.coordinates {
            match *c {
                Coordinate::Log { index, .. } | Coordinate::Interval { index, .. } => {
                    out.push(index)
                }
                Coordinate::Triangle { index, .. } => {
                    out.push(index);
                    out.push(index + 1);
                }
            }
        }
        out
    }
}

/// The likelihood estimator: one particle filter on a point-mass prior at θ.
pub struct FilterLikelihood {
    pub spec: ChainSpec,
    pub map: ThetaMap,
    pub algorithm: Algorithm,
    pub particles: usize,
    pub ys: Vec<f64>,
    pub ny: usize,
    /// Estimates that failed (a numerical failure is a rejected proposal, counted here).
    pub failures: u64,
    pub evaluations: u64,
}

impl FilterLikelihood {
    /// `log p̂(y | θ)` from one filter run (−∞ if the run fails).
    pub fn estimate(&mut self, theta: &[f64], rng: &mut StreamRng) -> f64 {
        self.evaluations += 1;
        let mut spec = self.spec.clone();
        let mut prior = spec.prior.clone();
        for (name, v) in prior.names().into_iter().zip(theta) {
            if prior.fix(&name, *v).is_err() {
                self.failures += 1;
                return f64::NEG_INFINITY;
            }
        }
        spec.prior = prior;
        let settings = FilterSettings::default();
        let Ok(mut filter) = build_filter(self.algorithm, spec, &settings) else {
            self.failures += 1;
            return f64::NEG_INFINITY;
        };
        let config = SmcConfig {
            particles: self.particles,
            // Resampling when the ESS falls below half the particles keeps the estimate unbiased
            // and lowers its variance against resampling at every step.
            resampling: ResamplePolicy {
                scheme: Scheme::Systematic,
                ess_threshold: Some(0.5),
            },
            rejuvenation: None,
        };
        let summary = run(
            filter.as_mut(),
            &config,
            &self.ys,
            self.ny,
            rng,
            &mut NoObserver,
        );
        if summary.failure.is_some() || !summary.loglik.is_finite() {
            self.failures += 1;
            return f64::NEG_INFINITY;
        }
        summary.loglik
    }
}

impl Target for FilterLikelihood {
    fn dim(&self) -> usize {
        self.map.dim()
    }
    fn log_prior(&self, u: &[f64]) -> f64 {
        self.map.log_prior(u)
    }
    fn log_likelihood(&mut self, u: &[f64], rng: &mut StreamRng) -> f64 {
        let theta = self.map.theta(u);
        self.estimate(&theta, rng)
    }
}

/// Posterior summary of one parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamSummary {
    pub name: String,
    #[serde(with = "identify::record::number::scalar")]
    pub mean: f64,
    #[serde(with = "identify::record::number::scalar")]
    pub sd: f64,
    /// 2.5, 25, 50, 75 and 97.5% quantiles.
    #[serde(with = "identify::record::number::array")]
    pub quantiles: [f64; 5],
    /// Effective sample size of the chain for this parameter.
    #[serde(with = "identify::record::number::scalar")]
    pub ess: f64,
    #[serde(with = "identify::record::number::opt_scalar")]
    pub truth: Option<f64>,
}

/// Summaries of a chain in θ space.
pub(crate) fn summarise(
    chain: &PmmhChain,
    map: &ThetaMap,
    names: &[String],
    truth: Option<&[f64]>,
) -> Vec<ParamSummary> {
    let thetas: Vec<Vec<f64>> = chain.samples.iter().map(|u| map.theta(u)).collect();
    map.free_indices()
        .into_iter()
        .map(|i| {
            let x: Vec<f64> = thetas.iter().map(|t| t[i]).collect();
            let (mean, sd, _) = identify::metrics::mean_sd(&x);
            let n = x.len() as f64;
            let mut sorted = x.clone();
            sorted.sort_by(f64::total_cmp);
            let q = |p: f64| sorted[((p * (n - 1.0)).round() as usize).min(sorted.len() - 1)];
            ParamSummary {
                name: names[i].clone(),
                mean,
                sd,
                quantiles: [q(0.025), q(0.25), q(0.5), q(0.75), q(0.975)],
                ess: effective_sample_size(&x),
                truth: truth.map(|t| t[i]),
            }
        })
        .collect()
}

/// Runs the chain from θ0 with per-coordinate initial random-walk s.d. `initial_sd`.
pub(crate) fn run_chain(
    target: &mut FilterLikelihood,
    theta0: &[f64],
    config: &PmmhConfig,
    rng: &mut StreamRng,
    on_iteration: &mut dyn FnMut(usize, usize),
) -> PmmhChain {
    let u0 = target.map.unconstrained(theta0);
    pmmh(target, &u0, config, rng, on_iteration)
}

/// Several chains' summaries of the same posterior pooled as an equal-weight mixture: mean the
/// mean of the means, variance the mean variance plus the variance of the means (so chains that
/// disagree widen the reference instead of hiding it), ESS summed; quantiles are not pooled
/// (NaN) unless there is one chain.
pub fn pool_chains(chains: &[Vec<ParamSummary>]) -> crate::error::Result<Vec<ParamSummary>> {
    let Some(first) = chains.first() else {
        bail!("no reference chain given");
    };
    if chains.len() == 1 {
        return Ok(first.clone());
    }
    let mut out = Vec::new();
    for (i, p) in first.iter().enumerate() {
        let same: Vec<&ParamSummary> = chains
            .iter()
            .map(|c| c.get(i).filter(|q| q.name == p.name))
            .collect::<Option<_>>()
            .ok_or_else(|| crate::error::invalid!("the chains do not have the same parameters"))?;
        let m = same.len() as f64;
        let mean = same.iter().map(|q| q.mean).sum::<f64>() / m;
        let var = same
            .iter()
            .map(|q| q.sd * q.sd + (q.mean - mean).powi(2))
            .sum::<f64>()
            / m;
        out.push(ParamSummary {
            name: p.name.clone(),
            mean,
            sd: var.sqrt(),
            quantiles: [f64::NAN; 5],
            ess: same.iter().map(|q| q.ess).sum(),
            truth: p.truth,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prior() -> ChainPrior {
        ChainPrior::paper(3, &[0])
    }

    #[test]
    fn theta_round_trips_through_the_unconstrained_coordinates() {
        let map = ThetaMap::new(&prior()).unwrap();
        assert_eq!(map.dim(), 9);
        let theta = vec![9.0, 8.0, 7.0, 0.25, 0.3, 0.35, 2.0, -1.5, 2.5];
        let back = map.theta(&map.unconstrained(&theta));
        for (a, b) in theta.iter().zip(&back) {
            assert!((a - b).abs() < 1e-12 * a.abs().max(1.0), "{a} vs {b}");
        }
    }

    #[test]
    fn fixed_parameters_are_not_coordinates() {
        let mut p = prior();
        p.fix("k1", 8.0).unwrap();
        p.fix("n", 2.0).unwrap();
        let map = ThetaMap::new(&p).unwrap();
        assert_eq!(map.dim(), 7);
        let theta = map.theta(&[0.0; 7]);
        assert_eq!(theta[0], 8.0);
        assert_eq!(theta[8], 2.0);
    }

    /// The log-prior in u is the prior density of θ times the Jacobian: checked by integrating
    /// the density of one triangle coordinate pair numerically against its known mass, and the
    /// logistic interval coordinate against the uniform density.
    #[test]
    fn log_prior_includes_the_jacobian() {
        // Interval: ∫ σ(u)(1 − σ(u)) du = 1.
        let h = 1e-3;
        let mass: f64 = (-40_000..40_000)
            .map(|i| (log_sigmoid(i as f64 * h) + log_sigmoid(-(i as f64) * h)).exp() * h)
            .sum();
        assert!((mass - 1.0).abs() < 1e-6, "{mass}");
        // Triangle, the β part: with s = σ(a), ds = σ(1 − σ) da, so
        // ∫ σ(a)² (1 − σ(a)) da = ∫_0^1 s ds = 1/2 (the (b) part is the interval case above).
        let tri: f64 = (-4_000..4_000)
            .map(|i| {
                let a = i as f64 * 1e-2;
                (2.0 * log_sigmoid(a) + log_sigmoid(-a)).exp() * 1e-2
            })
            .sum();
        assert!((tri - 0.5).abs() < 1e-6, "{tri}");
    }

    #[test]
    fn log_sigmoid_is_stable() {
        for x in [-800.0, -30.0, -1.0, 0.0, 1.0, 30.0, 800.0] {
            let direct = sigmoid(x).ln();
            let stable = log_sigmoid(x);
            assert!(stable.is_finite(), "x = {x}");
            if direct.is_finite() {
                assert!(
                    (stable - direct).abs() < 1e-12 * direct.abs().max(1.0),
                    "x = {x}"
                );
            }
        }
        assert!((log_sigmoid(-800.0) + 800.0).abs() < 1e-9);
    }
}
