//! Integrators of the continuous equations of motion under a sampled ground acceleration
//! (SPEC §2 truth, SPEC §7 validation).
//!
//! The ground acceleration is known at the sample times `t_k = k·dt` and linearly interpolated
//! in between. Both integrators output the state at every sample time, starting from zero
//! initial conditions (row 0 is the state at `t = 0`).
//!
//! - [`simulate_rk4`]: classical RK4 with step `dt` (the truth of SPEC §2). The midpoint value of
//!   `ü_g` is the average of the two samples, which is exact for the linear interpolant.
//! - [`simulate_adaptive`]: adaptive Dormand–Prince 5(4) (the method of MATLAB's `ode45`) for the
//!   validation runs. It is written here rather than taken from the `ode_solvers` crate because
//!   the interpolated input has a kink at every sample time: steps must end exactly on the
//!   sample times (otherwise the error estimator sees the kink and the order drops), the step
//!   size should carry over from one sample interval to the next, and the state has a run-time
//!   dimension (N storeys). Integrating sample interval by sample interval with a carried step
//!   size gives all three and the output at the data times for free.
//! - [`simulate_linear_exact`]: a building without hysteretic element is a linear system, and
//!   under an input linear between samples its response has a closed form (the first-order
//!   hold): one matrix–vector product per sample instead of the adaptive steps, exact to
//!   round-off where [`simulate_adaptive`] is exact to its tolerance.

use crate::law::HysteresisLaw;
use crate::structure::ShearChainOf;
use thiserror::Error;

/// A system `ẏ = g(y, ü_g)` driven by a scalar input (the ground acceleration).
pub trait ForcedSystem {
    /// State dimension.
    fn dim(&self) -> usize;
    /// Writes `g(state, ug)` into `dstate`. Must not allocate.
    fn rhs(&self, state: &[f64], ug: f64, dstate: &mut [f64]);
}

impl<L: HysteresisLaw> ForcedSystem for ShearChainOf<L> {
    fn dim(&self) -> usize {
        ShearChainOf::dim(self)
    }
    fn rhs(&self, state: &[f64], ug: f64, dstate: &mut [f64]) {
        ShearChainOf::rhs(self, state, ug, dstate)
    }
}

/// States at every sample time, row-major (`row k` = state at `t_k = k·dt`).
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    dim: usize,
    dt: f64,
    states: Vec<f64>,
}

impl Trajectory {
    /// Wraps a row-major buffer of `len·dim` values.
    #[track_caller]
    pub fn from_flat(dim: usize, dt: f64, states: Vec<f64>) -> Self {
        assert!(
            dim > 0 && states.len().is_multiple_of(dim),
            "buffer is not a whole number of rows"
        );
        Self { dim, dt, states }
    }

    pub fn dim(&self) -> usize {
        self.dim
    }

    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.states.len() / self.dim
    }

    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// Time of sample `k`.
    pub fn t(&self, k: usize) -> f64 {
        k as f64 * self.dt
    }

    /// State at sample `k`.
    pub fn state(&self, k: usize) -> &[f64] {
        &self.states[k * self.dim..(k + 1) * self.dim]
    }

    /// Component `i` over time.
    pub fn component(&self, i: usize) -> Vec<f64> {
        assert!(i < self.dim, "component {i} out of range");
        self.states
            .iter()
            .skip(i)
            .step_by(self.dim)
            .copied()
            .collect()
    }

    /// The flat row-major buffer.
    pub fn as_flat(&self) -> &[f64] {
        &self.states
    }

    /// Rows as an iterator.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, f64> {
        self.states.chunks_exact(self.dim)
    }
}

/// The four stage derivatives and the stage state of one RK4 step.
struct Rk4Scratch {
    k: [Vec<f64>; 4],
    tmp: Vec<f64>,
}

