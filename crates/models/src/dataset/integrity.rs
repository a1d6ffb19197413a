//! What makes the files of a data-set directory one data set: `dataset.json` records the size
//! and SHA-256 of each CSV file written with it, and its own content is checked against the
//! data and against the structure it names, so that no later stage indexes past an array or
//! rebuilds a structure the data do not belong to.

use super::{DatasetError, DatasetMeta};
use crate::description::StructureDescription;
use crate::limits;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::path::Path;

/// Size and SHA-256 (lowercase hex) of one file of a data set.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileDigest {
    pub bytes: u64,
    pub sha256: String,
}

impl FileDigest {
    /// The digest of `content`.
    pub fn of(content: &[u8]) -> Self {
        let hash = Sha256::digest(content);
        let mut sha256 = String::with_capacity(64);
        for b in hash {
            use std::fmt::Write as _;
            let _ = write!(sha256, "{b:02x}");
        }
        Self {
            bytes: content.len() as u64,
            sha256,
        }
    }
}

/// The content of `dataset.json`: the metadata and, from this version on, the digests of the
/// CSV files it was written with (absent in data sets written before: they load unchecked).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct MetaFile {
    #[serde(flatten)]
    pub(crate) meta: DatasetMeta,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) files: Option<BTreeMap<String, FileDigest>>,
}

/// 1-based line of the first occurrence of `"key"` in a JSON text (1 when absent), so that a
/// semantic error points near the field.
pub(crate) fn json_line(text: &str, key: &str) -> usize {
    let needle = format!("\"{key}\"");
    text.find(&needle)
        .map_or(1, |pos| text[..pos].matches('\n').count() + 1)
}

/// Checks `content` of `file` (named `name` in the data set) against its recorded digest.
pub(crate) fn verify(
    meta_file: &Path,
    file: &Path,
    name: &str,
    content: &[u8],
    recorded: &FileDigest,
) -> Result<(), DatasetError> {
    let found = FileDigest::of(content);
    let what = if found.bytes != recorded.bytes {
        format!(
            "{} bytes, but {} records {} bytes",
            found.bytes,
            meta_file.display(),
            recorded.bytes
        )
    } else if found.sha256 != recorded.sha256 {
        format!(
            "SHA-256 {}, but {} records {}",
            found.sha256,
            meta_file.display(),
            recorded.sha256
        )
    } else {
        return Ok(());
    };
    Err(DatasetError::Checksum {
        file: file.to_path_buf(),
        message: format!(
            "{what}: `{name}` does not belong with this dataset.json (files of different \
             data sets mixed, or edited by hand); regenerate the data set, or remove \
             dataset.json to load the data without metadata"
        ),
    })
}

/// Checks the metadata against the limits, against itself, against the structure it names and
/// against the measured data (`samples` rows; `sensors`, the 1-based storeys named by the header
/// of `measured` file).
pub(crate) fn check_meta(
    file: &Path,
    text: &str,
    meta: &DatasetMeta,
    samples: usize,
    measured: &Path,
    sensors: &[usize],
) -> Result<(), DatasetError> {
    let at = MetaErrors { file, text };
    check_step_and_size(&at, meta, samples, measured)?;
    let structure = recorded_structure(&at, meta)?;
    check_sensors(file, measured, &structure, sensors)?;
    check_noise_and_scale(&at, meta)?;
    check_lengths(&at, meta, sensors.len())?;
    check_magnitudes(&at, meta)?;
    check_against_preset(&at, meta)
}

/// Where a metadata error points: `dataset.json` (`file`) and its text, to find the field's line.
struct MetaErrors<'a> {
    file: &'a Path,
    text: &'a str,
}

impl MetaErrors<'_> {
    /// A mismatch of `field` (dotted path; its line is that of its last component).
    fn bad(&self, field: &str, message: String) -> DatasetError {
        DatasetError::Mismatch {
            file: self.file.to_path_buf(),
            line: json_line(self.text, field.rsplit('.').next().unwrap_or(field)),
            field: field.to_string(),
            message,
        }
    }

    /// A limit check of `field`, as a mismatch of that field when it fails.
    fn lim(&self, field: &str, r: Result<f64, limits::LimitError>) -> Result<(), DatasetError> {
        r.map(|_| ()).map_err(|e| self.bad(field, e.to_string()))
    }
}

