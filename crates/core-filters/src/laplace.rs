//! The Laplace approximation of a smooth log-density known only through its values: its
//! gradient and Hessian by central differences, Newton's ascent to its mode, and the covariance
//! `(−H)⁻¹` there.
//!
//! What it is for: the information a record holds about θ when its likelihood is exact and
//! smooth in θ — a linear building, whose likelihood is the Kalman filter's. Then the maximum of
//! `log p(y | θ)` is the answer the record supports best, and `(−H)⁻¹` at it is the smallest
//! covariance an unbiased answer can have (the Cramér–Rao bound, with the observed information
//! in place of the expected). A particle estimate of the likelihood is not smooth in θ and must
//! not be given to it; the reference posterior of such data is sampled ([`crate::pmmh`]).
//!
//! Steps are absolute, one per coordinate, fixed for the whole ascent (a caller chooses them
//! relative to the start). The stencils are exact for a quadratic, so the Hessian's error is the
//! third derivatives' `O(h²)` plus round-off `O(ε·|f| / h²)`.
//!
//! The values of a stencil are asked for in one batch, so a caller may evaluate them in
//! parallel; the points and their order are a function of (x, h) only.

use nalgebra::{Cholesky, DMatrix, DVector, Dyn};

/// Why the ascent stopped without a mode.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LaplaceError {
    /// A step is not positive and finite, or the start and its steps differ in length.
    #[error("step {index}: {step} is not a positive finite step")]
    BadStep { index: usize, step: f64 },
    /// The log-density is not finite at a point of a stencil.
    #[error("the log-density is not finite at {at:?}")]
    NonFinite { at: Vec<f64> },
    /// −H is not positive definite: the point is not near a maximum, or the log-density is flat
    /// in some direction (the data do not identify that combination).
    #[error("the Hessian of the log-density is not negative definite at {at:?}: no maximum there, or a direction the data do not identify")]
    NotConcave { at: Vec<f64> },
    /// Newton's step did not increase the log-density, even halved `halvings` times.
    #[error("no increase along Newton's direction from {at:?} (halved {halvings} times)")]
    NoAscent { at: Vec<f64>, halvings: usize },
    /// The predicted gain was still above the tolerance after the last step.
    #[error("no convergence in {steps} Newton steps (predicted gain {gain:.3e} nats)")]
    NoConvergence { steps: usize, gain: f64 },
}

/// How far Newton's ascent goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonOptions {
    /// Newton steps at most.
    pub max_steps: usize,
    /// Converged when the predicted gain of the next step, `½ gᵀ(−H)⁻¹g`, is below this
    /// (nats; the default 10⁻⁶ leaves the mode within about 0.0014 s.d. of the maximum).
    pub tolerance: f64,
    /// Find the mode by quasi-Newton steps and evaluate the Hessian again near it (otherwise
    /// Newton's steps use the start's Hessian, which is then the one reported).
    pub hessian_at_mode: bool,
    /// When set, no step moves a coordinate by more than this fraction of its absolute value
    /// (for parameters on a ratio scale, such as stiffnesses, which must stay positive).
    pub max_rel_step: Option<f64>,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        Self {
            max_steps: 100,
            tolerance: 1e-6,
            hessian_at_mode: true,
            max_rel_step: None,
        }
    }
}

/// The mode of a log-density and its Gaussian approximation there.
#[derive(Debug, Clone, PartialEq)]
pub struct Laplace {
    /// Where the ascent started.
    pub start: Vec<f64>,
    /// The log-density at the start.
    pub value_at_start: f64,
    /// The mode reached.
    pub mode: Vec<f64>,
    /// The log-density at the mode.
    pub value: f64,
    /// The Hessian where the quasi-Newton phase stopped, within about √(2·tolerance) s.d. of
    /// the mode (the start's when not evaluated again).
    pub hessian: DMatrix<f64>,
    /// `(−H)⁻¹`.
    pub covariance: DMatrix<f64>,
    /// Newton steps taken.
    pub steps: usize,
    /// Values of the log-density asked for.
    pub evaluations: usize,
    /// The predicted gain of one more step when it stopped (nats).
    pub gain: f64,
}

impl Laplace {
    /// Standard deviation of each coordinate.
    pub fn sd(&self) -> Vec<f64> {
        self.covariance
            .diagonal()
            .iter()
            .map(|v| v.sqrt())
            .collect()
    }
}

