//! Putting real channels on one time grid: what a real record brings and how each thing is
//! repaired, or refused when a repair would invent data.
//!
//! In order, per channel: leading rows of zeros dropped (a logger's row before its first
//! sample); gaps in the time stamps up to `max_gap` filled by linear interpolation, longer ones
//! refused; then every storey channel is matched to the ground's samples *by time stamp* —
//! shifted by whole samples when its clock ticks with the ground's, resampled by linear
//! interpolation when it does not — and refused when its clock does not overlap the ground's;
//! then all channels are trimmed to the span they share, and the mean (gravity or an offset in
//! the axis) and, if asked, a straight line (drift) are removed. Every step that changes data
//! is logged as a [`Repair`].

use super::channel_map::{Align, Options, Role};
use super::ImportError;
use crate::limits;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// One channel as read: time stamps of its clock (s) and values in m/s², with the 1-based line
/// of each row.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Recorded {
    pub role: Role,
    pub file: PathBuf,
    pub times: Vec<f64>,
    pub values: Vec<f64>,
    pub lines: Vec<usize>,
}

impl Recorded {
    pub(crate) fn name(&self) -> String {
        format!("{} ({})", self.role, self.file.display())
    }
}

/// One change the import made to the data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Repair {
    /// `ground (file)` or `storey 2 (file)`, or `all` for what applies to every channel.
    pub channel: String,
    pub action: String,
}

/// The channels on the ground's time grid.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Aligned {
    pub dt: f64,
    /// The ground clock's time of the first kept sample (s): the origin of `t`.
    pub t0: f64,
    pub ug: Vec<f64>,
    /// Per storey channel, in the order given.
    pub storeys: Vec<Vec<f64>>,
    pub repairs: Vec<Repair>,
    pub warnings: Vec<String>,
}

fn refuse(c: &Recorded, line: usize, message: String) -> ImportError {
    ImportError::Refused {
        file: c.file.clone(),
        line,
        channel: c.role.to_string(),
        message,
    }
}

/// Largest relative difference between a storey clock's sample interval and the ground's that is
/// resampled (1 %): a logger's clock drifts by parts per million, so a larger difference is
/// another sampling rate or a time unit misread, which interpolation would only hide.
pub(crate) const MAX_RATE_DIFFERENCE: f64 = 0.01;

/// Smallest share of the longest channel's samples that the span all channels share must keep
/// (one half): a channel much shorter than the others is an export cut short, not a clock
/// offset, and trimming every channel to it would throw the record away.
pub(crate) const MIN_KEPT_SHARE: f64 = 0.5;

fn ms(s: f64) -> String {
    format!("{:.3} ms", s * 1e3)
}

/// Drops the leading rows whose value is exactly 0.
fn drop_leading_zeros(c: &mut Recorded, log: &mut Vec<Repair>) -> Result<(), ImportError> {
    let n = c.values.iter().take_while(|&&v| v == 0.0).count();
    if n == 0 {
        return Ok(());
    }
    if n + 2 > c.values.len() {
        return Err(refuse(
            c,
            c.lines[0],
            format!(
                "{n} of its {} samples are leading zeros: nothing was recorded",
                c.values.len()
            ),
        ));
    }
    log.push(Repair {
        channel: c.name(),
        action: format!(
            "dropped {n} leading row{} of zeros (line {}{})",
            if n == 1 { "" } else { "s" },
            c.lines[0],
            if n > 1 {
                format!("–{}", c.lines[n - 1])
            } else {
                String::new()
            }
        ),
    });
    c.times.drain(..n);
    c.values.drain(..n);
    c.lines.drain(..n);
    Ok(())
}

