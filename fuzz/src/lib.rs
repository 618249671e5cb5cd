//! The fuzz harnesses, one function per target, shared by the libFuzzer
//! targets in `fuzz_targets/` (nightly, `cargo fuzz`) and by the stable
//! regression tests in `tests/fuzz_regressions.rs`, which include this file
//! with `#[path]` and replay the committed corpora and every saved crash
//! through exactly the same code.
//!
//! Each harness must never panic on any input; a panic (or a sanitizer
//! report, a timeout, or libFuzzer's RSS limit) is a bug. Besides "no
//! panic", the harnesses assert a few documented invariants of the code
//! under test (marked `invariant:`), so a silent wrong answer counts too.
//!
//! This file must stay a plain module (no crate attributes) so it can be
//! included with `#[path]`.

use std::cell::RefCell;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Once};

use mapc::compiler::mapfile::{load_image, load_yaml};
use mapc::tools::scanio::bag::open_bag_bytes;
use mapc::tools::scanio::cdr::{decode_laser_scan, LaserScanMsg, Writer as CdrWriter};
use mapc::tools::scanio::{
    open_input, read_scans, scan_to_json, InputFormat, ReadOptions, ScanData, ScanErrorKind,
};
use refloc::format::{
    header_crc, Header, ENDIAN_CHECK, ENTRY_LEN, FORMAT_VERSION, HEADER_LEN, MAGIC, MAX_SECTIONS,
};
use refloc::{localize, scratch_size, RangeScan, RefDb, Scan};
use zerocopy::FromBytes;

// ---------------------------------------------------------------------------
// refdb

/// Length of the fixed header prefix the `refdb` harness puts before the
/// fuzz input: magic, endianness check, header length and format version.
pub const REFDB_PREFIX_LEN: usize = 16;

/// Largest scratch buffer the `refdb` harness hands to `localize` (a
/// database asking for more is only parsed and verified).
pub const REFDB_SCRATCH_CAP: usize = 8 << 20;

/// The 16 bytes every `.refdb` starts with.
pub fn refdb_prefix() -> [u8; REFDB_PREFIX_LEN] {
    let mut p = [0u8; REFDB_PREFIX_LEN];
    p[..8].copy_from_slice(&MAGIC);
    p[8..10].copy_from_slice(&ENDIAN_CHECK.to_le_bytes());
    p[10..12].copy_from_slice(&(HEADER_LEN as u16).to_le_bytes());
    p[12..16].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    p
}

/// A corpus entry for the `refdb` target from a whole `.refdb` file (the
/// file without its first 16 bytes, which the harness supplies).
pub fn refdb_seed(file: &[u8]) -> &[u8] {
    file.get(REFDB_PREFIX_LEN..).unwrap_or(&[])
}

/// Byte offsets of header fields (see `refloc::format::Header`).
const SECTION_COUNT_AT: usize = 20;
const FILE_LEN_AT: usize = 24;
const HEADER_CRC_AT: usize = 32;

/// A `len`-byte buffer whose first byte is 16-byte aligned (as a memory map
/// is).
pub struct Aligned {
    buf: Vec<u8>,
    start: usize,
    len: usize,
}

impl Aligned {
    /// `len` zero bytes.
    pub fn new(len: usize) -> Self {
        let buf = vec![0u8; len + 16];
        let start = buf.as_ptr().align_offset(16).min(16);
        Aligned { buf, start, len }
    }
    /// An aligned copy of `b`.
    pub fn copy_of(b: &[u8]) -> Self {
        let mut a = Aligned::new(b.len());
        a.bytes_mut().copy_from_slice(b);
        a
    }
    /// The bytes.
    pub fn bytes(&self) -> &[u8] {
        &self.buf[self.start..self.start + self.len]
    }
    /// The bytes, mutable.
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        &mut self.buf[self.start..self.start + self.len]
    }
}

