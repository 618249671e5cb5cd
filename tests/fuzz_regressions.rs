//! Fuzzing regressions, on stable: the committed seed corpora and every
//! saved fuzzer finding (`tests/fuzz/<target>/`) replayed through the very
//! harnesses the libFuzzer targets run (`fuzz/src/lib.rs`, included below),
//! plus checks that the seeds are still meaningful (a valid database, a
//! loadable map, readable scans) so a format change cannot silently turn the
//! corpora into noise.
//!
//! Every replay also bounds memory the way libFuzzer's `-rss_limit_mb=2048`
//! does: a counting global allocator records the largest single allocation
//! the test thread asks for, which must stay under [`MAX_ALLOC`].
//!
//! Fuzzing itself needs nightly: `scripts/fuzz.sh` (see
//! `docs/robustness.md`).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};

/// The largest single allocation a harness may make for one input (the
/// default `-malloc_limit_mb` of libFuzzer, which equals `-rss_limit_mb`).
const MAX_ALLOC: usize = 2048 << 20;

thread_local! {
    /// Largest allocation (bytes) requested by this thread since the last
    /// reset. `const`-initialized without destructor: reading it never
    /// allocates.
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

fn note(size: usize) {
    let _ = LARGEST.try_with(|c| c.set(c.get().max(size)));
}

/// `System`, recording the largest request of each thread.
struct Tracking;

// SAFETY: every call is forwarded unchanged to `System`; the bookkeeping
// only touches a const thread-local `Cell`, which does not allocate.
unsafe impl GlobalAlloc for Tracking {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Tracking = Tracking;

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

/// Runs `f` on one saved input; on panic, names the file. Also fails when
/// the harness asked for more than [`MAX_ALLOC`] bytes at once.
fn replay(path: &Path, f: fn(&[u8])) {
    let data = read(path);
    LARGEST.with(|c| c.set(0));
    if std::panic::catch_unwind(|| f(&data)).is_err() {
        panic!("harness panicked on {}", path.display());
    }
    let largest = LARGEST.with(Cell::get);
    assert!(
        largest <= MAX_ALLOC,
        "{}: one allocation of {largest} bytes (limit {MAX_ALLOC})",
        path.display()
    );
}

/// A saved finding of `target`.
fn finding(target: &str, name: &str) -> PathBuf {
    root().join("tests/fuzz").join(target).join(name)
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
    let mut with_index = 0;
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
        // A seed with a coarse-search index that has internal nodes, so the
        // fuzzer starts inside the index's validation and search.
        if db.index().is_some_and(|i| i.node_count() > 3) {
            with_index += 1;
        }
    }
    assert!(
        with_index > 0,
        "no refdb seed has a coarse-search index; rerun fuzz/make-seeds.sh"
    );
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
        std::fs::write(
            dir.path().join(harness::MAP_IMAGE_NAME),
            &data[i + sep.len()..],
        )
        .unwrap();
        let src = mapc::compiler::mapfile::load_yaml(&dir.path().join("map.yaml"))
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(src.grid.free_count() > 0);
    }
}

#[test]
fn scanio_seeds_yield_scans() {
    use mapc::tools::scanio::{open_input, read_scans, InputFormat, ReadOptions};
    for p in corpus("scanio") {
        let reader = open_input(&p.to_string_lossy()).unwrap();
        let ok = read_scans(reader, InputFormat::Auto, &ReadOptions::default())
            .filter(|r| r.is_ok())
            .count();
        assert!(ok > 0, "{}: no scan read", p.display());
    }
}

#[test]
fn replay_bag_corpus() {
    for p in corpus("bag") {
        replay(&p, harness::bag);
    }
}

#[test]
fn replay_cdr_corpus() {
    for p in corpus("cdr") {
        replay(&p, harness::cdr);
    }
}

