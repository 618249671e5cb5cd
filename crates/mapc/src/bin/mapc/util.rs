//! Shared CLI plumbing: errors with exit codes, progress, database opening.

/// `println!` that ignores a closed stdout (e.g. `mapc info x | head`)
/// instead of panicking.
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}
pub(crate) use outln;

use std::io::IsTerminal;
use std::path::Path;

use indicatif::{ProgressBar, ProgressStyle};

/// An error and the exit code it maps to.
pub struct CliError {
    pub error: anyhow::Error,
    pub code: u8,
}

pub type CliResult = Result<std::process::ExitCode, CliError>;

/// Bad input or usage: exit code 2.
pub fn input_err(e: impl Into<anyhow::Error>) -> CliError {
    CliError {
        error: e.into(),
        code: 2,
    }
}

/// A failed run: exit code 1.
pub fn fail_err(e: impl Into<anyhow::Error>) -> CliError {
    CliError {
        error: e.into(),
        code: 1,
    }
}

/// Terminal-aware output helpers.
pub struct Ui {
    pub quiet: bool,
    pub tty: bool,
}

impl Ui {
    pub fn new(quiet: bool) -> Ui {
        Ui {
            quiet,
            tty: std::io::stderr().is_terminal(),
        }
    }

    /// A progress bar on a terminal, hidden otherwise.
    pub fn progress(&self, len: u64, what: &str) -> ProgressBar {
        if self.quiet || !self.tty {
            return ProgressBar::hidden();
        }
        let pb = ProgressBar::new(len);
        pb.set_style(
            ProgressStyle::with_template(
                "{msg:>12} [{bar:40}] {pos}/{len} {elapsed_precise} eta {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        pb.set_message(what.to_string());
        pb
    }

    /// A spinner for a stage of unknown length.
    pub fn stage(&self, what: &str) -> ProgressBar {
        if self.quiet || !self.tty {
            return ProgressBar::hidden();
        }
        let pb = ProgressBar::new_spinner();
        pb.set_message(what.to_string());
        pb.enable_steady_tick(std::time::Duration::from_millis(120));
        pb
    }

    /// Prints to stderr unless quiet.
    pub fn note(&self, s: &str) {
        if !self.quiet {
            eprintln!("{s}");
        }
    }
}

/// Opens a database by memory map and validates its structure.
pub fn open_db(path: &Path) -> Result<refloc::RefDb<memmap2::Mmap>, CliError> {
    refloc::open_mmap(path).map_err(|e| input_err(anyhow::anyhow!("{}: {e}", path.display())))
}

/// Parses "x,y,yaw" (metres, metres, radians).
pub fn parse_triple(s: &str) -> Result<[f64; 3], String> {
    let v: Result<Vec<f64>, _> = s.split(',').map(|t| t.trim().parse::<f64>()).collect();
    match v {
        Ok(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => Ok([v[0], v[1], v[2]]),
        _ => Err(format!(
            "expected three finite numbers 'x,y,yaw', got '{s}'"
        )),
    }
}
