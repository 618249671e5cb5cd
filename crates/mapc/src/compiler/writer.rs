//! Writing a `.refdb` safely: the file is streamed into a temporary file in
//! the target directory, flushed and synced, and only then renamed over the
//! final name. A full disk or a write error leaves any existing database
//! under that name untouched and no half-written file behind. A killed
//! process cannot remove its temporary file (`.<name>.XXXXXX.tmp`); the
//! next write to the same name removes such stale files ([`remove_stale`]).

use std::io::{self, Write};
use std::path::Path;

use refloc::format::{encode, SectionKind};

/// Writes the sections as a `.refdb` at `path` atomically. Returns the file size.
///
/// Before the new file takes the name, it is read back from the temporary
/// file with the reader `localize` uses (`refloc::open_mmap`: structure,
/// parameters, sections) and its checksums are verified: a database that
/// would not load (for example a map origin that is finite as f64 but not
/// as f32) is an `InvalidData` error, and any old file under `path` stays
/// byte-identical.
pub fn write_refdb(path: &Path, sections: &[(SectionKind, &[u8])]) -> io::Result<u64> {
    write_atomic_checked(
        path,
        |w| encode(sections, |b| w.write_all(b)),
        |tmp| {
            let bad = |e: &dyn std::fmt::Display| {
                io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("the database built does not read back, so it was not written: {e}"),
                )
            };
            let db = match refloc::open_mmap(tmp) {
                Ok(db) => db,
                Err(refloc::OpenError::Io(e)) => return Err(e),
                Err(e) => return Err(bad(&e)),
            };
            db.verify().map_err(|e| bad(&e))
        },
    )
}

/// A new, empty temporary file beside `path` (same directory, so the
/// final rename cannot cross file systems), removed when dropped.
fn temp_beside(path: &Path) -> io::Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} is not a file path", path.display()),
        )
    })?;
    tempfile::Builder::new()
        .prefix(&temp_prefix(name))
        .suffix(TEMP_SUFFIX)
        .rand_bytes(TEMP_RAND)
        .tempfile_in(dir)
}

/// The temporary files of `name` are `.<name>.` + [`TEMP_RAND`] random
/// ASCII letters and digits + [`TEMP_SUFFIX`].
fn temp_prefix(name: &std::ffi::OsStr) -> String {
    format!(".{}.", name.to_string_lossy())
}
const TEMP_SUFFIX: &str = ".tmp";
const TEMP_RAND: usize = 6;

/// A temporary file younger than this is never removed as stale: it may
/// belong to a writer that has created it and not yet locked it.
pub const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(10);

/// Removes the temporary files a killed writer of `path` left behind; returns
/// how many were removed. A file is removed only when its name has exactly
/// the writer's pattern for this `path` (`.<name>.XXXXXX.tmp`), it is a
/// regular file (not a symlink), it was last modified at least
/// [`STALE_AFTER`] ago, and no process holds its lock: every writer holds
/// an exclusive `flock` on its temporary file while it writes, and the
/// kernel releases it when the writer dies, so a live writer's file is
/// never taken. Errors (an unreadable directory, a file that vanished)
/// skip the file. Unix only; elsewhere nothing is removed.
pub fn remove_stale(path: &Path) -> usize {
    #[cfg(unix)]
    {
        let Some(name) = path.file_name() else {
            return 0;
        };
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let prefix = temp_prefix(name);
        let Ok(entries) = std::fs::read_dir(dir) else {
            return 0;
        };
        let mut removed = 0;
        for entry in entries.flatten() {
            let file_name = entry.file_name();
            let Some(n) = file_name.to_str() else {
                continue;
            };
            let Some(rand) = n
                .strip_prefix(prefix.as_str())
                .and_then(|r| r.strip_suffix(TEMP_SUFFIX))
            else {
                continue;
            };
            if rand.len() != TEMP_RAND || !rand.bytes().all(|b| b.is_ascii_alphanumeric()) {
                continue;
            }
            let p = entry.path();
            if is_stale(&p) && std::fs::remove_file(&p).is_ok() {
                removed += 1;
            }
        }
        removed
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        0
    }
}

/// A regular file (not followed through a symlink), old enough, whose
/// `flock` can be taken (the lock is dropped with the file).
#[cfg(unix)]
fn is_stale(p: &Path) -> bool {
    let Ok(meta) = std::fs::symlink_metadata(p) else {
        return false;
    };
    let old = meta
        .modified()
        .ok()
        .and_then(|m| m.elapsed().ok())
        .is_some_and(|age| age >= STALE_AFTER);
    if !meta.file_type().is_file() || !old {
        return false;
    }
    std::fs::File::open(p).is_ok_and(|f| try_lock(&f))
}

