//! Limits on every size and value that comes from a user: files, command-line flags, study
//! and filter configs. They sit in one place so that the readers, `sysid simulate` and the
//! filter settings agree, and they are checked *before* anything is allocated from the value,
//! so that no input can make the tool panic on a capacity overflow or abort on an allocation
//! it cannot satisfy.
//!
//! Each limit lies far beyond any real use (the paper's data set is 6,237 samples × 3 storeys
//! at dt = 0.005 s, SPEC §2) and well inside what the machine can hold: the largest data set
//! the limits admit is `MAX_CELLS` (5·10⁷) numbers per table (400 MB of `f64`).
//!
//! The check functions return a [`LimitError`], which says which limit is broken and by which
//! value; the caller wraps it with the place the value came from (file, line and field, or the
//! flag).

use thiserror::Error;

/// Most samples of one record or data set (10⁷: 13.9 h at dt = 0.005 s).
pub const MAX_SAMPLES: usize = 10_000_000;

/// Most numbers of one table, samples × columns (5·10⁷, 400 MB of `f64`): a 200-storey chain
/// with its 401 true states fits for 1.2·10⁵ samples, the paper's for 10⁷.
pub(crate) const MAX_CELLS: usize = 50_000_000;

/// Smallest and largest time step, in seconds (strong-motion records use 0.001–0.02 s).
pub(crate) const MIN_DT: f64 = 1e-5;
pub(crate) const MAX_DT: f64 = 1.0;

/// Largest |time| in a CSV time column, in seconds (3.2 centuries: room for absolute time
/// stamps, none for the values that only a typo produces).
pub(crate) const MAX_ABS_TIME: f64 = 1e10;

/// Largest |value| of a data sample (accelerations, displacements, velocities, hysteretic
/// variables, in SI units). A real record stays below 10³; the bound keeps every sum of squares
/// over [`MAX_SAMPLES`] samples finite, so an RMS can never become ∞.
pub(crate) const MAX_ABS_VALUE: f64 = 1e12;

/// Most storeys of a shear chain.
pub const MAX_STOREYS: usize = 200;

/// Largest |amplitude scale| of an excitation (a sign flip, −1, is valid).
pub const MAX_ABS_SCALE: f64 = 1e3;

/// Largest noise fraction (noise s.d. / signal RMS) of a generated data set; 0 (noiseless) is
/// valid.
pub(crate) const MAX_NOISE_FRACTION: f64 = 10.0;

/// Range of the noise fraction a filter assumes (SPEC §3: 0.1). Below 10⁻³ the likelihood is
/// so sharp that a particle cloud collapses onto one particle at the first step and the
/// estimate is whatever that particle holds (10⁻⁹ gave negative stiffnesses).
pub const MIN_FILTER_NOISE_FRACTION: f64 = 1e-3;
pub const MAX_FILTER_NOISE_FRACTION: f64 = 10.0;

/// Smallest and largest process noise of a hysteretic variable a filter assumes, as a fraction
/// of dt × RMS drift velocity (SPEC §3: 0.05).
pub const MIN_R_NOISE_FRACTION: f64 = 1e-4;
pub const MAX_R_NOISE_FRACTION: f64 = 10.0;

/// Most particles of one filter run (10⁷; SPEC §3 uses 500).
pub const MAX_PARTICLES: usize = 10_000_000;

/// Most `f64` a filter's particle cloud may hold, particles × numbers per particle
/// (2·10⁸, 1.6 GB).
pub(crate) const MAX_PARTICLE_CELLS: usize = 200_000_000;

/// Most kept iterations, and most burn-in iterations, of a reference chain (`sysid reference`,
/// 10⁶ each): every iteration runs one particle filter over the record (about 1.4 ms for the
/// paper's 3-storey record with 200 particles, so 10⁶ iterations are half an hour), and the kept
/// samples are held in memory (10⁶ × the free parameters).
pub(crate) const MAX_CHAIN_ITERATIONS: usize = 1_000_000;

/// Most repeated likelihood estimates at a chain's start point (`sysid reference --probe`):
/// they only measure the estimator's s.d., for which 20 suffice.
pub(crate) const MAX_PROBES: usize = 10_000;

/// Most worker threads of a sweep (`--threads`): far beyond the cores of any machine the runs
/// share; a larger count only asks the system for threads it cannot give.
pub const MAX_THREADS: usize = 1024;

/// Largest input file the readers accept (2 GiB): a table of `MAX_CELLS` (5·10⁷) numbers, each
/// printed in at most 24 characters plus a separator, is 1.25 GB, so every data set
/// `simulate` can write loads back.
pub const MAX_FILE_BYTES: u64 = 1 << 31;

