//! Fuzzing regressions, on stable: the committed seed corpora and every
//! saved fuzzer finding (`tests/fuzz/<target>/`) replayed through the very
//! harnesses the libFuzzer targets run (`fuzz/src/lib.rs`, included below),
//! plus checks that the seeds are still meaningful (a valid database, a
//! loadable map, readable scans) so a format change cannot silently turn the
//! corpora into noise.
//!
//! Fuzzing itself needs nightly: `scripts/fuzz.sh` (see
//! `docs/robustness.md`).

use std::path::{Path, PathBuf};

#[allow(dead_code)]
#[path = "../fuzz/src/lib.rs"]
mod harness;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The files of a directory, sorted; empty if it does not exist.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

fn corpus(target: &str) -> Vec<PathBuf> {
    let v = files(&root().join("fuzz/corpus").join(target));
    assert!(!v.is_empty(), "no seeds in fuzz/corpus/{target}");
    v
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Runs `f` on one saved input; on panic, names the file.
fn replay(path: &Path, f: fn(&[u8])) {
    let data = read(path);
    if std::panic::catch_unwind(|| f(&data)).is_err() {
        panic!("harness panicked on {}", path.display());
    }
}

// ---------------------------------------------------------------------------
// Corpus replay (what `scripts/fuzz.sh --replay` does, without nightly).

#[test]
fn replay_refdb_corpus() {
    for p in corpus("refdb") {
        replay(&p, harness::refdb);
    }
}

#[test]
fn replay_mapfile_corpus() {
    for p in corpus("mapfile") {
        replay(&p, harness::mapfile);
    }
}

#[test]
fn replay_scanio_corpus() {
    for p in corpus("scanio") {
        replay(&p, harness::scanio);
    }
}

// ---------------------------------------------------------------------------
// The seeds still mean something.

#[test]
fn refdb_seeds_are_valid_databases() {
    for p in corpus("refdb") {
        let mut file = harness::refdb_prefix().to_vec();
        file.extend_from_slice(&read(&p));
        let aligned = harness::Aligned::copy_of(&file);
        let db = refloc::RefDb::new(aligned.bytes()).unwrap_or_else(|e| {
            panic!(
                "{}: not a valid database for this reader ({e}); rerun fuzz/make-seeds.sh",
                p.display()
            )
        });
        db.verify()
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    }
}

#[test]
fn mapfile_seeds_load() {
    for p in corpus("mapfile") {
        let data = read(&p);
        let sep = harness::MAP_SEPARATOR;
        let i = data
            .windows(sep.len())
            .position(|w| w == sep)
            .unwrap_or_else(|| panic!("{}: no separator", p.display()));
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("map.yaml"), &data[..i]).unwrap();
        std::fs::write(dir.path().join(harness::MAP_IMAGE_NAME), &data[i + sep.len()..]).unwrap();
        let src = mapc::mapfile::load_yaml(&dir.path().join("map.yaml"))
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(src.grid.free_count() > 0);
    }
}

#[test]
fn scanio_seeds_yield_scans() {
    use mapc::scanio::{open_input, read_scans, InputFormat, ReadOptions};
    for p in corpus("scanio") {
        let reader = open_input(&p.to_string_lossy()).unwrap();
        let ok = read_scans(reader, InputFormat::Auto, &ReadOptions::default())
            .filter(|r| r.is_ok())
            .count();
        assert!(ok > 0, "{}: no scan read", p.display());
    }
}

// ---------------------------------------------------------------------------
// Saved fuzzer findings (minimized with `cargo fuzz tmin`), one test each.