/// Rewrites the header CRC (and, with `fix_len`, the file length) so the
/// rest of the reader is reachable. Returns false if nothing changed, or if
/// the buffer is too short to hold the header and the table it announces.
fn patch_header(b: &mut [u8], fix_len: bool) -> bool {
    if b.len() < HEADER_LEN {
        return false;
    }
    let before: [u8; HEADER_LEN] = b[..HEADER_LEN].try_into().unwrap();
    if fix_len {
        let len = b.len() as u64;
        b[FILE_LEN_AT..FILE_LEN_AT + 8].copy_from_slice(&len.to_le_bytes());
    }
    let count = u32::from_le_bytes(
        b[SECTION_COUNT_AT..SECTION_COUNT_AT + 4]
            .try_into()
            .unwrap(),
    ) as usize;
    if count == 0 || count > MAX_SECTIONS {
        return false;
    }
    let table_end = HEADER_LEN + count * ENTRY_LEN;
    if b.len() < table_end {
        return false;
    }
    let Ok(header) = Header::read_from_bytes(&b[..HEADER_LEN]) else {
        return false;
    };
    let crc = header_crc(&header, &b[HEADER_LEN..table_end]);
    b[HEADER_CRC_AT..HEADER_CRC_AT + 4].copy_from_slice(&crc.to_le_bytes());
    b[..HEADER_LEN] != before
}

/// A fixed 90-beam, 360-degree query: a 6 m x 4 m room seen from off-centre,
/// with a few no-return beams (NaN, infinity, negative, zero).
fn fixed_ranges() -> [f32; 90] {
    let mut r = [0.0f32; 90];
    let inc = std::f32::consts::TAU / 90.0;
    for (k, v) in r.iter_mut().enumerate() {
        let a = -std::f32::consts::PI + k as f32 * inc;
        let (s, c) = a.sin_cos();
        // Distance to the walls x = -2.5, x = 3.5, y = -1.5, y = 2.5.
        let tx = if c > 1e-6 {
            3.5 / c
        } else if c < -1e-6 {
            -2.5 / c
        } else {
            f32::INFINITY
        };
        let ty = if s > 1e-6 {
            2.5 / s
        } else if s < -1e-6 {
            -1.5 / s
        } else {
            f32::INFINITY
        };
        *v = tx.min(ty);
    }
    r[3] = f32::NAN;
    r[17] = f32::NAN;
    r[40] = f32::INFINITY;
    r[41] = -1.0;
    r[62] = 0.0;
    r[88] = f32::NAN;
    r
}

thread_local! {
    static SCRATCH: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
}

/// Runs the reader, the checksum pass, every accessor and `localize` on one
/// candidate database.
fn exercise_db(bytes: &[u8]) {
    let Ok(db) = RefDb::new(bytes) else {
        return;
    };
    let _ = db.verify();
    // invariant: after `new` succeeds no accessor fails or panics.
    let n = db.site_count();
    assert!(n >= 1, "RefDb::new accepted a database with no site");
    assert_eq!(db.sites().len(), n, "sites() disagrees with site_count()");
    let _ = db.manifest();
    let _ = db.grid();
    let p = *db.params();
    for i in [0, n / 2, n - 1, n, usize::MAX] {
        let _ = db.site(i);
        let _ = db.site_xy(i);
        let _ = db.neighbors(i);
        let _ = db.hist(i);
        for w in 0..3 {
            let _ = db.window_hist(i, w, 0);
        }
    }
    assert_eq!(
        db.scan(n - 1).len(),
        p.sensor.beams as usize,
        "scan() length"
    );
    assert_eq!(db.hist(n - 1).len(), p.coarse.hist_cells(), "hist() length");

    let ranges = fixed_ranges();
    let reference = db.scan(0);
    let beams = ranges.len().max(reference.len());
    let need = scratch_size(&p, beams);
    if need > REFDB_SCRATCH_CAP {
        return;
    }
    SCRATCH.with(|s| {
        let mut s = s.borrow_mut();
        s.clear();
        s.resize(need, 0);
        let fixed = Scan::Ranges(RangeScan {
            angle_min: -std::f32::consts::PI,
            angle_increment: std::f32::consts::TAU / ranges.len() as f32,
            range_min: 0.05,
            range_max: 30.0,
            ranges: &ranges,
        });
        let _ = localize(&db, &fixed, &mut s);
        // The database's own first reference scan, with its own geometry:
        // exercises the SSM / refinement / verification stages past the
        // coarse stage on databases that are structurally valid.
        let own = Scan::Ranges(RangeScan {
            angle_min: p.sensor.angle_min,
            angle_increment: p.sensor.angle_increment,
            range_min: p.sensor.range_min,
            range_max: p.sensor.range_max,
            ranges: reference,
        });
        s.fill(0);
        let _ = localize(&db, &own, &mut s);
    });
}

