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
use std::sync::atomic::{AtomicBool, Ordering};

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

/// The largest auxiliary text file a command reads whole (a baseline report
/// for `eval --check`): 64 MiB, far above any report `mapc eval` writes
/// (a few kB).
pub const MAX_AUX_BYTES: u64 = 64 << 20;

/// Reads a small text file given by `option`, at most [`MAX_AUX_BYTES`]:
/// a device or an endless stream (`/dev/zero`) is refused once the bound is
/// passed instead of filling memory.
pub fn read_aux_text(path: &Path, option: &str) -> Result<String, CliError> {
    use std::io::Read as _;
    let bad = |why: String| input_err(anyhow::anyhow!("{option} {}: {why}", path.display()));
    let f = std::fs::File::open(path).map_err(|e| bad(e.to_string()))?;
    if f.metadata().map_err(|e| bad(e.to_string()))?.is_dir() {
        return Err(bad("is a directory".into()));
    }
    let mut bytes = Vec::new();
    f.take(MAX_AUX_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| bad(e.to_string()))?;
    if bytes.len() as u64 > MAX_AUX_BYTES {
        return Err(bad(format!(
            "larger than {} MiB; not a file this option reads",
            MAX_AUX_BYTES >> 20
        )));
    }
    String::from_utf8(bytes).map_err(|e| {
        bad(format!(
            "not UTF-8 text (byte {})",
            e.utf8_error().valid_up_to()
        ))
    })
}

/// Databases up to this size are read into memory instead of mapped:
/// 256 MiB. A file truncated or rewritten in place by another process
/// while a mapped database is in use can kill the process with SIGBUS; a
/// copy in memory cannot be changed under it. (`mapc build` replaces files
/// by rename, which leaves a running reader's mapping intact either way.)
/// Larger databases are mapped (`refloc::map_file`, its contract applies).
pub const MAX_READ_DB_BYTES: u64 = 256 << 20;

/// A database's bytes: a 4-byte aligned copy in memory, or a mapping.
pub enum DbBytes {
    /// Read into memory; `len` bytes of `words` are the file.
    Owned { words: Vec<u32>, len: usize },
    /// Mapped (larger than [`MAX_READ_DB_BYTES`]).
    Mapped(memmap2::Mmap),
}

impl AsRef<[u8]> for DbBytes {
    fn as_ref(&self) -> &[u8] {
        match self {
            DbBytes::Owned { words, len } => &zerocopy::IntoBytes::as_bytes(&words[..])[..*len],
            DbBytes::Mapped(m) => m,
        }
    }
}

/// Whether commands check the database's section CRCs when they open it
/// (the default; `--no-verify` turns it off for the whole run).
static VERIFY_CRCS: AtomicBool = AtomicBool::new(true);

/// Sets whether [`open_db`] checks CRCs (from `--no-verify`).
pub fn set_verify_crcs(on: bool) {
    VERIFY_CRCS.store(on, Ordering::Relaxed);
}

/// How much [`open_db`] checks.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// Structure, and the CRCs unless `--no-verify` was given.
    Full,
    /// Structure only (for `mapc verify`, which reports the CRCs itself).
    Structure,
}

/// Opens a database and validates its structure (and, by default, its
/// CRCs): only a regular file is opened (a FIFO or a device would block or
/// never end); up to [`MAX_READ_DB_BYTES`] it is read into memory, above
/// that it is mapped.
pub fn open_db(path: &Path, check: Check) -> Result<refloc::RefDb<DbBytes>, CliError> {
    use std::io::Read as _;
    let bad = |why: String| input_err(anyhow::anyhow!("{}: {why}", path.display()));
    let meta = std::fs::metadata(path).map_err(|e| bad(e.to_string()))?;
    if !meta.is_file() {
        return Err(bad(
            "not a regular file (a directory, FIFO or device cannot hold a database)".into(),
        ));
    }
    let bytes = if meta.len() <= MAX_READ_DB_BYTES {
        let len = meta.len() as usize;
        let mut words = vec![0u32; len.div_ceil(4)];
        let mut f = std::fs::File::open(path).map_err(|e| bad(e.to_string()))?;
        f.read_exact(&mut zerocopy::IntoBytes::as_mut_bytes(&mut words[..])[..len])
            .map_err(|e| bad(format!("cannot read {len} bytes: {e}")))?;
        DbBytes::Owned { words, len }
    } else {
        DbBytes::Mapped(refloc::map_file(path).map_err(|e| bad(e.to_string()))?)
    };
    let db = refloc::RefDb::new(bytes).map_err(|e| bad(e.to_string()))?;
    if check == Check::Full && VERIFY_CRCS.load(Ordering::Relaxed) {
        db.verify().map_err(|e| {
            bad(format!(
                "{e} (the database is damaged; `mapc verify` checks it, --no-verify skips the check)"
            ))
        })?;
    }
    Ok(db)
}

/// A clap value parser for a count within `LO..=HI`: a count past the bound
/// is a usage error (exit 2) that names the bound.
pub fn count<const LO: usize, const HI: usize>(s: &str) -> Result<usize, String> {
    let n: usize = s
        .trim()
        .parse()
        .map_err(|_| format!("not a whole number: {s:?}"))?;
    if (LO..=HI).contains(&n) {
        Ok(n)
    } else {
        Err(format!("must be between {LO} and {HI}, not {n}"))
    }
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