/// The time steps within limits, the sample count that of the data, the storey counts within
/// limits.
fn check_step_and_size(
    at: &MetaErrors,
    meta: &DatasetMeta,
    samples: usize,
    measured: &Path,
) -> Result<(), DatasetError> {
    at.lim("dt", limits::check_dt(meta.dt))?;
    at.lim("config.dt", limits::check_dt(meta.config.dt))?;
    if meta.samples != samples {
        return Err(at.bad(
            "samples",
            format!(
                "{} samples, but {} has {samples}",
                meta.samples,
                measured.display()
            ),
        ));
    }
    if let Some(n) = meta.config.storeys {
        limits::check_storeys(n).map_err(|e| at.bad("config.storeys", e.to_string()))?;
    }
    limits::check_storeys(meta.storeys).map_err(|e| at.bad("storeys", e.to_string()))?;
    Ok(())
}

/// The structure it records, valid and the one its config generates (that one when none is
/// recorded), with the recorded storey count.
fn recorded_structure(
    at: &MetaErrors,
    meta: &DatasetMeta,
) -> Result<StructureDescription, DatasetError> {
    let generated = meta.config.description().map_err(|e| match e {
        DatasetError::InvalidConfig { field, message } => {
            at.bad(&format!("config.{field}"), message)
        }
        other => at.bad("preset", other.to_string()),
    })?;
    let structure = match &meta.structure {
        Some(d) => {
            d.validate()
                .map_err(|e| at.bad(&format!("structure.{}", e.field), e.message))?;
            if *d != generated {
                return Err(at.bad(
                    "structure",
                    format!("{d:?} is not the structure its config generates ({generated:?})"),
                ));
            }
            d.clone()
        }
        None => generated,
    };
    if meta.storeys != structure.storeys {
        return Err(at.bad(
            "storeys",
            format!(
                "{} storeys, but its structure has {}",
                meta.storeys, structure.storeys
            ),
        ));
    }
    Ok(structure)
}

/// The measured storeys: the header of `measured` (`sensors`) against the sensors recorded in
/// `file`; a mismatch points at the first differing column of the header.
fn check_sensors(
    file: &Path,
    measured: &Path,
    structure: &StructureDescription,
    sensors: &[usize],
) -> Result<(), DatasetError> {
    if structure.sensors == sensors {
        return Ok(());
    }
    let column = structure
        .sensors
        .iter()
        .zip(sensors)
        .find(|(a, b)| a != b)
        .map(|(_, b)| format!("a{b}"))
        .or_else(|| {
            sensors
                .get(structure.sensors.len())
                .map(|b| format!("a{b}"))
        })
        .unwrap_or_else(|| "header".to_string());
    Err(DatasetError::Mismatch {
        file: measured.to_path_buf(),
        line: 1,
        field: column,
        message: format!(
            "the header measures storeys {sensors:?}, but {} records sensors {:?} \
             (files of different data sets mixed?)",
            file.display(),
            structure.sensors
        ),
    })
}

/// The noise fractions and the excitation scale within limits.
fn check_noise_and_scale(at: &MetaErrors, meta: &DatasetMeta) -> Result<(), DatasetError> {
    at.lim(
        "noise.fraction",
        limits::check_noise_fraction(meta.noise.fraction),
    )?;
    at.lim(
        "config.noise_fraction",
        limits::check_noise_fraction(meta.config.noise_fraction),
    )?;
    at.lim("config.scale", limits::check_scale(meta.config.scale))
}