/// The `refdb` target: `data` follows a valid 16-byte header prefix. Tried
/// as is (the header CRC must match), with the header CRC recomputed, with
/// both the file length and the CRC fixed up, and at a misaligned address.
pub fn refdb(data: &[u8]) {
    let len = REFDB_PREFIX_LEN + data.len();
    let mut a = Aligned::new(len);
    a.bytes_mut()[..REFDB_PREFIX_LEN].copy_from_slice(&refdb_prefix());
    a.bytes_mut()[REFDB_PREFIX_LEN..].copy_from_slice(data);

    // 1. Raw.
    exercise_db(a.bytes());
    // 2. Header CRC patched: everything after the header checksum (skipped
    //    when the CRC was right, which would repeat step 1).
    if patch_header(a.bytes_mut(), false) {
        exercise_db(a.bytes());
    }
    // 3. File length and CRC patched (skipped when the length was right).
    if patch_header(a.bytes_mut(), true) {
        exercise_db(a.bytes());
    }
    // 4. Misaligned container: the reader must refuse (or handle) arrays
    //    that are not 4-byte aligned in memory.
    let mut m = Aligned::new(len + 1);
    m.bytes_mut()[1..].copy_from_slice(a.bytes());
    let _ = RefDb::new(&m.bytes()[1..]).map(|db| db.verify());
}

// ---------------------------------------------------------------------------
// mapfile

/// Separates the YAML part from the image part of a `mapfile` input; without
/// it the whole input is both.
pub const MAP_SEPARATOR: &[u8] = b"\n%%IMAGE%%\n";

/// The file the image part is written to (the YAML names it to load it).
pub const MAP_IMAGE_NAME: &str = "map.pgm";

/// Builds a `mapfile` input from its two parts.
pub fn mapfile_input(yaml: &[u8], image: &[u8]) -> Vec<u8> {
    let mut v = yaml.to_vec();
    v.extend_from_slice(MAP_SEPARATOR);
    v.extend_from_slice(image);
    v
}

fn split_map_input(data: &[u8]) -> (&[u8], &[u8]) {
    match data
        .windows(MAP_SEPARATOR.len())
        .position(|w| w == MAP_SEPARATOR)
    {
        Some(i) => (&data[..i], &data[i + MAP_SEPARATOR.len()..]),
        None => (data, data),
    }
}

/// True when the YAML could name a file outside the scratch directory: it
/// contains a `/`, or a slash (or backslash) spelled as a YAML escape. Such
/// inputs are not loaded: the harness must not read arbitrary files of the
/// host (`/proc/kmsg` blocks). A bare `..` names a directory, which the
/// loader refuses as a missing image.
fn may_escape_dir(yaml: &[u8]) -> bool {
    let lower: Vec<u8> = yaml.iter().map(|b| b.to_ascii_lowercase()).collect();
    lower.contains(&b'/')
        || lower.contains(&b'\\') && {
            let s = String::from_utf8_lossy(&lower);
            s.contains("\\x2f")
                || s.contains("\\u002f")
                || s.contains("\\u0000002f")
                || s.contains("\\x5c")
                || s.contains("\\u005c")
                || s.contains("\\u0000005c")
                || s.contains("\\/")
        }
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).expect("write to the temporary directory");
}

/// The `mapfile` target: in a fresh temporary directory, the YAML part is
/// written to `map.yaml`, the image part to `map.pgm` beside it and to
/// `solo/map.pgm` (no YAML beside); then `load_image(solo/map.pgm,
/// Some(0.05), None)`, `load_yaml(map.yaml)` (unless [`may_escape_dir`]),
/// and, when the YAML loaded, `load_image(map.pgm, ..)` (the YAML beside
/// it) with resolution 0.05, and with the YAML's own resolution and origin.
pub fn mapfile(data: &[u8]) {
    let (yaml, image) = split_map_input(data);
    // A fresh directory per input (removed on return), so nothing carries
    // over from one input to the next, nor stays behind when libFuzzer exits.
    let dir = tempfile::tempdir().expect("temporary directory");
    let root = dir.path();
    let solo_dir = root.join("solo");
    std::fs::create_dir(&solo_dir).expect("create a directory");
    let yaml_path = root.join("map.yaml");
    let image_path = root.join(MAP_IMAGE_NAME);
    let solo_path: PathBuf = solo_dir.join(MAP_IMAGE_NAME);
    write(&image_path, image);
    write(&solo_path, image);

    if let Ok(src) = load_image(&solo_path, Some(0.05), None) {
        check_map(&src.grid);
    }
    if may_escape_dir(yaml) {
        return;
    }
    write(&yaml_path, yaml);
    if let Ok(src) = load_yaml(&yaml_path) {
        check_map(&src.grid);
        let _ = load_image(&image_path, Some(0.05), None);
        let _ = load_image(
            &image_path,
            Some(src.grid.resolution),
            Some(src.grid.origin),
        );
    }
}

