//! The library's one error type.
//!
//! Every fallible function of this crate returns [`Result`], whose [`Error`] says *what kind* of
//! failure happened — a file that could not be read or written, a malformed JSON or TOML text,
//! an input the toolkit refuses, a run stopped by an interruption, an error of a lower layer
//! (a data set, a record, a simulation, a cluster) — so a caller can match on it (the Python
//! package maps an interruption to its own exception; `sysid` exits with the message). What was
//! being done when it happened is added on the way up by [`Context`], as a chain of causes that
//! [`std::error::Error::source`] walks: the binary prints the chain, a caller matching on the kind
//! looks through the context with [`Error::kind`].
//!
//! `{e}` prints the outermost message, `{e:#}` the whole chain joined by `: `.

use std::fmt;

/// A run stopped at its caller's request (`pipeline::identify_stoppable`): no record
/// is made of it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("interrupted before step {step} of {steps}")]
pub struct Interrupted {
    /// The step that was not run (1-based).
    pub step: usize,
    /// The steps of the run.
    pub steps: usize,
}

/// Declares [`Error`] with its variants that wrap another error transparently (their message
/// is the wrapped error's), each with its `From` conversion, so `?` converts them. The wrapped
/// errors are boxed: some are large, and an error is rare while every `Result` carries its size.
macro_rules! error_type {
    ($($(#[$doc:meta])* $variant:ident($t:ty),)*) => {
        /// What went wrong, with the causes below it.
        #[derive(Debug)]
        pub enum Error {
            $($(#[$doc])* $variant(Box<$t>),)*
            /// An input the toolkit refuses: a config, data set, record or argument that is
            /// malformed, out of range or contradicts another. The message names the file,
            /// line and field.
            Invalid(String),
            /// A figure could not be drawn or written.
            Figure(String),
            /// An error of one of this crate's studies or checks (a cluster run, a simulation,
            /// a refused answer, broken regression bounds, …), kept with its own type: the
            /// module that defines it declares it with the crate's `domain_error!` macro, and
            /// [`Error::domain`] finds it again by type.
            Domain(Box<dyn std::error::Error + Send + Sync + 'static>),
            /// `source`, with what was being done when it happened.
            Context { context: String, source: Box<Error> },
        }

        $(impl From<$t> for Error {
            fn from(e: $t) -> Self {
                Error::$variant(Box::new(e))
            }
        })*

        impl Error {
            /// The wrapped error of a transparent variant.
            fn wrapped(&self) -> Option<&(dyn std::error::Error + 'static)> {
                match self {
                    $(Error::$variant(e) => Some(e.as_ref()),)*
                    Error::Domain(e) => Some(e.as_ref()),
                    _ => None,
                }
            }
        }
    };
}

error_type! {
    /// Reading, writing or listing a file or directory failed.
    Io(std::io::Error),
    /// A JSON text did not parse or did not have the expected shape.
    Json(serde_json::Error),
    /// A TOML text did not parse or did not have the expected shape.
    Toml(toml::de::Error),
    /// A value could not be written as TOML.
    TomlWrite(toml::ser::Error),
    /// A run stopped at a step because it was asked to.
    Interrupted(Interrupted),
    /// A filter failed numerically.
    Filter(core_filters::error::FilterError),
    /// A likelihood's maximum or its curvature could not be found.
    Laplace(core_filters::laplace::LaplaceError),
    /// A building (masses, hysteretic storeys, damping) is not valid.
    Building(models::building::BuildingError),
    /// A data set could not be read or is not valid.
    Dataset(models::dataset::DatasetError),
    /// A filter specification is not valid.
    Spec(models::filtering::spec::SpecError),
    /// A value is outside the limits the toolkit accepts.
    Limit(models::limits::LimitError),
    /// A structure preset is not valid.
    Preset(models::preset::PresetError),
    /// A prior is not valid.
    Prior(models::priors::PriorError),
    /// A run record could not be read.
    Record(crate::record::read::ReadError),
    /// An output path is refused (not a regular file, or one of the command's inputs).
    Output(crate::record::atomic::OutputError),
    /// Recordings could not be imported into a data set.
    Import(models::import::ImportError),
    /// An input file is refused (not a regular file, too large, not UTF-8) or could not be read.
    Read(models::readers::ReadError),
    /// Text written into a `String` (never fails in practice).
    Format(std::fmt::Error),
    /// A text that is not UTF-8.
    Utf8(std::string::FromUtf8Error),
    /// The worker threads could not be started.
    Threads(rayon::ThreadPoolBuildError),
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An input the toolkit refuses, with its message.
    pub fn invalid(message: impl fmt::Display) -> Self {
        Error::Invalid(message.to_string())
    }

    /// The error below every context: what kind of failure this is.
    pub fn kind(&self) -> &Error {
        match self {
            Error::Context { source, .. } => source.kind(),
            e => e,
        }
    }

    /// The error of this crate's type `E` this error is (through any context), if it is one.
    pub fn domain<E: std::error::Error + 'static>(&self) -> Option<&E> {
        match self.kind() {
            Error::Domain(e) => e.downcast_ref::<E>(),
            _ => None,
        }
    }

    /// The interruption this error is (through any context), if it is one.
    pub fn interrupted(&self) -> Option<&Interrupted> {
        match self.kind() {
            Error::Interrupted(i) => Some(i.as_ref()),
            _ => None,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Invalid(m) | Error::Figure(m) => f.write_str(m)?,
            Error::Context { context, .. } => f.write_str(context)?,
            e => write!(f, "{}", e.wrapped().expect("a transparent variant"))?,
        }
        if f.alternate() {
            let mut cause = std::error::Error::source(self);
            while let Some(c) = cause {
                write!(f, ": {c}")?;
                cause = c.source();
            }
        }
        Ok(())
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Invalid(_) | Error::Figure(_) => None,
            Error::Context { source, .. } => Some(source.as_ref()),
            // A wrapped error is transparent: its message is this error's, so the chain
            // continues with its own causes.
            e => e.wrapped().and_then(|w| w.source()),
        }
    }
}

impl<E: std::error::Error + Send + Sync> From<plotters::drawing::DrawingAreaErrorKind<E>>
    for Error
{
    fn from(e: plotters::drawing::DrawingAreaErrorKind<E>) -> Self {
        Error::Figure(e.to_string())
    }
}

/// Adds what was being done to an error on its way up.
pub trait Context<T> {
    /// The error, as the cause of `context`.
    fn context<C: fmt::Display>(self, context: C) -> Result<T>;
    /// The error, as the cause of the message `f` makes (only made on an error).
    fn with_context<C: fmt::Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context<C: fmt::Display>(self, context: C) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: context.to_string(),
            source: Box::new(e.into()),
        })
    }

    fn with_context<C: fmt::Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: f().to_string(),
            source: Box::new(e.into()),
        })
    }
}

