//! The compass search the choices that maximise a log-likelihood share (the masses' ratios, each
//! channel's noise level): from `u = 0`, each coordinate moved by ±`step` in turn, the best
//! neighbour taken while it gains, then the step halved, `halvings` times; each coordinate held
//! within ±`bound`.

use rayon::prelude::*;

/// A compass search's steps and limits.
#[derive(Debug, Clone, Copy)]
pub struct Compass {
    /// The first step of every coordinate.
    pub first_step: f64,
    /// Times the step is halved once no move gains.
    pub halvings: usize,
    /// Farthest a coordinate moves from 0, either way.
    pub bound: f64,
    /// Most evaluations the search may make (a safeguard).
    pub max_evaluations: usize,
}

/// The point a search reached from 0, its value (none when nothing evaluated finite), the
/// evaluations made and how many of them failed.
pub type Reached = (Vec<f64>, Option<f64>, usize, usize);

/// The points the search's last round evaluated, with their values: where it stopped, the
/// neighbours one last step either side of the answer (those inside the bound).
pub type LastRound = Vec<(Vec<f64>, Option<f64>)>;

impl Compass {
    /// Maximises `eval` over `dims` coordinates from 0, whose value `at_zero` is given (`None`:
    /// the evaluation failed). A failed evaluation (`None`) scores −∞. The neighbours of a step
    /// are evaluated side by side and the best (the first of equals) taken, so the answer is
    /// the same for any thread count.
    pub fn maximise(
        &self,
        dims: usize,
        at_zero: Option<f64>,
        eval: &(dyn Fn(&[f64]) -> Option<f64> + Sync),
    ) -> Reached {
        self.maximise_keeping_last(dims, at_zero, eval).0
    }

    /// [`Compass::maximise`], with the points its last round evaluated (what a curvature at
    /// the answer needs, without running them again).
    pub fn maximise_keeping_last(
        &self,
        dims: usize,
        at_zero: Option<f64>,
        eval: &(dyn Fn(&[f64]) -> Option<f64> + Sync),
    ) -> (Reached, LastRound) {
        let mut last: LastRound = Vec::new();
        let (mut evaluations, mut failed) = (1, usize::from(at_zero.is_none()));
        let (mut u, mut best) = (vec![0.0; dims], at_zero.unwrap_or(f64::NEG_INFINITY));
        let mut step = self.first_step;
        for _ in 0..=self.halvings {
            while evaluations < self.max_evaluations {
                let moves: Vec<Vec<f64>> = (0..dims)
                    .flat_map(|j| [step, -step].map(|d| (j, d)))
                    .map(|(j, d)| {
                        let mut v = u.clone();
                        v[j] += d;
                        v
                    })
                    .filter(|v| v.iter().all(|x| x.abs() <= self.bound + 1e-12))
                    .collect();
                let tried: Vec<Option<f64>> = moves.par_iter().map(|v| eval(v)).collect();
                evaluations += tried.len();
                failed += tried.iter().filter(|l| l.is_none()).count();
                let mut gain: Option<(Vec<f64>, f64)> = None;
                for (v, l) in moves.iter().zip(&tried) {
                    if let Some(l) = *l {
                        if l > best && gain.as_ref().is_none_or(|(_, g)| l > *g) {
                            gain = Some((v.clone(), l));
                        }
                    }
                }
                last = moves.into_iter().zip(tried).collect();
                match gain {
                    Some((v, l)) => (u, best) = (v, l),
                    None => break,
                }
            }
            step /= 2.0;
        }
        (
            (u, best.is_finite().then_some(best), evaluations, failed),
            last,
        )
    }

    /// The last step the search takes.
    pub fn last_step(&self) -> f64 {
        self.first_step / 2f64.powi(self.halvings as i32)
    }
}