/// The median step of a clock.
fn median_step(times: &[f64]) -> f64 {
    let mut d: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// Fills gaps up to `max_gap` by linear interpolation; refuses a longer gap or a step that is
/// not a whole number of samples.
fn fill_gaps(c: &mut Recorded, max_gap: f64, log: &mut Vec<Repair>) -> Result<(), ImportError> {
    let step = median_step(&c.times);
    limits::check_dt(step)
        .map_err(|e| refuse(c, c.lines[1], format!("its usual time step: {e} (s)")))?;
    let mut missing_total = 0usize;
    let mut gaps = Vec::new();
    for k in 1..c.times.len() {
        let d = c.times[k] - c.times[k - 1];
        if d < 0.5 * step {
            return Err(refuse(
                c,
                c.lines[k],
                format!(
                    "time step {} against its usual {}: irregular sampling is not repaired",
                    ms(d),
                    ms(step)
                ),
            ));
        }
        if d > 1.5 * step {
            let missing = (d / step).round() as usize - 1;
            let gap = d - step;
            if gap > max_gap {
                return Err(refuse(
                    c,
                    c.lines[k],
                    format!(
                        "a gap of {} ({missing} samples missing) before this row, longer than \
                         max_gap = {} s: not interpolated (cut the record, or raise \
                         [options] max_gap if interpolating it is acceptable)",
                        ms(gap),
                        max_gap
                    ),
                ));
            }
            missing_total += missing;
            gaps.push((k, missing, gap));
        }
    }
    if gaps.is_empty() {
        return Ok(());
    }
    limits::check_count(c.times.len() + missing_total, 0, limits::MAX_SAMPLES).map_err(|e| {
        refuse(
            c,
            c.lines[gaps[0].0],
            format!("filling its gaps: {e} samples"),
        )
    })?;
    let (mut t, mut v, mut l) = (
        Vec::with_capacity(c.times.len() + missing_total),
        Vec::with_capacity(c.times.len() + missing_total),
        Vec::with_capacity(c.times.len() + missing_total),
    );
    let mut next = gaps.iter().peekable();
    for k in 0..c.times.len() {
        if let Some(&&(gk, missing, _)) = next.peek() {
            if gk == k {
                next.next();
                let (t0, t1, v0, v1) = (c.times[k - 1], c.times[k], c.values[k - 1], c.values[k]);
                for j in 1..=missing {
                    let f = j as f64 / (missing + 1) as f64;
                    t.push(t0 + f * (t1 - t0));
                    v.push(v0 + f * (v1 - v0));
                    l.push(c.lines[k]);
                }
            }
        }
        t.push(c.times[k]);
        v.push(c.values[k]);
        l.push(c.lines[k]);
    }
    for (k, missing, gap) in gaps {
        log.push(Repair {
            channel: c.name(),
            action: format!(
                "filled a gap of {} ({missing} sample{}) before line {} by linear interpolation",
                ms(gap),
                if missing == 1 { "" } else { "s" },
                c.lines[k]
            ),
        });
    }
    c.times = t;
    c.values = v;
    c.lines = l;
    Ok(())
}

/// A channel on the ground's grid: `values[i]` is at grid index `first + i`.
struct OnGrid {
    first: usize,
    values: Vec<f64>,
}

/// Matches a storey channel to the ground grid `t0 + k·dt`, `k < n`, by its time stamps.
fn to_grid(
    c: &Recorded,
    t0: f64,
    dt: f64,
    n: usize,
    opts: &Options,
    log: &mut Vec<Repair>,
) -> Result<OnGrid, ImportError> {
    check_clocks_overlap(c, t0, dt, n, opts)?;
    let step = check_sampling_rate(c, dt)?;
    let first = c.times[0];
    let start_offset = first - t0;
    let shift = start_offset / dt;
    let same_rate = (step - dt).abs() <= 1e-4 * dt;
    // Whole samples apart (within `clock_tolerance` of a sample) and ticking together: a
    // shift moves no value between samples.
    let tol = opts.clock_tolerance;
    let jitter_ok = c
        .times
        .iter()
        .enumerate()
        .all(|(i, &t)| (t - (first + i as f64 * dt)).abs() <= tol * dt);
    if same_rate && (shift - shift.round()).abs() <= tol && jitter_ok {
        return shift_whole_samples(c, shift.round() as i64, start_offset, tol, log);
    }
    // A clock at the ground's rate to a hundredth of a sample over the whole record: one
    // shift holds for every sample.
    let drift = (step / dt - 1.0).abs() * c.times.len() as f64;
    if same_rate && jitter_ok && drift <= 0.01 {
        return shift_band_limited(c, shift, start_offset, log);
    }
    resample_linear(c, t0, dt, n, step, log)
}

/// Refuses a channel whose clock starts more than `max_clock_offset` from the ground's, or
/// overlaps it for less than half the shorter record: pairing its rows with the ground's
/// would pair samples that were not simultaneous.
fn check_clocks_overlap(
    c: &Recorded,
    t0: f64,
    dt: f64,
    n: usize,
    opts: &Options,
) -> Result<(), ImportError> {
    let (first, last) = (c.times[0], c.times[c.times.len() - 1]);
    let g_last = t0 + (n - 1) as f64 * dt;
    let start_offset = first - t0;
    let overlap = last.min(g_last) - first.max(t0);
    let shorter = (last - first).min(g_last - t0);
    if start_offset.abs() > opts.max_clock_offset || overlap < 0.5 * shorter {
        return Err(refuse(
            c,
            c.lines[0],
            format!(
                "its time stamps ({:.6}–{:.6} s) and the ground's ({:.6}–{:.6} s) start {:.6} s \
                 apart{}: the clocks disagree, and matching rows by number would pair samples \
                 that were not simultaneous. If the files' first rows are simultaneous, set \
                 [options] align = \"start\"; if the offset is known, give this channel \
                 `offset` (s); max_clock_offset = {} s",
                first,
                last,
                t0,
                g_last,
                start_offset,
                if overlap <= 0.0 {
                    " and do not overlap".to_string()
                } else {
                    format!(" and overlap for {overlap:.3} s")
                },
                opts.max_clock_offset
            ),
        ));
    }
    Ok(())
}

/// The channel's mean sample spacing (s), refused when it is another sampling rate than the
/// ground's `dt` (beyond the clock difference [`MAX_RATE_DIFFERENCE`]): that is not resampled.
fn check_sampling_rate(c: &Recorded, dt: f64) -> Result<f64, ImportError> {
    let (first, last) = (c.times[0], c.times[c.times.len() - 1]);
    let step = (last - first) / (c.times.len() - 1) as f64;
    if (step / dt - 1.0).abs() > MAX_RATE_DIFFERENCE {
        return Err(refuse(
            c,
            c.lines[0],
            format!(
                "its samples are {step:.6} s apart on average, the ground's {dt:.6} s ({:+.1} %): \
                 another sampling rate (or a misread time unit) is not resampled; give channels \
                 recorded at one rate (clocks may differ by at most {} %)",
                (step / dt - 1.0) * 100.0,
                MAX_RATE_DIFFERENCE * 100.0
            ),
        ));
    }
    Ok(step)
}

/// A channel ticking with the ground's clock and `s` whole samples after it (before, when
/// negative; within `tol` of a sample): its values as they are, from grid index `s`, those
/// before the ground's first sample dropped; the shift logged.
fn shift_whole_samples(
    c: &Recorded,
    s: i64,
    start_offset: f64,
    tol: f64,
    log: &mut Vec<Repair>,
) -> Result<OnGrid, ImportError> {
    let mut values = c.values.clone();
    let mut before = String::new();
    let first_index = if s >= 0 {
        s as usize
    } else {
        let drop = (-s) as usize;
        if drop >= values.len() {
            return Err(refuse(
                c,
                c.lines[0],
                "no sample in the ground's span".into(),
            ));
        }
        values.drain(..drop);
        before = format!(
            "; its {drop} sample{} before the ground's first {} not used",
            if drop == 1 { "" } else { "s" },
            if drop == 1 { "is" } else { "are" }
        );
        0
    };
    if s == 0 && start_offset != 0.0 {
        log.push(Repair {
            channel: c.name(),
            action: format!(
                "its clock starts {} {} the ground's, within clock_tolerance = {tol} of a \
                 sample: rows paired by time stamp without interpolation",
                ms(start_offset.abs()),
                if start_offset > 0.0 {
                    "after"
                } else {
                    "before"
                },
            ),
        });
    }
    if s != 0 {
        log.push(Repair {
            channel: c.name(),
            action: format!(
                "its clock starts {} {} the ground's: matched by time stamp, shifted by {} \
                 sample{} against row numbers{before}",
                ms(start_offset.abs()),
                if s > 0 { "after" } else { "before" },
                s.abs(),
                if s.abs() == 1 { "" } else { "s" }
            ),
        });
    }
    // Samples beyond the ground's last one stay: the common span below trims them, and
    // says so.
    Ok(OnGrid {
        first: first_index,
        values,
    })
}

/// Resample: linear interpolation at the grid times inside the channel's span, for a clock
/// that does not tick with the ground's (`step`, its mean sample spacing); logged with the
/// clocks' offset and rates and the samples left outside the ground's span.
fn resample_linear(
    c: &Recorded,
    t0: f64,
    dt: f64,
    n: usize,
    step: f64,
    log: &mut Vec<Repair>,
) -> Result<OnGrid, ImportError> {
    let (first, last) = (c.times[0], c.times[c.times.len() - 1]);
    let start_offset = first - t0;
    let k0 = ((first - t0) / dt).ceil().max(0.0) as usize;
    let k1 = (((last - t0) / dt).floor() as i64).min(n as i64 - 1);
    if k1 < k0 as i64 + 1 {
        return Err(refuse(
            c,
            c.lines[0],
            "fewer than 2 samples in the ground's span".into(),
        ));
    }
    let k1 = k1 as usize;
    let g_end = t0 + k1 as f64 * dt;
    let g_start = t0 + k0 as f64 * dt;
    let outside = c
        .times
        .iter()
        .filter(|&&t| t < g_start || t > g_end)
        .count();
    let mut values = Vec::with_capacity(k1 - k0 + 1);
    let mut j = 0usize;
    for k in k0..=k1 {
        let t = t0 + k as f64 * dt;
        while j + 2 < c.times.len() && c.times[j + 1] < t {
            j += 1;
        }
        let (ta, tb) = (c.times[j], c.times[j + 1]);
        let f = ((t - ta) / (tb - ta)).clamp(0.0, 1.0);
        values.push(c.values[j] + f * (c.values[j + 1] - c.values[j]));
    }
    log.push(Repair {
        channel: c.name(),
        action: format!(
            "resampled onto the ground's samples by linear interpolation at their time stamps: \
             its clock starts {} {} the ground's and ticks every {:.3} µs against the ground's \
             {:.3} µs ({:+.1} ppm){}",
            ms(start_offset.abs()),
            if start_offset >= 0.0 {
                "after"
            } else {
                "before"
            },
            step * 1e6,
            dt * 1e6,
            (step / dt - 1.0) * 1e6,
            if outside > 0 {
                format!("; {outside} of its samples lie outside the ground's span and are not used")
            } else {
                String::new()
            }
        ),
    });
    Ok(OnGrid { first: k0, values })
}

/// A channel on the ground's sampling rate whose clock starts `shift` samples (not whole)
/// after the ground's: its values at the ground's sample times by a band-limited shift
/// ([`super::delay::advance`]). Linear interpolation would lower a mode's amplitude — by 16 %
/// at 22 Hz sampled at 120 Hz and half a sample — as a low-pass filter does.
fn shift_band_limited(
    c: &Recorded,
    shift: f64,
    start_offset: f64,
    log: &mut Vec<Repair>,
) -> Result<OnGrid, ImportError> {
    // The ground's sample `first + m` lies `frac` samples after the channel's sample `m`.
    let first = shift.ceil();
    let frac = first - shift;
    let mut values = super::delay::advance(&c.values, frac);
    // The last value would need a sample after the channel's last.
    values.pop();
    let (first_index, before) = if first >= 0.0 {
        (first as usize, 0)
    } else {
        let drop = (-first) as usize;
        if drop + 2 > values.len() {
            return Err(refuse(
                c,
                c.lines[0],
                "fewer than 2 samples in the ground's span".into(),
            ));
        }
        values.drain(..drop);
        (0, drop)
    };
    log.push(Repair {
        channel: c.name(),
        action: format!(
            "resampled onto the ground's samples by a band-limited shift of {frac:.3} sample: \
             its clock starts {} {} the ground's, at the ground's rate{}",
            ms(start_offset.abs()),
            if start_offset >= 0.0 {
                "after"
            } else {
                "before"
            },
            if before > 0 {
                format!("; its {before} samples before the ground's first are not used")
            } else {
                String::new()
            }
        ),
    });
    Ok(OnGrid {
        first: first_index,
        values,
    })
}

/// Refuses a channel whose kept samples are all the same value (a stuck sensor, or a column
/// that holds no motion): after the mean is removed it would read as a structure or ground at
/// rest, silently. `line` is the channel's first kept line.
fn refuse_stuck(c: &Recorded, line: usize, kept: &[f64]) -> Result<(), ImportError> {
    match kept.first() {
        Some(&v) if kept.len() > 1 && kept.iter().all(|&x| x == v) => Err(refuse(
            c,
            line,
            format!(
                "every one of its {} kept samples is {v}: the channel is stuck (a constant \
                 signal records no motion); check the sensor and the map's column",
                kept.len()
            ),
        )),
        _ => Ok(()),
    }
}

/// Subtracts the mean and, with `detrend`, the least-squares line; logs both.
fn remove_offsets(values: &mut [f64], name: &str, opts: &Options, out: &mut Aligned) {
    let n = values.len() as f64;
    if opts.remove_mean {
        let mean = values.iter().sum::<f64>() / n;
        values.iter_mut().for_each(|v| *v -= mean);
        out.repairs.push(Repair {
            channel: name.to_string(),
            action: format!(
                "removed its mean {} m/s2 (gravity or an offset in the axis)",
                if mean.abs() >= 1e-3 {
                    format!("{mean:.6}")
                } else {
                    format!("{mean:.3e}")
                }
            ),
        });
        if mean.abs() > 0.3 * crate::excitation::G {
            out.warnings.push(format!(
                "{name}: its mean was {mean:.3} m/s2, a large part of g: this axis carries \
                 gravity, so the sensor is tilted or the axis is not horizontal; check the \
                 column"
            ));
        }
    }
    if opts.detrend {
        // Least squares on x = i − (n−1)/2, where Σx = 0.
        let c = (n - 1.0) / 2.0;
        let (sxy, sxx, sy) = values
            .iter()
            .enumerate()
            .fold((0.0, 0.0, 0.0), |a, (i, &v)| {
                let x = i as f64 - c;
                (a.0 + x * v, a.1 + x * x, a.2 + v)
            });
        let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
        let intercept = sy / n;
        for (i, v) in values.iter_mut().enumerate() {
            *v -= intercept + slope * (i as f64 - c);
        }
        out.repairs.push(Repair {
            channel: name.to_string(),
            action: format!("removed a linear drift of {:.3e} m/s2 per sample", slope),
        });
    }
}

/// Puts the ground and storey channels on the ground's grid; see the module documentation.
pub(crate) fn align(
    mut ground: Recorded,
    mut storeys: Vec<Recorded>,
    opts: &Options,
) -> Result<Aligned, ImportError> {
    let mut out = Aligned {
        dt: 0.0,
        t0: 0.0,
        ug: Vec::new(),
        storeys: Vec::new(),
        repairs: Vec::new(),
        warnings: Vec::new(),
    };
    if opts.align == Align::Start {
        align_starts(&ground, &mut storeys, &mut out.repairs);
    }
    for c in std::iter::once(&mut ground).chain(storeys.iter_mut()) {
        if opts.drop_leading_zeros {
            drop_leading_zeros(c, &mut out.repairs)?;
        }
        fill_gaps(c, opts.max_gap, &mut out.repairs)?;
    }
    let (n, t0, dt) = ground_grid(&ground)?;
    let mut grids = Vec::with_capacity(storeys.len());
    for c in &storeys {
        grids.push(to_grid(c, t0, dt, n, opts, &mut out.repairs)?);
    }
    let span = common_span(&ground, &storeys, &grids, n)?;
    let (lo, hi) = (span.lo, span.hi);
    log_different_spans(&span, t0, dt, &mut out.repairs);
    span.log_trim(ground.name(), 0, n, &mut out.repairs);
    let mut ug = ground.values[lo..hi].to_vec();
    refuse_stuck(&ground, ground.lines[lo], &ug)?;
    let gname = ground.name();
    remove_offsets(&mut ug, &gname, opts, &mut out);
    for (c, g) in storeys.iter().zip(&grids) {
        span.log_trim(c.name(), g.first, g.values.len(), &mut out.repairs);
        let mut v = g.values[lo - g.first..hi - g.first].to_vec();
        refuse_stuck(c, c.lines[0], &v)?;
        remove_offsets(&mut v, &c.name(), opts, &mut out);
        out.storeys.push(v);
    }
    check_values_within_limits(gname, &ug, &storeys, &out.storeys)?;
    out.ug = ug;
    out.dt = dt;
    out.t0 = t0 + lo as f64 * dt;
    Ok(out)
}

/// `align = "start"`: moves each storey channel's clock so that its first row is simultaneous
/// with the ground's, and logs it as the assumption it is.
fn align_starts(ground: &Recorded, storeys: &mut [Recorded], repairs: &mut Vec<Repair>) {
    let g0 = ground.times[0];
    for c in storeys {
        let d = c.times[0] - g0;
        if d != 0.0 {
            c.times.iter_mut().for_each(|t| *t -= d);
            repairs.push(Repair {
                channel: c.name(),
                action: format!(
                    "its clock moved by {:.6} s so that its first row is simultaneous with \
                     the ground's (align = \"start\": an assumption, not a measurement)",
                    -d
                ),
            });
        }
    }
}

/// The ground's grid: its sample count, first time stamp and mean time step (s), the step
/// within limits.
fn ground_grid(ground: &Recorded) -> Result<(usize, f64, f64), ImportError> {
    let n = ground.times.len();
    let t0 = ground.times[0];
    let dt = (ground.times[n - 1] - t0) / (n - 1) as f64;
    limits::check_dt(dt)
        .map_err(|e| refuse(ground, ground.lines[n - 1], format!("time step: {e} (s)")))?;
    Ok((n, t0, dt))
}

/// The span of the ground's grid every channel covers, `lo..hi`, with the length each channel
/// covers (the ground's first).
struct CommonSpan {
    lo: usize,
    hi: usize,
    lengths: Vec<usize>,
}

impl CommonSpan {
    /// Logs what trimming the channel `name` (on the grid from `first`, `len` samples) to the
    /// common span drops, if anything.
    fn log_trim(&self, name: String, first: usize, len: usize, repairs: &mut Vec<Repair>) {
        let (a, b) = (self.lo - first, first + len - self.hi);
        if a + b > 0 {
            repairs.push(Repair {
                channel: name,
                action: format!(
                    "trimmed to the span all channels share: {a} sample{} dropped at the start, \
                     {b} at the end",
                    if a == 1 { "" } else { "s" }
                ),
            });
        }
    }
}

/// The span every channel covers (`n`, the ground's sample count); refused when there is none,
/// or when it keeps less than [`MIN_KEPT_SHARE`] of the longest channel (a file cut short).
fn common_span(
    ground: &Recorded,
    storeys: &[Recorded],
    grids: &[OnGrid],
    n: usize,
) -> Result<CommonSpan, ImportError> {
    let lo = grids.iter().map(|g| g.first).max().unwrap_or(0);
    let hi = grids
        .iter()
        .map(|g| g.first + g.values.len())
        .min()
        .unwrap_or(n)
        .min(n);
    if hi < lo + 2 {
        return Err(ImportError::NoCommonSpan {
            channels: std::iter::once(ground)
                .chain(storeys)
                .map(Recorded::name)
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    let lengths: Vec<usize> = std::iter::once(n)
        .chain(grids.iter().map(|g| g.values.len()))
        .collect();
    let longest = lengths.iter().copied().max().unwrap_or(n);
    if ((hi - lo) as f64) < MIN_KEPT_SHARE * longest as f64 {
        // The channel that covers least of the ground's grid.
        let (c, len) = std::iter::once((ground, n))
            .chain(storeys.iter().zip(grids.iter().map(|g| g.values.len())))
            .min_by_key(|&(_, len)| len)
            .expect("the ground at least");
        return Err(refuse(
            c,
            c.lines[0],
            format!(
                "covers {len} of the ground's samples, the longest channel {longest}: the span \
                 all channels share keeps {} samples, less than {:.0} % of the record; a file \
                 cut short? (trim the longer files to the common span if that is meant)",
                hi - lo,
                MIN_KEPT_SHARE * 100.0
            ),
        ));
    }
    Ok(CommonSpan { lo, hi, lengths })
}

/// Logs, for all channels, that they cover different spans of the ground's grid (`t0`, `dt`)
/// and which span is kept — when they do.
fn log_different_spans(span: &CommonSpan, t0: f64, dt: f64, repairs: &mut Vec<Repair>) {
    let (lo, hi, lengths) = (span.lo, span.hi, &span.lengths);
    if lengths.iter().any(|&l| l != lengths[0]) {
        repairs.push(Repair {
            channel: "all".into(),
            action: format!(
                "the channels cover different spans of the ground's grid ({} samples); kept \
                 the {} samples all of them cover, t = {:.6}–{:.6} s of the ground's clock",
                lengths
                    .iter()
                    .map(|l| l.to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
                hi - lo,
                t0 + lo as f64 * dt,
                t0 + (hi - 1) as f64 * dt
            ),
        });
    }
}

/// Refuses a channel with a value beyond the limit on data values after conversion: the ground
/// (`gname`, `ug`) first, then the storey channels (their `values`) in order.
fn check_values_within_limits(
    gname: String,
    ug: &[f64],
    storeys: &[Recorded],
    values: &[Vec<f64>],
) -> Result<(), ImportError> {
    for (name, v) in std::iter::once((gname, ug)).chain(
        storeys
            .iter()
            .map(Recorded::name)
            .zip(values.iter().map(|v| &v[..])),
    ) {
        if let Some(x) = v.iter().find(|x| limits::check_value(**x).is_err()) {
            return Err(ImportError::Value {
                channel: name,
                message: format!(
                    "{} after conversion is beyond the limit ±{} m/s2 on data values",
                    limits::num(*x),
                    limits::num(limits::MAX_ABS_VALUE)
                ),
            });
        }
    }
    Ok(())
}
