//! One look per algorithm and per discretisation scheme, in every figure.
//!
//! A reader compares figures side by side (Fig. 6b, Fig. 7, the discretisation, calibration and
//! scaling figures), so an algorithm keeps its colour and marker everywhere and a scheme keeps
//! its line style: the MPF-EKF2 is always the blue circle, forward Euler always a solid line.
//! Series that are not an algorithm (runs of one algorithm, channels, parameters) take the
//! palette by position instead.

use models::filtering::Discretisation;
use plotters::style::RGBColor;

use super::{colour, PALETTE};
use crate::pipeline::Algorithm;

/// How one series is drawn: its colour, its marker (an index into the four marker shapes of
/// the figures) and whether its lines are dashed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeriesStyle {
    pub colour: RGBColor,
    pub marker: usize,
    pub dashed: bool,
}

/// The colour of an algorithm (Okabe–Ito, colour-blind safe).
pub fn algorithm_colour(a: Algorithm) -> RGBColor {
    match a {
        Algorithm::MpfEkf2 => PALETTE[0],
        Algorithm::MlnRbpf => PALETTE[1],
        Algorithm::Storvik => PALETTE[2],
        Algorithm::Bootstrap => PALETTE[3],
    }
}

/// The marker of an algorithm: circle, triangle, square, diamond.
pub(crate) fn algorithm_marker(a: Algorithm) -> usize {
    match a {
        Algorithm::MpfEkf2 => 0,
        Algorithm::MlnRbpf => 1,
        Algorithm::Storvik => 2,
        Algorithm::Bootstrap => 3,
    }
}

/// Whether a scheme's lines are dashed: forward Euler (the paper's) solid, the others dashed.
pub(crate) fn scheme_dashed(d: Discretisation) -> bool {
    !matches!(d, Discretisation::Euler)
}

/// The algorithm a series label names, if any: its figure label ("MPF-EKF2", "Bootstrap PF") or
/// its command-line name ("mpf-ekf2"), anywhere in the label.
pub(crate) fn algorithm_in(label: &str) -> Option<Algorithm> {
    let lower = label.to_lowercase();
    Algorithm::ALL.into_iter().find(|a| {
        lower.contains(&a.label().to_lowercase())
            || lower.contains(a.name())
            || (*a == Algorithm::Bootstrap && lower.contains("bootstrap"))
    })
}

/// The scheme a series label names, if any ("· symplectic", "euler").
pub(crate) fn scheme_in(label: &str) -> Option<Discretisation> {
    let lower = label.to_lowercase();
    if lower.contains("symplectic") || lower.contains("semi-implicit") {
        Some(Discretisation::Symplectic)
    } else if lower.contains("rk4") {
        Some(Discretisation::Rk4)
    } else if lower.contains("euler") {
        Some(Discretisation::Euler)
    } else {
        None
    }
}

/// The style of series `index` labelled `label`: the algorithm's colour and marker and the
/// scheme's line style when the label names them, the palette by position otherwise.
pub fn for_label(label: &str, index: usize) -> SeriesStyle {
    let dashed = scheme_in(label).is_some_and(scheme_dashed);
    match algorithm_in(label) {
        Some(a) => SeriesStyle {
            colour: algorithm_colour(a),
            marker: algorithm_marker(a),
            dashed,
        },
        None => SeriesStyle {
            colour: colour(index),
            marker: index,
            dashed,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The style of an algorithm's series (solid lines).
    fn for_algorithm(a: Algorithm) -> SeriesStyle {
        SeriesStyle {
            colour: algorithm_colour(a),
            marker: algorithm_marker(a),
            dashed: false,
        }
    }

    #[test]
    fn every_algorithm_has_its_own_colour_and_marker() {
        for (i, a) in Algorithm::ALL.iter().enumerate() {
            for b in &Algorithm::ALL[i + 1..] {
                assert_ne!(algorithm_colour(*a), algorithm_colour(*b));
                assert_ne!(algorithm_marker(*a), algorithm_marker(*b));
            }
        }
    }

    #[test]
    fn labels_of_every_figure_resolve_to_the_same_style() {
        for a in Algorithm::ALL {
            let by_label = for_label(a.label(), 5);
            let by_name = for_label(&format!("{}: coverage ± 2 s.e.", a.name()), 0);
            let with_scheme = for_label(&format!("{} · symplectic", a.label()), 2);
            assert_eq!(by_label, for_algorithm(a));
            assert_eq!(by_name, for_algorithm(a));
            assert_eq!(with_scheme.colour, algorithm_colour(a));
            assert_eq!(with_scheme.marker, algorithm_marker(a));
            assert!(with_scheme.dashed);
            assert!(!for_label(&format!("{} · euler", a.label()), 2).dashed);
        }
        // "MLN-RBPF" must not be read as another algorithm, nor "mpf-ekf2" as "MPF".
        assert_eq!(algorithm_in("MLN-RBPF (n = 50)"), Some(Algorithm::MlnRbpf));
        assert_eq!(algorithm_in("run 3"), None);
        assert_eq!(for_label("run 3", 1).colour, colour(1));
    }
}
