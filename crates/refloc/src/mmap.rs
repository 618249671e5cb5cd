//! Opening a `.refdb` file by memory map (feature `mmap`, needs `std`).

extern crate std;

use std::fs::File;
use std::path::Path;

use crate::RefDb;

/// Error opening a mapped database.
#[derive(Debug)]
pub enum OpenError {
    /// The file could not be opened or mapped.
    Io(std::io::Error),
    /// The bytes are not a valid database.
    Db(crate::DbError),
}

impl core::fmt::Display for OpenError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            OpenError::Io(e) => write!(f, "{e}"),
            OpenError::Db(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for OpenError {}

/// Maps `path` read-only and validates it with [`RefDb::new`].
///
/// The mapping is made by [`map_file`]; its safety contract applies.
pub fn open_mmap(path: &Path) -> Result<RefDb<memmap2::Mmap>, OpenError> {
    let map = map_file(path).map_err(OpenError::Io)?;
    RefDb::new(map).map_err(OpenError::Db)
}

/// Maps `path` read-only, without validating it (for a caller that builds
/// its own container around the mapping; [`open_mmap`] validates).
///
/// # Safety contract (why this is sound in practice)
/// A memory map is only valid while nobody truncates or rewrites the file:
/// another process doing so can make reads fault (SIGBUS) or change bytes
/// after validation. `mapc build` never rewrites a database in place (it
/// writes a temporary file and renames it over the old one, which leaves
/// existing maps intact), so a database produced by mapc and left alone by
/// other programs is safe to map. Callers who cannot guarantee that should
/// read the file into a `Vec<u8>` instead.
#[allow(unsafe_code)]
pub fn map_file(path: &Path) -> std::io::Result<memmap2::Mmap> {
    let file = File::open(path)?;
    // SAFETY: see the contract above: the file is opened read-only and the
    // mapping is treated as immutable bytes; concurrent truncation by another
    // process is outside what this function can prevent and is documented.
    unsafe { memmap2::Mmap::map(&file) }
}
