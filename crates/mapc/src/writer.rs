//! Writing a `.refdb` safely: the file is streamed into a temporary file in
//! the target directory, flushed and synced, and only then renamed over the
//! final name. A crash, a full disk or a write error leaves any existing
//! database under that name untouched and no half-written file behind.

use std::io::{self, Write};
use std::path::Path;

use refloc::format::{encode, SectionKind};

/// Writes the sections as a `.refdb` at `path` atomically. Returns the file size.
pub fn write_refdb(path: &Path, sections: &[(SectionKind, &[u8])]) -> io::Result<u64> {
    write_atomic(path, |w| encode(sections, |b| w.write_all(b)))
}

/// Runs `fill` on a temporary file beside `path`, then renames it to `path`.
/// On any error the temporary file is removed and `path` is untouched.
pub fn write_atomic<T>(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> io::Result<T>,
) -> io::Result<T> {
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
    let mut tmp = tempfile::Builder::new()
        .prefix(&format!(".{}.", name.to_string_lossy()))
        .suffix(".tmp")
        .tempfile_in(dir)?;
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
    fn success_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.refdb");
        std::fs::write(&p, b"old").unwrap();
        write_atomic(&p, |w| w.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
    }
}
