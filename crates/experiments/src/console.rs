//! Where a command's text goes. Run by a person, `sysid`'s results go to standard output and its
//! notes, warnings and progress to standard error; run as a step of a field study
//! ([`crate::field_study`]), both go to the step's log file, in the order written, and no
//! progress bar is drawn.

use std::io::{IsTerminal, Write};

/// The two streams of one command.
pub struct Console {
    out: Box<dyn Write + Send>,
    err: Box<dyn Write + Send>,
    terminal: bool,
}

impl Console {
    /// Standard output and standard error; a progress bar where standard error is a terminal.
    pub fn standard() -> Self {
        Self {
            out: Box::new(std::io::stdout()),
            err: Box::new(std::io::stderr()),
            terminal: std::io::stderr().is_terminal(),
        }
    }

    /// Both streams into one log file (the two handles share its offset, so the lines keep
    /// their order); no progress bar.
    pub(crate) fn log_file(file: std::fs::File) -> std::io::Result<Self> {
        Ok(Self {
            out: Box::new(file.try_clone()?),
            err: Box::new(file),
            terminal: false,
        })
    }

    /// The results (a summary table, the files written).
    pub fn out(&mut self) -> &mut dyn Write {
        &mut self.out
    }

    /// Notes, warnings, the decisions of a plan.
    pub fn err(&mut self) -> &mut dyn Write {
        &mut self.err
    }

    /// Writes `e` as `sysid` shows an error on exit: its message, then each cause on a line —
    /// never a stack trace (an error is a message to the user, not a bug report).
    pub fn error(&mut self, e: &(dyn std::error::Error + 'static)) -> std::io::Result<()> {
        writeln!(self.err, "Error: {e}")?;
        let mut cause = e.source();
        while let Some(c) = cause {
            writeln!(self.err, "  caused by: {c}")?;
            cause = c.source();
        }
        Ok(())
    }

    /// Whether a person watches standard error (a progress bar is drawn there).
    pub fn terminal(&self) -> bool {
        self.terminal
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_file_keeps_both_streams_in_the_order_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("step.log");
        let mut c = Console::log_file(std::fs::File::create(&path).unwrap()).unwrap();
        writeln!(c.out(), "one").unwrap();
        writeln!(c.err(), "two").unwrap();
        writeln!(c.out(), "three").unwrap();
        assert!(!c.terminal());
        drop(c);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "one\ntwo\nthree\n");
    }
}