impl Rk4Scratch {
    fn new(n: usize) -> Self {
        Self {
            k: std::array::from_fn(|_| vec![0.0; n]),
            tmp: vec![0.0; n],
        }
    }
}

/// One classical RK4 step of size `h` from `y` into `out`, `ü_g` going linearly from `ua` to `ub`
/// over the step (its midpoint value for the two middle stages).
fn rk4_step<S: ForcedSystem + ?Sized>(
    sys: &S,
    y: &[f64],
    out: &mut [f64],
    (ua, ub): (f64, f64),
    h: f64,
    s: &mut Rk4Scratch,
) {
    let um = 0.5 * (ua + ub);
    let [k1, k2, k3, k4] = &mut s.k;
    let tmp = &mut s.tmp;
    sys.rhs(y, ua, k1);
    for i in 0..y.len() {
        tmp[i] = y[i] + 0.5 * h * k1[i];
    }
    sys.rhs(tmp, um, k2);
    for i in 0..y.len() {
        tmp[i] = y[i] + 0.5 * h * k2[i];
    }
    sys.rhs(tmp, um, k3);
    for i in 0..y.len() {
        tmp[i] = y[i] + h * k3[i];
    }
    sys.rhs(tmp, ub, k4);
    for i in 0..y.len() {
        out[i] = y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
}

/// Classical RK4 at fixed step `dt` from zero initial conditions, one step per sample interval,
/// `ü_g` linearly interpolated (SPEC §2). Returns `ug.len()` rows.
#[track_caller]
pub fn simulate_rk4<S: ForcedSystem + ?Sized>(sys: &S, ug: &[f64], dt: f64) -> Trajectory {
    assert!(dt > 0.0, "dt must be positive");
    let n = sys.dim();
    let mut states = vec![0.0; ug.len() * n];
    let mut scratch = Rk4Scratch::new(n);
    for k in 1..ug.len() {
        let (done, rest) = states.split_at_mut(k * n);
        rk4_step(
            sys,
            &done[(k - 1) * n..],
            &mut rest[..n],
            (ug[k - 1], ug[k]),
            dt,
            &mut scratch,
        );
    }
    Trajectory::from_flat(n, dt, states)
}

/// Largest `|λ|·h` on the negative real axis for which a classical RK4 step of size `h` is stable
/// (the exact bound is 2.7853; the margin keeps rounding on the stable side).
pub(crate) const RK4_REAL_STABILITY: f64 = 2.78;

/// An upper bound of the fastest decay rate `|λ|` (s⁻¹) of a shear chain's damping:
/// Gershgorin's bound of the eigenvalues of `M⁻¹C`, `max_i (|c_i| + |c_{i+1}|)·2 / m_i`. The
/// overdamped top modes of a chain with stiffness-proportional damping decay at nearly this rate
/// (the `building-chain` preset at 200 storeys: 913 s⁻¹), which is what limits an explicit step;
/// the oscillatory modes (|λ| = ω ≤ 2√(max k/m), 89 s⁻¹ there) are far inside the limit.
pub fn fastest_damping_rate<L: HysteresisLaw>(chain: &ShearChainOf<L>) -> f64 {
    let (m, c) = (chain.masses(), chain.damping());
    (0..m.len())
        .map(|i| {
            let above = c.get(i + 1).map_or(0.0, |x| x.abs());
            2.0 * (c[i].abs() + above) / m[i]
        })
        .fold(0.0, f64::max)
}

/// RK4 steps per sample interval that keep the truth integration of `chain` at step `dt`
/// stable: 1 while [`fastest_damping_rate`]`·dt ≤ RK4_REAL_STABILITY` (2.78; every chain of the
/// paper and of the scaling study, whose data are unchanged), else the smallest count that
/// brings the sub-step inside the bound (2 for the 200-storey `building-chain`).
pub fn rk4_substeps<L: HysteresisLaw>(chain: &ShearChainOf<L>, dt: f64) -> usize {
    let z = fastest_damping_rate(chain) * dt;
    if z.is_finite() && z > RK4_REAL_STABILITY {
        (z / RK4_REAL_STABILITY).ceil() as usize
    } else {
        1
    }
}

/// [`simulate_rk4`] with `substeps` equal RK4 steps per sample interval, `ü_g` linearly
/// interpolated at the sub-step times; `substeps = 1` is [`simulate_rk4`] itself (the same
/// operations, bit for bit). Returns `ug.len()` rows at the sample times.
#[track_caller]
pub fn simulate_rk4_substeps<S: ForcedSystem + ?Sized>(
    sys: &S,
    ug: &[f64],
    dt: f64,
    substeps: usize,
) -> Trajectory {
    if substeps <= 1 {
        return simulate_rk4(sys, ug, dt);
    }
    assert!(dt > 0.0, "dt must be positive");
    let n = sys.dim();
    let h = dt / substeps as f64;
    let mut states = vec![0.0; ug.len() * n];
    let (mut y, mut next) = (vec![0.0; n], vec![0.0; n]);
    let mut scratch = Rk4Scratch::new(n);
    for k in 1..ug.len() {
        let (u0, u1) = (ug[k - 1], ug[k]);
        let at = |j: f64| u0 + (u1 - u0) * (j / substeps as f64);
        for j in 0..substeps {
            let u = (at(j as f64), at(j as f64 + 1.0));
            rk4_step(sys, &y, &mut next, u, h, &mut scratch);
            std::mem::swap(&mut y, &mut next);
        }
        states[k * n..(k + 1) * n].copy_from_slice(&y);
    }
    Trajectory::from_flat(n, dt, states)
}

/// Tolerances of the adaptive integrator: a step is accepted when the RMS over components of
/// `err_i / (atol + rtol·max(|y_i|, |y_new_i|))` is at most 1 (Hairer–Nørsett–Wanner).
///
/// Defaults `rtol = 1e-6`, `atol = 1e-9`. MATLAB's `ode45` defaults (`1e-3`, `1e-6`) are looser;
/// they would put the validation run's own error near the differences between parameter sets
/// that SPEC §7 compares, so the tighter values are used.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Tolerance {
    pub rtol: f64,
    pub atol: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Self {
            rtol: 1e-6,
            atol: 1e-9,
        }
    }
}

