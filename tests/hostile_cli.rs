//! The `mapc` binary against hostile surroundings rather than hostile
//! files: output that cannot be written, a reader that goes away, a live
//! stream of scans, auxiliary files that never end, option values that
//! would make the process spawn without bound (issue 17).
//!
//! Registered as an integration test of the `mapc` package (see
//! crates/mapc/Cargo.toml) so `CARGO_BIN_EXE_mapc` points at the binary.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;

mod common;

fn mapc() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_mapc"));
    c.env("NO_COLOR", "1");
    c
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The number of simulated scans in the shared input file.
const SCANS: usize = 40;

/// The demo map compiled once for all tests, and `SCANS` simulated scans
/// of it as JSON Lines: (database, scans file).
/// The temporary directory lives as long as the static: the files stay for
/// every test of the run.
fn fixture() -> (&'static Path, &'static Path) {
    static F: OnceLock<(tempfile::TempDir, PathBuf, PathBuf)> = OnceLock::new();
    let f = F.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let map =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../maps/office-demo/office-demo.yaml");
        let db = dir.path().join("demo.refdb");
        let o = mapc()
            .args(["build", map.to_str().unwrap(), "-o", db.to_str().unwrap()])
            .args(["--fit-queries", "40", "-q"])
            .output()
            .unwrap();
        assert!(o.status.success(), "build: {}", text(&o));
        let (_, lines) = common::jsonl_scans(&std::fs::read(&db).unwrap(), SCANS, 5);
        let scans = dir.path().join("scans.jsonl");
        std::fs::write(&scans, lines).unwrap();
        (dir, db, scans)
    });
    (&f.1, &f.2)
}

#[test]
fn localize_into_a_full_device_fails_and_says_so() {
    let (db, scans) = fixture();
    let full = std::fs::OpenOptions::new().write(true).open("/dev/full");
    let Ok(full) = full else {
        eprintln!("skipped: /dev/full is not available on this system");
        return;
    };
    let o = mapc()
        .args(["localize", db.to_str().unwrap(), scans.to_str().unwrap()])
        .stdout(full)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("cannot write the results to standard output"),
        "{}",
        text(&o)
    );
}

#[test]
fn localize_stops_when_its_reader_goes_away() {
    let (db, scans) = fixture();
    let mut child = mapc()
        .args(["localize", db.to_str().unwrap(), scans.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    out.read_line(&mut first).unwrap();
    assert!(first.contains("\"id\":\"s0\""), "{first}");
    // `| head -1`: the reader closes after one line. The results of all
    // scans (80 candidates each) are far more than a pipe and the output
    // buffer hold, so mapc must meet the closed pipe and stop.
    drop(out);
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{err}");
    let stopped: usize = err
        .split("output closed by its reader after ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no note of the closed output: {err}"));
    assert!(stopped < SCANS, "went on through every scan: {err}");
}

#[test]
fn localize_from_a_stream_answers_each_scan_before_the_next_arrives() {
    let (db, scans) = fixture();
    let first_scan = std::fs::read_to_string(scans)
        .unwrap()
        .lines()
        .next()
        .unwrap()
        .to_string();
    let mut child = mapc()
        .args(["localize", db.to_str().unwrap(), "-", "--no-candidates"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    writeln!(stdin, "{first_scan}").unwrap();
    stdin.flush().unwrap();
    // stdin stays open: the result must come out now. The reader runs on
    // its own thread only so that a regression fails the test instead of
    // hanging it (a bound on a deadlock, not a timing assertion).
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut line = String::new();
        let r = out.read_line(&mut line).map(|_| line);
        let _ = tx.send(r);
        out
    });
    let got = rx.recv_timeout(std::time::Duration::from_secs(300));
    drop(stdin);
    let status = child.wait().unwrap();
    let line = got
        .expect("no result while the stream stayed open: results are held back")
        .unwrap();
    let _ = reader.join();
    let j: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(j["id"], "s0");
    assert!(status.success());
}

/// Reads one line from `out` on a helper thread, so that a process that
/// never answers fails the test instead of hanging it (a bound on a
/// deadlock, not a timing assertion).
fn read_line_or_fail(
    out: BufReader<std::process::ChildStdout>,
) -> (String, BufReader<std::process::ChildStdout>) {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut out = out;
        let mut line = String::new();
        let r = out.read_line(&mut line).map(|_| line);
        let _ = tx.send((r, out));
    });
    let (line, out) = rx
        .recv_timeout(std::time::Duration::from_secs(300))
        .expect("no result from mapc localize");
    (line.unwrap(), out)
}