/// Each per-channel, per-storey and per-element array as long as the structure makes it
/// (`channels` measured storeys).
fn check_lengths(at: &MetaErrors, meta: &DatasetMeta, channels: usize) -> Result<(), DatasetError> {
    let n = meta.storeys;
    let nbw = meta.bouc_wen_storeys.len();
    let lengths: [(&str, usize, usize); 9] = [
        ("rms.acc", meta.rms.acc.len(), channels),
        ("rms.vel", meta.rms.vel.len(), n),
        ("rms.disp", meta.rms.disp.len(), n),
        ("rms.r", meta.rms.r.len(), nbw),
        ("noise.acc_sd", meta.noise.acc_sd.len(), channels),
        ("max_abs_r", meta.max_abs_r.len(), nbw),
        ("saturation", meta.saturation.len(), nbw),
        ("theta_true", meta.theta_true.len(), meta.theta_names.len()),
        ("state_names", meta.state_names.len(), 2 * n + nbw),
    ];
    for (field, found, want) in lengths {
        if found != want {
            return Err(at.bad(
                field,
                format!(
                    "{found} entries, {want} expected ({n} storeys, {channels} measured, \
                     {nbw} Bouc–Wen elements)"
                ),
            ));
        }
    }
    Ok(())
}

/// Non-negative finite magnitudes (an RMS or a s.d.), bounded like data values; the true
/// parameters finite and bounded likewise.
fn check_magnitudes(at: &MetaErrors, meta: &DatasetMeta) -> Result<(), DatasetError> {
    let magnitudes = [
        ("rms.acc", &meta.rms.acc[..]),
        ("rms.vel", &meta.rms.vel[..]),
        ("rms.disp", &meta.rms.disp[..]),
        ("rms.r", &meta.rms.r[..]),
        ("noise.acc_sd", &meta.noise.acc_sd[..]),
        ("max_abs_r", &meta.max_abs_r[..]),
        ("rms.ug", std::slice::from_ref(&meta.rms.ug)),
        ("noise.ug_sd", std::slice::from_ref(&meta.noise.ug_sd)),
    ];
    for (field, values) in magnitudes {
        for &v in values {
            at.lim(field, limits::check_range(v, 0.0, limits::MAX_ABS_VALUE))?;
        }
    }
    for &v in &meta.theta_true {
        at.lim(
            "theta_true",
            limits::check_range(v, -limits::MAX_ABS_VALUE, limits::MAX_ABS_VALUE),
        )?;
    }
    Ok(())
}

/// The structure the metadata names must be the one the data were generated with: storeys,
/// Bouc–Wen elements, parameter and state names of its preset, and true parameters it accepts.
fn check_against_preset(at: &MetaErrors, meta: &DatasetMeta) -> Result<(), DatasetError> {
    let n = meta.storeys;
    let chain = meta
        .config
        .chain()
        .map_err(|e| at.bad("preset", e.to_string()))?;
    if chain.storeys() != n {
        return Err(at.bad(
            "storeys",
            format!(
                "{n} storeys, but its config (preset `{}`) has {}",
                meta.config.preset,
                chain.storeys()
            ),
        ));
    }
    let bw: Vec<usize> = chain.bouc_wen().iter().map(|b| b.storey).collect();
    if bw != meta.bouc_wen_storeys {
        return Err(at.bad(
            "bouc_wen_storeys",
            format!(
                "{:?}, but preset `{}` has Bouc–Wen elements at {bw:?}",
                meta.bouc_wen_storeys, meta.config.preset
            ),
        ));
    }
    if chain.theta_names() != meta.theta_names {
        return Err(at.bad(
            "theta_names",
            format!(
                "{:?}, but preset `{}` has {:?}",
                meta.theta_names,
                meta.config.preset,
                chain.theta_names()
            ),
        ));
    }
    if chain.state_names() != meta.state_names {
        return Err(at.bad(
            "state_names",
            format!(
                "{:?}, but preset `{}` has {:?}",
                meta.state_names,
                meta.config.preset,
                chain.state_names()
            ),
        ));
    }
    chain
        .with_theta(&meta.theta_true)
        .map_err(|e| at.bad("theta_true", e.to_string()))?;
    Ok(())
}