/// Failures of the adaptive integrator.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum IntegrateError {
    #[error(
        "invalid tolerance rtol = {rtol}, atol = {atol} (both must be finite, atol > 0, rtol ≥ 0)"
    )]
    InvalidTolerance { rtol: f64, atol: f64 },
    #[error("non-finite state at t = {t}")]
    NonFinite { t: f64 },
    #[error("step size underflow at t = {t} (h = {h:e}); the solution is probably blowing up")]
    StepSizeUnderflow { t: f64, h: f64 },
    #[error(
        "the exact linear solution needs a building without hysteretic element; this one has {0}"
    )]
    NotLinear(usize),
}

// Dormand–Prince 5(4) coefficients (Dormand & Prince 1980; Hairer, Nørsett & Wanner, Table 5.2).
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const B1: f64 = 35.0 / 384.0;
const B3: f64 = 500.0 / 1113.0;
const B4: f64 = 125.0 / 192.0;
const B5: f64 = -2187.0 / 6784.0;
const B6: f64 = 11.0 / 84.0;
// Error coefficients: 5th-order weights minus the embedded 4th-order ones.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

/// Adaptive Dormand–Prince 5(4) from zero initial conditions with output at every sample time
/// (SPEC §7 validation). Steps never cross a sample time; the step size carries over between
/// intervals; FSAL is used across intervals (the input is continuous there).
pub fn simulate_adaptive<S: ForcedSystem + ?Sized>(
    sys: &S,
    ug: &[f64],
    dt: f64,
    tol: Tolerance,
) -> Result<Trajectory, IntegrateError> {
    assert!(dt > 0.0, "dt must be positive");
    if !(tol.rtol >= 0.0 && tol.atol > 0.0 && tol.rtol.is_finite() && tol.atol.is_finite()) {
        return Err(IntegrateError::InvalidTolerance {
            rtol: tol.rtol,
            atol: tol.atol,
        });
    }
    let n = sys.dim();
    let mut states = vec![0.0; ug.len() * n];
    if ug.len() < 2 {
        return Ok(Trajectory::from_flat(n, dt, states));
    }
    let mut st = DpState {
        y: vec![0.0; n],
        ynew: vec![0.0; n],
        tmp: vec![0.0; n],
        k: std::array::from_fn(|_| vec![0.0; n]),
        h: 0.1 * dt,
        h_min: 1e-12 * dt,
    };
    sys.rhs(&st.y, ug[0], &mut st.k[0]);
    for step in 1..ug.len() {
        let t0 = (step - 1) as f64 * dt;
        advance_interval(sys, &mut st, (ug[step - 1], ug[step]), t0, dt, tol)?;
        if st.y.iter().any(|v| !v.is_finite()) {
            return Err(IntegrateError::NonFinite {
                t: step as f64 * dt,
            });
        }
        states[step * n..(step + 1) * n].copy_from_slice(&st.y);
    }
    Ok(Trajectory::from_flat(n, dt, states))
}

