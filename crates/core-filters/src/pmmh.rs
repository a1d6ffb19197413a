//! Particle marginal Metropolis–Hastings (PMMH; Andrieu, Doucet & Holenstein 2010): an offline
//! sampler of the posterior of static parameters driven by an unbiased likelihood estimate
//! (SPEC §9 "Calibration": the reference posterior the online filters are compared with).
//!
//! The chain lives in unconstrained coordinates `u ∈ ℝ^d` (the target maps them to θ and
//! includes the Jacobian in [`Target::log_prior`]). A proposal `u' = u + L ξ`, `ξ ~ N(0, I)`, is
//! accepted with probability `min(1, p̂(y|u') p(u') / p̂(y|u) p(u))`, where `p̂` is the particle
//! filter's estimate *kept* with the state (never recomputed for the current point): with an
//! unbiased `p̂` the chain's stationary law is the exact posterior whatever the estimator's
//! variance, which only costs mixing.
//!
//! The random-walk covariance `L Lᵀ` adapts during the burn-in only (Haario et al. 2001:
//! `(2.38²/d) Σ̂ + ε I` from the burn-in samples, refreshed every [`PmmhConfig::adapt_every`]
//! iterations); after the burn-in it is frozen, so the kept samples come from a plain
//! Metropolis–Hastings chain with a fixed kernel.

use crate::linalg::gauss::psd_cholesky;
use crate::rng::StreamRng;
use rand::Rng;
use rand_distr::StandardNormal;

/// A posterior known up to a constant, with a likelihood that may only be estimated.
pub trait Target {
    /// Dimension of the unconstrained coordinates.
    fn dim(&self) -> usize;
    /// `log p(u)`: the prior of θ(u) plus `log |dθ/du|` (−∞ outside the support).
    fn log_prior(&self, u: &[f64]) -> f64;
    /// An estimate of `log p(y | θ(u))` whose exponential is unbiased (−∞ when the model cannot
    /// explain the data, NaN never: a failed estimate is −∞, i.e. a rejected proposal).
    fn log_likelihood(&mut self, u: &[f64], rng: &mut StreamRng) -> f64;
}

/// Settings of a PMMH chain.
#[derive(Debug, Clone, PartialEq)]
pub struct PmmhConfig {
    /// Iterations after the burn-in (kept).
    pub iterations: usize,
    /// Iterations of burn-in (adaptation; discarded).
    pub burn_in: usize,
    /// Initial random-walk s.d. per coordinate.
    pub initial_sd: Vec<f64>,
    /// Refresh of the adapted covariance during the burn-in.
    pub adapt_every: usize,
}

/// The output of a chain.
#[derive(Debug, Clone, PartialEq)]
pub struct PmmhChain {
    /// Kept states (unconstrained), one row per iteration after the burn-in.
    pub samples: Vec<Vec<f64>>,
    /// Log-likelihood estimate carried with each kept state.
    pub loglik: Vec<f64>,
    /// Acceptance rate over the kept iterations and over the burn-in.
    pub acceptance: f64,
    pub acceptance_burn_in: f64,
    /// The frozen proposal factor `L` (column-major `d × d`).
    pub proposal_chol: Vec<f64>,
}

/// Running mean and covariance (Welford) of the burn-in samples.
struct Moments {
    n: f64,
    mean: Vec<f64>,
    m2: Vec<f64>,
}

impl Moments {
    fn new(d: usize) -> Self {
        Self {
            n: 0.0,
            mean: vec![0.0; d],
            m2: vec![0.0; d * d],
        }
    }

    fn push(&mut self, x: &[f64]) {
        let d = x.len();
        self.n += 1.0;
        let delta: Vec<f64> = x.iter().zip(&self.mean).map(|(a, m)| a - m).collect();
        for (m, dl) in self.mean.iter_mut().zip(&delta) {
            *m += dl / self.n;
        }
        for (c, (xc, mc)) in x.iter().zip(&self.mean).enumerate() {
            let after = xc - mc;
            for (m2, dr) in self.m2[c * d..(c + 1) * d].iter_mut().zip(&delta) {
                *m2 += dr * after;
            }
        }
    }

