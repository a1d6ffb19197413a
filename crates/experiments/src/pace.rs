//! The pace of a long filter run, measured while it runs: where no progress bar is drawn (a log
//! file, a batch job), `sysid filter` says after 10 s, and every minute after, how far it is and
//! how long the whole record will take at the pace so far. A large structure costs far more per
//! step than the paper's (MPF-EKF2 with 4 particles: 0.5 s for 1 s of record at 20 storeys,
//! 10 s at 80, about 90 s at 200; docs/guarantees.md), so a user learns the cost of a run from
//! the run itself instead of waiting without word.

use std::time::Instant;

/// Wall time before the first report, and between reports (s).
const FIRST_REPORT_S: f64 = 10.0;
const REPORT_EVERY_S: f64 = 60.0;

/// The pace of one run: `total` filter steps (steps × pooled filters) over `record_s` seconds
/// of record, timed from its creation.
#[derive(Debug)]
pub(crate) struct Pace {
    label: String,
    total: usize,
    record_s: f64,
    started: Instant,
    next_report_s: f64,
}

impl Pace {
    pub fn new(label: &str, total: usize, record_s: f64) -> Self {
        Self {
            label: label.to_string(),
            total,
            record_s,
            started: Instant::now(),
            // Reports fall at 10 s, 70 s, 130 s, … of the run.
            next_report_s: FIRST_REPORT_S,
        }
    }

    /// After `done` of the run's steps (counted over every pooled filter): a report when due.
    pub fn step(&mut self, done: usize) {
        let elapsed = self.started.elapsed().as_secs_f64();
        if elapsed < self.next_report_s || done == 0 || done >= self.total {
            return;
        }
        self.next_report_s = next_report_after(elapsed);
        log::info!(
            "{}",
            report(&self.label, done, self.total, self.record_s, elapsed)
        );
    }
}

/// The first report time (10 s, 70 s, 130 s, …) after `elapsed`.
fn next_report_after(elapsed: f64) -> f64 {
    if elapsed < FIRST_REPORT_S {
        FIRST_REPORT_S
    } else {
        FIRST_REPORT_S
            + ((elapsed - FIRST_REPORT_S) / REPORT_EVERY_S).floor() * REPORT_EVERY_S
            + REPORT_EVERY_S
    }
}

/// The words of a report: steps done, the expected whole and the cost per second of record.
pub fn report(label: &str, done: usize, total: usize, record_s: f64, elapsed: f64) -> String {
    let whole = elapsed / done as f64 * total as f64;
    format!(
        "{label}: {done} of {total} steps in {elapsed:.0} s; at this pace the run takes about \
         {whole:.0} s ({:.1} s of computation per second of record, {:.0} s left)",
        whole / record_s,
        whole - elapsed
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_extrapolates_the_pace_so_far() {
        // 20 of 200 steps over 1 s of record in 9 s: 0.45 s per step, 90 s per second of record.
        let r = report("mpf-ekf2", 20, 200, 1.0, 9.0);
        assert!(r.contains("about 90 s"), "{r}");
        assert!(
            r.contains("90.0 s of computation per second of record"),
            "{r}"
        );
        assert!(r.contains("81 s left"), "{r}");
        assert_eq!(next_report_after(0.0), 10.0);
        assert_eq!(next_report_after(10.0), 70.0);
        assert_eq!(next_report_after(12.0), 70.0);
        assert_eq!(next_report_after(71.0), 130.0);
    }
}