/// What the adaptive integrator carries from step to step: the state `y`, the candidate
/// `ynew`, a stage input `tmp`, the stage derivatives `k` (`k[0]` the derivative at `y`,
/// `k[6]` the one at `ynew`: FSAL), the step size `h` and its floor `h_min`.
struct DpState {
    y: Vec<f64>,
    ynew: Vec<f64>,
    tmp: Vec<f64>,
    k: [Vec<f64>; 7],
    h: f64,
    h_min: f64,
}

/// Integrates over one sample interval `[t0, t0 + dt]`, the input linear from `u0` to `u1`:
/// adaptive steps that never cross its end (no sliver step before it), rejected and retried
/// smaller when the error is above tolerance; the step size carries in and out in `st.h`.
fn advance_interval<S: ForcedSystem + ?Sized>(
    sys: &S,
    st: &mut DpState,
    (u0, u1): (f64, f64),
    t0: f64,
    dt: f64,
    tol: Tolerance,
) -> Result<(), IntegrateError> {
    // Input inside the interval, as a function of the offset s ∈ [0, dt].
    let u_at = |s: f64| u0 + (u1 - u0) * (s / dt);
    let mut s = 0.0;
    while s < dt {
        let last = s + 1.01 * st.h >= dt; // no sliver steps before a sample time
        let hh = if last { dt - s } else { st.h };
        let u_end = if last { u1 } else { u_at(s + hh) };
        dormand_prince_step(sys, st, s, hh, u_at, u_end);
        let err = error_norm(st, hh, tol);
        if !err.is_finite() {
            // A non-finite error estimate: shrink hard, fail if it cannot be resolved.
            st.h = 0.1 * hh;
            if st.h < st.h_min {
                return Err(IntegrateError::NonFinite { t: t0 + s });
            }
            continue;
        }
        let fac = if err == 0.0 {
            5.0
        } else {
            (0.9 * err.powf(-0.2)).clamp(0.2, 5.0)
        };
        if err <= 1.0 {
            s = if last { dt } else { s + hh };
            st.y.copy_from_slice(&st.ynew);
            st.k.swap(0, 6);
            // Only grow the step beyond the shortened last step of an interval if the
            // full step also succeeded; keep the previous step size otherwise.
            if !last || hh >= st.h {
                st.h = hh * fac;
            }
        } else {
            st.h = hh * fac.min(1.0);
            if st.h < st.h_min {
                return Err(IntegrateError::StepSizeUnderflow { t: t0 + s, h: st.h });
            }
        }
    }
    Ok(())
}

