//! Output safety of `mapc build`: writing a database into a directory the
//! process may not write fails with a clear error and a non-zero exit, and a
//! good database already there stays byte for byte as it was (the writer's
//! simulated mid-write failure is a unit test in `crates/mapc/src/compiler/writer.rs`).
//!
//! Permissions only bind an unprivileged process: root (uid 0, as in this
//! project's containers and some CI runners) writes into a `chmod 0555`
//! directory anyway. So when the tests run as root, the `mapc` process is
//! started as `nobody` (uid/gid 65534) through util-linux's `setpriv`, and
//! the permission really applies. Either way the failure is exercised: if
//! it cannot be (root without `setpriv`, or a process that writes through
//! `0555` without being root, e.g. with `CAP_DAC_OVERRIDE`), the test fails
//! and says why; it never skips.
//!
//! Registered as an integration test of the `mapc` package (see
//! crates/mapc/Cargo.toml) so `CARGO_BIN_EXE_mapc` points at the binary.

#![cfg(unix)]

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The unprivileged user and group the test switches to when it runs as
/// root (`nobody` / `nogroup` on Debian and most distributions).
const NOBODY: u32 = 65534;

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn chmod(p: &Path, mode: u32) {
    std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode))
        .unwrap_or_else(|e| panic!("chmod {mode:o} {}: {e}", p.display()));
}

/// The effective user id of this process, as the owner of a file it
/// creates (no libc call needed).
fn effective_uid(dir: &Path) -> u32 {
    let probe = dir.join("uid-probe");
    std::fs::write(&probe, b"").unwrap();
    let uid = std::fs::metadata(&probe).unwrap().uid();
    std::fs::remove_file(&probe).unwrap();
    uid
}

/// How the `mapc` process is run.
enum Runner {
    /// As this (unprivileged) process's user.
    Direct,
    /// Through `setpriv` as uid/gid [`NOBODY`], without supplementary
    /// groups; `mapc` is a copy that user can execute.
    Nobody { setpriv: PathBuf, mapc: PathBuf },
}

impl Runner {
    /// Picks the way to run `mapc` so that a `0555` directory is read-only
    /// to it; `work` is a directory every user may traverse, for a copy of
    /// the binary.
    fn new(work: &Path) -> Runner {
        if effective_uid(work) != 0 {
            return Runner::Direct;
        }
        let setpriv = ["/usr/bin/setpriv", "/bin/setpriv", "/usr/sbin/setpriv"]
            .iter()
            .map(PathBuf::from)
            .find(|p| p.is_file())
            .unwrap_or_else(|| {
                panic!(
                    "the tests run as root, where `chmod 0555` does not stop writes, and \
                     `setpriv` (util-linux) is not installed to run mapc as an unprivileged \
                     user; install util-linux or run the tests as a normal user"
                )
            });
        // The build tree may sit under a directory other users cannot
        // traverse (a 0700 home): run a copy from the world-readable `work`.
        let bin = work.join("bin");
        std::fs::create_dir(&bin).unwrap();
        chmod(&bin, 0o755);
        let mapc = bin.join("mapc");
        std::fs::copy(env!("CARGO_BIN_EXE_mapc"), &mapc).unwrap();
        chmod(&mapc, 0o755);
        Runner::Nobody { setpriv, mapc }
    }

    fn mapc(&self, args: &[&str], cwd: &Path) -> Output {
        let mut cmd = match self {
            Runner::Direct => Command::new(env!("CARGO_BIN_EXE_mapc")),
            Runner::Nobody { setpriv, mapc } => {
                let mut c = Command::new(setpriv);
                c.arg(format!("--reuid={NOBODY}"))
                    .arg(format!("--regid={NOBODY}"))
                    .arg("--clear-groups")
                    .arg("--")
                    .arg(mapc);
                c
            }
        };
        cmd.args(args)
            .current_dir(cwd)
            .env("NO_COLOR", "1")
            .output()
            .expect("run mapc")
    }
}

