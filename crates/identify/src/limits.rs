//! Checks of the filter settings a user gives (config file, study file, command line) against
//! the limits of [`models::limits`], the one place where every limit is defined.
//!
//! [`check_filter_settings`] must run before a filter is built from the settings (the pipeline
//! calls it first thing in a run); [`check_particle_cloud`] once the number of values per
//! particle is known (it depends on the algorithm and the storey count);
//! [`load_filter_settings`] reads, parses and checks a filter config file, naming the file in
//! every error.

use std::path::Path;

use crate::error::{bail, Context, Result};
pub use models::limits::*;

use crate::settings::FilterSettings;

/// Accepted range of `process_noise_factor` (the velocities' process noise relative to SPEC §3's).
pub(crate) const MIN_PROCESS_NOISE_FACTOR: f64 = 1e-4;
pub(crate) const MAX_PROCESS_NOISE_FACTOR: f64 = 100.0;

/// Checks the user-given sizes and values of `s`; the error names the settings field.
///
/// - `particles` in `1..=MAX_PARTICLES`;
/// - `window` (θ_val averaging, SPEC eq. 26) in `1..=MAX_SAMPLES`: 0 has no mean;
/// - `noise_fraction` in `[MIN_FILTER_NOISE_FRACTION, MAX_FILTER_NOISE_FRACTION]`;
/// - `r_noise_fraction` in `[MIN_R_NOISE_FRACTION, MAX_R_NOISE_FRACTION]`;
/// - `process_noise_factor` in `[MIN_PROCESS_NOISE_FACTOR, MAX_PROCESS_NOISE_FACTOR]`;
/// - `ess_threshold` in `(0, 1]`;
/// - `rejuvenation` (the Liu–West discount) in `[1/3, 1]`;
/// - `substeps` in `1..=MAX_SUBSTEPS`;
/// - `coloured_noise`: `rho` in `[0, 1)`, `share` in `(0, 1)`;
/// - `structure.masses`: at most `MAX_STOREYS`, each finite and positive;
/// - `fix`: finite values.
pub fn check_filter_settings(s: &FilterSettings) -> Result<()> {
    check_count(s.particles, 1, MAX_PARTICLES).context("field `particles`")?;
    check_window(s.window).context("field `window`")?;
    // One filter at least; more than the particles is refused when the run knows its count.
    check_count(s.pool, 1, MAX_PARTICLES).context("field `pool`")?;
    check_filter_noise_fraction(s.noise_fraction).context("field `noise_fraction`")?;
    check_r_noise_fraction(s.r_noise_fraction).context("field `r_noise_fraction`")?;
    if !(MIN_PROCESS_NOISE_FACTOR..=MAX_PROCESS_NOISE_FACTOR).contains(&s.process_noise_factor) {
        bail!(
            "field `process_noise_factor`: {} is outside [{MIN_PROCESS_NOISE_FACTOR}, {MAX_PROCESS_NOISE_FACTOR}]",
            s.process_noise_factor
        );
    }
    if let Some(t) = s.ess_threshold {
        if !(t > 0.0 && t <= 1.0) {
            bail!("field `ess_threshold`: {t} is not in (0, 1]");
        }
    }
    s.liu_west()?;
    if let Some(c) = &s.coloured_noise {
        c.validate().context("field `coloured_noise`")?;
    }
    if let crate::settings::Substeps::Fixed(m) = s.substeps {
        check_count(m, 1, models::filtering::MAX_SUBSTEPS).context("field `substeps`")?;
    }
    if let Some(m) = &s.structure.masses {
        check_count(m.len(), 1, MAX_STOREYS).context("field `masses`: number of storeys")?;
        models::building::check_masses(m)?;
    }
    if let Some((name, v)) = s.fix.iter().find(|(_, v)| check_value(**v).is_err()) {
        bail!(
            "field `fix`: value of {name}: {}",
            check_value(*v).unwrap_err()
        );
    }
    Ok(())
}

/// Checks a particle count against the limits once the number of values each particle holds
/// (state, parameters and any Kalman moments) is known.
pub fn check_particle_cloud(particles: usize, per_particle: usize) -> Result<()> {
    check_particles(particles, per_particle).with_context(|| {
        format!("field `particles`: {particles} particles of {per_particle} values each")
    })?;
    Ok(())
}

/// Reads a text file a user gives (a config, a run plan, a study): through the one reader of
/// input files, [`models::readers::read_input`] — a regular file of at most [`MAX_FILE_BYTES`]
/// bytes, checked before a byte is read (a FIFO, a device or a directory is refused, naming the
/// file) — UTF-8 (a byte that is not is refused with its line), its byte-order mark dropped;
/// `what` names the file in errors.
pub fn read_text_file(path: &Path, what: &str) -> Result<String> {
    let text = models::readers::read_input_text(path).with_context(|| format!("reading {what}"))?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(t) => t.to_string(),
        None => text,
    })
}

