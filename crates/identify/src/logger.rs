//! The logger of the binaries (`sysid`, `xtask`).

use std::io::Write;
use std::sync::Mutex;

/// Where the records go instead of stderr while a [`Diverted`] guard lives.
static DIVERTED: Mutex<Option<Box<dyn Write + Send>>> = Mutex::new(None);

/// While alive, the installed logger writes every record to the writer given to [`divert`]
/// instead of stderr (a command run as a step of a study writes into the step's log file,
/// whichever thread logs); dropped, records go to stderr again.
#[must_use = "the records go back to stderr when the guard is dropped"]
pub struct Diverted(());

/// Sends the installed logger's records to `to` until the guard is dropped. One diversion at a
/// time: a second one replaces the first.
pub fn divert(to: Box<dyn Write + Send>) -> Diverted {
    *DIVERTED.lock().unwrap_or_else(|e| e.into_inner()) = Some(to);
    Diverted(())
}

impl Drop for Diverted {
    fn drop(&mut self) {
        *DIVERTED.lock().unwrap_or_else(|e| e.into_inner()) = None;
    }
}

/// Prints the library's `log` records — progress lines, notes and warnings of studies, sweeps
/// and long runs — on stderr, as they are written (the library itself never prints). `sysid`
/// and `xtask` install it first thing; a program that embeds the library chooses its own logger
/// or none.
pub fn install_logger() {
    struct Stderr;
    impl log::Log for Stderr {
        fn enabled(&self, m: &log::Metadata) -> bool {
            m.level() <= log::Level::Info
        }
        fn log(&self, r: &log::Record) {
            if !self.enabled(r.metadata()) {
                return;
            }
            let mut diverted = DIVERTED.lock().unwrap_or_else(|e| e.into_inner());
            match diverted.as_mut() {
                Some(w) => {
                    let _ = writeln!(w, "{}", r.args());
                }
                // Not `eprintln!`: a closed stderr loses the line instead of panicking.
                None => {
                    let _ = writeln!(std::io::stderr().lock(), "{}", r.args());
                }
            }
        }
        fn flush(&self) {}
    }
    // A second installation (a test calling it twice) keeps the first logger.
    if log::set_logger(&Stderr).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
}