/// invariant: a loaded grid is consistent (cell count, resolution, at least
/// one free cell).
fn check_map(g: &mapc::compiler::mapfile::OccupancyGrid) {
    assert_eq!(
        g.cells.len() as u64,
        g.width as u64 * g.height as u64,
        "cell count"
    );
    assert!(g.width > 0 && g.height > 0, "empty grid loaded");
    assert!(g.resolution.is_finite() && g.resolution > 0.0, "resolution");
    assert!(g.origin.iter().all(|v| v.is_finite()), "origin");
    assert!(g.free_count() > 0, "a map with no free cell was loaded");
    let _ = g.blocked_bits(true);
    let _ = g.frame();
}

// ---------------------------------------------------------------------------
// scanio

/// Small limits, so the "too many beams" and "line too long" paths are hit.
pub fn small_read_options() -> ReadOptions {
    ReadOptions {
        fov: Some(4.5),
        range_max: 8.0,
        max_beams: 24,
        max_line_bytes: 300,
    }
}

/// The `scanio` target: `data` read with every format and two option sets
/// (all items consumed); gzip input also through `open_input`.
pub fn scanio(data: &[u8]) {
    for opts in [ReadOptions::default(), small_read_options()] {
        for format in [
            InputFormat::Auto,
            InputFormat::JsonLines,
            InputFormat::Carmen,
        ] {
            // Errors are fine (each names its line); scans must be sound.
            for scan in read_scans(Cursor::new(data), format, &opts).flatten() {
                check_scan(&scan.data, &opts);
                check_round_trip(&scan.data, &scan.id, scan.truth);
            }
        }
    }
    if data.starts_with(&[0x1f, 0x8b]) {
        let Ok(file) = tempfile::NamedTempFile::new() else {
            return;
        };
        write(file.path(), data);
        if let Ok(reader) = open_input(&file.path().to_string_lossy()) {
            let opts = ReadOptions::default();
            for scan in read_scans(reader, InputFormat::Auto, &opts)
                .take(1 << 16)
                .flatten()
            {
                check_scan(&scan.data, &opts);
            }
        }
    }
}

/// invariant: the documented guarantees of `ScanData` from `read_scans`.
fn check_scan(d: &ScanData, opts: &ReadOptions) {
    assert!(!d.is_empty(), "read_scans returned an empty scan");
    assert!(d.len() <= opts.max_beams, "more than max_beams beams");
    match d {
        ScanData::Ranges {
            angle_min,
            angle_increment,
            range_min,
            range_max,
            ..
        } => {
            assert!(angle_min.is_finite(), "angle_min {angle_min}");
            assert!(
                angle_increment.is_finite() && *angle_increment != 0.0,
                "angle_increment {angle_increment}"
            );
            assert!(
                range_max.is_finite() && *range_max > 0.0,
                "range_max {range_max}"
            );
            assert!(
                range_min.is_finite() && *range_min >= 0.0,
                "range_min {range_min}"
            );
        }
        ScanData::Points { points, range_max } => {
            assert!(
                range_max.is_finite() && *range_max > 0.0,
                "range_max {range_max}"
            );
            assert!(
                points.iter().all(|p| p[0].is_finite() && p[1].is_finite()),
                "a point is not finite"
            );
        }
    }
}