    /// The adapted proposal covariance `(2.38²/d) Σ̂ + ε I`.
    fn proposal_cov(&self, floor: &[f64]) -> Vec<f64> {
        let d = self.mean.len();
        let scale = 2.38 * 2.38 / d as f64;
        let mut cov = vec![0.0; d * d];
        for c in 0..d {
            for r in 0..d {
                // Symmetrised: the Welford sums are symmetric only up to rounding.
                let s = 0.5 * (self.m2[r + c * d] + self.m2[c + r * d]) / (self.n - 1.0);
                cov[r + c * d] = scale * s;
            }
            cov[c + c * d] += floor[c] * floor[c];
        }
        cov
    }
}

/// Runs a PMMH chain from `start` (unconstrained). `on_iteration(i, total)` is called after
/// every iteration (progress reporting).
pub fn pmmh(
    target: &mut dyn Target,
    start: &[f64],
    config: &PmmhConfig,
    rng: &mut StreamRng,
    on_iteration: &mut dyn FnMut(usize, usize),
) -> PmmhChain {
    let d = target.dim();
    assert_eq!(start.len(), d, "the start has the target's dimension");
    assert_eq!(
        config.initial_sd.len(),
        d,
        "one initial s.d. per coordinate"
    );
    let mut chol = vec![0.0; d * d];
    for (i, s) in config.initial_sd.iter().enumerate() {
        chol[i + i * d] = *s;
    }
    // The adapted covariance keeps a floor of 1% of the initial s.d. per coordinate so that a
    // coordinate the burn-in never moved can still move.
    let floor: Vec<f64> = config.initial_sd.iter().map(|s| 0.01 * s).collect();

    let mut u = start.to_vec();
    let mut lp = target.log_prior(&u);
    let mut ll = if lp.is_finite() {
        target.log_likelihood(&u, rng)
    } else {
        f64::NEG_INFINITY
    };
    let mut moments = Moments::new(d);
    let (mut acc_burn, mut acc_kept) = (0usize, 0usize);
    let total = config.burn_in + config.iterations;
    let mut out = PmmhChain {
        samples: Vec::with_capacity(config.iterations),
        loglik: Vec::with_capacity(config.iterations),
        acceptance: 0.0,
        acceptance_burn_in: 0.0,
        proposal_chol: Vec::new(),
    };
    let mut xi = vec![0.0; d];
    let mut prop = vec![0.0; d];
    for it in 0..total {
        for x in xi.iter_mut() {
            *x = rng.sample(StandardNormal);
        }
        for r in 0..d {
            prop[r] = u[r] + (0..=r).map(|c| chol[r + c * d] * xi[c]).sum::<f64>();
        }
        let lp_new = target.log_prior(&prop);
        let accepted = if lp_new.is_finite() {
            let ll_new = target.log_likelihood(&prop, rng);
            let log_ratio = (ll_new + lp_new) - (ll + lp);
            // A current state with −∞ (a bad start) accepts any finite proposal.
            let accept = ll_new.is_finite()
                && (!(ll + lp).is_finite() || rng.random::<f64>().ln() < log_ratio);
            if accept {
                u.copy_from_slice(&prop);
                lp = lp_new;
                ll = ll_new;
            }
            accept
        } else {
            false
        };
        if it < config.burn_in {
            acc_burn += usize::from(accepted);
            moments.push(&u);
            let refresh = (it + 1) % config.adapt_every.max(1) == 0 && moments.n > 2.0 * d as f64;
            if refresh {
                let cov = moments.proposal_cov(&floor);
                let mut l = vec![0.0; d * d];
                if psd_cholesky(&cov, d, &mut l) {
                    chol = l;
                }
            }
        } else {
            acc_kept += usize::from(accepted);
            out.samples.push(u.clone());
            out.loglik.push(ll);
        }
        on_iteration(it + 1, total);
    }
    out.acceptance = acc_kept as f64 / config.iterations.max(1) as f64;
    out.acceptance_burn_in = acc_burn as f64 / config.burn_in.max(1) as f64;
    out.proposal_chol = chol;
    out
}