/// A value outside its limit.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LimitError {
    #[error("{} is not a finite number", num(*.value))]
    NotFinite { value: f64 },
    #[error("{} is below the minimum {}", num(*.value), num(*.min))]
    TooSmall { value: f64, min: f64 },
    #[error("{} exceeds the maximum {}", num(*.value), num(*.max))]
    TooLarge { value: f64, max: f64 },
    #[error("{value} exceeds the maximum {max}")]
    CountTooLarge { value: u128, max: u128 },
    #[error("must be at least {min}, got {value}")]
    CountTooSmall { value: u128, min: u128 },
}

/// A number as a person reads it: `1e308`, not 309 digits.
pub fn num(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e7).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// `value` is finite and within `[min, max]`.
pub(crate) fn check_range(value: f64, min: f64, max: f64) -> Result<f64, LimitError> {
    if !value.is_finite() {
        return Err(LimitError::NotFinite { value });
    }
    if value < min {
        return Err(LimitError::TooSmall { value, min });
    }
    if value > max {
        return Err(LimitError::TooLarge { value, max });
    }
    Ok(value)
}

/// `count` is within `[min, max]`.
pub fn check_count(count: usize, min: usize, max: usize) -> Result<usize, LimitError> {
    if count < min {
        return Err(LimitError::CountTooSmall {
            value: count as u128,
            min: min as u128,
        });
    }
    if count > max {
        return Err(LimitError::CountTooLarge {
            value: count as u128,
            max: max as u128,
        });
    }
    Ok(count)
}

/// A time step in `[MIN_DT, MAX_DT]`.
pub fn check_dt(dt: f64) -> Result<f64, LimitError> {
    check_range(dt, MIN_DT, MAX_DT)
}

/// A storey count in `1..=MAX_STOREYS`.
pub fn check_storeys(storeys: usize) -> Result<usize, LimitError> {
    check_count(storeys, 1, MAX_STOREYS)
}

/// A noise fraction of generated data in `[0, MAX_NOISE_FRACTION]`.
pub fn check_noise_fraction(f: f64) -> Result<f64, LimitError> {
    check_range(f, 0.0, MAX_NOISE_FRACTION)
}

/// The noise fraction a filter assumes, in `[MIN_FILTER_NOISE_FRACTION,
/// MAX_FILTER_NOISE_FRACTION]`.
pub fn check_filter_noise_fraction(f: f64) -> Result<f64, LimitError> {
    check_range(f, MIN_FILTER_NOISE_FRACTION, MAX_FILTER_NOISE_FRACTION)
}

/// The process noise fraction of a hysteretic variable, in `[MIN_R_NOISE_FRACTION,
/// MAX_R_NOISE_FRACTION]`.
pub fn check_r_noise_fraction(f: f64) -> Result<f64, LimitError> {
    check_range(f, MIN_R_NOISE_FRACTION, MAX_R_NOISE_FRACTION)
}

/// An amplitude scale with `|scale| ≤ MAX_ABS_SCALE` (negative scales flip the sign).
pub fn check_scale(scale: f64) -> Result<f64, LimitError> {
    check_range(scale, -MAX_ABS_SCALE, MAX_ABS_SCALE)
}

/// One data sample with `|v| ≤ MAX_ABS_VALUE`.
pub fn check_value(v: f64) -> Result<f64, LimitError> {
    check_range(v, -MAX_ABS_VALUE, MAX_ABS_VALUE)
}

/// One time stamp with `|t| ≤ MAX_ABS_TIME`.
pub fn check_time(t: f64) -> Result<f64, LimitError> {
    check_range(t, -MAX_ABS_TIME, MAX_ABS_TIME)
}

/// The number of samples `floor(duration/dt·(1 + 1e-9)) + 1` that a duration covers at `dt`
/// (the rule of [`crate::excitation::harmonic`]), computed in `f64` and checked against
/// [`MAX_SAMPLES`] before anything is allocated. `dt` must already be checked.
pub fn samples_for_duration(duration: f64, dt: f64) -> Result<usize, LimitError> {
    if !duration.is_finite() {
        return Err(LimitError::NotFinite { value: duration });
    }
    if duration <= 0.0 {
        return Err(LimitError::TooSmall {
            value: duration,
            min: dt,
        });
    }
    let intervals = (duration / dt * (1.0 + 1e-9)).floor();
    // (MAX_SAMPLES − 1)·dt is the longest duration; say it in seconds. (`dt` is checked, so
    // `intervals` is a number, possibly +∞.)
    if intervals >= MAX_SAMPLES as f64 || intervals.is_nan() {
        return Err(LimitError::TooLarge {
            value: duration,
            max: max_duration(dt),
        });
    }
    Ok(intervals as usize + 1)
}

/// The longest duration at `dt`: `(MAX_SAMPLES − 1)·dt`.
pub fn max_duration(dt: f64) -> f64 {
    (MAX_SAMPLES - 1) as f64 * dt
}