/// Every bag seed but `no-scan-topic` opens with `/scan` chosen by name and
/// yields scans; the chunked one has two LaserScan topics, so it needs the
/// name; the cut one ends with the end-of-bag error.
#[test]
fn bag_seeds_yield_scans() {
    use mapc::tools::scanio::bag::{open_bag, BagError};
    use mapc::tools::scanio::ReadOptions;
    for p in corpus("bag") {
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        match (name.as_str(), open_bag(&p, None)) {
            ("no-scan-topic", Err(BagError::NoScanTopic { .. })) => continue,
            ("chunked-two-scan-topics", Err(BagError::SeveralScanTopics { .. })) => {}
            (_, Ok(_)) => {}
            (_, Err(e)) => panic!("{name}: {e}"),
        }
        let bag = open_bag(&p, Some(harness::BAG_TOPIC)).unwrap();
        let items: Vec<_> = bag.scans(&ReadOptions::default()).unwrap().collect();
        let ok = items.iter().filter(|r| r.is_ok()).count();
        assert!(ok > 0, "{name}: no scan read");
        let last_failed = items.last().is_some_and(|r| r.is_err());
        assert_eq!(last_failed, name == "cut", "{name}: {items:?}");
    }
}

/// Every CDR seed decodes.
#[test]
fn cdr_seeds_decode() {
    for p in corpus("cdr") {
        let m = mapc::tools::scanio::cdr::decode_laser_scan(&read(&p), 1000);
        assert!(m.is_ok(), "{}: {m:?}", p.display());
    }
}

// ---------------------------------------------------------------------------
// Saved fuzzer findings (minimized with `cargo fuzz tmin`), one test each.

/// `tests/fuzz/refdb/win-cells-overflow-scratch-size`: the `cave` seed (a
/// 360-degree-only database: both `win_widths` are 0) with `win_rho_bins =
/// win_theta_bins = u32::MAX` in its params record and the header CRC fixed
/// up (the params section CRC is stale, which only `verify` checks).
/// `RefDb::new` accepts it (`Params::validate` checks the window layout only
/// when a window width is used), then `scratch_size` computes
/// `max(hist_cells, win_cells) * 4` for the histogram array and overflows
/// (`Dims::bytes`, localize.rs): a panic with overflow checks, a wrapped,
/// meaningless size without them. Below the overflow, e.g. 65536 x 65536
/// bins, it asks for 16 GiB of scratch for an array that is never used.
///
/// Fixed either way: `RefDb::new` rejects the layout (`Value` naming the
/// window layout), or it accepts it and `scratch_size` stays small.
#[test]
fn refdb_unused_window_layout_keeps_scratch_size_sane() {
    let path = finding("refdb", "win-cells-overflow-scratch-size");
    replay(&path, harness::refdb);
    let mut file = harness::refdb_prefix().to_vec();
    file.extend_from_slice(&read(&path));
    let a = harness::Aligned::copy_of(&file);
    match refloc::RefDb::new(a.bytes()) {
        Ok(db) => {
            let n = std::panic::catch_unwind(|| refloc::scratch_size(db.params(), 90))
                .expect("scratch_size panicked");
            assert!(n < 64 << 20, "scratch_size = {n} bytes");
        }
        Err(e) => assert!(
            e.kind == refloc::DbErrorKind::Value && e.context.contains("window"),
            "{}: rejected for another reason ({e}); the input is stale, remake it from \
             fuzz/corpus/refdb/cave",
            path.display()
        ),
    }
}

/// `tests/fuzz/mapfile/png-rgba16-header-4gib-alloc`: a 64 KB PNG whose
/// IHDR claims 23000 x 23000 pixels of 16-bit RGBA, followed by a cut-off
/// IDAT. It is within `MAX_SIDE`/`MAX_CELLS`, and passed the old
/// `minimum_file_bytes` (which allowed 1032:1 deflate of 1 bit per pixel),
/// so `load_pixels` let the image crate reserve `width * height * 8` bytes
/// before any pixel data was read: 4.2 GB for a 64 KB file (libFuzzer:
/// `out-of-memory (malloc(4232000000))`).
///
/// Fixed in `mapc::compiler::mapfile`: the lower bound on the file size uses the bits
/// per pixel the IHDR declares (colour type x bit depth: 64 here, so at
/// least 4.1 MB), and the pixel buffer is allocated fallibly by the loader.
/// The largest map-size limit (`--max-cells 2147483648`): the file-size
/// bounds are tested behind it.
const WIDEST: mapc::compiler::mapfile::MapLimits = mapc::compiler::mapfile::MapLimits {
    max_cells: mapc::compiler::mapfile::MAX_CELLS,
};

