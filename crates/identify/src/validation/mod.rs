//! Validation without the truth (docs/validation.md): what an identified model predicts of a
//! record it is given only the ground motion of.
//!
//! - **Free run** ([`free_run`](mod@free_run)): the identified building (θ_val) simulated from rest under the
//!   measured ground motion with the toolkit's own simulator, compared with every measured
//!   channel (fit %, NRMSE), with a band from θ drawn from the run's recorded posterior on the
//!   stream (seed, run, `validation-band`).
//! - **Modes** ([`modal`]): natural frequencies and damping ratios of the identified model
//!   linearised at rest ([`models::modal`]) beside the peaks of the measured floor/ground transfer
//!   functions ([`spectral`]), paired mode by mode.
//!
//! `sysid filter` attaches both to the record of every field-data run ([`attach`]); `sysid
//! validate` applies them to another record of the same building (cross-validation).

pub mod cross;
pub mod discrepancy;
pub mod figures;
pub mod free_run;
pub mod prediction;
pub mod shapes;
pub mod spectral;

use std::fmt::Write as _;

use crate::error::{bail, Context, Result};
use models::dataset::LoadedDataset;
use models::description::StructureDescription;
use models::modal::Mode;
use models::sensors::{MeasurementKind, SensorLayout};
use rayon::prelude::*;

pub use crate::record::validation::{
    BandInfo, ChannelFit, ErrorSource, FreeRun, ModalComparison, ModePair, ModelError,
};
use crate::record::RunRecord;
use free_run::{
    chain_of, fit_percent, free_run_integrator, nrmse, percentile_sorted,
    simulate_channels_between, Between, FreeRunError, QuantileDraw,
};
use spectral::Peak;

/// A record's θ distribution with its seed and run (the band's stream).
type Posterior<'a> = (&'a QuantileDraw, u64, u64);

/// One draw of the band: its fit per channel and its kept series, or why it is invalid.
type DrawResult = Result<(Vec<f64>, Vec<Vec<f64>>), String>;

/// Purpose of the band's random stream.
pub(crate) const BAND_PURPOSE: &str = "validation-band";
/// Draws of θ for the band.
pub const BAND_DRAWS: usize = 100;
/// At most this many time points of each series are kept in a record.
pub(crate) const MAX_POINTS: usize = 5000;

/// The measured channels of a record, channel-major.
pub(crate) fn measured_channels(data: &LoadedDataset) -> Vec<Vec<f64>> {
    (0..data.channels)
        .map(|c| (0..data.len()).map(|k| data.y(k)[c]).collect())
        .collect()
}