/// The points whose values give the central-difference gradient at `x`: `x`, then `x ± hᵢeᵢ`
/// for each i (plus before minus).
pub(crate) fn gradient_points(x: &[f64], h: &[f64]) -> Vec<Vec<f64>> {
    let mut pts = Vec::with_capacity(1 + 2 * x.len());
    pts.push(x.to_vec());
    for i in 0..x.len() {
        for s in [1.0, -1.0] {
            let mut p = x.to_vec();
            p[i] += s * h[i];
            pts.push(p);
        }
    }
    pts
}

/// The points whose values give the central-difference Hessian (and gradient) at `x`: the
/// [`gradient_points`], then for each pair i < j the corners `x + a·hᵢeᵢ + b·hⱼeⱼ` with
/// (a, b) = (+,+), (+,−), (−,+), (−,−). `1 + 2p + 2p(p − 1)` points.
pub(crate) fn hessian_points(x: &[f64], h: &[f64]) -> Vec<Vec<f64>> {
    let p = x.len();
    let mut pts = gradient_points(x, h);
    pts.reserve(2 * p * p.saturating_sub(1));
    for i in 0..p {
        for j in i + 1..p {
            for (a, b) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                let mut q = x.to_vec();
                q[i] += a * h[i];
                q[j] += b * h[j];
                pts.push(q);
            }
        }
    }
    pts
}

/// The gradient from the values at [`gradient_points`] (or the first `1 + 2p` of
/// [`hessian_points`]): `gᵢ = (f(x + hᵢeᵢ) − f(x − hᵢeᵢ)) / 2hᵢ`.
pub(crate) fn gradient_from(values: &[f64], h: &[f64]) -> DVector<f64> {
    DVector::from_fn(h.len(), |i, _| {
        (values[1 + 2 * i] - values[2 + 2 * i]) / (2.0 * h[i])
    })
}

/// The Hessian from the values at [`hessian_points`]: `Hᵢᵢ = (f₊ − 2f + f₋) / hᵢ²` and
/// `Hᵢⱼ = (f₊₊ − f₊₋ − f₋₊ + f₋₋) / 4hᵢhⱼ`.
pub(crate) fn hessian_from(values: &[f64], h: &[f64]) -> DMatrix<f64> {
    let p = h.len();
    let mut m = DMatrix::zeros(p, p);
    for i in 0..p {
        m[(i, i)] = (values[1 + 2 * i] - 2.0 * values[0] + values[2 + 2 * i]) / (h[i] * h[i]);
    }
    let mut k = 1 + 2 * p;
    for i in 0..p {
        for j in i + 1..p {
            let v = &values[k..k + 4];
            let hij = (v[0] - v[1] - v[2] + v[3]) / (4.0 * h[i] * h[j]);
            m[(i, j)] = hij;
            m[(j, i)] = hij;
            k += 4;
        }
    }
    m
}

/// A positive definite stand-in for `−H` where `−H` is not one (far from the mode the
/// log-density may curve upwards in some direction): in the metric that makes the diagonal of
/// `−H` one in absolute value, its eigenvalues are replaced by their absolute values, floored at
/// 10⁻⁶ of the largest. Where `−H` is positive definite it is returned unchanged.
fn repaired(neg_h: &DMatrix<f64>) -> DMatrix<f64> {
    if neg_h.clone().cholesky().is_some() {
        return neg_h.clone();
    }
    let p = neg_h.nrows();
    let d = DVector::from_fn(p, |i, _| {
        let v = neg_h[(i, i)].abs();
        if v > 0.0 {
            v.sqrt()
        } else {
            1.0
        }
    });
    let scaled = DMatrix::from_fn(p, p, |i, j| neg_h[(i, j)] / (d[i] * d[j]));
    let eig = scaled.symmetric_eigen();
    let top = eig.eigenvalues.amax();
    let lambda = eig.eigenvalues.map(|l| l.abs().max(1e-6 * top));
    let fixed = &eig.eigenvectors * DMatrix::from_diagonal(&lambda) * eig.eigenvectors.transpose();
    DMatrix::from_fn(p, p, |i, j| fixed[(i, j)] * d[i] * d[j])
}

/// Where the ascent stands: the point, the log-density and its gradient there.
struct Point {
    x: DVector<f64>,
    f: f64,
    g: DVector<f64>,
}

/// One ascent: the log-density's evaluator, the steps and options, and what it has cost.
struct Ascent<'a, F> {
    eval: F,
    h: &'a [f64],
    opts: NewtonOptions,
    steps: usize,
    evaluations: usize,
}

