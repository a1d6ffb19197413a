//! Progress of a sweep on stderr: a bar in a terminal; elsewhere (a log file, CI, a batch job)
//! one plain line every 10 s or every 5% of the runs, whichever comes first.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// Seconds between two plain progress lines at most (when runs finish often enough).
const LINE_EVERY: Duration = Duration::from_secs(10);

/// How progress is shown.
enum Mode {
    Hidden,
    Bar(ProgressBar),
    Lines { last: Mutex<(Instant, usize)> },
}

/// Progress of the runs a sweep executes.
pub struct Progress {
    label: String,
    total: usize,
    done: AtomicUsize,
    failed: AtomicUsize,
    start: Instant,
    mode: Mode,
}

impl Progress {
    /// Progress of `total` runs; `show = false` shows nothing.
    pub fn new(label: &str, total: usize, show: bool) -> Self {
        let start = Instant::now();
        let mode = if !show || total == 0 {
            Mode::Hidden
        } else if std::io::stderr().is_terminal() {
            let bar = ProgressBar::new(total as u64);
            bar.set_style(
                ProgressStyle::with_template(
                    "{prefix:>12} [{bar:30}] {pos}/{len} runs, {elapsed} elapsed, ETA {eta} {msg}",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar.set_prefix(label.to_string());
            Mode::Bar(bar)
        } else {
            Mode::Lines {
                last: Mutex::new((start, 0)),
            }
        };
        Self {
            label: label.to_string(),
            total,
            done: AtomicUsize::new(0),
            failed: AtomicUsize::new(0),
            start,
            mode,
        }
    }

    /// One run finished.
    pub(crate) fn inc(&self, failed: bool) {
        let done = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        let failures = if failed {
            self.failed.fetch_add(1, Ordering::Relaxed) + 1
        } else {
            self.failed.load(Ordering::Relaxed)
        };
        match &self.mode {
            Mode::Hidden => {}
            Mode::Bar(bar) => {
                bar.inc(1);
                if failed {
                    bar.set_message(format!("{failures} failed"));
                }
            }
            Mode::Lines { last } => {
                let step = self.total.div_ceil(20).max(1);
                let mut last = last.lock().unwrap_or_else(|e| e.into_inner());
                let now = Instant::now();
                let due = now.duration_since(last.0) >= LINE_EVERY
                    || done / step > last.1 / step
                    || done == self.total;
                if due {
                    *last = (now, done);
                    log::info!("{}", self.line(done, failures));
                }
            }
        }
    }

    fn line(&self, done: usize, failures: usize) -> String {
        let elapsed = self.start.elapsed();
        let eta = if done > 0 && done < self.total {
            let per = elapsed.as_secs_f64() / done as f64;
            format!(
                ", ETA {}",
                clock(Duration::from_secs_f64(per * (self.total - done) as f64))
            )
        } else {
            String::new()
        };
        format!(
            "{}: {done}/{} runs ({:.0}%), {failures} failed, {} elapsed{eta}",
            self.label,
            self.total,
            100.0 * done as f64 / self.total.max(1) as f64,
            clock(elapsed)
        )
    }

    /// Removes the bar (the caller prints the summary).
    pub fn finish(&self) {
        if let Mode::Bar(bar) = &self.mode {
            bar.finish_and_clear();
        }
    }
}

/// `1h 02m 03s`, `2m 03s` or `3.4 s`.
pub fn clock(d: Duration) -> String {
    let s = d.as_secs();
    match s {
        0..60 => format!("{:.1} s", d.as_secs_f64()),
        60..3600 => format!("{}m {:02}s", s / 60, s % 60),
        _ => format!("{}h {:02}m {:02}s", s / 3600, s / 60 % 60, s % 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_format() {
        assert_eq!(clock(Duration::from_millis(3400)), "3.4 s");
        assert_eq!(clock(Duration::from_secs(123)), "2m 03s");
        assert_eq!(clock(Duration::from_secs(3723)), "1h 02m 03s");
    }

    #[test]
    fn plain_line_names_study_counts_and_eta() {
        let p = Progress::new("fig7", 200, false);
        let l = p.line(40, 2);
        assert!(l.starts_with("fig7: 40/200 runs (20%), 2 failed,"), "{l}");
        assert!(l.contains("ETA"), "{l}");
    }
}