/// The discrepancy term of a free run ([`discrepancy`]).
#[derive(Debug, Clone, Copy)]
pub enum DiscrepancyUse<'a> {
    /// None: the physical model alone.
    Without,
    /// These modes, their coefficients fitted on this record (the identifying one).
    Fit(&'a [discrepancy::DiscrepancyMode]),
    /// This discrepancy as identified (on another record of the same channels).
    Given(&'a discrepancy::Discrepancy),
}

/// The free run of building `d` with θ on record `data` (its measured ü_g and channels; the
/// channels' storeys from its header, their kind from `d`), the discrepancy term `disc` added,
/// with a band of `draws` θ from `posterior` on the stream (seed, run, `BAND_PURPOSE`) when
/// given, widened by the model error `error` ([`prediction`]); each channel's coverage by the
/// band.
pub fn free_run(
    d: &StructureDescription,
    data: &LoadedDataset,
    theta: &[f64],
    posterior: Option<(&QuantileDraw, u64, u64)>,
    draws: usize,
    error: prediction::ErrorBand<'_>,
    disc: DiscrepancyUse<'_>,
) -> Result<FreeRun, FreeRunError> {
    let chain = chain_of(d, theta)?;
    let kind = d.measurement;
    let names: Vec<String> = data.sensors.iter().map(|s| format!("a{s}")).collect();
    let measured = measured_channels(data);
    let physical = simulate_record(&chain, data, d)?;
    let (discrepancy, disc_note) = discrepancy_of(disc, &names, &measured, &physical, data);
    let added = discrepancy
        .as_ref()
        .map(|dd| discrepancy::contribution(dd, &data.ug_meas, data.dt));
    let compared = Compared {
        simulated: match &added {
            Some(a) => plus(&physical, a),
            None => physical.clone(),
        },
        names,
        measured,
    };
    let every = data.len().div_ceil(MAX_POINTS).max(1);
    let mut channels = channel_fits(&compared);
    if discrepancy.is_some() {
        for (c, ch) in channels.iter_mut().enumerate() {
            ch.physical_fit_percent = Some(fit_percent(&compared.measured[c], &physical[c]));
        }
    }
    let mut spread = match posterior {
        None => ParameterBand::failed("no posterior to draw from".into()),
        Some(posterior) => parameter_band(
            d,
            data,
            &compared,
            (posterior, added.as_deref()),
            draws,
            every,
            &mut channels,
        ),
    };
    let model_error = match model_error_for(error, d, data, theta, &compared) {
        Ok(model_error) => model_error,
        Err(why) => {
            spread.error = Some(match spread.error {
                Some(e) => format!("{e}; {why}"),
                None => why,
            });
            None
        }
    };
    if let Some(me) = &model_error {
        (spread.lo, spread.hi) = widen_by_model_error(me, data, &compared, every, &spread);
    }
    if let (Some(b), Some(me)) = (&mut spread.info, &model_error) {
        let _ = write!(
            b.method,
            "; widened in quadrature by the model error learned {} (docs/validation.md)",
            match me.source {
                ErrorSource::HeldOut { .. } => "on the held-out part of the identifying record",
                ErrorSource::InSample => "in-sample on the identifying record",
            }
        );
    }
    if !spread.lo.is_empty() {
        for (c, ch) in channels.iter_mut().enumerate() {
            ch.coverage_percent = Some(prediction::coverage_percent(
                &thin(&compared.measured[c], every),
                &spread.lo[c],
                &spread.hi[c],
            ));
        }
    }
    Ok(FreeRun {
        method: format!(
            "the identified model (posterior mean θ_val) simulated from rest under the measured \
             ground acceleration, {} accelerations compared with each measured channel; fit = \
             100·(1 − ‖y − ŷ‖/‖y − ȳ‖), NRMSE = RMSE/RMS(y){}{}",
            kind,
            match &discrepancy {
                Some(dd) => format!(
                    "; the discrepancy term ({}) added (docs/validation.md)",
                    dd.describe_modes()
                ),
                None => String::new(),
            },
            disc_note.map_or(String::new(), |n| format!("; {n}"))
        ),
        integrator: free_run_integrator(&chain),
        measurement: kind,
        channels,
        band: spread.info,
        band_error: spread.error,
        model_error,
        discrepancy,
        every,
        t: thin(&data.t, every),
        measured: compared.measured.iter().map(|v| thin(v, every)).collect(),
        simulated: compared.simulated.iter().map(|v| thin(v, every)).collect(),
        band_lo: spread.lo,
        band_hi: spread.hi,
    })
}

/// Channel by channel, `a + b`.
fn plus(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    a.iter()
        .zip(b)
        .map(|(x, y)| x.iter().zip(y).map(|(p, q)| p + q).collect())
        .collect()
}

/// The discrepancy `disc` asks for on a record of channels `names` (`physical`: the physical
/// model's free run of `measured`), or none and why not.
fn discrepancy_of(
    disc: DiscrepancyUse<'_>,
    names: &[String],
    measured: &[Vec<f64>],
    physical: &[Vec<f64>],
    data: &LoadedDataset,
) -> (Option<discrepancy::Discrepancy>, Option<String>) {
    match disc {
        DiscrepancyUse::Without => (None, None),
        DiscrepancyUse::Fit([]) => (None, None),
        DiscrepancyUse::Fit(modes) => (
            Some(discrepancy::refit(
                modes,
                names,
                measured,
                physical,
                (&data.ug_meas, data.dt),
                data.len(),
            )),
            None,
        ),
        DiscrepancyUse::Given(dd) if dd.modes.is_empty() => (None, None),
        DiscrepancyUse::Given(dd) if dd.channels == names => {
            (Some(dd.clone()), discrepancy::above_band_note(dd, data.dt))
        }
        DiscrepancyUse::Given(dd) => (
            None,
            Some(format!(
                "the discrepancy term was learned on channels {} and this record has {}: the \
                 physical model alone",
                dd.channels.join(", "),
                names.join(", ")
            )),
        ),
    }
}

/// What a free run compares, channel by channel: the record's measured channels beside the
/// identified model's simulation of them.
struct Compared {
    names: Vec<String>,
    measured: Vec<Vec<f64>>,
    simulated: Vec<Vec<f64>>,
}

/// The band of the parameters' spread: how it was drawn (or why there is none) and its
/// pointwise bounds per channel, thinned like the kept series (empty without a band).
struct ParameterBand {
    info: Option<BandInfo>,
    error: Option<String>,
    lo: Vec<Vec<f64>>,
    hi: Vec<Vec<f64>>,
}

impl ParameterBand {
    /// No band, for the reason `why`.
    fn failed(why: String) -> Self {
        ParameterBand {
            info: None,
            error: Some(why),
            lo: Vec::new(),
            hi: Vec::new(),
        }
    }
}

/// The channels of building `chain` under the measured ground motion of `data`, as its sensors
/// record them (`kind`), with the free run's integrator.
fn simulate_record(
    chain: &models::structure::ShearChain,
    data: &LoadedDataset,
    d: &StructureDescription,
) -> Result<Vec<Vec<f64>>, FreeRunError> {
    simulate_channels_between(
        chain,
        &data.ug_meas,
        data.dt,
        &data.sensors,
        d.measurement,
        free_run_integrator(chain),
        d.ground_between,
    )
}

/// Every `every`-th point of a series: what a record keeps of it.
fn thin(v: &[f64], every: usize) -> Vec<f64> {
    v.iter().step_by(every).copied().collect()
}

/// The fit % and NRMSE of θ_val's simulation against each measured channel.
fn channel_fits(compared: &Compared) -> Vec<ChannelFit> {
    let (measured, simulated) = (&compared.measured, &compared.simulated);
    compared
        .names
        .iter()
        .enumerate()
        .map(|(c, name)| ChannelFit {
            channel: name.clone(),
            fit_percent: fit_percent(&measured[c], &simulated[c]),
            nrmse: nrmse(&measured[c], &simulated[c]),
            physical_fit_percent: None,
            fit_draws: None,
            coverage_percent: None,
        })
        .collect()
}

/// The band of `draws` θ from the record's posterior on the stream (seed, run, `BAND_PURPOSE`):
/// each draw simulated (the discrepancy's contribution `added` added), the spread of its fit
/// written into `channels`, and the pointwise 2.5–97.5 % of the kept series; no band when fewer
/// than two draws are valid.
fn parameter_band(
    d: &StructureDescription,
    data: &LoadedDataset,
    compared: &Compared,
    ((q, seed, run), added): (Posterior<'_>, Option<&[Vec<f64>]>),
    draws: usize,
    every: usize,
    channels: &mut [ChannelFit],
) -> ParameterBand {
    let mut rng = core_filters::rng::stream(seed, run, BAND_PURPOSE);
    let thetas: Vec<Vec<f64>> = (0..draws).map(|_| q.draw(&mut rng)).collect();
    let results = simulate_draws(d, data, &compared.measured, &thetas, every, added);
    let invalid_reason = results.iter().find_map(|r| r.as_ref().err().cloned());
    let ok: Vec<&(Vec<f64>, Vec<Vec<f64>>)> = results.iter().flatten().collect();
    if ok.len() < 2 {
        return ParameterBand::failed(format!(
            "{} of {draws} draws were valid{}",
            ok.len(),
            invalid_reason
                .as_ref()
                .map_or(String::new(), |r| format!(" ({r})"))
        ));
    }
    let (lo, hi) = spread_of_draws(&ok, channels);
    ParameterBand {
        info: Some(BandInfo {
            method: format!(
                "{}{}; pointwise 2.5–97.5 % of the draws",
                if q.gaussian() {
                    format!(
                        "θ drawn from {}, inside each 95 % interval, {}",
                        drawn_from(true),
                        how_drawn(true, true)
                    )
                } else {
                    format!(
                        "θ drawn from {} (quantile function interpolated through its \
                         2.5/5/25/75/95/97.5 % points, so draws stay inside the 95 % intervals), \
                         {}",
                        drawn_from(q.correlated()),
                        how_drawn(q.correlated(), false)
                    )
                },
                if q.shifted() { SHIFTED } else { "" }
            ),
            correlated: q.correlated(),
            gaussian: q.gaussian(),
            shifted: q.shifted(),
            purpose: BAND_PURPOSE.into(),
            draws,
            valid: ok.len(),
            invalid_reason,
        }),
        error: None,
        lo,
        hi,
    }
}

/// Each drawn θ simulated on the record (with `added`, the discrepancy's contribution), side by
/// side: its fit per channel and its kept series (or why it is invalid).
fn simulate_draws(
    d: &StructureDescription,
    data: &LoadedDataset,
    measured: &[Vec<f64>],
    thetas: &[Vec<f64>],
    every: usize,
    added: Option<&[Vec<f64>]>,
) -> Vec<DrawResult> {
    thetas
        .par_iter()
        .map(|th| {
            let c = chain_of(d, th).map_err(|e| e.to_string())?;
            let mut y = simulate_record(&c, data, d).map_err(|e| e.to_string())?;
            if let Some(a) = added {
                y = plus(&y, a);
            }
            let fits = (0..y.len())
                .map(|i| fit_percent(&measured[i], &y[i]))
                .collect();
            Ok((fits, y.iter().map(|v| thin(v, every)).collect()))
        })
        .collect()
}

/// The spread of the valid draws `ok`: the 2.5/50/97.5 % of each channel's fit (written into
/// `channels`) and each channel's pointwise 2.5 % and 97.5 % series.
fn spread_of_draws(
    ok: &[&(Vec<f64>, Vec<Vec<f64>>)],
    channels: &mut [ChannelFit],
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let (mut band_lo, mut band_hi) = (Vec::new(), Vec::new());
    for (c, ch) in channels.iter_mut().enumerate() {
        let mut f: Vec<f64> = ok.iter().map(|(fits, _)| fits[c]).collect();
        f.sort_by(f64::total_cmp);
        ch.fit_draws = Some(
            [0.025, 0.5, 0.975]
                .iter()
                .map(|&p| percentile_sorted(&f, p))
                .collect(),
        );
        let points = ok[0].1[c].len();
        let (mut lo, mut hi) = (Vec::with_capacity(points), Vec::with_capacity(points));
        let mut col = Vec::with_capacity(ok.len());
        for i in 0..points {
            col.clear();
            col.extend(ok.iter().map(|(_, s)| s[c][i]));
            col.sort_by(f64::total_cmp);
            lo.push(percentile_sorted(&col, 0.025));
            hi.push(percentile_sorted(&col, 0.975));
        }
        band_lo.push(lo);
        band_hi.push(hi);
    }
    (band_lo, band_hi)
}

/// The model error that widens the band: none, learned in-sample on this record, or the one
/// given when it was learned on these channels; `Err` says why a given one does not apply.
fn model_error_for(
    error: prediction::ErrorBand<'_>,
    d: &StructureDescription,
    data: &LoadedDataset,
    theta: &[f64],
    compared: &Compared,
) -> Result<Option<ModelError>, String> {
    let names = &compared.names;
    Ok(match error {
        prediction::ErrorBand::Without => None,
        prediction::ErrorBand::InSample => prediction::learn(
            names,
            &compared.measured,
            &compared.simulated,
            data.dt,
            prediction::window_seconds(d, theta),
            0,
            ErrorSource::InSample,
        ),
        prediction::ErrorBand::Given(m) if &m.channels == names => Some(m.clone()),
        prediction::ErrorBand::Given(m) => {
            return Err(format!(
                "the model error was learned on channels {} and this record has {}: the band \
                 holds the parameters' spread only",
                m.channels.join(", "),
                names.join(", ")
            ))
        }
    })
}

/// The band widened in quadrature by the model error `me` around θ_val's simulation, per
/// channel at the kept points (around the parameters' band where there is one).
fn widen_by_model_error(
    me: &ModelError,
    data: &LoadedDataset,
    compared: &Compared,
    every: usize,
    spread: &ParameterBand,
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let simulated = &compared.simulated;
    let with_param = !spread.lo.is_empty();
    let (mut lo_all, mut hi_all) = (Vec::new(), Vec::new());
    for c in 0..compared.names.len() {
        let scale = prediction::local_scale(&simulated[c], data.dt, me.window_s, me.floor[c]);
        let (lo, hi): (Vec<f64>, Vec<f64>) = (0..data.len())
            .step_by(every)
            .enumerate()
            .map(|(i, t)| {
                let param = with_param.then(|| (spread.lo[c][i], spread.hi[c][i]));
                prediction::widen(simulated[c][t], param, me.quantile[c] * scale[t])
            })
            .unzip();
        lo_all.push(lo);
        hi_all.push(hi);
    }
    (lo_all, hi_all)
}

/// The modes of building `d` with θ (linearised at rest) beside the peaks of the measured
/// transfer functions of `data`, paired mode by mode ([`pair`]). A part that cannot be computed
/// is named in `errors`.
pub fn modal(d: &StructureDescription, data: &LoadedDataset, theta: &[f64]) -> ModalComparison {
    let mut out = ModalComparison {
        linearisation: "every Bouc–Wen element at its initial tangent stiffness k_j (r = drift \
                        to first order at rest); modes from the eigenvalues of the state matrix \
                        [[0, I], [−M⁻¹K, −M⁻¹C]]"
            .into(),
        method: format!(
            "Welch H1 = P_xy/P_xx of each floor's absolute acceleration against the measured \
             ground acceleration (Hann, 50 % overlap); peaks: the N largest local maxima of the \
             summed |H1| where the ground motion is within {:.0} dB of its strongest frequency \
             (up to the Nyquist frequency) and a floor's coherence with it is at least {}",
            -10.0 * spectral::BAND_FRACTION.log10(),
            spectral::MIN_COHERENCE
        ),
        ..Default::default()
    };
    // From θ's k, c (and α) directly: an impossible θ (a negative damping) still has modes.
    let n = d.storeys;
    let na = d.damping.extra_parameters();
    let linear = if theta.len() >= 2 * n + na {
        let alpha = d.damping.has_mass_term().then(|| theta[2 * n]);
        models::modal::modes_of_damped(&d.masses, &theta[..n], &theta[n..2 * n], alpha)
            .map_err(|e| e.to_string())
    } else {
        Err(format!("θ has {} entries for {n} storeys", theta.len()))
    };
    match linear {
        Ok(m) => {
            out.modes = m.modes;
            out.overdamped = m.overdamped;
        }
        Err(e) => out.errors.push(format!("model modes: {e}")),
    }
    let measured = measured_channels(data);
    let absolute: Vec<Vec<f64>> = measured
        .iter()
        .map(|y| match d.measurement {
            MeasurementKind::Absolute => y.clone(),
            MeasurementKind::Relative => y.iter().zip(&data.ug_meas).map(|(a, u)| a + u).collect(),
        })
        .collect();
    let mut excitation = Vec::new();
    let transfer = spectral::welch_h1(&data.ug_meas, &absolute, data.dt);
    match &transfer {
        Ok(t) => {
            excitation = out
                .modes
                .iter()
                .map(|m| spectral::excitation_db(t, m.frequency_hz))
                .collect();
            out.peaks = spectral::peaks(t, d.storeys);
            let band = spectral::in_band(t);
            let (first, last) = (
                band.iter().position(|b| *b).unwrap_or(0),
                band.iter().rposition(|b| *b).unwrap_or(0),
            );
            out.segment = t.segment;
            out.segments = t.segments;
            out.resolution_hz = t.resolution_hz;
            out.frequency_hz = t.frequency_hz[first..=last].to_vec();
            out.magnitude = t
                .magnitude
                .iter()
                .map(|m| m[first..=last].to_vec())
                .collect();
            out.channels = data.sensors.iter().map(|s| format!("a{s}")).collect();
        }
        Err(e) => out.errors.push(format!("transfer functions: {e}")),
    }
    out.pairs = pair(&out.modes, &out.peaks, out.resolution_hz, &excitation);
    if shapes::comparable(d, &data.sensors) && theta.len() >= n {
        shapes::compare(
            &mut out.pairs,
            &d.masses,
            &theta[..n],
            transfer.as_ref().ok(),
            &data.sensors,
        );
    }
    out
}

/// Largest frequency ratio between a model mode and the measured peak it is paired with.
pub(crate) const PAIR_RATIO: f64 = 1.5;

/// Ground-motion power near a mode below which the record does not excite it (dB relative to
/// the strongest frequency): the band the measured peaks are read in (`spectral::BAND_FRACTION`).
pub(crate) fn not_excited_db() -> f64 {
    10.0 * spectral::BAND_FRACTION.log10()
}

/// Pairs each model mode with a measured peak: repeatedly the closest remaining (mode, peak)
/// pair in log-frequency, as long as their ratio is below `PAIR_RATIO`; a mode left without
/// a peak (none near it, it lies below two frequency bins where no peak can be resolved, or the
/// record's ground motion near it — `excitation[i]`, dB below its strongest frequency — is
/// below `not_excited_db`, so a peak elsewhere would be a bump of the input's spectrum, not
/// this mode) shows none, and a peak left without a mode is listed apart. Modes keep their
/// order (1 = the lowest).
pub fn pair(
    modes: &[Mode],
    peaks: &[Peak],
    resolution_hz: f64,
    excitation: &[Option<f64>],
) -> Vec<ModePair> {
    let mut candidates: Vec<(f64, usize, usize)> = Vec::new();
    for (i, m) in modes.iter().enumerate() {
        if m.frequency_hz.is_nan() || m.frequency_hz < 2.0 * resolution_hz {
            continue;
        }
        if excitation
            .get(i)
            .copied()
            .flatten()
            .is_some_and(|db| db < not_excited_db())
        {
            continue;
        }
        for (j, p) in peaks.iter().enumerate() {
            let d = (m.frequency_hz / p.frequency_hz).ln().abs();
            if d < PAIR_RATIO.ln() {
                candidates.push((d, i, j));
            }
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut peak_of = vec![None; modes.len()];
    let mut used = vec![false; peaks.len()];
    for (_, i, j) in candidates {
        if peak_of[i].is_none() && !used[j] {
            peak_of[i] = Some(j);
            used[j] = true;
        }
    }
    modes
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let p = peak_of[i].map(|j| peaks[j].frequency_hz);
            ModePair {
                mode: i + 1,
                model_hz: m.frequency_hz,
                damping_ratio: m.damping_ratio,
                measured_hz: p,
                difference_percent: p.map(|p| 100.0 * (m.frequency_hz - p) / p),
                excitation_db: excitation.get(i).copied().flatten(),
                model_hz_95: None,
                damping_ratio_95: None,
                model_shape: Vec::new(),
                model_shape_95: Vec::new(),
                operating_shape: Vec::new(),
                mac: None,
                mac_95: None,
            }
        })
        .collect()
}

/// Purpose of the random stream of the modal intervals' draws.
pub(crate) const MODAL_PURPOSE: &str = "validation-modes";

/// θ drawn for the modal intervals.
pub(crate) const MODAL_DRAWS: usize = 400;

/// The central 95 % of each mode's natural frequency and damping ratio over `MODAL_DRAWS` θ
/// drawn from `q` as the free-run band on the record draws them (each parameter inside its 95 %
/// interval, with the posterior's correlations where the record keeps them; never shifted as on
/// another record) on the stream (seed, run, `MODAL_PURPOSE`); one entry per mode of θ_val
/// (`count`), `None` for all when fewer than half the draws give a building with as many
/// under-damped modes (mode `r` of a draw is its `r`-th by frequency).
pub fn modal_intervals(
    d: &StructureDescription,
    q: &QuantileDraw,
    seed: u64,
    run: u64,
    count: usize,
) -> Vec<Option<([f64; 2], [f64; 2])>> {
    let n = d.storeys;
    let alpha_at = d.damping.has_mass_term().then_some(2 * n);
    let mut rng = core_filters::rng::stream(seed, run, MODAL_PURPOSE);
    let mut freq = vec![Vec::with_capacity(MODAL_DRAWS); count];
    let mut zeta = vec![Vec::with_capacity(MODAL_DRAWS); count];
    for _ in 0..MODAL_DRAWS {
        let theta = q.draw(&mut rng);
        let alpha = alpha_at.map(|i| theta[i]);
        let Ok(m) = models::modal::modes_of_damped(&d.masses, &theta[..n], &theta[n..2 * n], alpha)
        else {
            continue;
        };
        if m.modes.len() != count {
            continue;
        }
        for (r, mode) in m.modes.iter().enumerate() {
            freq[r].push(mode.frequency_hz);
            zeta[r].push(mode.damping_ratio);
        }
    }
    let valid = freq.first().map_or(0, Vec::len);
    if count == 0 || 2 * valid < MODAL_DRAWS {
        return vec![None; count];
    }
    let central = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        [
            free_run::percentile_sorted(v, 0.025),
            free_run::percentile_sorted(v, 0.975),
        ]
    };
    freq.iter_mut()
        .zip(zeta.iter_mut())
        .map(|(f, z)| Some((central(f), central(z))))
        .collect()
}

/// The building a record was identified on, from its `config.spec` (masses, 0-based
/// hysteretic storeys, sensor layout).
pub(crate) fn description_of(r: &RunRecord) -> Result<StructureDescription> {
    let spec = r
        .config
        .get("spec")
        .context("the record has no `config.spec` (the structure its filter used)")?;
    let masses: Vec<f64> = serde_json::from_value(spec.get("masses").cloned().unwrap_or_default())
        .context("field `config.spec.masses`")?;
    let hysteretic: Vec<usize> =
        serde_json::from_value(spec.get("hysteretic").cloned().unwrap_or_default())
            .context("field `config.spec.hysteretic`")?;
    let sensors: SensorLayout =
        serde_json::from_value(spec.get("sensors").cloned().unwrap_or_default())
            .context("field `config.spec.sensors`")?;
    let damping: models::structure::Damping = match spec.get("damping") {
        Some(v) => serde_json::from_value(v.clone()).context("field `config.spec.damping`")?,
        None => Default::default(),
    };
    let building = models::building::Building::new(masses, hysteretic, damping)
        .context("the record's structure (`config.spec`)")?;
    let mut d = StructureDescription::of(&building, sensors.one_based(), sensors.kind());
    // Records before it interpolated linearly (the default, not written).
    if let Some(v) = spec.get("ground_between") {
        d.ground_between =
            serde_json::from_value(v.clone()).context("field `config.spec.ground_between`")?;
    }
    d.validate()
        .context("the record's structure (`config.spec`)")?;
    Ok(d)
}

/// The band's θ distribution for a record, or why there is none: the filter's posterior, its own
/// intervals with its correlations. Where the spread between the record's parts widened the
/// record's intervals, the draws still take the filter's own: on the record itself θ's drift
/// enters the band through the error learned on the held-out part ([`prediction`]); on another
/// record it enters as a shift of each joint draw ([`shifted_to_another`]), not through the
/// widened marginals, which with the filter's correlations are no distribution at all (the data
/// fix c1 + α of a one-storey bent; widened and truncated at zero, every pair of quantiles the
/// copula couples sums far above it, and a mode's drawn damping ratios excluded its own). A record without
/// correlations (written before they were kept) draws its intervals independently, as then.
pub(crate) fn posterior_of(r: &RunRecord) -> Result<QuantileDraw, String> {
    if !r.theta_correlation.is_empty() {
        let own = r
            .segment_spread
            .as_ref()
            .map_or(&r.credible, |s| &s.filter_credible);
        let mut q = QuantileDraw::new(&r.param_names, own)?.with_correlation(&r.theta_correlation);
        if r.one_gaussian_filter {
            q = q.with_gaussian(&r.theta_val, &r.theta_sd_final);
        }
        if q.correlated() {
            return Ok(q);
        }
    }
    // No usable matrix (none recorded, or not a correlation matrix): the record's intervals,
    // independently, as the band then says.
    QuantileDraw::new(&r.param_names, &r.credible)
}

/// The band's θ distribution on **another** record of the structure: the record's posterior `q`
/// ([`posterior_of`]) with each draw shifted by the spread between the record's parts where they
/// disagree ([`QuantileDraw::with_between`]; `crate::spread`). The parts of one record are the
/// nearest thing to other records it holds: what they disagree on, θ of another record may
/// differ by — the random-effects prediction of a new part, whose quantiles the widened
/// intervals state. On the record itself the band keeps the posterior alone: there θ's drift
/// within the record is already in the model error learned on its held-out part. A record
/// without a spread (too short, or older), or whose draws are its widened intervals drawn
/// independently, keeps `q` as it is.
pub(crate) fn shifted_to_another(r: &RunRecord, q: QuantileDraw) -> QuantileDraw {
    let Some(s) = r.segment_spread.as_ref().filter(|_| q.correlated()) else {
        return q;
    };
    let between: Vec<Between> = r
        .param_names
        .iter()
        .map(|name| {
            s.parameters
                .iter()
                .find(|p| &p.parameter == name)
                .map_or(Between::NONE, |p| Between {
                    tau: p.tau.unwrap_or(0.0),
                    parts: p.part_mean.len(),
                    bounded: crate::spread::physically_bounded(name),
                })
        })
        .collect();
    q.with_between(&between)
}

/// Checks that a record's θ_val can be simulated: a completed run with finite values and no
/// physically impossible parameter (a stiffness or damping ≤ 0, `checks::check`).
pub(crate) fn check_identified(r: &RunRecord) -> Result<()> {
    if let Some(f) = &r.failure {
        bail!("the run failed ({f}): it identified no θ to validate");
    }
    let impossible: Vec<&str> = r
        .warnings
        .iter()
        .filter(|w| w.kind.is_fatal())
        .filter_map(|w| w.parameter.as_deref())
        .collect();
    if !impossible.is_empty() {
        bail!(
            "θ_val is physically impossible ({} ≤ 0): no building to simulate",
            impossible.join(", ")
        );
    }
    if let Some((name, v)) = r
        .param_names
        .iter()
        .zip(&r.theta_val)
        .find(|(_, v)| !v.is_finite())
    {
        bail!("θ_val of {name} is {v}: no model to simulate");
    }
    Ok(())
}

/// Attaches the free run and the modal comparison to the record of a field-data run on
/// `data` with building `d` (nothing when the run failed: the record says why). The band's
/// model error is `held_out` (learned by the held-out choice) or, without one, learned
/// in-sample on `data`; the discrepancy term has the `modes` the choice kept (none: none), its
/// coefficients fitted on `data` ([`discrepancy::refit`]).
pub fn attach(
    r: &mut RunRecord,
    data: &LoadedDataset,
    d: &StructureDescription,
    held_out: Option<&ModelError>,
    modes: &[discrepancy::DiscrepancyMode],
) {
    r.warnings = crate::checks::check(r);
    if let Err(e) = check_identified(r) {
        // The modes of an impossible θ are still shown (a negative damping can leave every
        // mode decaying); the free run is not.
        r.modal = Some(ModalComparison {
            errors: vec![format!("free run: {e}")],
            ..modal(d, data, &r.theta_val)
        });
        return;
    }
    let posterior = posterior_of(r);
    let q = posterior.as_ref().ok().map(|q| (q, r.seed, r.run));
    let error = held_out.map_or(
        prediction::ErrorBand::InSample,
        prediction::ErrorBand::Given,
    );
    match free_run(
        d,
        data,
        &r.theta_val,
        q,
        BAND_DRAWS,
        error,
        DiscrepancyUse::Fit(modes),
    ) {
        Ok(mut f) => {
            if let Err(e) = &posterior {
                f.band_error = Some(e.clone());
            }
            r.free_run = Some(f);
        }
        Err(e) => {
            r.modal = Some(ModalComparison {
                errors: vec![format!("free run: θ_val: {e}")],
                ..modal(d, data, &r.theta_val)
            });
            return;
        }
    }
    r.modal = Some(modal_with_intervals(
        d,
        data,
        &r.theta_val,
        posterior.as_ref().ok().map(|q| (q, r.seed, r.run)),
    ));
}

/// [`modal`] with each mode's 95 % intervals ([`modal_intervals`]) from `posterior` (the
/// record's θ distribution, seed and run) when there is one.
pub(crate) fn modal_with_intervals(
    d: &StructureDescription,
    data: &LoadedDataset,
    theta: &[f64],
    posterior: Option<(&QuantileDraw, u64, u64)>,
) -> ModalComparison {
    let mut m = modal(d, data, theta);
    if let Some((q, seed, run)) = posterior {
        let intervals = modal_intervals(d, q, seed, run, m.modes.len());
        for p in &mut m.pairs {
            if let Some(Some((f, z))) = intervals.get(p.mode - 1) {
                p.model_hz_95 = Some(*f);
                p.damping_ratio_95 = Some(*z);
            }
        }
        if shapes::comparable(d, &data.sensors) {
            shapes::intervals(&mut m.pairs, d, q, (seed, run), &data.sensors);
        }
    }
    m
}

/// The terminal table of a free run and a modal comparison (empty when neither is present).
pub fn summary(free: Option<&FreeRun>, modal: Option<&ModalComparison>) -> String {
    let mut o = String::new();
    if let Some(f) = free {
        write_free_run(&mut o, f);
    }
    if let Some(m) = modal {
        write_modal_table(&mut o, m);
        write_modal_notes(&mut o, m);
    }
    o
}

/// The free run's part of [`summary`]: the fit of every channel, the model error that widens
/// the band, and how the band was drawn (or why there is none).
fn write_free_run(o: &mut String, f: &FreeRun) {
    let _ = writeln!(
        o,
        "free run of the identified model (θ_val, from rest, driven by the measured ground \
         motion) against the measured {} accelerations:",
        f.measurement
    );
    let _ = writeln!(
        o,
        "{:<8}  {:>8}  {:>7}  {:>26}  {:>12}",
        "channel",
        "fit %",
        "NRMSE",
        format!(
            "fit of {} draws 2.5/50/97.5",
            f.band.as_ref().map_or(0, |b| b.valid)
        ),
        "band covers"
    );
    for c in &f.channels {
        let draws = match &c.fit_draws {
            Some(p) if p.len() == 3 => format!("{:.1} / {:.1} / {:.1}", p[0], p[1], p[2]),
            _ => "–".into(),
        };
        let covers = c
            .coverage_percent
            .map_or("–".to_string(), |v| format!("{v:.1} %"));
        let _ = writeln!(
            o,
            "{:<8}  {:>8.1}  {:>7.3}  {draws:>26}  {covers:>12}",
            c.channel, c.fit_percent, c.nrmse
        );
    }
    if let Some(dd) = &f.discrepancy {
        let physical: Vec<String> = f
            .channels
            .iter()
            .map(|c| {
                c.physical_fit_percent
                    .map_or("–".into(), |v| format!("{v:.1}"))
            })
            .collect();
        let _ = writeln!(
            o,
            "the fits include a discrepancy term of {} mode(s) — {} — driven by the ground \
             motion, beside the building (docs/validation.md); the building alone: {} %",
            dd.modes.len(),
            dd.describe_modes(),
            physical.join(" / ")
        );
    }
    if let Some(me) = &f.model_error {
        write_model_error(o, me);
    }
    match (&f.band, &f.band_error) {
        (Some(b), _) => {
            let _ = writeln!(
                o,
                "band: {} of {} draws valid; θ drawn from {}, inside each 95 % interval, {}{} — \
                 docs/validation.md",
                b.valid,
                b.draws,
                drawn_from(b.correlated),
                how_drawn(b.correlated, b.gaussian),
                if b.shifted { SHIFTED } else { "" }
            );
        }
        (None, Some(e)) => {
            let _ = writeln!(o, "no band: {e}");
        }
        (None, None) => {}
    }
}

/// How the model error `me` widens the predictive band, where it was learned, and why its
/// coverage on the identifying record is no independent test.
fn write_model_error(o: &mut String, me: &ModelError) {
    let _ = writeln!(
        o,
        "95 % predictive band: the parameters' spread and the model's error, learned {} \
         (|error| ≤ {} × √(m + (f·RMS)²), m the predicted motion's mean square over \
         {:.2} s, f = {}; channels in order). On the record it was learned on, its \
         coverage is not an independent test: `sysid validate` on another record gives \
         one — docs/validation.md",
        match me.source {
            ErrorSource::HeldOut { samples } =>
                format!("on the {samples} held-out samples the identification did not fit"),
            ErrorSource::InSample =>
                "in-sample on this record (narrower than a new record needs)".to_string(),
        },
        me.quantile
            .iter()
            .map(|q| format!("{q:.2}"))
            .collect::<Vec<_>>()
            .join(" / "),
        me.window_s,
        me.floor
            .iter()
            .map(|q| format!("{q:.2}"))
            .collect::<Vec<_>>()
            .join(" / "),
    );
}

/// The modal part of [`summary`]: each model mode with its 95 % interval and damping ratio
/// beside the measured peak it is paired with.
fn write_modal_table(o: &mut String, m: &ModalComparison) {
    let _ = writeln!(
        o,
        "modes of the identified model linearised at rest (Bouc–Wen at its initial tangent) \
         beside the peaks of the measured transfer functions (Welch H1, resolution {:.3} Hz):",
        m.resolution_hz
    );
    // The MAC column only where a shape could be compared (two measured floors or more).
    let with_mac = m.pairs.iter().any(|p| p.mac.is_some());
    let mut head = format!(
        "{:<5}  {:>12}  {:>18}  {:>8}  {:>18}  {:>16}  {:>10}",
        "mode", "model [Hz]", "95 % [Hz]", "ζ", "ζ 95 %", "measured [Hz]", "difference"
    );
    if with_mac {
        head += &format!("  {:>5}  {:>14}", "MAC", "MAC 95 %");
    }
    let _ = writeln!(o, "{head}");
    let span = |v: Option<[f64; 2]>, digits: usize| {
        v.map_or("–".to_string(), |[a, b]| {
            format!("[{a:.digits$}, {b:.digits$}]")
        })
    };
    for p in &m.pairs {
        let mut row = format!(
            "{:<5}  {:>12.3}  {:>18}  {:>8.4}  {:>18}  {:>16}  {:>10}",
            p.mode,
            p.model_hz,
            span(p.model_hz_95, 3),
            p.damping_ratio,
            span(p.damping_ratio_95, 4),
            measured_peak_cell(p, m.resolution_hz),
            p.difference_percent
                .map_or("–".to_string(), |d| format!("{d:+.1} %")),
        );
        if with_mac {
            row += &format!(
                "  {:>5}  {:>14}",
                p.mac.map_or("–".to_string(), |v| format!("{v:.3}")),
                span(p.mac_95, 3)
            );
        }
        let _ = writeln!(o, "{row}");
    }
}

/// The measured column of a mode's row: the paired peak's frequency, or why there is none
/// (below the resolution, not excited by the record, or no peak near).
fn measured_peak_cell(p: &ModePair, resolution_hz: f64) -> String {
    p.measured_hz.map_or(
        if p.model_hz < 2.0 * resolution_hz {
            "below resolution".to_string()
        } else if let Some(db) = p.excitation_db.filter(|db| *db < not_excited_db()) {
            format!("not excited ({db:.0} dB)")
        } else {
            "no peak near".to_string()
        },
        |f| format!("{f:.3}"),
    )
}

/// Which intervals the band's θ were drawn from, for its method and the summary
/// ([`posterior_of`]).
fn drawn_from(correlated: bool) -> &'static str {
    if correlated {
        "the filter's posterior (its own credible intervals, before any widening by the spread \
         between the record's parts)"
    } else {
        "the record's credible intervals"
    }
}

