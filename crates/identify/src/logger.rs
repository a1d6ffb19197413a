//! The logger of the binaries (`sysid`, `xtask`).

/// Prints the library's `log` records — progress lines, notes and warnings of studies, sweeps
/// and long runs — on stderr, as they are written (the library itself never prints). `sysid`
/// and `xtask` install it first thing; a program that embeds the library chooses its own logger
/// or none.
pub fn install_logger() {
    use std::io::Write;
    struct Stderr;
    impl log::Log for Stderr {
        fn enabled(&self, m: &log::Metadata) -> bool {
            m.level() <= log::Level::Info
        }
        fn log(&self, r: &log::Record) {
            if self.enabled(r.metadata()) {
                // Not `eprintln!`: a closed stderr loses the line instead of panicking.
                let _ = writeln!(std::io::stderr().lock(), "{}", r.args());
            }
        }
        fn flush(&self) {}
    }
    // A second installation (a test calling it twice) keeps the first logger.
    if log::set_logger(&Stderr).is_ok() {
        log::set_max_level(log::LevelFilter::Info);
    }
}