/// invariant (documented on `scan_to_json`): a scan written as JSON reads
/// back bit for bit, ranges outside `[range_min, range_max]` as NaN.
fn check_round_trip(d: &ScanData, id: &str, truth: Option<[f64; 3]>) {
    let json = scan_to_json(d, id, truth);
    let opts = ReadOptions {
        max_beams: d.len().max(1),
        max_line_bytes: json.len() + 1,
        ..ReadOptions::default()
    };
    let mut items = read_scans(Cursor::new(json.as_bytes()), InputFormat::JsonLines, &opts);
    let back = match items.next() {
        Some(Ok(s)) => s,
        Some(Err(e)) => panic!("scan_to_json output does not read back: {e}\n{json}"),
        None => panic!("scan_to_json output reads back as nothing\n{json}"),
    };
    assert!(items.next().is_none(), "one record read back as several");
    assert_eq!(back.id, id, "id round trip");
    // The truth pose (f64) must read back within one unit in the last place
    // (finding `tests/fuzz/scanio/truth-f64-not-bit-exact`: serde_json's
    // default parser misrounded ~9% of 17-digit values). The reader now
    // parses every number from its text with Rust's correctly rounded
    // parser, so it is exact in practice; the tolerance stays. Scan data is
    // f32 and exact.
    match (truth, back.truth) {
        (None, None) => {}
        (Some(a), Some(b)) => {
            for (u, v) in a.iter().zip(b.iter()) {
                let ulps = (u.to_bits() as i64)
                    .wrapping_sub(v.to_bits() as i64)
                    .unsigned_abs();
                assert!(
                    u == v || ulps <= 1,
                    "truth round trip: wrote {a:?}, read {b:?}\n{json}"
                );
            }
        }
        (a, b) => panic!("truth round trip: wrote {a:?}, read {b:?}\n{json}"),
    }
    match (d, &back.data) {
        (
            ScanData::Ranges {
                angle_min: a0,
                angle_increment: i0,
                range_min: n0,
                range_max: x0,
                ranges: r0,
            },
            ScanData::Ranges {
                angle_min: a1,
                angle_increment: i1,
                range_min: n1,
                range_max: x1,
                ranges: r1,
            },
        ) => {
            assert_eq!(
                [a0.to_bits(), i0.to_bits(), n0.to_bits(), x0.to_bits()],
                [a1.to_bits(), i1.to_bits(), n1.to_bits(), x1.to_bits()],
                "geometry round trip\n{json}"
            );
            assert_eq!(r0.len(), r1.len(), "beam count round trip");
            for (k, (u, v)) in r0.iter().zip(r1).enumerate() {
                let inside = *u > 0.0 && *u >= *n0 && *u <= *x0;
                let ok = if inside {
                    u.to_bits() == v.to_bits()
                } else {
                    v.is_nan()
                };
                assert!(ok, "range {k}: wrote {u}, read {v}\n{json}");
            }
        }
        (
            ScanData::Points {
                points: p0,
                range_max: x0,
            },
            ScanData::Points {
                points: p1,
                range_max: x1,
            },
        ) => {
            assert_eq!(x0.to_bits(), x1.to_bits(), "range_max round trip");
            let bits = |p: &Vec<[f32; 2]>| -> Vec<[u32; 2]> {
                p.iter().map(|q| [q[0].to_bits(), q[1].to_bits()]).collect()
            };
            assert_eq!(bits(p0), bits(p1), "points round trip\n{json}");
        }
        _ => panic!("scan kind changed in the round trip\n{json}"),
    }
}

// ---------------------------------------------------------------------------
// bag and cdr

/// The topic the `bag` harness also asks for by name (the one rosbag2 and
/// the seeds use).
pub const BAG_TOPIC: &str = "/scan";

/// Installs, once, a panic hook that stays silent for panics raised inside
/// the `mcap` crate and hands every other panic to the hook before it
/// (libFuzzer's, which aborts). The bag reader runs the mcap reader under
/// `catch_unwind` and turns its panics (arithmetic overflow on a crafted
/// chunk, with debug assertions) into an error, by design
/// (`RecordStream::next` in `mapc::tools::scanio::bag`); libFuzzer's hook would
/// abort on them before they are caught. A panic anywhere else, the CDR
/// decoder and the reader's own code included, still counts.
fn let_the_bag_reader_catch_mcap_panics() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let before = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let in_mcap = info
                .location()
                .is_some_and(|l| l.file().replace('\\', "/").contains("/mcap-"));
            if !in_mcap {
                before(info);
            }
        }));
    });
}

