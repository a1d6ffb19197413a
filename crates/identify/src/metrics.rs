//! Metrics of SPEC §7: θ_val, relative errors, state-estimate errors (CV(RMSE) and NRMSE).

pub use crate::record::signal_errors::{SignalError, StateErrors};

/// Relative error `|θ − θ_true| / |θ_true|` per entry (SPEC §7).
pub(crate) fn relative_errors(theta: &[f64], truth: &[f64]) -> Vec<f64> {
    theta
        .iter()
        .zip(truth)
        .map(|(t, tt)| (t - tt).abs() / tt.abs())
        .collect()
}

/// Running sums for the error of an estimated signal against the true one.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct ErrorSums {
    sse: f64,
    sum_abs_true: f64,
    sum_sq_true: f64,
    n: usize,
}

impl ErrorSums {
    pub fn add(&mut self, estimate: f64, truth: f64) {
        let e = estimate - truth;
        self.sse += e * e;
        self.sum_abs_true += truth.abs();
        self.sum_sq_true += truth * truth;
        self.n += 1;
    }

    /// RMSE, CV(RMSE) with denominator mean(|x_true|), and NRMSE = RMSE / RMS(x_true).
    pub fn finish(&self) -> SignalError {
        let n = self.n.max(1) as f64;
        let rmse = (self.sse / n).sqrt();
        SignalError {
            rmse,
            cv_rmse: rmse / (self.sum_abs_true / n),
            nrmse: rmse / (self.sum_sq_true / n).sqrt(),
        }
    }
}

impl StateErrors {
    pub(crate) fn from_sums(names: &[String], sums: &[ErrorSums]) -> Self {
        Self {
            names: names.to_vec(),
            errors: sums.iter().map(ErrorSums::finish).collect(),
        }
    }

    /// Mean NRMSE over the states (a one-number summary for tables).
    pub fn mean_nrmse(&self) -> f64 {
        self.errors.iter().map(|e| e.nrmse).sum::<f64>() / self.errors.len().max(1) as f64
    }
}

/// The median of the finite values of `v` (None when there are none).
pub fn median(v: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let m = v.len() / 2;
    Some(if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    })
}

/// Mean and sample standard deviation (n − 1) of a slice; NaN entries are skipped.
pub fn mean_sd(values: &[f64]) -> (f64, f64, usize) {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    let n = finite.len();
    if n == 0 {
        return (f64::NAN, f64::NAN, 0);
    }
    let mean = finite.iter().sum::<f64>() / n as f64;
    let var = if n > 1 {
        finite.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64
    } else {
        0.0
    };
    (mean, var.sqrt(), n)
}

/// Mean and run-to-run s.d. ([`mean_sd`]); the s.d. is undefined (NaN) below two runs rather
/// than 0, so one run never looks free of Monte-Carlo error.
pub fn mean_spread(x: &[f64]) -> (f64, f64) {
    let (m, sd, n) = mean_sd(x);
    (m, if n > 1 { sd } else { f64::NAN })
}

/// Whether `name` is a parameter of the group `prefix` followed by digits (`k1`, `c12`).
pub fn in_group(name: &str, prefix: char) -> bool {
    name.strip_prefix(prefix)
        .is_some_and(|rest| !rest.is_empty() && rest.chars().all(|c| c.is_ascii_digit()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_sums_by_hand() {
        let mut s = ErrorSums::default();
        // truth 1, −1, 2, −2; estimates off by 1, 0, 0, 1 → sse 2, n 4, rmse √0.5.
        for (e, t) in [(2.0, 1.0), (-1.0, -1.0), (2.0, 2.0), (-1.0, -2.0)] {
            s.add(e, t);
        }
        let r = s.finish();
        assert!((r.rmse - 0.5f64.sqrt()).abs() < 1e-15);
        assert!((r.cv_rmse - 0.5f64.sqrt() / 1.5).abs() < 1e-15);
        assert!((r.nrmse - 0.5f64.sqrt() / 2.5f64.sqrt()).abs() < 1e-15);
    }

    #[test]
    fn relative_errors_and_mean_sd() {
        let e = relative_errors(&[9.0, 0.2], &[8.0, -0.25]);
        assert_eq!(e[0], 0.125);
        assert!((e[1] - 1.8).abs() < 1e-15, "{e:?}");
        let (m, sd, n) = mean_sd(&[1.0, 2.0, f64::NAN, 3.0]);
        assert_eq!((m, sd, n), (2.0, 1.0, 3));
    }
}