impl<F, E> Ascent<'_, F>
where
    F: FnMut(&[Vec<f64>]) -> Result<Vec<f64>, E>,
    E: From<LaplaceError>,
{
    /// The values at `pts`, checked (one per point, all finite).
    fn values(&mut self, pts: &[Vec<f64>]) -> Result<Vec<f64>, E> {
        let v = (self.eval)(pts)?;
        self.evaluations += pts.len();
        assert_eq!(v.len(), pts.len(), "one value per point");
        if let Some(i) = v.iter().position(|f| !f.is_finite()) {
            return Err(LaplaceError::NonFinite { at: pts[i].clone() }.into());
        }
        Ok(v)
    }

    /// The point `x` with the Hessian there.
    fn curvature(&mut self, x: DVector<f64>) -> Result<(Point, DMatrix<f64>), E> {
        let v = self.values(&hessian_points(x.as_slice(), self.h))?;
        let at = Point {
            x,
            f: v[0],
            g: gradient_from(&v, self.h),
        };
        Ok((at, hessian_from(&v, self.h)))
    }

    /// A trial point along `delta` from `at`, with the gradient there. The step is first
    /// shortened so that no coordinate moves by more than `max_rel_step` of its absolute value
    /// (when set), then halved until the value at the trial point is finite and not below
    /// `at.f` (at most `HALVINGS` times); only then is the rest of its stencil evaluated.
    fn trial(&mut self, at: &Point, delta: &DVector<f64>) -> Result<Point, E> {
        const HALVINGS: usize = 10;
        let mut t: f64 = 1.0;
        if let Some(m) = self.opts.max_rel_step {
            for (xi, di) in at.x.iter().zip(delta.iter()) {
                if di.abs() > 0.0 {
                    t = t.min(m * xi.abs() / di.abs());
                }
            }
        }
        for _ in 0..=HALVINGS {
            let x = &at.x + t * delta;
            let centre = (self.eval)(&[x.as_slice().to_vec()])?;
            self.evaluations += 1;
            if centre[0].is_finite() && centre[0] >= at.f {
                let mut pts = gradient_points(x.as_slice(), self.h);
                pts.remove(0);
                let mut v = centre;
                v.extend(self.values(&pts)?);
                let g = gradient_from(&v, self.h);
                return Ok(Point { x, f: v[0], g });
            }
            t *= 0.5;
        }
        Err(LaplaceError::NoAscent {
            at: at.x.as_slice().to_vec(),
            halvings: HALVINGS,
        }
        .into())
    }

    /// Steps `δ = B⁻¹g` from `at` until the predicted gain `½ gᵀδ` is below the tolerance;
    /// returns the factor of `B` there and that gain. With `bfgs` (the quasi-Newton phase) `B`
    /// ≈ −H is updated by BFGS after each step and [`repaired`] when it is not positive
    /// definite; without it `B` is −H, fixed, and must be positive definite
    /// ([`LaplaceError::NotConcave`]).
    fn climb(
        &mut self,
        at: &mut Point,
        b: &mut DMatrix<f64>,
        bfgs: bool,
    ) -> Result<(Cholesky<f64, Dyn>, f64), E> {
        loop {
            let factor = match b.clone().cholesky() {
                Some(c) => Some(c),
                None if bfgs => {
                    *b = repaired(b);
                    b.clone().cholesky()
                }
                None => None,
            };
            let Some(chol) = factor else {
                return Err(LaplaceError::NotConcave {
                    at: at.x.as_slice().to_vec(),
                }
                .into());
            };
            let delta = chol.solve(&at.g);
            let gain = 0.5 * at.g.dot(&delta);
            if gain < self.opts.tolerance {
                return Ok((chol, gain));
            }
            if self.steps == self.opts.max_steps {
                return Err(LaplaceError::NoConvergence {
                    steps: self.steps,
                    gain,
                }
                .into());
            }
            let next = self.trial(at, &delta)?;
            if bfgs {
                let s = &next.x - &at.x;
                let y = &at.g - &next.g;
                let sy = s.dot(&y);
                if sy > 0.0 {
                    let bs = &*b * &s;
                    *b += &y * y.transpose() / sy - &bs * bs.transpose() / s.dot(&bs);
                }
            }
            *at = next;
            self.steps += 1;
        }
    }
}

