//! Fingerprints: a record's identity is what determined its result, not its file name.
//!
//! The fingerprint of a run is the SHA-256 (lower-case hex) of the *canonical JSON* of its inputs:
//!
//! ```text
//! { "algorithm": "mpf-ekf2", "data": { "meta": …, "sha256": … }, "filter": { …settings… },
//!   "numerics": NUMERICS_VERSION, "run": 0, "seed": 2016 }
//! ```
//!
//! - `data.sha256` digests the data set exactly as the filter saw it ([`data_identity`]): sample
//!   interval, measured signals, the truth when present, and the metadata (`dataset.json`: the
//!   generation settings — preset, excitation, scale, duration, noise, master seed and run — and
//!   the RMS values and true θ the filter's noise levels and metrics are set from);
//!   `data.meta.config` repeats the generation settings in readable form;
//! - `filter` is every filter setting ([`FilterSettings`](crate::settings::FilterSettings)), particles and resampling included;
//! - `numerics` is [`NUMERICS_VERSION`](super::NUMERICS_VERSION), bumped by hand whenever a code
//!   change alters results;
//! - `field_validation`, on field data only, is
//!   [`FIELD_VALIDATION_VERSION`](super::FIELD_VALIDATION_VERSION): the version of the free run,
//!   band and discrepancy term such a record carries;
//! - canonical JSON: object keys sorted by their UTF-8 bytes, no whitespace, strings and numbers
//!   as `serde_json` writes them (numbers in their shortest round-trip form; a non-finite
//!   number, which JSON cannot hold, as `null`). The text therefore depends on no map's iteration
//!   order and no formatting option.
//!
//! The inputs are kept in the record beside the hash, so anyone can see what was hashed and check
//! the hash ([`Fingerprint::verify`]).

use models::dataset::LoadedDataset;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use sha2::{Digest, Sha256};

/// The fingerprint of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fingerprint {
    /// SHA-256 (lower-case hex) of the canonical JSON of `inputs`.
    pub sha256: String,
    /// What was hashed (see the module documentation).
    pub inputs: Value,
    /// SHA-256 (lower-case hex) of the canonical JSON of the record's own `config` (the filter's
    /// specification as it ran: building, sensors and their kind, noise levels, prior), which
    /// the inputs determine but do not hold: an edit of the record's `config` (a sensor kind
    /// changed, so that `sysid validate` would model another building) is refused when the
    /// record is read (`Fingerprint::verify_config`). Absent in records written before it was
    /// kept, whose `config` is then not checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub config_sha256: Option<String>,
}

impl Fingerprint {
    /// The fingerprint of `inputs`.
    pub fn new(inputs: Value) -> Self {
        Self {
            sha256: sha256_hex(canonical_json(&inputs).as_bytes()),
            inputs,
            config_sha256: None,
        }
    }

    /// The fingerprint with the digest of the record's `config` kept beside it.
    pub(crate) fn with_config(mut self, config: &Value) -> Self {
        self.config_sha256 = Some(sha256_hex(canonical_json(config).as_bytes()));
        self
    }

    /// Whether the record's `config` is the one the digest was taken of (when it was kept).
    pub(crate) fn verify_config(&self, config: &Value) -> Result<(), String> {
        match &self.config_sha256 {
            Some(kept) if *kept != sha256_hex(canonical_json(config).as_bytes()) => Err(
                "the record's `config` is not the one it was written with (edited after the \
                 run: its digest `fingerprint.config_sha256` no longer matches)"
                    .to_string(),
            ),
            _ => Ok(()),
        }
    }

    /// The fingerprint of one run of `algorithm` with `settings` on `data`, seeded by
    /// `(seed, run)`, by the numerics of this build (and, on field data, the version of its
    /// validation, [`FIELD_VALIDATION_VERSION`](super::FIELD_VALIDATION_VERSION)).
    pub fn of_run(
        algorithm: &str,
        seed: u64,
        run: u64,
        settings: &(impl serde::Serialize + ?Sized),
        data: &LoadedDataset,
    ) -> Self {
        let mut inputs = serde_json::json!({
            "numerics": super::NUMERICS_VERSION,
            "algorithm": algorithm,
            "seed": seed,
            "run": run,
            "filter": settings,
            "data": data_identity(data),
        });
        if data.meta.is_none() {
            inputs["field_validation"] = super::FIELD_VALIDATION_VERSION.into();
        }
        Self::new(inputs)
    }

    /// Whether `sha256` is the hash of `inputs` (a record whose fingerprint was altered or
    /// damaged fails).
    pub fn verify(&self) -> Result<(), String> {
        let expected = sha256_hex(canonical_json(&self.inputs).as_bytes());
        if expected == self.sha256 {
            Ok(())
        } else {
            Err(format!(
                "fingerprint {} is not the hash of its inputs ({expected})",
                self.sha256
            ))
        }
    }

    /// The first 12 hex digits, for messages.
    pub fn short(&self) -> &str {
        &self.sha256[..self.sha256.len().min(12)]
    }
}