/// The stage input `y + hh·Σ a_j·k_j` (`coef`: the pairs `(j, a_j)`), into `tmp`.
fn stage_state(y: &[f64], k: &[Vec<f64>; 7], coef: &[(usize, f64)], hh: f64, tmp: &mut [f64]) {
    for i in 0..y.len() {
        let mut acc = 0.0;
        for &(j, a) in coef {
            acc += a * k[j][i];
        }
        tmp[i] = y[i] + hh * acc;
    }
}

/// One Dormand–Prince step of size `hh` from the offset `s` (input `u_at`): the stage
/// derivatives `k[1..6]`, the 5th-order solution `ynew` and its derivative `k[6]` at the
/// input `u_end`.
fn dormand_prince_step<S: ForcedSystem + ?Sized>(
    sys: &S,
    st: &mut DpState,
    s: f64,
    hh: f64,
    u_at: impl Fn(f64) -> f64,
    u_end: f64,
) {
    let (y, k, tmp) = (&st.y, &mut st.k, &mut st.tmp);
    stage_state(y, k, &[(0, A21)], hh, tmp);
    sys.rhs(tmp, u_at(s + C2 * hh), &mut k[1]);
    stage_state(y, k, &[(0, A31), (1, A32)], hh, tmp);
    sys.rhs(tmp, u_at(s + C3 * hh), &mut k[2]);
    stage_state(y, k, &[(0, A41), (1, A42), (2, A43)], hh, tmp);
    sys.rhs(tmp, u_at(s + C4 * hh), &mut k[3]);
    stage_state(y, k, &[(0, A51), (1, A52), (2, A53), (3, A54)], hh, tmp);
    sys.rhs(tmp, u_at(s + C5 * hh), &mut k[4]);
    stage_state(
        y,
        k,
        &[(0, A61), (1, A62), (2, A63), (3, A64), (4, A65)],
        hh,
        tmp,
    );
    sys.rhs(tmp, u_at(s + hh), &mut k[5]);
    for i in 0..y.len() {
        st.ynew[i] =
            y[i] + hh * (B1 * k[0][i] + B3 * k[2][i] + B4 * k[3][i] + B5 * k[4][i] + B6 * k[5][i]);
    }
    sys.rhs(&st.ynew, u_end, &mut k[6]);
}

/// The step's error estimate (5th- minus embedded 4th-order solution) as the RMS over the
/// state of `err_i / (atol + rtol·max(|y_i|, |ynew_i|))`.
fn error_norm(st: &DpState, hh: f64, tol: Tolerance) -> f64 {
    let (y, ynew, k) = (&st.y, &st.ynew, &st.k);
    let n = y.len();
    let mut err2 = 0.0;
    for i in 0..n {
        let e = hh
            * (E1 * k[0][i]
                + E3 * k[2][i]
                + E4 * k[3][i]
                + E5 * k[4][i]
                + E6 * k[5][i]
                + E7 * k[6][i]);
        let sc = tol.atol + tol.rtol * y[i].abs().max(ynew[i].abs());
        err2 += (e / sc) * (e / sc);
    }
    (err2 / n as f64).sqrt()
}