/// The mode of a log-density from `start` with central-difference steps `h`, and its Laplace
/// approximation there. `eval` returns the log-density at each of a batch of points.
///
/// Two phases, so that a start far from the mode (where the log-density need not be concave)
/// costs gradients, not Hessians: (1) quasi-Newton (BFGS) ascent from the start's Hessian,
/// made positive definite where it is not, until the predicted gain of a step is below the
/// tolerance; (2) the Hessian there, which must be negative definite (otherwise
/// [`LaplaceError::NotConcave`]: the record does not identify some direction), and Newton's
/// steps with it until the predicted gain `½ gᵀ(−H)⁻¹g` is below the tolerance. Every step is
/// halved until the value does not fall. With `hessian_at_mode` false the second phase uses
/// the start's Hessian (for a log-density known to be concave and near-quadratic). A trial
/// point where the log-density is not finite (outside its support) counts as a fall.
pub fn maximise<E, F>(start: &[f64], h: &[f64], opts: NewtonOptions, eval: F) -> Result<Laplace, E>
where
    F: FnMut(&[Vec<f64>]) -> Result<Vec<f64>, E>,
    E: From<LaplaceError>,
{
    if h.len() != start.len() {
        return Err(LaplaceError::BadStep {
            index: h.len().min(start.len()),
            step: f64::NAN,
        }
        .into());
    }
    if let Some(i) = h.iter().position(|s| !(s.is_finite() && *s > 0.0)) {
        return Err(LaplaceError::BadStep {
            index: i,
            step: h[i],
        }
        .into());
    }
    let mut ascent = Ascent {
        eval,
        h,
        opts,
        steps: 0,
        evaluations: 0,
    };
    let (mut at, mut hessian) = ascent.curvature(DVector::from_column_slice(start))?;
    let value_at_start = at.f;
    // Phase 1: BFGS on −f from the start's curvature, made positive definite.
    if opts.hessian_at_mode {
        let mut b = repaired(&-&hessian);
        ascent.climb(&mut at, &mut b, true)?;
        if ascent.steps > 0 {
            (at, hessian) = ascent.curvature(at.x)?;
        }
    }
    // Phase 2: Newton with the Hessian near the mode, which must be negative definite.
    let (chol, gain) = ascent.climb(&mut at, &mut -&hessian, false)?;
    let covariance = chol.inverse();
    let Ascent {
        steps, evaluations, ..
    } = ascent;
    let Point { x, f, .. } = at;
    Ok(Laplace {
        start: start.to_vec(),
        value_at_start,
        mode: x.as_slice().to_vec(),
        value: f,
        hessian,
        covariance,
        steps,
        evaluations,
        gain,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serial(
        f: impl Fn(&[f64]) -> f64,
    ) -> impl FnMut(&[Vec<f64>]) -> Result<Vec<f64>, LaplaceError> {
        move |pts| Ok(pts.iter().map(|p| f(p)).collect())
    }

    /// −½ (x − m)ᵀ A (x − m) + 3 with a full, positive definite A.
    fn quadratic() -> (DMatrix<f64>, DVector<f64>, impl Fn(&[f64]) -> f64) {
        let a = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, -0.7, 0.5, -0.7, 2.0]);
        let m = DVector::from_column_slice(&[1.0, -2.0, 0.5]);
        let (a2, m2) = (a.clone(), m.clone());
        let f = move |x: &[f64]| {
            let d = DVector::from_column_slice(x) - &m2;
            -0.5 * d.dot(&(&a2 * &d)) + 3.0
        };
        (a, m, f)
    }

    #[test]
    fn the_stencils_are_exact_for_a_quadratic() {
        let (a, m, f) = quadratic();
        let x = [0.3, 0.1, -0.4];
        let h = [1e-2, 2e-2, 5e-3];
        let pts = hessian_points(&x, &h);
        assert_eq!(pts.len(), 1 + 2 * 3 + 2 * 3 * 2);
        let v: Vec<f64> = pts.iter().map(|p| f(p)).collect();
        let hess = hessian_from(&v, &h);
        assert!((&hess + &a).amax() < 1e-9, "{hess}");
        let g = gradient_from(&v, &h);
        let exact = -&a * (DVector::from_column_slice(&x) - m);
        assert!((g - exact).amax() < 1e-10);
    }

    #[test]
    fn newton_reaches_a_quadratics_maximum_in_one_step() {
        let (a, m, f) = quadratic();
        let l = maximise(
            &[0.0, 0.0, 0.0],
            &[1e-2; 3],
            NewtonOptions::default(),
            serial(f),
        )
        .unwrap();
        assert_eq!(l.steps, 1);
        let mode = DVector::from_column_slice(&l.mode);
        assert!((mode - m).amax() < 1e-9, "{:?}", l.mode);
        assert!((l.value - 3.0).abs() < 1e-12);
        let cov = a.try_inverse().unwrap();
        assert!((&l.covariance - &cov).amax() < 1e-9);
        // The start's Hessian, then one gradient stencil, then the mode's Hessian.
        assert_eq!(l.evaluations, 19 + 7 + 19);
    }

    #[test]
    fn newton_finds_the_mode_of_a_non_quadratic_log_density() {
        // Independent gamma log-densities aᵢ ln x − bᵢ x: mode aᵢ/bᵢ, −H = aᵢ/x² there.
        let (a, b) = ([50.0, 200.0], [10.0, 4.0]);
        let f = move |x: &[f64]| (0..2).map(|i| a[i] * x[i].ln() - b[i] * x[i]).sum::<f64>();
        let start = [4.0, 60.0];
        let h = [4e-4, 6e-3];
        let l = maximise(&start, &h, NewtonOptions::default(), serial(f)).unwrap();
        // The start's Hessian steers every step, so the ascent is linear, and it stops when the
        // predicted gain is below 10⁻⁶ nats: within √(2·10⁻⁶) ≈ 0.0014 s.d. of the mode.
        for i in 0..2 {
            let mode = a[i] / b[i];
            let sd = mode / a[i].sqrt();
            assert!((l.mode[i] - mode).abs() < 0.002 * sd, "{:?}", l.mode);
            assert!((l.sd()[i] / sd - 1.0).abs() < 1e-3, "{:?}", l.sd());
        }
        assert!(l.steps >= 2 && l.steps <= 10, "{}", l.steps);
        assert!(l.value > l.value_at_start);
    }

    #[test]
    fn a_start_where_the_log_density_is_not_concave_still_reaches_the_mode() {
        // −(1 − x)² − 10(y − x²)²: at (0, 0.5) the Hessian is indefinite; the mode is (1, 1),
        // where −H = [[82, −40], [−40, 20]].
        let f = |x: &[f64]| -(1.0 - x[0]).powi(2) - 10.0 * (x[1] - x[0] * x[0]).powi(2);
        let l = maximise(&[0.0, 0.5], &[1e-3; 2], NewtonOptions::default(), serial(f)).unwrap();
        assert!(
            (l.mode[0] - 1.0).abs() < 1e-3 && (l.mode[1] - 1.0).abs() < 2e-3,
            "{:?}",
            l.mode
        );
        let cov = DMatrix::from_row_slice(2, 2, &[82.0, -40.0, -40.0, 20.0])
            .try_inverse()
            .unwrap();
        assert!(
            (&l.covariance - &cov).amax() < 1e-3 * cov.amax(),
            "{}",
            l.covariance
        );
    }

    #[test]
    fn a_step_out_of_the_support_is_shortened() {
        // 3 ln x − x from x = 20: the first Newton step (−113) leaves the support; halving finds
        // a finite, higher value, and the ascent ends at the mode 3 with s.d. √3.
        let f = |x: &[f64]| 3.0 * x[0].ln() - x[0];
        let l = maximise(&[20.0], &[1e-3], NewtonOptions::default(), serial(f)).unwrap();
        assert!((l.mode[0] - 3.0).abs() < 0.01, "{:?}", l.mode);
        assert!((l.sd()[0] / 3f64.sqrt() - 1.0).abs() < 0.01, "{:?}", l.sd());
        // With steps of at most a fifth of the value, the same mode.
        let opts = NewtonOptions {
            max_rel_step: Some(0.2),
            ..NewtonOptions::default()
        };
        let l2 = maximise(&[20.0], &[1e-3], opts, serial(f)).unwrap();
        assert!((l2.mode[0] - 3.0).abs() < 0.01, "{:?}", l2.mode);
        assert!(l2.steps > l.steps, "{} {}", l2.steps, l.steps);
    }

    #[test]
    fn no_maximum_an_unidentified_direction_a_bad_step_and_a_non_finite_value_are_errors() {
        let saddle = |x: &[f64]| x[0] * x[0] - x[1] * x[1];
        assert!(maximise(
            &[0.1, 0.1],
            &[1e-3; 2],
            NewtonOptions::default(),
            serial(saddle)
        )
        .is_err());
        // Nothing depends on x₁: a direction the log-density does not identify.
        let flat = |x: &[f64]| -x[0] * x[0];
        assert!(matches!(
            maximise(
                &[0.1, 0.1],
                &[1e-3; 2],
                NewtonOptions::default(),
                serial(flat)
            ),
            Err(LaplaceError::NotConcave { .. })
        ));
        let bowl = |x: &[f64]| -x[0] * x[0] - x[1] * x[1];
        assert!(matches!(
            maximise(
                &[0.1, 0.1],
                &[1e-3, 0.0],
                NewtonOptions::default(),
                serial(bowl)
            ),
            Err(LaplaceError::BadStep { index: 1, .. })
        ));
        let log = |x: &[f64]| x[0].ln() - x[0];
        assert!(matches!(
            maximise(&[0.0], &[1e-3], NewtonOptions::default(), serial(log)),
            Err(LaplaceError::NonFinite { .. })
        ));
    }
}
