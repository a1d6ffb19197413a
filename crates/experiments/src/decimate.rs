//! Decimation of a data set: keep one sample in `factor`, as a logger running at a lower rate
//! would have recorded the same motion.
//!
//! The discretisation study (`experiments/discretisation-100hz.toml`, `docs/discretisation.md`)
//! asks how the filters' time step changes their bias; its 100 Hz data are the 200 Hz data of the
//! paper's preset with every second sample kept (samples 0, 2, 4, …): the noisy excitation and
//! accelerations, the clean excitation and the true states. No anti-alias filter is applied: the
//! structure's modes are below 1 Hz, far under the 50 Hz Nyquist frequency of the decimated
//! record, and each kept sample keeps its own measurement noise (s.d. 10% of the clean signal's
//! RMS, SPEC §2), as an instrument sampling at 100 Hz with the same noise per sample would give.
//! The metadata's `dt` and sample count become the decimated ones; its RMS values (which set the
//! filters' Q and R, SPEC §3) stay those of the underlying signals.

use models::dataset::{LoadedDataset, LoadedTruth};
use models::integrate::Trajectory;
use thiserror::Error;

/// Largest decimation factor accepted (a factor beyond it leaves too few samples of any record).
pub(crate) const MAX_FACTOR: usize = 1000;

/// A decimation that cannot be applied.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub(crate) enum DecimateError {
    #[error("decimation factor {0} is not in [1, {MAX_FACTOR}]")]
    Factor(usize),
    #[error("decimating {samples} samples by {factor} leaves {kept}; at least 2 are needed")]
    TooShort {
        samples: usize,
        factor: usize,
        kept: usize,
    },
}

crate::error::domain_error!(DecimateError);

/// Checks a decimation factor on its own (before any data exist).
pub(crate) fn check_factor(factor: usize) -> Result<(), DecimateError> {
    if (1..=MAX_FACTOR).contains(&factor) {
        Ok(())
    } else {
        Err(DecimateError::Factor(factor))
    }
}

fn every<T: Copy>(v: &[T], width: usize, factor: usize) -> Vec<T> {
    v.chunks_exact(width)
        .step_by(factor)
        .flatten()
        .copied()
        .collect()
}

/// The data set with samples 0, factor, 2·factor, … kept; `factor = 1` returns it unchanged.
pub(crate) fn decimate(
    data: &LoadedDataset,
    factor: usize,
) -> Result<LoadedDataset, DecimateError> {
    check_factor(factor)?;
    if factor == 1 {
        return Ok(data.clone());
    }
    let kept = data.len().div_ceil(factor);
    if kept < 2 {
        return Err(DecimateError::TooShort {
            samples: data.len(),
            factor,
            kept,
        });
    }
    let dt = data.dt * factor as f64;
    let truth = data.truth.as_ref().map(|t| LoadedTruth {
        ug_clean: every(&t.ug_clean, 1, factor),
        states: Trajectory::from_flat(
            t.states.dim(),
            t.states.dt() * factor as f64,
            every(t.states.as_flat(), t.states.dim(), factor),
        ),
        state_names: t.state_names.clone(),
    });
    let meta = data.meta.clone().map(|mut m| {
        m.dt = dt;
        m.samples = kept;
        m
    });
    Ok(LoadedDataset {
        dt,
        t: every(&data.t, 1, factor),
        ug_meas: every(&data.ug_meas, 1, factor),
        y_meas: every(&data.y_meas, data.channels, factor),
        channels: data.channels,
        sensors: data.sensors.clone(),
        truth,
        meta,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use models::dataset::{generate, DatasetConfig};

    #[test]
    fn keeps_every_other_sample_of_every_array() {
        let mut c = DatasetConfig::from_preset("paper-3dof", 7).unwrap();
        c.duration = Some(1.0);
        let full = generate(&c).unwrap().to_loaded();
        let half = decimate(&full, 2).unwrap();
        assert_eq!(half.len(), full.len().div_ceil(2));
        assert_eq!(half.dt, 2.0 * full.dt);
        for k in 0..half.len() {
            assert_eq!(half.t[k], full.t[2 * k]);
            assert_eq!(half.ug_meas[k], full.ug_meas[2 * k]);
            assert_eq!(half.y(k), full.y(2 * k));
            let (ht, ft) = (half.truth.as_ref().unwrap(), full.truth.as_ref().unwrap());
            assert_eq!(ht.ug_clean[k], ft.ug_clean[2 * k]);
            assert_eq!(ht.states.state(k), ft.states.state(2 * k));
        }
        let meta = half.meta.as_ref().unwrap();
        assert_eq!((meta.dt, meta.samples), (half.dt, half.len()));
        assert_eq!(decimate(&full, 1).unwrap(), full);
    }

    #[test]
    fn refuses_bad_factors_and_too_short_results() {
        let mut c = DatasetConfig::from_preset("paper-3dof", 7).unwrap();
        c.duration = Some(0.02);
        let data = generate(&c).unwrap().to_loaded();
        assert_eq!(decimate(&data, 0), Err(DecimateError::Factor(0)));
        assert_eq!(
            decimate(&data, MAX_FACTOR + 1),
            Err(DecimateError::Factor(MAX_FACTOR + 1))
        );
        let err = decimate(&data, data.len()).unwrap_err();
        assert!(
            matches!(err, DecimateError::TooShort { kept: 1, .. }),
            "{err}"
        );
    }
}