/// Takes an exclusive `flock` on `f` without waiting; false when another
/// open file holds it (or locking fails).
#[cfg(unix)]
fn try_lock(f: &std::fs::File) -> bool {
    use std::os::unix::io::AsRawFd;
    // SAFETY: flock on a valid, open descriptor; no memory is passed.
    unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// Checks that [`write_atomic`] could write `path` now: a temporary file
/// can be created beside it (and is removed again). `path` itself is not
/// touched. Meant to fail fast, before a long computation whose result
/// could not be saved (a read-only or missing directory); the write itself
/// still reports its own errors.
pub fn check_writable(path: &Path) -> io::Result<()> {
    temp_beside(path).map(drop)
}

/// Checks that `path` may receive a new file by rename: it does not exist,
/// or it is a regular file (following symlinks) that is none of `inputs`
/// (compared by device and inode, so another name for the same file is
/// caught too). A device (`/dev/null`, `/dev/stdout`), a FIFO or a
/// directory would be replaced by a regular file; an input would be
/// destroyed by its own output. The error is `InvalidInput` and says which.
pub fn check_output_path(path: &Path, inputs: &[&Path]) -> io::Result<()> {
    let refuse = |why: String| Err(io::Error::new(io::ErrorKind::InvalidInput, why));
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(e),
    };
    if !meta.is_file() {
        return refuse(
            "not a regular file (a device, FIFO or directory): the output must be a new name or a regular file".into(),
        );
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        for input in inputs {
            if let Ok(m) = std::fs::metadata(input) {
                if (m.dev(), m.ino()) == (meta.dev(), meta.ino()) {
                    return refuse(format!(
                        "is the same file as the input {}: writing it would destroy the input",
                        input.display()
                    ));
                }
            }
        }
    }
    #[cfg(not(unix))]
    for input in inputs {
        if let (Ok(a), Ok(b)) = (std::fs::canonicalize(input), std::fs::canonicalize(path)) {
            if a == b {
                return refuse(format!("is the same file as the input {}", input.display()));
            }
        }
    }
    Ok(())
}

/// Runs `fill` on a temporary file beside `path`, then renames it to `path`.
/// On any error the temporary file is removed and `path` is untouched.
pub fn write_atomic<T>(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<T>,
) -> io::Result<T> {
    write_atomic_checked(path, fill, |_| Ok(()))
}

/// [`write_atomic`] with a last check: `check` gets the path of the
/// complete, synced temporary file and can refuse it; only then is it
/// renamed to `path`. On any error (of `fill` or `check`) the temporary
/// file is removed and `path` is untouched.
pub fn write_atomic_checked<T>(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<T>,
    check: impl FnOnce(&Path) -> io::Result<()>,
) -> io::Result<T> {
    remove_stale(path);
    let mut tmp = temp_beside(path)?;
    // Held until the file is dropped (after the rename): marks it live
    // for `remove_stale` in other processes.
    #[cfg(unix)]
    if !try_lock(tmp.as_file()) {
        return Err(io::Error::last_os_error());
    }
    let out = {
        let mut w = io::BufWriter::new(tmp.as_file_mut());
        let out = fill(&mut w)?;
        w.flush()?;
        out
    };
    // The temporary file is created 0600; give the database the usual
    // permissions of a new file (or keep those of the file it replaces).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(path)
            .map(|m| m.permissions().mode() & 0o777)
            .unwrap_or(0o644);
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(mode))?;
    }
    tmp.as_file().sync_all()?;
    check(tmp.path())?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failure_leaves_old_file_and_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.refdb");
        std::fs::write(&p, b"good").unwrap();
        let r: io::Result<()> = write_atomic(&p, |w| {
            w.write_all(b"half")?;
            Err(io::Error::other("simulated disk full"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"good");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "temporary file left behind: {names:?}");
    }

    #[test]
    fn check_writable_leaves_nothing_and_fails_on_a_missing_directory() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.refdb");
        check_writable(&p).unwrap();
        std::fs::write(&p, b"good").unwrap();
        check_writable(&p).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"good");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let e = check_writable(&dir.path().join("missing/a.refdb")).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::NotFound, "{e}");
        assert!(check_writable(Path::new("/")).is_err());
    }

    #[test]
    fn a_refused_file_leaves_the_old_one_and_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.refdb");
        std::fs::write(&p, b"good").unwrap();
        let mut seen = Vec::new();
        let r = write_atomic_checked(
            &p,
            |w| w.write_all(b"complete but wrong"),
            |tmp| {
                seen = std::fs::read(tmp)?;
                Err(io::Error::new(io::ErrorKind::InvalidData, "refused"))
            },
        );
        assert_eq!(r.unwrap_err().kind(), io::ErrorKind::InvalidData);
        assert_eq!(seen, b"complete but wrong", "check saw the whole file");
        assert_eq!(std::fs::read(&p).unwrap(), b"good");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        // An image that is no database is refused by write_refdb's check.
        let e = write_refdb(&p, &[]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData, "{e}");
        assert!(e.to_string().contains("does not read back"), "{e}");
        assert_eq!(std::fs::read(&p).unwrap(), b"good");
    }

    #[test]
    fn output_paths_that_are_inputs_or_special_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let map = dir.path().join("m.yaml");
        std::fs::write(&map, b"image: m.pgm").unwrap();
        let new = dir.path().join("new.refdb");
        check_output_path(&new, &[&map]).unwrap();
        std::fs::write(&new, b"old db").unwrap();
        check_output_path(&new, &[&map]).unwrap();
        let e = check_output_path(&map, &[&map]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput, "{e}");
        assert!(e.to_string().contains("same file as the input"), "{e}");
        // Another name for the input (a hard link) is the same file.
        let link = dir.path().join("alias.refdb");
        std::fs::hard_link(&map, &link).unwrap();
        assert!(check_output_path(&link, &[&map]).is_err());
        let e = check_output_path(dir.path(), &[]).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        if Path::new("/dev/null").exists() {
            assert!(check_output_path(Path::new("/dev/null"), &[]).is_err());
        }
    }

    #[test]
    fn success_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.refdb");
        std::fs::write(&p, b"old").unwrap();
        write_atomic(&p, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
    }
}