/// A table of `rows × columns` numbers within [`MAX_SAMPLES`] rows and `MAX_CELLS` (5·10⁷) numbers.
pub fn check_table(rows: usize, columns: usize) -> Result<(), LimitError> {
    check_count(rows, 0, MAX_SAMPLES)?;
    let cells = (rows as u128) * (columns as u128);
    if cells > MAX_CELLS as u128 {
        return Err(LimitError::CountTooLarge {
            value: cells,
            max: MAX_CELLS as u128,
        });
    }
    Ok(())
}

/// A particle count in `1..=MAX_PARTICLES` whose cloud, `per_particle` numbers each, stays
/// within `MAX_PARTICLE_CELLS` (2·10⁸) numbers.
pub fn check_particles(particles: usize, per_particle: usize) -> Result<usize, LimitError> {
    check_count(particles, 1, MAX_PARTICLES)?;
    let cells = (particles as u128) * (per_particle.max(1) as u128);
    if cells > MAX_PARTICLE_CELLS as u128 {
        return Err(LimitError::CountTooLarge {
            value: cells,
            max: MAX_PARTICLE_CELLS as u128,
        });
    }
    Ok(particles)
}

/// The θ_val averaging window (SPEC eq. 26: 80 steps) in `1..=MAX_SAMPLES`: an empty window
/// has no mean (0 gave θ_val = 0 with no failure).
pub fn check_window(window: usize) -> Result<usize, LimitError> {
    check_count(window, 1, MAX_SAMPLES)
}

/// The lengths of a reference chain: `iterations` in `1..=MAX_CHAIN_ITERATIONS`, `burn_in` in
/// `0..=MAX_CHAIN_ITERATIONS`, `probe` in `0..=MAX_PROBES`; the error names the flag.
pub fn check_chain(
    iterations: usize,
    burn_in: usize,
    probe: usize,
) -> Result<(), (&'static str, LimitError)> {
    check_count(iterations, 1, MAX_CHAIN_ITERATIONS).map_err(|e| ("--iterations", e))?;
    check_count(burn_in, 0, MAX_CHAIN_ITERATIONS).map_err(|e| ("--burn-in", e))?;
    check_count(probe, 0, MAX_PROBES).map_err(|e| ("--probe", e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_and_counts() {
        assert_eq!(check_dt(0.005), Ok(0.005));
        assert!(matches!(check_dt(1e6), Err(LimitError::TooLarge { .. })));
        assert!(matches!(check_dt(0.0), Err(LimitError::TooSmall { .. })));
        assert!(matches!(
            check_dt(f64::NAN),
            Err(LimitError::NotFinite { .. })
        ));
        assert_eq!(check_scale(-1.0), Ok(-1.0));
        assert!(check_noise_fraction(1e308).is_err());
        assert_eq!(check_noise_fraction(0.0), Ok(0.0));
        assert!(check_filter_noise_fraction(1e-9).is_err());
        assert_eq!(check_filter_noise_fraction(0.1), Ok(0.1));
        assert!(check_storeys(0).is_err());
        assert_eq!(check_storeys(200), Ok(200));
        assert!(check_storeys(201).is_err());
        assert!(check_storeys(usize::MAX).is_err());
        assert!(check_particles(0, 10).is_err());
        assert_eq!(check_particles(500, 10), Ok(500));
        assert!(check_particles(usize::MAX, 10).is_err());
        assert!(check_particles(10_000_000, 1_000).is_err());
        assert!(check_window(0).is_err());
        assert_eq!(check_window(80), Ok(80));
        assert!(check_window(usize::MAX).is_err());
        assert_eq!(check_chain(5000, 1000, 20), Ok(()));
        assert_eq!(check_chain(usize::MAX, 0, 0).unwrap_err().0, "--iterations");
        assert_eq!(check_chain(0, 0, 0).unwrap_err().0, "--iterations");
        assert_eq!(check_chain(1, usize::MAX, 0).unwrap_err().0, "--burn-in");
        assert_eq!(
            check_chain(1, 0, 1_000_000_000_000).unwrap_err().0,
            "--probe"
        );
        assert!(check_table(MAX_SAMPLES, 5).is_ok());
        assert!(check_table(MAX_SAMPLES, 6).is_err());
        assert!(check_table(usize::MAX, usize::MAX).is_err());
        assert!(check_value(1e308).is_err());
        assert!(check_time(1e300).is_err());
        assert_eq!(
            check_noise_fraction(1e308).unwrap_err().to_string(),
            "1e308 exceeds the maximum 10"
        );
    }

    #[test]
    fn durations() {
        assert_eq!(samples_for_duration(31.18, 0.005), Ok(6237));
        assert_eq!(samples_for_duration(1.0, 0.005), Ok(201));
        let longest = max_duration(0.005);
        assert_eq!(samples_for_duration(longest, 0.005), Ok(MAX_SAMPLES));
        assert!(samples_for_duration(longest + 0.005, 0.005).is_err());
        assert!(samples_for_duration(1e300, 0.005).is_err());
        assert!(samples_for_duration(f64::INFINITY, 0.005).is_err());
        assert!(samples_for_duration(-1.0, 0.005).is_err());
    }
}