/// The `bag` target: `data` as an MCAP file in memory, through
/// `open_bag_bytes` (any LaserScan topic, and `/scan` by name), then every
/// item of `Bag::scans` with the default and the small read options.
pub fn bag(data: &[u8]) {
    let_the_bag_reader_catch_mcap_panics();
    let bytes: Arc<[u8]> = data.into();
    for topic in [None, Some(BAG_TOPIC)] {
        let bag = match open_bag_bytes(Arc::clone(&bytes), Path::new("fuzz.mcap"), topic) {
            Ok(b) => b,
            Err(e) => {
                assert!(!e.to_string().is_empty(), "empty bag error");
                continue;
            }
        };
        // invariant: the chosen topic is one of the bag's, with a LaserScan
        // channel (a bag may have other channels of the same name).
        let mut chosen = bag.topics.iter().filter(|t| t.topic == bag.topic);
        assert!(
            chosen.any(|t| t.schema.ends_with("LaserScan") && t.encoding == "cdr"),
            "chose {} of {:?}",
            bag.topic,
            bag.topics
        );
        if let Some(want) = topic {
            assert_eq!(bag.topic, want, "asked for {want}");
        }
        for opts in [ReadOptions::default(), small_read_options()] {
            let items = bag.scans(&opts).expect("scans from memory");
            let mut ended = false;
            for (k, item) in items.enumerate() {
                // invariants: one item per message of the topic, numbered
                // from 1 (`msg K` on line K + 1); a broken bag ends the
                // stream with one more error.
                assert!(!ended, "an item after the end-of-bag error");
                match item {
                    Ok(scan) => {
                        check_scan(&scan.data, &opts);
                        assert!(scan.stamp.is_some(), "a bag scan without its stamp");
                        assert_eq!((scan.line, scan.id), (k + 1, format!("msg {k}")));
                    }
                    Err(e) => {
                        assert!(!e.message().is_empty(), "empty scan error");
                        assert_eq!(e.line, k + 1, "{e}");
                        ended = matches!(e.kind, ScanErrorKind::BagDamaged { .. });
                    }
                }
            }
        }
    }
}

/// The `cdr` target: `data` as one CDR `sensor_msgs/msg/LaserScan` (the
/// payload of a bag message), decoded with room for 1,000,000 beams and
/// for 24; a decoded message must encode (little-endian) and decode again
/// to the same bits.
pub fn cdr(data: &[u8]) {
    for max_beams in [1_000_000, 24] {
        let Ok(m) = decode_laser_scan(data, max_beams) else {
            continue;
        };
        // invariant: the sequences are bounded by max_beams.
        assert!(m.ranges.len() <= max_beams && m.intensities.len() <= max_beams);
        let again = decode_laser_scan(&encode_laser_scan(&m), max_beams)
            .unwrap_or_else(|e| panic!("a decoded LaserScan does not decode again: {e}"));
        assert_eq!(bits_of(&again), bits_of(&m), "CDR round trip");
        assert_eq!(again.frame_id, m.frame_id, "frame_id round trip");
    }
}

/// The seven `float32` fields of `m` between the header and the ranges,
/// in message order.
fn scalars(m: &LaserScanMsg) -> [f32; 7] {
    [
        m.angle_min,
        m.angle_max,
        m.angle_increment,
        m.time_increment,
        m.scan_time,
        m.range_min,
        m.range_max,
    ]
}

/// `m` in little-endian CDR, field by field.
fn encode_laser_scan(m: &LaserScanMsg) -> Vec<u8> {
    let mut w = CdrWriter::new();
    w.i32(m.stamp_sec).u32(m.stamp_nanosec).string(&m.frame_id);
    for v in scalars(m) {
        w.f32(v);
    }
    w.f32_seq(&m.ranges).f32_seq(&m.intensities);
    w.into_bytes()
}

/// Every number of `m` as bits (NaN payloads included).
fn bits_of(m: &LaserScanMsg) -> Vec<u32> {
    let mut v = vec![m.stamp_sec as u32, m.stamp_nanosec];
    v.extend(scalars(m).iter().map(|x| x.to_bits()));
    v.push(m.ranges.len() as u32);
    v.extend(m.ranges.iter().map(|x| x.to_bits()));
    v.push(m.intensities.len() as u32);
    v.extend(m.intensities.iter().map(|x| x.to_bits()));
    v
}
