//! `sysid`: online Bayesian identification of hysteretic structures from the command line.

use clap::{Parser, Subcommand};
use experiments::cli;
use experiments::console::Console;

#[derive(Parser)]
#[command(
    name = "sysid",
    version,
    about = "Online Bayesian identification of hysteretic structures",
    allow_negative_numbers = true
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Every subcommand accepts negative numbers as values (`--scale -1` flips the sign of the
/// excitation); an unsigned option given a negative number then gets clap's "invalid value"
/// message instead of "unexpected argument".
#[derive(Subcommand)]
enum Command {
    /// Simulate a structure under an excitation and write a noisy data set.
    #[command(allow_negative_numbers = true)]
    Simulate(cli::simulate::Args),
    /// Build a data set from real recordings (sensor CSV exports, CSMIP V2) and a channel map.
    #[command(allow_negative_numbers = true)]
    Import(cli::import::Args),
    /// Run one identification filter on a data set and write a run record.
    #[command(allow_negative_numbers = true)]
    Filter(Box<cli::filter::Args>),
    /// Reproduce the paper: every study, figure and the report.
    #[command(allow_negative_numbers = true)]
    Reproduce(cli::reproduce::Args),
    /// Identification-accuracy regression check against reviewed thresholds.
    #[command(allow_negative_numbers = true)]
    Regression(cli::regression::Args),
    /// The scaling study: chains of 3 to 40 storeys, cost and accuracy per algorithm.
    #[command(allow_negative_numbers = true)]
    Scaling(cli::scaling::Args),
    /// The excitations study: the paper's structure under other real ground motions.
    #[command(allow_negative_numbers = true)]
    Excitations(cli::scaling::Args),
    /// Run a study as a Slurm job array: submit, status, resubmit, finish, compare.
    Cluster(cli::cluster::Args),
    /// Merge the records of sharded sweeps.
    #[command(allow_negative_numbers = true)]
    Merge(cli::merge::Args),
    /// Reference posterior of θ for one (short) data set by particle marginal Metropolis–Hastings.
    Reference(cli::reference::Args),
    /// Run a study file, e.g. N filter seeds × algorithms on a data directory of your own.
    #[command(allow_negative_numbers = true)]
    Study(cli::study::Args),
    /// Compare online filters' final posteriors (run records) with a reference posterior.
    CompareReference(cli::reference::CompareArgs),
    /// Which answers a record supports: the log-likelihood of a data set at the θ_val of run
    /// records (and its true θ), each shown outside the record's 95 % likelihood region or not.
    Loglik(cli::loglik::Args),
    /// The information limit of a linear record: the maximum-likelihood θ, its error and the
    /// Cramér–Rao s.d. of every parameter (exact Kalman likelihood), beside run records' answers.
    Information(cli::information::Args),
    /// Draw the figures of one run record (convergence, ESS, hysteresis loop, residuals; of field
    /// data also the free run, the transfer functions and the mode shapes).
    Plot(cli::plot::Args),
    /// A study of one real structure from its recordings: import, identify model variants,
    /// cross-validate, compare with a black-box baseline, REPORT.md.
    FieldStudy(cli::field_study::Args),
    /// Cross-validation: the model identified in a run record predicts another record of the
    /// same building (free run, fit per channel, modes beside the measured peaks).
    Validate(cli::validate::Args),
    /// Compute Table I (moments of z = xᵀx by linearisation, EKF2 and the unscented transform).
    #[command(allow_negative_numbers = true)]
    Table1(cli::table1::Args),
}

fn main() -> std::process::ExitCode {
    // Rust ignores SIGPIPE, so a write to a closed standard output (`sysid … | head`) fails, and
    // `print!` panics on the failure. Restored to its default, the signal ends the process
    // quietly, as it ends any Unix tool whose reader has gone; the commands write their files
    // before they print, so what they were asked to write is already written. No child process
    // is fed through a pipe, so the default is right for every other write too.
    #[cfg(unix)]
    // SAFETY: called first thing in `main`, before any thread is started; resetting a signal's
    // disposition to its default installs no handler.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    identify::logger::install_logger();
    // The error and its causes, one per line — never a stack trace: an error here is a message
    // to the user (bad input, a failed run), not a bug report.
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // A closed stderr loses the message; the exit status still says it failed.
            let _ = Console::standard().error(&e);
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> experiments::error::Result<()> {
    match cli.command {
        Command::Simulate(args) => cli::simulate::run(args, &mut Console::standard()),
        Command::Filter(args) => cli::filter::run(*args, &mut Console::standard()),
        Command::Import(args) => cli::import::run(args, &mut Console::standard()),
        Command::Table1(args) => cli::table1::run(args, &mut Console::standard()),
        Command::Reference(args) => cli::reference::run(args, &mut Console::standard()),
        Command::Study(args) => cli::study::run(args, &mut Console::standard()),
        Command::CompareReference(args) => cli::reference::compare(args, &mut Console::standard()),
        Command::Reproduce(args) => cli::reproduce::run(args),
        Command::Merge(args) => cli::merge::run(args, &mut Console::standard()),
        Command::Cluster(args) => cli::cluster::run(args, &mut Console::standard()),
        Command::Scaling(args) => cli::scaling::run(args),
        Command::Excitations(args) => cli::scaling::run_excitations(args),
        Command::Regression(args) => cli::regression::run(args, &mut Console::standard()),
        Command::Plot(args) => cli::plot::run(args, &mut Console::standard()),
        Command::Loglik(args) => cli::loglik::run(args, &mut Console::standard()),
        Command::Information(args) => cli::information::run(args, &mut Console::standard()),
        Command::Validate(args) => cli::validate::run(args, &mut Console::standard()),
        Command::FieldStudy(args) => cli::field_study::run(args, &mut Console::standard()),
    }
}