/// The response of a linear chain (no hysteretic element) from rest under `ug` linear between
/// the samples, exactly: with the state s = [x; v], ṡ = A s + B ü_g, and ü_g = u_k + u̇_k t on
/// each interval (u̇_k = (u_{k+1} − u_k)/dt), the augmented state z = [s; ü_g; u̇] obeys ż = Z z
/// with `Z = [[A, B, 0], [0, 0, 1], [0, 0, 0]]`, so over one interval
///
/// `s_{k+1} = Φ s_k + Γ₀ u_k + Γ₁ u̇_k`, with `[Φ Γ₀ Γ₁]` the first n rows of `exp(Z·dt)`.
///
/// A and B are read from the chain's own right-hand side (its columns at the unit states and at
/// a unit input), so the equations are those every other integrator uses; `exp` is nalgebra's
/// Padé scaling-and-squaring. The same solution [`simulate_adaptive`] approaches to its
/// tolerance, at the cost of one n × n matrix–vector product per sample.
pub fn simulate_linear_exact<L: HysteresisLaw>(
    chain: &ShearChainOf<L>,
    ug: &[f64],
    dt: f64,
) -> Result<Trajectory, IntegrateError> {
    assert!(dt > 0.0, "dt must be positive");
    if !chain.elements().is_empty() {
        return Err(IntegrateError::NotLinear(chain.elements().len()));
    }
    let n = chain.dim();
    let mut states = vec![0.0; ug.len() * n];
    if ug.len() < 2 {
        return Ok(Trajectory::from_flat(n, dt, states));
    }
    let (phi, g0, g1) = first_order_hold(chain, n, dt);
    let mut s = vec![0.0; n];
    for k in 1..ug.len() {
        let (u, du) = (ug[k - 1], (ug[k] - ug[k - 1]) / dt);
        let row = &mut states[k * n..(k + 1) * n];
        for (i, out) in row.iter_mut().enumerate() {
            let phi_s: f64 = (0..n).map(|j| phi[(i, j)] * s[j]).sum();
            *out = phi_s + g0[i] * u + g1[i] * du;
        }
        if row.iter().any(|v| !v.is_finite()) {
            return Err(IntegrateError::NonFinite { t: k as f64 * dt });
        }
        s.copy_from_slice(row);
    }
    Ok(Trajectory::from_flat(n, dt, states))
}

/// `Φ`, `Γ₀`, `Γ₁` of [`simulate_linear_exact`] for a linear `chain` of `n` = `chain.dim()`
/// states: the first n rows of `exp(Z·dt)`, so that `s[k] = Φ s[k−1] + Γ₀ ü_g[k−1] + Γ₁
/// (ü_g[k] − ü_g[k−1])/dt` exactly. Public for callers that run many small chains and keep
/// their own states (the discrepancy modes of a free run).
pub fn first_order_hold<L: HysteresisLaw>(
    chain: &ShearChainOf<L>,
    n: usize,
    dt: f64,
) -> (nalgebra::DMatrix<f64>, Vec<f64>, Vec<f64>) {
    let mut z = nalgebra::DMatrix::<f64>::zeros(n + 2, n + 2);
    let (mut unit, mut column) = (vec![0.0; n], vec![0.0; n]);
    for j in 0..n {
        unit[j] = 1.0;
        chain.rhs(&unit, 0.0, &mut column);
        unit[j] = 0.0;
        for i in 0..n {
            z[(i, j)] = column[i] * dt;
        }
    }
    chain.rhs(&unit, 1.0, &mut column);
    for i in 0..n {
        z[(i, n)] = column[i] * dt;
    }
    z[(n, n + 1)] = dt;
    let e = z.exp();
    let phi = e.view((0, 0), (n, n)).into_owned();
    let g0 = (0..n).map(|i| e[(i, n)]).collect();
    let g1 = (0..n).map(|i| e[(i, n + 1)]).collect();
    (phi, g0, g1)
}

