//! Where tests and benchmarks find the shared public data (`../shared/`
//! beside the repository: real maps and laser logs, never copied into it).
//!
//! A fresh clone may not have it: [`shared`] then returns `None` and the
//! caller skips with a message. CI sets `REFLOC_REQUIRE_SHARED=1` (see
//! `.ci/run`), which turns a missing file into a test failure, so those
//! tests cannot be skipped silently there. `REFLOC_SHARED=/path` overrides
//! the location.

use std::path::PathBuf;

/// The shared data folder, if present.
pub fn shared_root() -> Option<PathBuf> {
    let root = match std::env::var_os("REFLOC_SHARED") {
        Some(p) => PathBuf::from(p),
        None => PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared")),
    };
    root.is_dir().then_some(root)
}

/// `rel` inside the shared folder (e.g. `maps/intel/intel.yaml`), or `None`
/// with a message on stderr when it is absent.
///
/// # Panics
/// When the file is absent and `REFLOC_REQUIRE_SHARED=1` (as in CI).
pub fn shared(rel: &str) -> Option<PathBuf> {
    let p = shared_root().map(|r| r.join(rel)).filter(|p| p.exists());
    if p.is_none() {
        let required = std::env::var("REFLOC_REQUIRE_SHARED").is_ok_and(|v| v == "1");
        assert!(!required, "shared data file {rel} is missing but REFLOC_REQUIRE_SHARED=1 (expected ../shared beside the repository, or REFLOC_SHARED)");
        eprintln!("skipped: shared data {rel} not found (../shared beside the repository); this part of the test did not run");
    }
    p
}

/// Raw PNG pieces for tests that hand-craft (often hostile) PNG files.
pub mod png {
    /// CRC-32 (ISO-HDLC, the PNG chunk checksum) of `data`.
    pub fn crc32(data: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in data {
            crc ^= b as u32;
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    /// Appends one chunk (length, kind, data, CRC) to `out`.
    pub fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut c = kind.to_vec();
        c.extend_from_slice(data);
        out.extend_from_slice(&c);
        out.extend_from_slice(&crc32(&c).to_be_bytes());
    }
}
