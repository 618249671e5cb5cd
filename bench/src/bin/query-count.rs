//! The program `scripts/callgrind.sh` counts instructions of.
//!
//! ```text
//! query-count --write-db FILE
//!     compile the benchmark database (Intel map, default BuildConfig; see
//!     refloc_bench::Database::build) and write it to FILE
//! query-count --db FILE [--beams 362|1081|361] [--condition static|dynamic] [--n N]
//!     load FILE, simulate the fixed scan set (always all of it), allocate
//!     the scratch, then localize N queries (query i = scan i mod 50) on
//!     one thread
//! ```
//!
//! Prints nothing on success (errors go to stderr, exit status 2), so the
//! instructions of a run with N queries minus those of a run with 0 are
//! the queries' own. Deterministic: same seeds every run.

use std::hint::black_box;
use std::path::PathBuf;
use std::process::ExitCode;

use refloc::{localize, scratch_size};
use refloc_bench::{scan_set, Condition, Database, Kind, SCAN_COUNT};

fn run() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let (mut db_path, mut write): (Option<PathBuf>, Option<PathBuf>) = (None, None);
    let (mut kind, mut cond, mut n) = (Kind::Full362, Condition::Static, SCAN_COUNT);
    while let Some(a) = args.next() {
        let mut val = || args.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--db" => db_path = Some(val()?.into()),
            "--write-db" => write = Some(val()?.into()),
            "--beams" => {
                let v = val()?;
                kind = Kind::parse(&v).ok_or(format!("unknown --beams {v} (362, 1081, 361)"))?
            }
            "--condition" => {
                let v = val()?;
                cond = Condition::parse(&v)
                    .ok_or(format!("unknown --condition {v} (static, dynamic)"))?
            }
            "--n" => n = val()?.parse().map_err(|e| format!("--n: {e}"))?,
            "-h" | "--help" => {
                eprintln!(
                    "usage: query-count --write-db FILE\n       query-count --db FILE \
                     [--beams 362|1081|361] [--condition static|dynamic] [--n N]"
                );
                return Ok(());
            }
            other => return Err(format!("unknown argument {other}")),
        }
    }
    if let Some(out) = write {
        let db = Database::build()?;
        std::fs::write(&out, db.bytes()).map_err(|e| format!("{}: {e}", out.display()))?;
        eprintln!("{}", db.origin);
        return Ok(());
    }
    let db = Database::load(&db_path.ok_or("--db FILE or --write-db FILE is required")?)?;
    let db = db.open();
    let scans = scan_set(&db, kind, cond, SCAN_COUNT);
    let mut scratch = vec![0u8; scratch_size(db.params(), kind.beams())];
    for i in 0..n {
        let q = &scans[i % scans.len()];
        let r = localize(&db, black_box(&q.scan()), &mut scratch);
        black_box(r.is_ok());
    }
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("query-count: {e}");
            ExitCode::from(2)
        }
    }
}