/// The response of the oscillator `q̈ + 2ζω q̇ + ω² q = −ü_g` (`f_hz`, `zeta`) to `ug` from rest as
/// the two signals `ω² q` and `ω q̇`, by the exact solution of the one-storey chain of unit mass
/// ([`first_order_hold`], as [`simulate_linear_exact`] steps it; the recursion written out for its two
/// states because the search runs it thousands of times).
pub fn oscillator_basis(f_hz: f64, zeta: f64, ug: &[f64], dt: f64) -> [Vec<f64>; 2] {
    let w = 2.0 * std::f64::consts::PI * f_hz;
    let building =
        crate::building::Building::new(vec![1.0], vec![], crate::building::Damping::Storey)
            .expect("a one-storey building of unit mass is valid");
    let chain = crate::structure::ShearChain::from_theta(&building, &[w * w, 2.0 * zeta * w])
        .expect("a positive stiffness and damping make a valid chain");
    let (phi, g0, g1) = first_order_hold(&chain, 2, dt);
    let n = ug.len();
    let (mut q, mut qd) = (vec![0.0; n], vec![0.0; n]);
    let (mut x, mut v) = (0.0, 0.0);
    for k in 1..n {
        let (u, du) = (ug[k - 1], (ug[k] - ug[k - 1]) / dt);
        (x, v) = (
            phi[(0, 0)] * x + phi[(0, 1)] * v + g0[0] * u + g1[0] * du,
            phi[(1, 0)] * x + phi[(1, 1)] * v + g0[1] * u + g1[1] * du,
        );
        q[k] = w * w * x;
        qd[k] = w * v;
    }
    [q, qd]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Damped linear oscillator `ẍ = −ω²x − 2ζωẋ − ü_g`, solved exactly for a constant input.
    struct Oscillator {
        w: f64,
        z: f64,
    }

    impl ForcedSystem for Oscillator {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&self, s: &[f64], ug: f64, d: &mut [f64]) {
            d[0] = s[1];
            d[1] = -self.w * self.w * s[0] - 2.0 * self.z * self.w * s[1] - ug;
        }
    }

    fn step_response(o: &Oscillator, a: f64, t: f64) -> f64 {
        // x(t) for x(0)=ẋ(0)=0 under constant ü_g = a: x = −a/ω² (1 − e^{−ζωt}(cos ω_d t +
        // ζω/ω_d sin ω_d t)).
        let wd = o.w * (1.0 - o.z * o.z).sqrt();
        let e = (-o.z * o.w * t).exp();
        -a / (o.w * o.w) * (1.0 - e * ((wd * t).cos() + o.z * o.w / wd * (wd * t).sin()))
    }

    /// A one-storey linear chain (m = 2, k = 18, c = 0.6: ω = 3, ζ = 0.05) is the oscillator
    /// above: its exact solution under a constant input is the step response to round-off.
    #[test]
    fn the_exact_linear_solution_is_the_step_response() {
        let chain =
            crate::structure::ShearChain::new(vec![2.0], vec![18.0], vec![0.6], vec![]).unwrap();
        let o = Oscillator { w: 3.0, z: 0.05 };
        let dt = 0.01;
        let ug = vec![2.0; 501];
        let ex = simulate_linear_exact(&chain, &ug, dt).unwrap();
        assert_eq!(ex.len(), 501);
        let err = (0..ex.len())
            .map(|k| (ex.state(k)[0] - step_response(&o, 2.0, ex.t(k))).abs())
            .fold(0.0, f64::max);
        // Amplitude 2/9; 500 products by Φ, each good to a few ulps.
        assert!(err < 1e-13, "exact solution error {err}");
    }

    /// Three storeys with mass-proportional damping under an input with kinks at every sample:
    /// the exact solution and the adaptive integrator at a tight tolerance agree to that
    /// tolerance; at a loose one they do not (so the comparison can fail).
    #[test]
    fn the_exact_linear_solution_is_what_the_adaptive_integrator_approaches() {
        use crate::building::Building;
        use crate::structure::{Damping, ShearChain};
        let building = Building::new(vec![1.0, 1.0, 1.2], vec![], Damping::StoreyMass).unwrap();
        let theta = [2000.0, 1800.0, 1500.0, 0.8, 0.5, 0.3, 0.4];
        let chain = ShearChain::from_theta(&building, &theta).unwrap();
        let dt = 0.005;
        let ug: Vec<f64> = (0..2000)
            .map(|k| {
                let t = k as f64 * dt;
                (7.0 * t).sin() + 0.5 * (31.0 * t).cos() + if k % 7 == 0 { 0.3 } else { 0.0 }
            })
            .collect();
        let ex = simulate_linear_exact(&chain, &ug, dt).unwrap();
        let gap = |rtol: f64| {
            let ad = simulate_adaptive(&chain, &ug, dt, Tolerance { rtol, atol: 1e-14 }).unwrap();
            let (mut diff, mut size) = (0.0_f64, 0.0_f64);
            for k in 0..ug.len() {
                for (a, b) in ad.state(k).iter().zip(ex.state(k)) {
                    diff = diff.max((a - b).abs());
                    size = size.max(b.abs());
                }
            }
            diff / size
        };
        let tight = gap(1e-11);
        assert!(tight < 1e-8, "relative gap at rtol 1e-11: {tight}");
        let loose = gap(1e-3);
        assert!(
            loose > 10.0 * tight,
            "a loose tolerance must show: {loose} vs {tight}"
        );
    }

    #[test]
    fn the_exact_linear_solution_refuses_a_hysteretic_chain() {
        let chain = crate::structure::ShearChain::new(
            vec![1.0],
            vec![10.0],
            vec![0.1],
            vec![crate::law::BoucWen {
                storey: 0,
                beta: 2.0,
                gamma: 1.0,
                n: 2.0,
            }],
        )
        .unwrap();
        let e = simulate_linear_exact(&chain, &[0.0, 1.0], 0.01).unwrap_err();
        assert_eq!(e, IntegrateError::NotLinear(1));
        assert!(e.to_string().contains("without hysteretic element"));
    }

    #[test]
    fn both_integrators_solve_a_step_response() {
        let o = Oscillator { w: 3.0, z: 0.05 };
        let dt = 0.01;
        let ug = vec![2.0; 501];
        let rk = simulate_rk4(&o, &ug, dt);
        let ad = simulate_adaptive(
            &o,
            &ug,
            dt,
            Tolerance {
                rtol: 1e-10,
                atol: 1e-12,
            },
        )
        .unwrap();
        assert_eq!(rk.len(), 501);
        let mut err_rk: f64 = 0.0;
        let mut err_ad: f64 = 0.0;
        for k in 0..rk.len() {
            let x = step_response(&o, 2.0, rk.t(k));
            err_rk = err_rk.max((rk.state(k)[0] - x).abs());
            err_ad = err_ad.max((ad.state(k)[0] - x).abs());
        }
        // Oscillation amplitude 2/9 ≈ 0.22; RK4's phase error per step on an oscillator is
        // (ω dt)^5/120, so after t = 5 s it is t·ω·(ω dt)^4/120 ≈ 1.0e-7 rad, i.e. a
        // displacement error ≲ 0.22 × 1.0e-7 ≈ 2.3e-8 (damping only reduces it).
        assert!(err_rk < 3e-8, "rk4 error {err_rk}");
        assert!(err_ad < 1e-9, "dopri error {err_ad}");
    }

    #[test]
    fn adaptive_rejects_bad_tolerance() {
        let o = Oscillator { w: 1.0, z: 0.0 };
        let r = simulate_adaptive(
            &o,
            &[0.0; 3],
            0.1,
            Tolerance {
                rtol: 1e-6,
                atol: 0.0,
            },
        );
        assert!(matches!(r, Err(IntegrateError::InvalidTolerance { .. })));
    }

    #[test]
    fn trajectory_accessors() {
        let t = Trajectory::from_flat(2, 0.5, vec![0., 1., 2., 3., 4., 5.]);
        assert_eq!(t.len(), 3);
        assert_eq!(t.state(1), &[2., 3.]);
        assert_eq!(t.component(1), vec![1., 3., 5.]);
        assert_eq!(t.t(2), 1.0);
        assert_eq!(t.rows().count(), 3);
    }
}