/// A small map: a 60 x 40 room with walls and two pillars, as PGM + YAML.
fn write_room(dir: &Path) -> PathBuf {
    let (w, h) = (60usize, 40usize);
    let mut px = vec![254u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let wall = x < 2 || y < 2 || x >= w - 2 || y >= h - 2;
            let pillar = (15..19).contains(&x) && (10..14).contains(&y)
                || (40..43).contains(&x) && (22..30).contains(&y);
            if wall || pillar {
                px[y * w + x] = 0;
            }
        }
    }
    let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
    pgm.extend_from_slice(&px);
    std::fs::write(dir.join("room.pgm"), pgm).unwrap();
    let yaml = dir.join("room.yaml");
    std::fs::write(
        &yaml,
        "image: room.pgm\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n\
         occupied_thresh: 0.65\nfree_thresh: 0.196\n",
    )
    .unwrap();
    yaml
}

/// The names in a directory, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Restores write permission on drop, so the temporary directory can be
/// removed whatever happens.
struct Writable<'a>(&'a Path);

impl Drop for Writable<'_> {
    fn drop(&mut self) {
        let _ = std::fs::set_permissions(self.0, std::fs::Permissions::from_mode(0o755));
    }
}

#[test]
fn build_into_a_read_only_directory_fails_and_keeps_the_old_database() {
    let tmp = tempfile::tempdir().unwrap();
    let work = tmp.path();
    // tempdir() is 0700: let an unprivileged mapc reach the map and the
    // output directory.
    chmod(work, 0o755);
    let map = write_room(work);
    let out_dir = work.join("ro");
    std::fs::create_dir(&out_dir).unwrap();
    let out = out_dir.join("room.refdb");
    let (map_s, out_s) = (map.to_str().unwrap(), out.to_str().unwrap());
    let args = ["build", map_s, "-o", out_s, "--fit-queries", "0", "--quiet"];

    // A good database, built by this process while the directory is
    // writable.
    let direct = Runner::Direct;
    let o = direct.mapc(&args, work);
    assert!(o.status.success(), "first build: {}", text(&o));
    let good = std::fs::read(&out).unwrap();
    let good_file = std::fs::metadata(&out).unwrap();
    let before = listing(&out_dir);

    let runner = Runner::new(work);
    chmod(&out_dir, 0o555);
    let _restore = Writable(&out_dir);

    // The runner really is refused: writing into the directory fails for
    // it. For a direct run, probe from this process; through setpriv, the
    // control below shows the same mapc can read and run as that user.
    if let Runner::Direct = runner {
        let probe = out_dir.join("probe");
        if std::fs::write(&probe, b"x").is_ok() {
            let _ = std::fs::remove_file(&probe);
            panic!(
                "this process is not root but can write into a 0555 directory (a capability \
                 such as CAP_DAC_OVERRIDE?): the read-only case cannot be exercised"
            );
        }
    } else {
        let o = runner.mapc(&["verify", out_s], work);
        assert!(
            o.status.success(),
            "control: mapc as uid {NOBODY} cannot verify the existing database: {}",
            text(&o)
        );
    }

    let o = runner.mapc(&args, work);
    let msg = text(&o);
    assert!(
        !o.status.success(),
        "build into a 0555 directory succeeded: {msg}"
    );
    assert_eq!(o.status.code(), Some(1), "{msg}");
    assert!(
        msg.contains(&format!("error: {out_s}: cannot write: Permission denied")),
        "unclear error: {msg}"
    );
    assert_eq!(
        std::fs::read(&out).unwrap(),
        good,
        "the old database changed"
    );
    let now = std::fs::metadata(&out).unwrap();
    assert_eq!(
        (now.ino(), now.modified().unwrap()),
        (good_file.ino(), good_file.modified().unwrap()),
        "the old database was replaced or rewritten"
    );
    assert_eq!(listing(&out_dir), before, "files left behind");

    // A read-only directory with no database yet: same error, nothing new.
    let fresh = out_dir.join("other.refdb");
    let fresh_s = fresh.to_str().unwrap();
    let o = runner.mapc(
        &[
            "build",
            map_s,
            "-o",
            fresh_s,
            "--fit-queries",
            "0",
            "--quiet",
        ],
        work,
    );
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains(&format!("{fresh_s}: cannot write: Permission denied")),
        "{}",
        text(&o)
    );
    assert_eq!(listing(&out_dir), before);

    // And once writable again, the same command replaces the database.
    drop(_restore);
    let o = direct.mapc(&args, work);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(listing(&out_dir), before);
    assert_eq!(
        std::fs::read(&out).unwrap(),
        good,
        "builds are deterministic"
    );
}