#[test]
fn mapfile_png_header_cannot_reserve_gigabytes() {
    let path = finding("mapfile", "png-rgba16-header-4gib-alloc");
    replay(&path, harness::mapfile);
    // The image part of the harness input (after the YAML part).
    let data = read(&path);
    let sep = harness::MAP_SEPARATOR;
    let at = data
        .windows(sep.len())
        .position(|w| w == sep)
        .expect("a YAML part and an image part");
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("map.png");
    std::fs::write(&image, &data[at + sep.len()..]).unwrap();
    LARGEST.with(|c| c.set(0));
    // Beyond the default --max-cells (refused from the header): loaded
    // with the largest limit, so the file-size bound behind it is tested.
    let e =
        mapc::compiler::mapfile::load_image_within(&image, Some(0.05), None, &WIDEST).unwrap_err();
    assert!(
        matches!(e, mapc::compiler::mapfile::MapError::ImageDecode { .. })
            && e.to_string()
                .contains("truncated: the header claims 23000 x 23000"),
        "{e}"
    );
    let largest = LARGEST.with(Cell::get);
    assert!(largest < 1 << 20, "one allocation of {largest} bytes");
}

/// The bound behind the fix above, for the worst PNG kinds: a file of
/// `len` bytes whose IHDR claims the largest square image `len` can hold at
/// deflate's best ratio (1032:1) makes the loader allocate at most the
/// decoded buffer of that image, i.e. no more than 1032 x (decoded bits per
/// pixel / raw bits per pixel) x `len` (32 x for a 1-bit palette with
/// transparency, expanded to RGBA) plus the decoders' 64 MiB of working
/// memory. Each file then fails as cut off, with a `MapError`.
#[test]
fn mapfile_png_allocation_is_bounded_by_the_file_size() {
    use mapc::testdata::png::chunk;
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("map.png");
    // (colour type, bit depth, raw bits per pixel, decoded bytes per pixel)
    for (colour, depth, bits, out) in [
        (3u8, 1u8, 1u64, 4u64), // palette + tRNS -> RGBA8
        (3, 1, 1, 3),           // palette -> RGB8
        (0, 1, 1, 1),
        (0, 16, 16, 2),
        (6, 16, 64, 8),
    ] {
        for len in [11_000u64, 64_000] {
            let side = ((len * 1032 * 8 / bits) as f64).sqrt() as u32;
            let mut f = b"\x89PNG\r\n\x1a\n".to_vec();
            let mut ihdr = side.to_be_bytes().to_vec();
            ihdr.extend_from_slice(&side.to_be_bytes());
            ihdr.extend_from_slice(&[depth, colour, 0, 0, 0]);
            chunk(&mut f, b"IHDR", &ihdr);
            if colour == 3 {
                chunk(&mut f, b"PLTE", &[0, 0, 0, 255, 255, 255]);
                if out == 4 {
                    chunk(&mut f, b"tRNS", &[255, 0]);
                }
            }
            chunk(&mut f, b"IDAT", &[0x78, 0x9c]);
            chunk(&mut f, b"IEND", &[]);
            f.resize(len as usize, 0);
            std::fs::write(&image, &f).unwrap();
            LARGEST.with(|c| c.set(0));
            let r = std::panic::catch_unwind(|| {
                mapc::compiler::mapfile::load_image_within(&image, Some(0.05), None, &WIDEST)
            });
            let largest = LARGEST.with(Cell::get);
            let what = format!("colour {colour} depth {depth}, {side} x {side} in {len} bytes");
            let e = r
                .unwrap_or_else(|_| panic!("{what}: panicked"))
                .unwrap_err();
            assert!(
                matches!(e, mapc::compiler::mapfile::MapError::ImageDecode { .. }),
                "{what}: {e}"
            );
            let decoded = side as u64 * side as u64 * out;
            assert!(
                decoded <= 1032 * 8 * out / bits * len,
                "{what}: the header claims more than the bound allows"
            );
            assert!(
                largest as u64 <= decoded + (64 << 20),
                "{what}: one allocation of {largest} bytes, decoded size {decoded}"
            );
            assert!(
                largest as u64 <= 33_024 * len + (64 << 20),
                "{what}: {largest} bytes"
            );
        }
    }
}

/// `tests/fuzz/scanio/angle-min-f32-rounds-past-limit`: one JSON record with
/// `angle_min` 6.2841853, just inside the reader's limit of 2 pi + 1e-3
/// rad. `check_angles` validates the f64 value, the scan stores it as f32
/// (6.2841854, just outside), and the record `scan_to_json` writes for that
/// scan is then rejected when read back ("angle_min (6.2841854) is not a
/// finite angle within [-2 pi, 2 pi] rad"), against the round trip
/// documented on `scan_to_json`.
#[test]
fn scanio_angle_min_near_the_limit_round_trips() {
    replay(
        &finding("scanio", "angle-min-f32-rounds-past-limit"),
        harness::scanio,
    );
}