/// A missing value is an input the toolkit refuses, described by the context.
impl<T> Context<T> for Option<T> {
    fn context<C: fmt::Display>(self, context: C) -> Result<T> {
        self.ok_or_else(|| Error::invalid(context))
    }

    fn with_context<C: fmt::Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.ok_or_else(|| Error::invalid(f()))
    }
}

/// Declares error types of this crate as [`Error::Domain`] errors, so `?` converts them.
#[doc(hidden)]
#[macro_export]
macro_rules! __domain_error {
    ($($t:ty),* $(,)?) => {$(
        impl From<$t> for $crate::error::Error {
            fn from(e: $t) -> Self {
                $crate::error::Error::Domain(Box::new(e))
            }
        }
    )*};
}
pub use crate::__domain_error as domain_error;

/// Returns an [`Error::Invalid`] with a formatted message.
#[doc(hidden)]
#[macro_export]
macro_rules! __bail {
    ($($arg:tt)*) => {
        return Err($crate::error::Error::Invalid(format!($($arg)*)))
    };
}
pub use crate::__bail as bail;

/// An [`Error::Invalid`] with a formatted message.
#[doc(hidden)]
#[macro_export]
macro_rules! __invalid {
    ($($arg:tt)*) => {
        $crate::error::Error::Invalid(format!($($arg)*))
    };
}
pub use crate::__invalid as invalid;

#[cfg(test)]
mod tests {
    use super::*;

    fn read(path: &str) -> Result<String> {
        std::fs::read_to_string(path).with_context(|| format!("reading {path}"))
    }

    #[test]
    fn context_chains_and_the_kind_is_found_below_it() {
        let e = read("/nonexistent/dir/file.json")
            .context("loading the study")
            .unwrap_err();
        assert_eq!(e.to_string(), "loading the study");
        let full = format!("{e:#}");
        assert!(
            full.starts_with("loading the study: reading /nonexistent/dir/file.json: "),
            "{full}"
        );
        assert!(matches!(e.kind(), Error::Io(io) if io.kind() == std::io::ErrorKind::NotFound));
    }

    #[test]
    fn an_interruption_is_found_through_context() {
        let i = Interrupted { step: 3, steps: 10 };
        let e = Err::<(), _>(Error::from(i.clone()))
            .context("run 2")
            .unwrap_err();
        assert_eq!(e.interrupted(), Some(&i));
        assert!(Error::invalid("x").interrupted().is_none());
    }

    #[test]
    fn a_lower_layer_error_keeps_its_type_and_message() {
        let e = Err::<(), _>(core_filters::error::FilterError::Interrupted { step: 4 })
            .context("filtering")
            .unwrap_err();
        assert!(matches!(e.kind(), Error::Filter(f) if f.step() == 4));
        let inner = core_filters::error::FilterError::Interrupted { step: 4 }.to_string();
        assert_eq!(format!("{e:#}"), format!("filtering: {inner}"));
    }

    /// A study error of this crate, declared as the modules declare theirs.
    #[derive(Debug, Clone, PartialEq, thiserror::Error)]
    #[error("bound breached")]
    struct Breached(u32);
    domain_error!(Breached);

    #[derive(Debug, thiserror::Error)]
    #[error("other")]
    struct Other;

    #[test]
    fn a_domain_error_is_found_by_its_type_through_context() {
        let e = Err::<(), _>(Breached(3))
            .context("regression check")
            .unwrap_err();
        assert!(matches!(e.kind(), Error::Domain(_)));
        assert_eq!(e.domain::<Breached>(), Some(&Breached(3)));
        assert!(e.domain::<Other>().is_none());
        assert!(Error::invalid("x").domain::<Breached>().is_none());
        assert_eq!(format!("{e:#}"), "regression check: bound breached");
    }

    #[test]
    fn bail_and_option_context_are_invalid_input() {
        fn f(x: i32) -> Result<i32> {
            if x < 0 {
                bail!("field `x`: {x} is negative");
            }
            None.context("no value")
        }
        assert!(
            matches!(f(-1).unwrap_err(), Error::Invalid(m) if m == "field `x`: -1 is negative")
        );
        assert!(matches!(f(1).unwrap_err(), Error::Invalid(m) if m == "no value"));
    }
}
