//! The identification algorithms (SPEC §5): their names on the command line, in records and in
//! figures.

use serde::{Deserialize, Serialize};

/// The identification algorithms (SPEC §5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Algorithm {
    Bootstrap,
    MlnRbpf,
    Storvik,
    MpfEkf2,
}

impl Algorithm {
    pub const ALL: [Algorithm; 4] = [
        Algorithm::Bootstrap,
        Algorithm::MlnRbpf,
        Algorithm::Storvik,
        Algorithm::MpfEkf2,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Algorithm::Bootstrap => "bootstrap",
            Algorithm::MlnRbpf => "mln-rbpf",
            Algorithm::Storvik => "storvik",
            Algorithm::MpfEkf2 => "mpf-ekf2",
        }
    }

    /// Name used in figures and reports.
    pub fn label(self) -> &'static str {
        match self {
            Algorithm::Bootstrap => "Bootstrap PF",
            Algorithm::MlnRbpf => "MLN-RBPF",
            Algorithm::Storvik => "Storvik",
            Algorithm::MpfEkf2 => "MPF-EKF2",
        }
    }
}

impl std::str::FromStr for Algorithm {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Algorithm::ALL
            .into_iter()
            .find(|a| a.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown algorithm `{s}` (expected bootstrap, mln-rbpf, storvik or mpf-ekf2)"
                )
            })
    }
}
