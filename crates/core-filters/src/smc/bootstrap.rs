//! The bootstrap particle filter on an augmented state (SPEC §5.1, the paper's Algorithm 1), on
//! run-time dimensions.
//!
//! Each particle is a full augmented state `x = [states; θ]`. Per step: propagate every particle
//! through the model's transition with its own standard normal draws (the model applies its noise
//! structure; static parameters get none), weight by `N(y_k; measure(k, x_k), R)`. Normalising
//! and resampling are the runner's.
//!
//! Failure policy: `R` is factorised once, in [`BootstrapPf::new`]; if it is not positive
//! definite (even after the documented repair) every step returns that typed error. A non-finite
//! particle log-likelihood is mapped to −∞ (and counted) by the weight routine.

use rand_distr::{Distribution, StandardNormal};

use crate::error::FilterError;
use crate::health::Health;
use crate::linalg::FactoredNoise;
use crate::model::Layout;
use crate::rng::StreamRng;

use super::model::StateSpace;
use super::runner::{Filter, StepInput, StepOutput};
use super::store::{Particles, Shape};

/// Bootstrap PF (SPEC §5.1). All buffers are allocated in [`BootstrapPf::new`].
pub struct BootstrapPf<M: StateSpace> {
    model: M,
    layout: Layout,
    noise: Result<FactoredNoise, FilterError>,
    setup_health: Health,
    health: Health,
    xi: Vec<f64>,
    y_hat: Vec<f64>,
    resid: Vec<f64>,
    white: Vec<f64>,
}

impl<M: StateSpace> BootstrapPf<M> {
    /// Reads the model and factorises `R` once.
    pub fn new(model: M) -> Self {
        let ny = model.ny();
        let mut setup_health = Health::default();
        let noise = FactoredNoise::new(
            &model.measurement_cov(),
            ny,
            "measurement covariance R",
            &mut setup_health,
        );
        Self {
            layout: model.layout(),
            xi: vec![0.0; model.noise_dim()],
            y_hat: vec![0.0; ny],
            resid: vec![0.0; ny],
            white: vec![0.0; ny],
            noise,
            health: setup_health,
            setup_health,
            model,
        }
    }

    pub fn model(&self) -> &M {
        &self.model
    }
}

impl<M: StateSpace> Filter for BootstrapPf<M> {
    fn name(&self) -> &'static str {
        "bootstrap"
    }

    fn layout(&self) -> &Layout {
        &self.layout
    }

    fn shape(&self) -> Shape {
        Shape {
            sampled: self.model.dim(),
            marginal: 0,
        }
    }

    fn initialise(&mut self, rng: &mut StreamRng, particles: &mut Particles) {
        self.health = self.setup_health;
        for i in 0..particles.len() {
            self.model
                .sample_initial(rng, particles.particle_mut(i).sampled);
        }
    }

    fn step(
        &mut self,
        input: &StepInput<'_>,
        out: &mut StepOutput<'_>,
        rng: &mut StreamRng,
    ) -> Result<(), FilterError> {
        let StepInput {
            k,
            y,
            src,
            ancestors,
        } = *input;
        let noise = FactoredNoise::at_step(&self.noise, k)?;
        for (i, lw) in out.log_w.iter_mut().enumerate() {
            for v in self.xi.iter_mut() {
                *v = StandardNormal.sample(rng);
            }
            let x_prev = src.sampled(ancestors[i]);
            let x = out.dst.particle_mut(i).sampled;
            if *lw == f64::NEG_INFINITY {
                x.copy_from_slice(x_prev);
                continue;
            }
            self.model.propagate(k, x_prev, &self.xi, x);
            self.model.measure(k, x, &mut self.y_hat);
            for j in 0..y.len() {
                self.resid[j] = y[j] - self.y_hat[j];
            }
            *lw += noise.log_density(&self.resid, &mut self.white);
        }
        Ok(())
    }

    fn health(&self) -> Health {
        self.health
    }
}
