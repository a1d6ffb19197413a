//! SPEC Table I by computation: moments of `z = xᵀx`, `x ~ N(0, I_nx)`, by the exact χ²
//! formulas, first-order linearisation at the mean (T1, the EKF), second-order expansion (T2, the
//! EKF2 with the Hessian `2I`) and the unscented transform (UT, β = 2, κ = 0).
//!
//! Every row except the exact one is produced by the filter code of this crate
//! ([`ekf2_moments`], [`unscented_transform`]) rather than typed in.

use nalgebra::{SMatrix, SVector};
use serde::Serialize;

use super::ekf2::{ekf2_moments, Expansion};
use super::kf::StepLog;
use super::ukf::{unscented_transform, UtParams};
use crate::error::FilterError;
use crate::health::Health;
use crate::model::SparseHessians;

/// The α used for the UT rows. Table I holds for any α; α = 1 keeps every weight O(1).
pub const TABLE1_UT_ALPHA: f64 = 1.0;

/// One row of Table I.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Table1Row {
    /// Dimension of `x`.
    pub nx: usize,
    /// `exact`, `T1`, `T2` or `UT`.
    pub method: &'static str,
    /// Computed `E[z]`.
    pub mean: f64,
    /// Computed `Var[z]`.
    pub variance: f64,
}

/// The four rows of Table I for `nx = NX`: exact, T1, T2, UT (with `ut` parameters).
pub fn table1_rows<const NX: usize>(ut: &UtParams) -> Result<[Table1Row; 4], FilterError> {
    let m = SVector::<f64, NX>::zeros();
    let p = SMatrix::<f64, NX, NX>::identity();
    let f = |x: &SVector<f64, NX>| SVector::<f64, 1>::new(x.dot(x));
    // Exact moments of a Gaussian quadratic form xᵀx, x ~ N(m, P):
    // E = tr(P) + mᵀm, Var = 2 tr(P²) + 4 mᵀ P m.
    let exact_mean = p.trace() + m.dot(&m);
    let exact_var = 2.0 * (p * p).trace() + 4.0 * (m.transpose() * p * m)[(0, 0)];
    // Value and Jacobian (2 mᵀ) at the mean; Hessian 2I as a sparse list.
    let value = f(&m);
    let jac = m.transpose() * 2.0;
    let zero_noise = SMatrix::<f64, 1, 1>::zeros();
    let t1 = Expansion {
        value,
        jac,
        hess: &SparseHessians::new(),
    };
    let (t1_mean, t1_cov) = ekf2_moments(&p, &t1, &zero_noise);
    let mut hess = SparseHessians::new();
    for j in 0..NX {
        hess.push(0, j, j, 2.0);
    }
    let t2 = Expansion { hess: &hess, ..t1 };
    let (t2_mean, t2_cov) = ekf2_moments(&p, &t2, &zero_noise);
    let mut health = Health::default();
    let log = StepLog {
        step: 0,
        health: &mut health,
    };
    let ut_m = unscented_transform(&m, &p, f, ut, log)?;
    let row = |method, mean, variance| Table1Row {
        nx: NX,
        method,
        mean,
        variance,
    };
    Ok([
        row("exact", exact_mean, exact_var),
        row("T1", t1_mean[0], t1_cov[(0, 0)]),
        row("T2", t2_mean[0], t2_cov[(0, 0)]),
        row("UT", ut_m.mean[0], ut_m.cov[(0, 0)]),
    ])
}

/// Table I for `nx = 1..=10` with the UT at α = [`TABLE1_UT_ALPHA`], β = 2, κ = 0.
pub fn table1() -> Result<Vec<Table1Row>, FilterError> {
    let ut = UtParams {
        alpha: TABLE1_UT_ALPHA,
        beta: 2.0,
        kappa: 0.0,
    };
    let mut rows = Vec::with_capacity(40);
    macro_rules! for_dims {
        ($($n:literal)*) => { $( rows.extend(table1_rows::<$n>(&ut)?); )* };
    }
    for_dims!(1 2 3 4 5 6 7 8 9 10);
    Ok(rows)
}