/// The identity of a data set as the filter sees it: `{"meta": dataset.json or null, "sha256":
/// digest}`. The digest covers, in this order, a version tag, `dt`, the channel count, and then
/// each array as its length followed by its values (little-endian IEEE-754 bits): `t`, `ug`
/// measured, `y` measured (row-major), and when the truth is present the clean excitation, the
/// true states (row-major, with their dimension) and the state names; then the canonical JSON of
/// the metadata (or `null`).
pub fn data_identity(data: &LoadedDataset) -> Value {
    let mut h = Sha256::new();
    h.update(b"sysid-data-1\0");
    h.update(data.dt.to_le_bytes());
    h.update((data.channels as u64).to_le_bytes());
    let floats = |h: &mut Sha256, xs: &[f64]| {
        h.update((xs.len() as u64).to_le_bytes());
        for x in xs {
            h.update(x.to_le_bytes());
        }
    };
    floats(&mut h, &data.t);
    floats(&mut h, &data.ug_meas);
    floats(&mut h, &data.y_meas);
    match &data.truth {
        Some(truth) => {
            h.update([1u8]);
            floats(&mut h, &truth.ug_clean);
            h.update((truth.states.dim() as u64).to_le_bytes());
            floats(&mut h, truth.states.as_flat());
            h.update((truth.state_names.len() as u64).to_le_bytes());
            for name in &truth.state_names {
                h.update((name.len() as u64).to_le_bytes());
                h.update(name.as_bytes());
            }
        }
        None => h.update([0u8]),
    }
    let meta = data
        .meta
        .as_ref()
        .and_then(|m| serde_json::to_value(m).ok())
        .unwrap_or(Value::Null);
    h.update(canonical_json(&meta).as_bytes());
    serde_json::json!({
        "sha256": hex(&h.finalize()),
        "meta": meta,
    })
}

/// Canonical JSON text of a value: object keys sorted by their UTF-8 bytes, no whitespace,
/// strings and numbers as `serde_json` writes them.
pub(crate) fn canonical_json(v: &Value) -> String {
    let mut out = String::new();
    write_canonical(v, &mut out);
    out
}

fn write_canonical(v: &Value, out: &mut String) {
    match v {
        Value::Object(map) => {
            let mut entries: Vec<(&String, &Value)> = map.iter().collect();
            entries.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
            out.push('{');
            for (i, (k, v)) in entries.into_iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                out.push_str(&Value::String(k.clone()).to_string());
                out.push(':');
                write_canonical(v, out);
            }
            out.push('}');
        }
        Value::Array(items) => {
            out.push('[');
            for (i, v) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                write_canonical(v, out);
            }
            out.push(']');
        }
        scalar => out.push_str(&scalar.to_string()),
    }
}

/// SHA-256 of `bytes`, lower-case hex.
pub(crate) fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// `bytes` as lower-case hex (a digest's usual spelling).
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write as _;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn canonical_json_sorts_keys_at_every_level() {
        let a: Value =
            serde_json::from_str(r#"{"b":1,"a":{"y":[1,{"d":2,"c":3}],"x":0.1}}"#).unwrap();
        assert_eq!(
            canonical_json(&a),
            r#"{"a":{"x":0.1,"y":[1,{"c":3,"d":2}]},"b":1}"#
        );
    }

    #[test]
    fn sha256_of_a_known_text() {
        // FIPS 180-2, appendix B.1.
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn fingerprint_verifies_and_detects_a_change_of_inputs() {
        let f = Fingerprint::new(serde_json::json!({"seed": 1, "run": 2}));
        f.verify().unwrap();
        let same = Fingerprint::new(serde_json::from_str(r#"{"run":2,"seed":1}"#).unwrap());
        assert_eq!(f.sha256, same.sha256, "key order must not matter");
        let mut g = f.clone();
        g.inputs["seed"] = 3.into();
        assert!(g.verify().is_err());
    }

    #[test]
    fn only_field_data_carries_the_validation_version() {
        let field = LoadedDataset {
            dt: 0.01,
            t: vec![0.0, 0.01],
            ug_meas: vec![0.0, 1.0],
            y_meas: vec![0.0, 1.0],
            channels: 1,
            sensors: vec![1],
            truth: None,
            meta: None,
        };
        let f = Fingerprint::of_run("mpf-ekf2", 1, 0, &serde_json::json!({}), &field);
        assert_eq!(
            f.inputs["field_validation"],
            serde_json::json!(super::super::FIELD_VALIDATION_VERSION)
        );
        // A simulated data set (with its `dataset.json`): the inputs of the committed studies'
        // records, unchanged by the field validation's version.
        let mut config = models::dataset::DatasetConfig::from_preset("paper-3dof", 3).unwrap();
        config.duration = Some(0.1);
        let simulated = models::dataset::generate(&config).unwrap().to_loaded();
        assert!(simulated.meta.is_some());
        let g = Fingerprint::of_run("mpf-ekf2", 1, 0, &serde_json::json!({}), &simulated);
        assert!(g.inputs.get("field_validation").is_none(), "{}", g.inputs);
        assert_eq!(
            g.inputs.as_object().unwrap().len(),
            6,
            "numerics, algorithm, seed, run, filter, data"
        );
    }
}