/// What a band on another record adds to each drawn θ ([`shifted_to_another`]), for its
/// method and the summary.
const SHIFTED: &str = ", then each shifted to another record's θ by the spread between the \
     identifying record's parts where they disagree (τ times Student's t on parts − 2 degrees of \
     freedom, kept physical)";

/// How the band's θ were drawn, for its method and the summary: from the one Gaussian filter's
/// posterior itself, or through the copula of the record's quantiles
/// ([`free_run::QuantileDraw`]).
fn how_drawn(correlated: bool, gaussian: bool) -> &'static str {
    match (correlated, gaussian) {
        (_, true) => {
            "parameters drawn jointly from the one Gaussian filter's posterior N(θ_val, Σ) \
             itself (its 95 % intervals hold k, c and α ≥ 0)"
        }
        (true, false) => {
            "parameters drawn jointly with the posterior's correlations (a Gaussian copula)"
        }
        (false, false) => {
            "parameters drawn independently (the record keeps no usable correlation matrix)"
        }
    }
}

/// The notes under the modal table: what its intervals and "not excited" mean, modes that are
/// not physical or not resonant, measured peaks without a mode, and what was not computed.
fn write_modal_notes(o: &mut String, m: &ModalComparison) {
    if m.pairs.iter().any(|p| p.model_hz_95.is_some()) {
        let _ = writeln!(
            o,
            "95 %: the central 95 % of each mode over {MODAL_DRAWS} θ drawn from the filter's \
             posterior, with its correlations where the record keeps them, and never shifted \
             as the band's θ are on another record: its statistical uncertainty, without the \
             model's error — docs/validation.md"
        );
    }
    let unlike: Vec<String> = m
        .pairs
        .iter()
        .filter_map(|p| {
            p.mac
                .filter(|v| *v < shapes::UNLIKE_MAC)
                .map(|v| format!("mode {} (MAC {v:.3})", p.mode))
        })
        .collect();
    if !unlike.is_empty() {
        let _ = writeln!(
            o,
            "not the same shape: {} — less than half of the measured shape lies along the \
             model's (MAC < {}), so the peak it is paired with by frequency is not that mode",
            unlike.join(", "),
            shapes::UNLIKE_MAC
        );
    }
    if m.pairs.iter().any(|p| p.mac.is_some()) {
        let _ = writeln!(
            o,
            "MAC: (φᵀψ)²/(φᵀφ·ψᵀψ) between the model's undamped mode shape φ on the measured \
             floors and the measured operating shape ψ = Im H1 at the paired peak (quadrature \
             picking; 1: the same shape); its 95 % over {} θ drawn as above, the measured ψ held \
             fixed — docs/validation.md",
            shapes::SHAPE_DRAWS
        );
    }
    if m.pairs
        .iter()
        .any(|p| p.measured_hz.is_none() && p.excitation_db.is_some_and(|db| db < not_excited_db()))
    {
        let _ = writeln!(
            o,
            "not excited: the record's ground motion near that mode is more than {:.0} dB \
             below its strongest frequency, so the record cannot show it (a sine or a narrow \
             band excites only its own frequencies); its measured peaks there are bumps of \
             the input's spectrum",
            -not_excited_db()
        );
    }
    if m.pairs.iter().any(|p| p.damping_ratio < 0.0) {
        let _ = writeln!(
            o,
            "a negative ζ: that mode of the identified model grows (a negative damping): \
             not a physical model"
        );
    }
    if m.overdamped > 0 {
        let _ = writeln!(
            o,
            "{} over-damped mode(s) of the model (no resonance)",
            m.overdamped
        );
    }
    let unpaired: Vec<String> = m
        .peaks
        .iter()
        .filter(|p| {
            !m.pairs
                .iter()
                .any(|q| q.measured_hz == Some(p.frequency_hz))
        })
        .map(|p| format!("{:.3}", p.frequency_hz))
        .collect();
    if !unpaired.is_empty() {
        let _ = writeln!(
            o,
            "measured peaks without a model mode: {} Hz",
            unpaired.join(", ")
        );
    }
    for e in &m.errors {
        let _ = writeln!(o, "not computed: {e}");
    }
}