/// Effective sample size of a scalar chain from its autocorrelations, summed over the initial
/// positive sequence of pair sums (Geyer 1992).
pub fn effective_sample_size(x: &[f64]) -> f64 {
    let n = x.len();
    if n < 4 {
        return n as f64;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64;
    if var <= 0.0 {
        return n as f64;
    }
    let rho = |lag: usize| -> f64 {
        (0..n - lag)
            .map(|i| (x[i] - mean) * (x[i + lag] - mean))
            .sum::<f64>()
            / (n as f64 * var)
    };
    let mut sum = 0.0;
    let mut lag = 0;
    while lag + 1 < n {
        let pair = rho(lag) + rho(lag + 1);
        if pair <= 0.0 {
            break;
        }
        sum += pair;
        lag += 2;
    }
    // τ = −1 + 2 Σ pairs (the lag-0 term counted once).
    let tau = (2.0 * sum - 1.0).max(1.0);
    n as f64 / tau
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream;

    /// y_i ~ N(μ, 1), μ ~ N(0, 10²): the exact posterior is Gaussian.
    struct GaussianMean {
        y: Vec<f64>,
        /// Extra noise on the log-likelihood estimate: `log p + σ ε − σ²/2` has an unbiased
        /// exponential (the lognormal correction), like a particle estimate.
        noise_sd: f64,
    }

    impl Target for GaussianMean {
        fn dim(&self) -> usize {
            1
        }
        fn log_prior(&self, u: &[f64]) -> f64 {
            -0.5 * (u[0] / 10.0).powi(2)
        }
        fn log_likelihood(&mut self, u: &[f64], rng: &mut StreamRng) -> f64 {
            let exact: f64 = self.y.iter().map(|y| -0.5 * (y - u[0]).powi(2)).sum();
            let e: f64 = rng.sample(StandardNormal);
            exact + self.noise_sd * e - 0.5 * self.noise_sd * self.noise_sd
        }
    }

    fn exact_posterior(y: &[f64]) -> (f64, f64) {
        let prec = 1.0 / 100.0 + y.len() as f64;
        (y.iter().sum::<f64>() / prec, (1.0 / prec).sqrt())
    }

    /// With a noisy (but unbiased) likelihood the chain still targets the exact posterior: the
    /// mean within 4 Monte-Carlo standard errors (s.d. / sqrt(chain ESS)) and the s.d. within 10%.
    #[test]
    fn noisy_likelihood_targets_the_exact_posterior() {
        let mut g = stream(3, 0, "test/pmmh/data");
        let y: Vec<f64> = (0..20).map(|_| 1.5 + rng_normal(&mut g)).collect();
        let (m, s) = exact_posterior(&y);
        let mut target = GaussianMean { y, noise_sd: 1.0 };
        let config = PmmhConfig {
            iterations: 40_000,
            burn_in: 2_000,
            initial_sd: vec![1.0],
            adapt_every: 100,
        };
        let mut rng = stream(3, 0, "test/pmmh/chain");
        let chain = pmmh(&mut target, &[0.0], &config, &mut rng, &mut |_, _| {});
        let x: Vec<f64> = chain.samples.iter().map(|r| r[0]).collect();
        let ess = effective_sample_size(&x);
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let sd = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / x.len() as f64).sqrt();
        let se = s / ess.sqrt();
        assert!(ess > 1000.0, "chain ESS {ess}");
        assert!((mean - m).abs() < 4.0 * se, "mean {mean} vs {m} (se {se})");
        assert!((sd / s - 1.0).abs() < 0.1, "sd {sd} vs {s}");
        assert!(chain.acceptance > 0.05 && chain.acceptance < 0.9);
    }

    fn rng_normal(g: &mut StreamRng) -> f64 {
        g.sample(StandardNormal)
    }

    #[test]
    fn ess_of_independent_draws_is_close_to_n() {
        let mut g = stream(5, 0, "test/pmmh/ess");
        let x: Vec<f64> = (0..4000).map(|_| rng_normal(&mut g)).collect();
        let ess = effective_sample_size(&x);
        assert!((ess / 4000.0 - 1.0).abs() < 0.15, "ess {ess}");
        // An AR(1) chain with ρ = 0.9 has τ = (1 + ρ)/(1 − ρ) = 19.
        let mut a = vec![0.0; 20_000];
        for i in 1..a.len() {
            a[i] = 0.9 * a[i - 1] + (1.0f64 - 0.81).sqrt() * rng_normal(&mut g);
        }
        let tau = a.len() as f64 / effective_sample_size(&a);
        assert!((tau / 19.0 - 1.0).abs() < 0.3, "tau {tau}");
    }
}