#[test]
fn a_database_truncated_under_a_running_localize_does_not_kill_it() {
    // Item 7 of issue 17: with the database mapped, truncating the file
    // under `mapc localize -` killed it with SIGBUS at the next access and
    // lost the results not yet written. Databases up to MAX_READ_DB_BYTES
    // are now read into memory, so the run goes on with what it read.
    let (db, scans) = fixture();
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("live.refdb");
    std::fs::copy(db, &copy).unwrap();
    let lines: Vec<String> = std::fs::read_to_string(scans)
        .unwrap()
        .lines()
        .take(2)
        .map(str::to_string)
        .collect();
    let mut child = mapc()
        .args(["localize", copy.to_str().unwrap(), "-", "--no-candidates"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let out = BufReader::new(child.stdout.take().unwrap());
    writeln!(stdin, "{}", lines[0]).unwrap();
    stdin.flush().unwrap();
    let (first, out) = read_line_or_fail(out);
    // Truncate the file in place, then write other bytes into it: a
    // mapping would now point past the end of the file.
    let f = std::fs::OpenOptions::new().write(true).open(&copy).unwrap();
    f.set_len(0).unwrap();
    drop(f);
    std::fs::write(&copy, b"not a database any more").unwrap();
    writeln!(stdin, "{}", lines[1]).unwrap();
    stdin.flush().unwrap();
    let (second, _out) = read_line_or_fail(out);
    drop(stdin);
    let o = child.wait_with_output().unwrap();
    assert!(
        o.status.success(),
        "{:?}: {}",
        o.status,
        String::from_utf8_lossy(&o.stderr)
    );
    let a: serde_json::Value = serde_json::from_str(&first).unwrap();
    let b: serde_json::Value = serde_json::from_str(&second).unwrap();
    assert_eq!(
        (a["id"].as_str(), b["id"].as_str()),
        (Some("s0"), Some("s1"))
    );
    // The second scan was localized against the database as it was read.
    let again = mapc()
        .args(["localize", db.to_str().unwrap(), "-", "--no-candidates"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .and_then(|mut c| {
            writeln!(c.stdin.take().unwrap(), "{}\n{}", lines[0], lines[1])?;
            c.wait_with_output()
        })
        .unwrap();
    let ref_second: serde_json::Value = serde_json::from_str(
        String::from_utf8_lossy(&again.stdout)
            .lines()
            .nth(1)
            .unwrap(),
    )
    .unwrap();
    for k in ["x", "y", "theta", "accepted", "confidence"] {
        assert_eq!(b[k], ref_second[k], "{k}");
    }
}

#[test]
fn eval_check_refuses_an_endless_baseline_before_evaluating() {
    if !Path::new("/dev/zero").exists() {
        eprintln!("skipped: /dev/zero is not available on this system");
        return;
    }
    let (db, _) = fixture();
    let out = tempfile::tempdir().unwrap();
    let o = mapc()
        .args(["eval", db.to_str().unwrap(), "--check", "/dev/zero"])
        .args(["--out", out.path().to_str().unwrap(), "--no-figures"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("--check /dev/zero"), "{}", text(&o));
    assert!(text(&o).contains("larger than 64 MiB"), "{}", text(&o));
    // Refused before the evaluation: no report was written.
    assert!(!out.path().join("report.json").exists());
}

/// Counts that size work or memory are bounded: each past its bound is a
/// usage error (exit 2) naming the option and the bound, before any work.
#[test]
fn counts_past_their_bounds_are_refused() {
    let (db, _) = fixture();
    let db = db.to_str().unwrap();
    let map = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../maps/office-demo/office-demo.yaml");
    let map = map.to_str().unwrap();
    let cases: [(&[&str], &str); 7] = [
        (
            &["eval", db, "--beams", "100000000"],
            "'--beams <BEAMS>': must be between 3 and 100000, not 100000000",
        ),
        (
            &["eval", db, "--beams", "2"],
            "'--beams <BEAMS>': must be between 3 and 100000, not 2",
        ),
        (
            &["eval", db, "--poses", "0"],
            "'--poses <POSES>': must be between 1 and 1000000, not 0",
        ),
        (
            &["eval", db, "--e1-trials", "99999999999"],
            "'--e1-trials <E1_TRIALS>': must be between 1 and 1000000",
        ),
        (
            &["eval", db, "--outliers", "400"],
            "--outliers must be between 0 and 362, not 400",
        ),
        (
            &[
                "build",
                map,
                "-o",
                "/nonexistent/x.refdb",
                "--fit-queries",
                "1000000000",
            ],
            "must be between 0 and 100000, not 1000000000",
        ),
        (
            &["demo", "--poses", "0"],
            "must be between 1 and 1000000, not 0",
        ),
    ];
    for (args, says) in cases {
        let o = mapc().args(args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
        assert!(text(&o).contains(says), "{args:?}: {}", text(&o));
    }
}

#[test]
fn thread_counts_out_of_range_are_refused() {
    for n in ["0", "100000"] {
        let o = mapc().args(["--threads", n, "info", "x"]).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "--threads {n}: {}", text(&o));
        assert!(
            text(&o).contains("--threads must be between 1 and 256"),
            "{}",
            text(&o)
        );
    }
}

#[test]
fn a_build_that_would_not_read_back_keeps_the_old_database() {
    let (db, _) = fixture();
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.refdb");
    std::fs::copy(db, &good).unwrap();
    let before = std::fs::read(&good).unwrap();
    // An origin finite as f64 but not as f32: it loads, compiles, and only
    // the database's reader refuses it.
    let maps = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../maps/office-demo");
    std::fs::copy(
        maps.join("office-demo.pgm"),
        dir.path().join("office-demo.pgm"),
    )
    .unwrap();
    let yaml = std::fs::read_to_string(maps.join("office-demo.yaml")).unwrap();
    let bad: String = yaml
        .lines()
        .map(|l| {
            if l.starts_with("origin:") {
                "origin: [1e300, 0.0, 0.0]".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(bad, yaml);
    std::fs::write(dir.path().join("bad.yaml"), bad).unwrap();
    let o = mapc()
        .current_dir(dir.path())
        .args([
            "build",
            "bad.yaml",
            "-o",
            "good.refdb",
            "--fit-queries",
            "10",
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("does not read back"), "{}", text(&o));
    assert_eq!(
        std::fs::read(&good).unwrap(),
        before,
        "old database changed"
    );
    assert_eq!(
        names_in(dir.path()),
        ["bad.yaml", "good.refdb", "office-demo.pgm"]
    );
}

#[test]
fn an_origin_or_resolution_that_contradicts_the_yaml_is_refused_not_ignored() {
    let yaml =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../maps/office-demo/office-demo.yaml");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.refdb");
    for (flag, value) in [("--origin", "5,5,0"), ("--resolution", "0.5")] {
        let o = mapc()
            .args(["build", yaml.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .args([flag, value])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{flag}: {}", text(&o));
        let field = flag.trim_start_matches("--");
        assert!(text(&o).contains(field), "{flag}: {}", text(&o));
        assert!(!out.exists(), "{flag}: a database was written");
    }
}

#[test]
fn synth_refuses_a_map_too_small_to_build() {
    let dir = tempfile::tempdir().unwrap();
    for (w, h) in [("0", "100"), ("100", "0"), ("8", "8")] {
        let o = mapc()
            .current_dir(dir.path())
            .args(["synth", "--width", w, "--height", h, "-o", "s"])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{w} x {h}: {}", text(&o));
        assert!(text(&o).contains("at least 16 cells"), "{}", text(&o));
    }
    assert!(!dir.path().join("s").exists(), "files were written");
}

#[test]
fn a_damaged_database_is_refused_unless_no_verify() {
    let (db, scans) = fixture();
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.refdb");
    let mut bytes = std::fs::read(db).unwrap();
    // One bit flipped in the middle of the file: inside a section's
    // payload (the grid, distance map and scans fill it), so the structure
    // still reads and only that section's CRC is wrong.
    let k = bytes.len() / 2;
    bytes[k] ^= 0x10;
    std::fs::write(&bad, &bytes).unwrap();
    let bad_s = bad.to_str().unwrap();
    for args in [
        vec!["info", bad_s],
        vec!["localize", bad_s, scans.to_str().unwrap()],
    ] {
        let o = mapc().args(&args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
        assert!(text(&o).contains("checksum"), "{args:?}: {}", text(&o));
        assert!(text(&o).contains("--no-verify"), "{args:?}: {}", text(&o));
    }
    // `mapc verify` reports it as a failed check (exit 1), not bad usage.
    let o = mapc().args(["verify", bad_s]).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    // The user can still choose to read it.
    let o = mapc()
        .args(["info", bad_s, "--no-verify"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

#[test]
fn a_fifo_as_the_database_is_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("db.fifo");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("skipped: mkfifo is not available");
        return;
    }
    // Opening a FIFO for reading blocks until a writer comes: this returns
    // only because mapc refuses it before opening.
    for cmd in ["info", "verify"] {
        let o = mapc().args([cmd, fifo.to_str().unwrap()]).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{cmd}: {}", text(&o));
        assert!(text(&o).contains("not a regular file"), "{}", text(&o));
    }
}

#[test]
fn build_refuses_an_output_that_is_an_input_or_a_special_file() {
    let maps = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../maps/office-demo");
    let dir = tempfile::tempdir().unwrap();
    for f in ["office-demo.pgm", "office-demo.yaml"] {
        std::fs::copy(maps.join(f), dir.path().join(f)).unwrap();
    }
    let before: Vec<Vec<u8>> = ["office-demo.pgm", "office-demo.yaml"]
        .iter()
        .map(|f| std::fs::read(dir.path().join(f)).unwrap())
        .collect();
    let mut outs = vec![
        ("office-demo.yaml", "same file as the input"),
        ("office-demo.pgm", "same file as the input"),
        (".", "not a regular file"),
    ];
    // A FIFO made here stands for devices like /dev/null or /dev/stdout (a
    // regression must not be able to replace a system file).
    let fifo_made = Command::new("mkfifo")
        .arg(dir.path().join("out.fifo"))
        .status()
        .is_ok_and(|s| s.success());
    if fifo_made {
        outs.push(("out.fifo", "not a regular file"));
    }
    for (out, why) in outs {
        let o = mapc()
            .current_dir(dir.path())
            .args(["build", "office-demo.yaml", "-o", out, "--fit-queries", "5"])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "-o {out}: {}", text(&o));
        assert!(text(&o).contains(why), "-o {out}: {}", text(&o));
    }
    let after: Vec<Vec<u8>> = ["office-demo.pgm", "office-demo.yaml"]
        .iter()
        .map(|f| std::fs::read(dir.path().join(f)).unwrap())
        .collect();
    assert!(before == after, "an input was changed");
    if fifo_made {
        use std::os::unix::fs::FileTypeExt;
        let t = std::fs::metadata(dir.path().join("out.fifo"))
            .unwrap()
            .file_type();
        assert!(t.is_fifo(), "the FIFO was replaced by a file");
    }
}

#[test]
fn render_synth_and_eval_refuse_outputs_that_are_inputs_or_special_files() {
    let maps = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../maps/office-demo");
    let dir = tempfile::tempdir().unwrap();
    for f in ["office-demo.pgm", "office-demo.yaml"] {
        std::fs::copy(maps.join(f), dir.path().join(f)).unwrap();
    }
    let pgm = std::fs::read(dir.path().join("office-demo.pgm")).unwrap();
    let run = |args: &[&str]| mapc().current_dir(dir.path()).args(args).output().unwrap();
    // render -o the map's own image.
    let o = run(&["render", "office-demo.yaml", "-o", "office-demo.pgm"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("same file as the input"), "{}", text(&o));
    assert_eq!(
        std::fs::read(dir.path().join("office-demo.pgm")).unwrap(),
        pgm
    );
    // synth into a name that is a directory.
    std::fs::create_dir(dir.path().join("taken.pgm")).unwrap();
    let o = run(&["synth", "--name", "taken", "-o", "."]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("not a regular file"), "{}", text(&o));
    assert!(dir.path().join("taken.pgm").is_dir());
    // eval --out a regular file, and a --check baseline that is the report
    // the run would write.
    let (db, _) = fixture();
    let db = db.to_str().unwrap();
    std::fs::write(dir.path().join("file"), b"x").unwrap();
    let o = run(&[
        "eval",
        db,
        "--out",
        "file",
        "--poses",
        "2",
        "--experiments",
        "static",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("not a directory"), "{}", text(&o));
    assert_eq!(std::fs::read(dir.path().join("file")).unwrap(), b"x");
    std::fs::create_dir(dir.path().join("ev")).unwrap();
    std::fs::write(dir.path().join("ev/report.json"), b"{}").unwrap();
    let o = run(&[
        "eval",
        db,
        "--out",
        "ev",
        "--check",
        "ev/report.json",
        "--poses",
        "2",
        "--experiments",
        "static",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("same file as the input"), "{}", text(&o));
    assert_eq!(
        std::fs::read(dir.path().join("ev/report.json")).unwrap(),
        b"{}"
    );
}

/// Address-space limit of the resource-bounded cases: far below what the
/// unbounded versions reached (4.3 GB to 22 GB), far above what a refusal
/// needs.
const LIMIT_AS: u64 = 1 << 30;
/// CPU-time limit (seconds) of the resource-bounded cases: exceeding it
/// kills the process with SIGXCPU/SIGKILL, which fails the exit-code
/// assertion. Not a wall-clock bound: a loaded machine does not trip it.
const LIMIT_CPU: u64 = 60;

/// `mapc` under `setrlimit` RLIMIT_AS (`LIMIT_AS`) and RLIMIT_CPU
/// (`LIMIT_CPU`), set in the child between fork and exec. A case that
/// allocated without bound would die (allocation failure aborts, or
/// SIGKILL at the CPU hard limit) instead of exiting 2.
#[cfg(unix)]
fn bounded_mapc() -> Command {
    use std::os::unix::process::CommandExt;
    let mut c = mapc();
    // SAFETY: only setrlimit (async-signal-safe) runs in the child.
    unsafe {
        c.pre_exec(|| {
            for (res, v) in [(libc::RLIMIT_AS, LIMIT_AS), (libc::RLIMIT_CPU, LIMIT_CPU)] {
                let lim = libc::rlimit {
                    rlim_cur: v as libc::rlim_t,
                    rlim_max: v as libc::rlim_t,
                };
                if libc::setrlimit(res, &lim) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
            }
            Ok(())
        });
    }
    c
}

/// Copies the demo map's image (400 x 300, no YAML beside it) into `dir`
/// as `room.pgm`.
fn copy_room(dir: &Path) {
    let maps = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../maps/office-demo");
    std::fs::copy(maps.join("office-demo.pgm"), dir.join("room.pgm")).unwrap();
}

/// Runs `cmd` as `build room.pgm --resolution 0.05 -o <out> --fit-queries 0
/// -q <extra>` in `dir`.
fn build_room(mut cmd: Command, dir: &Path, out: &str, extra: &[&str]) -> Output {
    cmd.current_dir(dir)
        .args(["build", "room.pgm", "--resolution", "0.05", "-o", out])
        .args(["--fit-queries", "0", "-q"])
        .args(extra)
        .output()
        .unwrap()
}

/// The names in `dir`, sorted.
fn names_in(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// A directory holding a copy of the fixture database as `good.refdb`:
/// (directory, its bytes).
fn dir_with_good_db() -> (tempfile::TempDir, Vec<u8>) {
    let (db, _) = fixture();
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(db, dir.path().join("good.refdb")).unwrap();
    let before = std::fs::read(dir.path().join("good.refdb")).unwrap();
    (dir, before)
}

/// Runs `mapc build <image> -o good.refdb --resolution 0.05 <extra>` in
/// `dir` under the resource limits; asserts exit 2, a message naming
/// `--max-cells` and containing `says`, and `good.refdb` unchanged.
#[cfg(unix)]
fn assert_image_refused(dir: &Path, before: &[u8], image: &str, extra: &[&str], says: &str) {
    let o = bounded_mapc()
        .current_dir(dir)
        .args(["build", image, "-o", "good.refdb", "--resolution", "0.05"])
        .args(extra)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{image}: {}", text(&o));
    assert!(text(&o).contains("--max-cells"), "{}", text(&o));
    assert!(text(&o).contains(says), "{}", text(&o));
    assert_eq!(std::fs::read(dir.join("good.refdb")).unwrap(), before);
}

#[cfg(unix)]
#[test]
fn image_size_bombs_are_refused_from_the_header_under_a_memory_limit() {
    let (dir, before) = dir_with_good_db();
    // A 40000 x 40000 PGM header (1.6e9 cells, within MAX_CELLS, above the
    // default --max-cells) followed by a few bytes.
    let mut pgm = b"P5\n40000 40000\n255\n".to_vec();
    pgm.extend_from_slice(&[255; 64]);
    std::fs::write(dir.path().join("bomb.pgm"), &pgm).unwrap();
    assert_image_refused(
        dir.path(),
        &before,
        "bomb.pgm",
        &[],
        "image is 40000 x 40000 pixels (1600000000 cells); the limit is 268435456 cells",
    );
    // The same PNG-sized claim: a real 8-bit grey PNG header (IHDR) of
    // 46000 x 46000 with a tiny IDAT.
    std::fs::write(dir.path().join("bomb.png"), png_header_only(46000, 46000)).unwrap();
    assert_image_refused(
        dir.path(),
        &before,
        "bomb.png",
        &[],
        "image is 46000 x 46000 pixels",
    );
    // A small map with a lower limit: the demo map is 400 x 300 (see
    // maps/office-demo).
    copy_room(dir.path());
    assert_image_refused(
        dir.path(),
        &before,
        "room.pgm",
        &["--max-cells", "1000"],
        "the limit is 1000 cells, 4000 decoded bytes",
    );
    // Few cells but 8 decoded bytes each (16-bit RGBA PAM): the decoded
    // size is refused before the pixels are read.
    let mut pam =
        b"P7\nWIDTH 30\nHEIGHT 30\nDEPTH 4\nMAXVAL 65535\nTUPLTYPE RGB_ALPHA\nENDHDR\n".to_vec();
    pam.extend(std::iter::repeat_n(0xffu8, 30 * 30 * 8));
    std::fs::write(dir.path().join("wide.pam"), &pam).unwrap();
    assert_image_refused(
        dir.path(),
        &before,
        "wide.pam",
        &["--max-cells", "1000"],
        "(900 cells, 7200 bytes decoded); the limit is 1000 cells, 4000 decoded bytes",
    );
    // Out-of-range limits are usage errors.
    for bad in ["0", "2147483649"] {
        let o = mapc()
            .current_dir(dir.path())
            .args([
                "build",
                "room.pgm",
                "--resolution",
                "0.05",
                "--max-cells",
                bad,
            ])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        assert!(text(&o).contains("--max-cells"), "{}", text(&o));
    }
    assert_eq!(
        names_in(dir.path()),
        ["bomb.pgm", "bomb.png", "good.refdb", "room.pgm", "wide.pam"]
    );
}

/// A PNG of `w` x `h` 8-bit grey pixels whose IDAT holds one empty stored
/// deflate block: the header is valid, the data far too short.
fn png_header_only(w: u32, h: u32) -> Vec<u8> {
    use mapc::testdata::png::chunk;
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    chunk(&mut png, b"IHDR", &ihdr);
    chunk(
        &mut png,
        b"IDAT",
        &[0x78, 0x01, 0x01, 0x00, 0x00, 0xff, 0xff, 0, 0, 0, 1],
    );
    chunk(&mut png, b"IEND", &[]);
    png
}

#[cfg(unix)]
#[test]
fn unbounded_cases_stay_bounded_under_memory_and_cpu_limits() {
    let (dir, before) = dir_with_good_db();
    copy_room(dir.path());
    // Sites per GVD edge are capped by the edge's cells: a spacing of
    // 1e-12 m (4.3 GB and an abort before) builds within the limits.
    let o = build_room(
        bounded_mapc(),
        dir.path(),
        "tiny.refdb",
        &["--site-spacing", "1e-12"],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = mapc()
        .args(["verify", dir.path().join("tiny.refdb").to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    // An endless --check baseline (22 GB in 60 s before) is refused by size.
    if Path::new("/dev/zero").exists() {
        let out = tempfile::tempdir().unwrap();
        let o = bounded_mapc()
            .current_dir(dir.path())
            .args(["eval", "good.refdb", "--check", "/dev/zero", "--no-figures"])
            .args(["--out", out.path().to_str().unwrap()])
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        assert!(text(&o).contains("larger than 64 MiB"), "{}", text(&o));
        assert!(!out.path().join("report.json").exists());
    }
    assert_eq!(
        std::fs::read(dir.path().join("good.refdb")).unwrap(),
        before
    );
    assert_eq!(
        names_in(dir.path()),
        ["good.refdb", "room.pgm", "tiny.refdb"]
    );
}

#[cfg(unix)]
#[test]
fn huge_yaml_resolutions_are_refused_by_database_size_under_a_memory_limit() {
    let (dir, before) = dir_with_good_db();
    copy_room(dir.path());
    // At 100 m (or 10^6 m) per cell the site spacing and the coverage
    // range are far below a cell, so almost every free cell of the demo
    // map becomes a site (3.5 GB, and past 4 GB, before): refused once the
    // sites are placed, before their scans and histograms exist.
    for res in ["100", "1e6"] {
        let yaml = format!("res-{res}.yaml");
        std::fs::write(
            dir.path().join(&yaml),
            format!(
                "image: room.pgm\nresolution: {res}\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n\
                 occupied_thresh: 0.65\nfree_thresh: 0.196\n"
            ),
        )
        .unwrap();
        let o = bounded_mapc()
            .current_dir(dir.path())
            .args(["build", &yaml, "-o", "good.refdb", "--fit-queries", "0"])
            .output()
            .unwrap();
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{res}: {t}");
        assert!(t.contains("reference sites of"), "{t}");
        assert!(
            t.contains("the limit is 1073741824 bytes (--max-db-bytes raises it)"),
            "{t}"
        );
        assert_eq!(
            std::fs::read(dir.path().join("good.refdb")).unwrap(),
            before
        );
    }
    // Zero is a usage error.
    let o = build_room(mapc(), dir.path(), "zero.refdb", &["--max-db-bytes", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("--max-db-bytes"), "{}", text(&o));
    assert_eq!(
        names_in(dir.path()),
        ["good.refdb", "res-100.yaml", "res-1e6.yaml", "room.pgm"]
    );
}

#[cfg(unix)]
#[test]
fn a_build_removes_stale_temporary_files_of_its_output_and_nothing_else() {
    use std::os::unix::io::AsRawFd;
    let (dir, _) = dir_with_good_db();
    copy_room(dir.path());
    let hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    let make = |name: &str, old: bool| {
        let f = std::fs::File::create(dir.path().join(name)).unwrap();
        f.set_len(1000).unwrap();
        if old {
            f.set_modified(hour_ago).unwrap();
        }
        f
    };
    // What a build killed mid-write leaves: its pattern, old, unlocked.
    drop(make(".good.refdb.Ab3xZ9.tmp", true));
    // A live writer's file: old but locked (flock) by this process.
    let live = make(".good.refdb.Live01.tmp", true);
    // SAFETY: flock on an open descriptor.
    assert_eq!(
        unsafe { libc::flock(live.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) },
        0
    );
    // Just created (another writer may not have locked it yet).
    drop(make(".good.refdb.Fresh1.tmp", false));
    // Other names: another output's, a wrong length, a user's file.
    drop(make(".other.refdb.Ab3xZ9.tmp", true));
    drop(make(".good.refdb.toolong7.tmp", true));
    drop(make("good.refdb.Ab3xZ9.tmp", true));
    let o = build_room(mapc(), dir.path(), "good.refdb", &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert_eq!(
        names_in(dir.path()),
        [
            ".good.refdb.Fresh1.tmp",
            ".good.refdb.Live01.tmp",
            ".good.refdb.toolong7.tmp",
            ".other.refdb.Ab3xZ9.tmp",
            "good.refdb",
            "good.refdb.Ab3xZ9.tmp",
            "room.pgm",
        ]
    );
    drop(live);
}