/// Most characters of a parser's message repeated in an error.
const MAX_MESSAGE_CHARS: usize = 300;

/// Parses the TOML text of the file `path` (a `what`: "study", "config", ...). An error names
/// the file, the line and the column, and says what is wrong in at most
/// `MAX_MESSAGE_CHARS` characters; the offending line is not echoed (a line of 200,000
/// brackets was, whole).
pub fn parse_toml<T: serde::de::DeserializeOwned>(
    text: &str,
    path: &Path,
    what: &str,
) -> Result<T> {
    toml::from_str(text).map_err(|e| {
        let (line, column) = e.span().map_or((1, 1), |s| {
            let before = text.get(..s.start).unwrap_or("");
            let line = before.bytes().filter(|&b| b == b'\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            (line, column)
        });
        let message = e.message().trim();
        let message: String = match message.char_indices().nth(MAX_MESSAGE_CHARS) {
            Some((cut, _)) => format!("{}…", &message[..cut]),
            None => message.to_string(),
        };
        crate::error::invalid!(
            "{what} {}:{line}:{column}: {}",
            path.display(),
            message.replace('\n', " ")
        )
    })
}

/// Reads a filter config file (TOML, [`FilterSettings`]) and checks it; every error names the
/// file.
pub fn load_filter_settings(path: &Path) -> Result<FilterSettings> {
    let text = read_text_file(path, "config")?;
    let s: FilterSettings = parse_toml(&text, path, "config")?;
    check_filter_settings(&s).with_context(|| format!("config {}", path.display()))?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(s: &FilterSettings) -> String {
        format!("{:#}", check_filter_settings(s).unwrap_err())
    }

    #[test]
    fn defaults_pass_and_each_bad_field_is_named() {
        let ok = FilterSettings::default();
        check_filter_settings(&ok).unwrap();
        let mut s = ok.clone();
        s.window = 0;
        assert!(err(&s).contains("`window`"), "{}", err(&s));
        let mut s = ok.clone();
        s.particles = 0;
        assert!(err(&s).contains("`particles`"));
        s.particles = usize::MAX;
        assert!(err(&s).contains("`particles`"));
        let mut s = ok.clone();
        s.noise_fraction = 1e-9;
        assert!(err(&s).contains("`noise_fraction`"));
        s.noise_fraction = 1e308;
        assert!(err(&s).contains("`noise_fraction`"));
        s.noise_fraction = 0.1;
        for bad in [0.0, -1.0, f64::NAN, 1e9] {
            s.process_noise_factor = bad;
            assert!(err(&s).contains("`process_noise_factor`"), "{bad}");
        }
        s.process_noise_factor = 1.0;
        for (rho, share) in [
            (1.0, 0.5),
            (-0.1, 0.5),
            (f64::NAN, 0.5),
            (0.9, 0.0),
            (0.9, 1.0),
        ] {
            s.coloured_noise = Some(models::filtering::ColouredNoise { rho, share });
            let e = err(&s);
            assert!(e.contains("`coloured_noise`"), "{rho} {share}: {e}");
            let part = if rho.is_finite() && (0.0..1.0).contains(&rho) {
                "share"
            } else {
                "rho"
            };
            assert!(e.contains(part), "{rho} {share}: {e}");
        }
        s.coloured_noise = Some(models::filtering::ColouredNoise {
            rho: 0.0,
            share: 0.5,
        });
        check_filter_settings(&s).unwrap();
        s.coloured_noise = None;
        for bad in [0.0, -0.05, f64::NAN, 1e9] {
            s.r_noise_fraction = bad;
            assert!(err(&s).contains("`r_noise_fraction`"), "{bad}");
        }
        let mut s = ok.clone();
        s.substeps = crate::settings::Substeps::Fixed(0);
        assert!(err(&s).contains("`substeps`"), "{}", err(&s));
        s.substeps = crate::settings::Substeps::Fixed(65);
        assert!(err(&s).contains("`substeps`"));
        let mut s = ok.clone();
        s.ess_threshold = Some(0.0);
        assert!(err(&s).contains("`ess_threshold`"));
        let mut s = ok.clone();
        s.structure.masses = Some(vec![1.0, -1.0]);
        assert!(err(&s).contains("field `masses`: mass of storey 2 is -1"));
        s.structure.masses = Some(vec![1.0; MAX_STOREYS + 1]);
        assert!(err(&s).contains("`masses`"));
        let mut s = ok.clone();
        s.fix.insert("k1".into(), 1e300);
        assert!(err(&s).contains("k1"));
        check_particle_cloud(500, 20).unwrap();
        assert!(check_particle_cloud(MAX_PARTICLES, 1000).is_err());
    }
}