/// `tests/fuzz/scanio/increment-f32-rounds-past-full-turn`: 4 beams at
/// `angle_increment` 2.0946048752367683 rad, a span just under the reader's
/// full-turn limit in f64; as f32 (2.094605) the span is just over it, so
/// the JSON record written for the scan does not read back. Same cause as
/// above.
#[test]
fn scanio_increment_near_a_full_turn_round_trips() {
    replay(
        &finding("scanio", "increment-f32-rounds-past-full-turn"),
        harness::scanio,
    );
}

/// `tests/fuzz/scanio/truth-f64-not-bit-exact` (found by the `scanio`
/// fuzzer, minimized): `FLASER 1 1 4444444444444444444444 1 2 3 2 3`, a
/// CARMEN scan whose laser pose x is 4444444444444444444444 (the f64
/// 4.4444444444444443e21). `scan_to_json` writes `4.4444444444444443e21`,
/// the shortest text that reads back exactly with a correctly rounding
/// parser, but the JSON reader parses it with serde_json's default float
/// parser, which is not correctly rounded without serde_json's
/// `float_roundtrip` feature: it reads 4.444444444444444e21, one unit in the
/// last place off. Not limited to huge values: about 9% of 17-digit values
/// in [-100, 100) m are misread the same way. The scan data (f32) is exact;
/// the harness accepts this one-ulp difference so the fuzzer can go on.
#[test]
fn scanio_truth_round_trips_bit_for_bit() {
    use mapc::tools::scanio::{read_scans, scan_to_json, InputFormat, ReadOptions};
    let data = read(&finding("scanio", "truth-f64-not-bit-exact"));
    let opts = ReadOptions::default();
    let scan = read_scans(&data[..], InputFormat::Carmen, &opts)
        .next()
        .expect("one item")
        .expect("a scan");
    let json = scan_to_json(&scan.data, &scan.id, scan.truth);
    let back = read_scans(json.as_bytes(), InputFormat::JsonLines, &opts)
        .next()
        .expect("one item")
        .expect("reads back");
    assert_eq!(back.data, scan.data);
    let bits = |t: Option<[f64; 3]>| t.map(|p| p.map(f64::to_bits));
    assert_eq!(bits(back.truth), bits(scan.truth), "{json}");
}

#[test]
fn scanio_truth_within_one_ulp_replays() {
    replay(
        &finding("scanio", "truth-f64-not-bit-exact"),
        harness::scanio,
    );
}

/// `tests/fuzz/bag/header-string-4gib-alloc` (found by the `bag` fuzzer in
/// its first second, 201 executions): a 256-byte bag whose header record's
/// profile string claims 4,294,639,620 bytes; the mcap crate reserved that
/// much before reading the string (libFuzzer: `malloc(4294639620)`). Fixed
/// by `check_string_lengths` in `mapc::tools::scanio::bag`: an error naming the
/// record, checked before the record is parsed.
#[test]
fn bag_string_longer_than_its_record_is_not_allocated() {
    replay(&finding("bag", "header-string-4gib-alloc"), harness::bag);
    let e = mapc::tools::scanio::bag::open_bag(&finding("bag", "header-string-4gib-alloc"), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("header record: a string at byte 0 claims"),
        "{e}"
    );
}

/// `tests/fuzz/bag/second-scan-channel-of-another-type` (found by the `bag`
/// fuzzer after 575,467 executions, 573 s): the `recording` seed with a
/// second `/scan` channel whose schema and encoding are not LaserScan /
/// `cdr`. It broke the harness's invariant on the chosen topic (which
/// assumed one channel per name) and showed that `Bag::scans` read the
/// messages of every channel named `/scan` as LaserScans. Fixed: only the
/// topic's LaserScan (`cdr`) channels are read
/// (`scanio::bag::tests::only_the_laser_scan_channels_of_the_topic_are_read`),
/// and the invariant asks for one such channel among those of the name.
#[test]
fn bag_other_channel_of_the_scan_topic_replays() {
    replay(
        &finding("bag", "second-scan-channel-of-another-type"),
        harness::bag,
    );
}
