//! # refloc-capi: the C ABI of refloc
//!
//! Global localization of one 2D laser scan against a compiled `.refdb`
//! map, callable from C. The library never allocates: the caller provides
//! every byte of memory.
//!
//! - The `.refdb` bytes: any memory (flash, a file read into a buffer, an
//!   mmap) that starts on a 16-byte boundary, stays alive and unchanged while
//!   the handle is used.
//! - The handle: a [`refloc_db`] struct of [`REFLOC_DB_SIZE`] bytes, declared
//!   by the caller (on the stack, in a static) and filled by
//!   [`refloc_db_open`].
//! - The scratch: [`refloc_scratch_size`] bytes per call of
//!   [`refloc_localize_ranges`] / [`refloc_localize_points`], any alignment.
//!
//! Every function returns a [`refloc_status`] (0 on success), reports
//! caller mistakes (null or misaligned pointers, a handle that was never
//! opened) as errors, and never panics.
//!
//! The crate uses `core` only. On an operating system (Linux, macOS, ...)
//! it links `std` for the panic runtime alone, so that it builds whatever
//! the panic strategy and whichever features `refloc` gets in a workspace;
//! on bare metal (`target_os = "none"`) it is fully `no_std` and brings its
//! own panic handler (feature `panic-handler`, on by default).
//!
//! Threads: an opened handle is read-only, so several threads may localize
//! against one handle at once, each with its own scratch buffer.
//!
//! The C header `include/refloc.h` is generated from this file by cbindgen
//! (`scripts/capi-test.sh --update-header`).
#![no_std]
#![allow(non_camel_case_types)]
#![deny(missing_docs)]

// The panic runtime on hosted targets (and the test harness); nothing in
// this crate allocates or otherwise uses std.
#[cfg(any(test, not(target_os = "none")))]
extern crate std;

use core::ffi::c_char;
use core::mem::{align_of, size_of};

use refloc::{
    localize_with_prior, scratch_size, DbErrorKind, Localization, LocalizeError, Polygon, Prior,
    RangeScan, RefDb, Scan,
};

/// Bytes of a [`refloc_db`] handle (an ABI constant: it changes only with
/// a new major version of this library).
pub const REFLOC_DB_SIZE: usize = 1024;
/// Alignment of a [`refloc_db`] handle.
pub const REFLOC_DB_ALIGN: usize = 8;
/// `REFLOC_DB_SIZE` in 64-bit words.
pub const REFLOC_DB_WORDS: usize = REFLOC_DB_SIZE / 8;
/// Alignment the `.refdb` bytes must have in memory.
pub const REFLOC_DB_BYTES_ALIGN: usize = 16;
/// Most vertices of a prior polygon ([`refloc_localize_ranges_polygon`]).
pub const REFLOC_MAX_POLYGON_VERTICES: usize = 32;

/// An opened map. Declare one (stack, static, or memory you manage), fill
/// it with [`refloc_db_open`], and pass its address to the other
/// functions. Its content is private.
#[repr(C)]
pub struct refloc_db {
    /// Private; `REFLOC_DB_SIZE` bytes, 8-byte aligned.
    pub opaque: [u64; REFLOC_DB_WORDS],
}

/// Status codes: `REFLOC_OK` (0) or an error. [`refloc_strerror`] names them.
#[repr(i32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum refloc_status {
    /// Success.
    REFLOC_OK = 0,
    /// A required pointer argument is NULL.
    REFLOC_ERR_NULL = 1,
    /// A pointer argument is not aligned for its type (handle: 8 bytes,
    /// ranges/points: 4 bytes).
    REFLOC_ERR_ALIGNMENT = 2,
    /// The handle was not opened by `refloc_db_open`, or was closed.
    REFLOC_ERR_BAD_HANDLE = 3,
    /// The bytes are not a `.refdb` file.
    REFLOC_ERR_DB_NOT_REFDB = 10,
    /// The `.refdb` has a format version this library does not read:
    /// rebuild it with a matching `mapc build`.
    REFLOC_ERR_DB_VERSION = 11,
    /// The `.refdb` is truncated (or longer than its header says).
    REFLOC_ERR_DB_TRUNCATED = 12,
    /// A checksum of the `.refdb` does not match (corrupted data).
    REFLOC_ERR_DB_CHECKSUM = 13,
    /// The `.refdb` bytes do not start on a 16-byte boundary in memory, or a
    /// section in the file is misaligned.
    REFLOC_ERR_DB_ALIGNMENT = 14,
    /// The `.refdb` has the other byte order, or this CPU is big-endian.
    REFLOC_ERR_DB_ENDIAN = 15,
    /// The `.refdb` is malformed (section table, sizes or values).
    REFLOC_ERR_DB_INVALID = 16,
    /// The scratch buffer is smaller than `refloc_scratch_size` says.
    REFLOC_ERR_SCRATCH_TOO_SMALL = 20,
    /// The scan has more beams than the scratch buffer was sized for.
    REFLOC_ERR_TOO_MANY_BEAMS = 21,
    /// The scan geometry is unusable (angles, range limits).
    REFLOC_ERR_BAD_SCAN = 22,
    /// Too few valid returns in the scan.
    REFLOC_ERR_NOT_ENOUGH_POINTS = 23,
    /// No candidate site produced a pose.
    REFLOC_ERR_NO_MATCH = 24,
    /// The prior makes no sense (non-finite centre or heading, radius not
    /// positive, negative tolerance).
    REFLOC_ERR_BAD_PRIOR = 25,
    /// The prior polygon is unusable: fewer than 3 or more than
    /// `REFLOC_MAX_POLYGON_VERTICES` vertices, a non-finite coordinate, or
    /// all vertices on one line.
    REFLOC_ERR_BAD_POLYGON = 26,
    /// An error this version of the C ABI does not know.
    REFLOC_ERR_UNKNOWN = 99,
}

use refloc_status::*;

/// What [`refloc_db_get_info`] reports about an opened map.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct refloc_db_info {
    /// Grid width (cells).
    pub width: u32,
    /// Grid height (cells).
    pub height: u32,
    /// Metres per cell.
    pub resolution: f32,
    /// Map-frame pose of the grid's lower-left corner (m, m, rad).
    pub origin_x: f32,
    /// See `origin_x`.
    pub origin_y: f32,
    /// See `origin_x`.
    pub origin_theta: f32,
    /// Reference sites.
    pub sites: u32,
    /// Beams of the reference scans.
    pub reference_beams: u32,
    /// Maximum range of the reference sensor (m).
    pub range_max: f32,
    /// Size of the `.refdb` (bytes).
    pub file_bytes: u64,
}

/// What the caller already knows about the robot pose, for
/// [`refloc_localize_ranges_prior`]: within `radius` m of (`x`, `y`) (map
/// frame; `INFINITY` for anywhere), facing `heading` +- `heading_tolerance`
/// rad (a tolerance of pi or more for any heading). Sites and poses outside
/// it are not considered. For a polygon region instead of the circle, see
/// [`refloc_localize_ranges_polygon`].
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct refloc_prior {
    /// Region centre x (m, map frame).
    pub x: f32,
    /// Region centre y (m, map frame).
    pub y: f32,
    /// Region radius (m); `INFINITY` for no region.
    pub radius: f32,
    /// Heading window centre (rad, map frame).
    pub heading: f32,
    /// Heading window half width (rad); pi or more for any heading.
    pub heading_tolerance: f32,
}

/// The answer for one scan, filled by the `refloc_localize_*` functions
/// (all zero when they return an error).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct refloc_result {
    /// Robot x in the map frame (m).
    pub x: f32,
    /// Robot y in the map frame (m).
    pub y: f32,
    /// Robot heading in the map frame (rad, in (-pi, pi]).
    pub theta: f32,
    /// Sensor x in the map frame (m): the robot pose composed with the
    /// sensor mounting offset stored in the map.
    pub sensor_x: f32,
    /// Sensor y in the map frame (m).
    pub sensor_y: f32,
    /// Sensor heading in the map frame (rad).
    pub sensor_theta: f32,
    /// The reference site the pose came through.
    pub site: u32,
    /// Coarse rank of that site (0 = best histogram correlation).
    pub coarse_rank: u32,
    /// Its histogram correlation coefficient.
    pub gamma: f32,
    /// Spectral matching score E.
    pub match_score: f32,
    /// RANSAC inliers.
    pub inliers: u32,
    /// Vicinity score M.
    pub vicinity: f32,
    /// The acceptance threshold of M.
    pub vicinity_threshold: f32,
    /// Valid points of the input scan.
    pub valid_points: u32,
    /// Candidate sites examined.
    pub candidates: u32,
    /// 1 when the pose is accepted (its confidence is at least the
    /// threshold the map stores; in a map built without one, M > threshold
    /// and the pose passes the free-space and ambiguity checks), 0
    /// otherwise: a rejected pose is the best guess, not a fix.
    pub accepted: u8,
    /// Zero.
    pub reserved: [u8; 3],
    /// Probability (0-1) that the pose is right.
    pub confidence: f32,
    /// Covariance of (x, y, theta), row-major 3x3 (m^2, m rad, rad^2) from
    /// the fit of the scan to the map; all zero when it could not be
    /// computed (too few points, degenerate geometry).
    pub covariance: [f32; 9],
    /// Entries of `hypotheses` in use (1-5).
    pub hypothesis_count: u32,
    /// The top distinct pose hypotheses (at least 1 m or 20 degrees apart),
    /// the first is the pose above, the alternatives follow by probability,
    /// highest first.
    pub hypotheses: [refloc_hypothesis; 5],
}

/// One distinct pose hypothesis of a `refloc_result`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct refloc_hypothesis {
    /// Robot x in the map frame (m).
    pub x: f32,
    /// Robot y in the map frame (m).
    pub y: f32,
    /// Robot heading in the map frame (rad).
    pub theta: f32,
    /// Probability (0-1) that this pose is right.
    pub confidence: f32,
}

/// What lives inside a `refloc_db`.
struct Handle {
    magic: u64,
    db: RefDb<&'static [u8]>,
}

const MAGIC: u64 = 0x5245_464C_4F43_4442; // "REFLOCDB"

// The handle must fit the caller's memory on every target.
const _: () = assert!(size_of::<Handle>() <= REFLOC_DB_SIZE);
const _: () = assert!(align_of::<Handle>() <= REFLOC_DB_ALIGN);
const _: () = assert!(align_of::<refloc_db>() == REFLOC_DB_ALIGN);
const _: () = assert!(size_of::<refloc_result>() == 188);
const _: () = assert!(size_of::<refloc_hypothesis>() == 16);
const _: () = assert!(REFLOC_MAX_POLYGON_VERTICES == refloc::prior::MAX_POLYGON_VERTICES);

fn db_status(kind: DbErrorKind) -> refloc_status {
    match kind {
        DbErrorKind::Magic => REFLOC_ERR_DB_NOT_REFDB,
        DbErrorKind::Version => REFLOC_ERR_DB_VERSION,
        DbErrorKind::Truncated => REFLOC_ERR_DB_TRUNCATED,
        DbErrorKind::HeaderChecksum | DbErrorKind::SectionChecksum => REFLOC_ERR_DB_CHECKSUM,
        DbErrorKind::Alignment => REFLOC_ERR_DB_ALIGNMENT,
        DbErrorKind::Endian | DbErrorKind::HostEndian => REFLOC_ERR_DB_ENDIAN,
        DbErrorKind::Table
        | DbErrorKind::OutOfBounds
        | DbErrorKind::Overlap
        | DbErrorKind::Missing
        | DbErrorKind::Size
        | DbErrorKind::Value => REFLOC_ERR_DB_INVALID,
        _ => REFLOC_ERR_UNKNOWN,
    }
}

fn localize_status(e: LocalizeError) -> refloc_status {
    match e {
        LocalizeError::ScratchTooSmall { .. } => REFLOC_ERR_SCRATCH_TOO_SMALL,
        LocalizeError::TooManyBeams { .. } => REFLOC_ERR_TOO_MANY_BEAMS,
        LocalizeError::BadScan(_) => REFLOC_ERR_BAD_SCAN,
        LocalizeError::NotEnoughPoints { .. } => REFLOC_ERR_NOT_ENOUGH_POINTS,
        LocalizeError::NoMatch { .. } => REFLOC_ERR_NO_MATCH,
        _ => REFLOC_ERR_UNKNOWN,
    }
}

/// The opened handle behind `db`.
///
/// # Safety
/// `db` is NULL or points to `REFLOC_DB_SIZE` readable bytes.
unsafe fn handle<'a>(db: *const refloc_db) -> Result<&'a Handle, refloc_status> {
    if db.is_null() {
        return Err(REFLOC_ERR_NULL);
    }
    if (db as usize) % align_of::<Handle>() != 0 {
        return Err(REFLOC_ERR_ALIGNMENT);
    }
    let h = db.cast::<Handle>();
    // SAFETY: `db` is non-null, aligned and points to REFLOC_DB_SIZE bytes
    // (the caller's contract); `magic` is a plain u64 at the start of them,
    // and only `refloc_db_open` writes MAGIC there, after the whole Handle.
    let magic = unsafe { core::ptr::addr_of!((*h).magic).read_volatile() };
    if magic != MAGIC {
        return Err(REFLOC_ERR_BAD_HANDLE);
    }
    // SAFETY: the magic says `refloc_db_open` wrote a valid Handle here, and
    // nothing but `refloc_db_close` (which needs the caller to have stopped
    // using it) changes it afterwards.
    Ok(unsafe { &*h })
}

/// Opens the `.refdb` in `bytes[0..len]` into the caller's handle `out_db`:
/// checks its structure, bounds, alignment and counts (not its checksums:
/// see [`refloc_db_verify`]). Copies nothing: `bytes` must start on a
/// 16-byte boundary and stay alive and unchanged while `out_db` is used.
///
/// Returns `REFLOC_OK`, `REFLOC_ERR_NULL`, `REFLOC_ERR_ALIGNMENT` (handle),
/// or a `REFLOC_ERR_DB_*` code; on error the handle is left closed.
///
/// # Safety
/// `bytes` points to `len` readable bytes (or is NULL); `out_db` points to
/// a writable `refloc_db` (or is NULL).
#[no_mangle]
pub unsafe extern "C" fn refloc_db_open(
    bytes: *const u8,
    len: usize,
    out_db: *mut refloc_db,
) -> refloc_status {
    if out_db.is_null() || bytes.is_null() {
        return REFLOC_ERR_NULL;
    }
    if (out_db as usize) % align_of::<Handle>() != 0 {
        return REFLOC_ERR_ALIGNMENT;
    }
    let h = out_db.cast::<Handle>();
    // SAFETY: out_db is non-null, aligned and writable (caller's contract);
    // clearing the magic first leaves the handle closed if opening fails.
    unsafe { core::ptr::addr_of_mut!((*h).magic).write_volatile(0) };
    // SAFETY: the caller keeps `len` bytes at `bytes` alive and unchanged
    // for as long as the handle is used; the 'static is that promise.
    let data: &'static [u8] = unsafe { core::slice::from_raw_parts(bytes, len) };
    match RefDb::new(data) {
        Ok(db) => {
            // SAFETY: as above; `h` is valid for a write of a Handle
            // (size and alignment asserted at compile time).
            unsafe { h.write(Handle { magic: MAGIC, db }) };
            REFLOC_OK
        }
        Err(e) => db_status(e.kind),
    }
}

/// Checks every checksum of an opened map (time proportional to its size):
/// `REFLOC_OK` or `REFLOC_ERR_DB_CHECKSUM`.
///
/// # Safety
/// `db` is NULL or points to a `refloc_db`.
#[no_mangle]
pub unsafe extern "C" fn refloc_db_verify(db: *const refloc_db) -> refloc_status {
    // SAFETY: the caller's contract.
    match unsafe { handle(db) } {
        Ok(h) => match h.db.verify() {
            Ok(()) => REFLOC_OK,
            Err(e) => db_status(e.kind),
        },
        Err(s) => s,
    }
}

/// Fills `out_info` with what the opened map holds.
///
/// # Safety
/// `db` is NULL or points to a `refloc_db`; `out_info` is NULL or points to
/// a writable `refloc_db_info`.
#[no_mangle]
pub unsafe extern "C" fn refloc_db_get_info(
    db: *const refloc_db,
    out_info: *mut refloc_db_info,
) -> refloc_status {
    if out_info.is_null() {
        return REFLOC_ERR_NULL;
    }
    if (out_info as usize) % align_of::<refloc_db_info>() != 0 {
        return REFLOC_ERR_ALIGNMENT;
    }
    // SAFETY: the caller's contract.
    let h = match unsafe { handle(db) } {
        Ok(h) => h,
        Err(s) => return s,
    };
    let (width, height) = h.db.grid_size();
    let f = h.db.frame();
    let p = h.db.params();
    let info = refloc_db_info {
        width,
        height,
        resolution: f.resolution,
        origin_x: f.origin.x,
        origin_y: f.origin.y,
        origin_theta: f.origin.theta,
        sites: h.db.site_count() as u32,
        reference_beams: p.sensor.beams,
        range_max: p.sensor.range_max,
        file_bytes: h.db.bytes().len() as u64,
    };
    // SAFETY: non-null, aligned, writable (caller's contract).
    unsafe { out_info.write(info) };
    REFLOC_OK
}

/// Bytes of scratch memory a localization needs for scans of up to
/// `max_beams` beams (or points) against this map; 0 if `db` is not an
/// opened handle.
///
/// # Safety
/// `db` is NULL or points to a `refloc_db`.
#[no_mangle]
pub unsafe extern "C" fn refloc_scratch_size(db: *const refloc_db, max_beams: usize) -> usize {
    // SAFETY: the caller's contract.
    match unsafe { handle(db) } {
        Ok(h) => scratch_size(h.db.params(), max_beams),
        Err(_) => 0,
    }
}

/// Marks the handle closed (later calls with it return
/// `REFLOC_ERR_BAD_HANDLE`). There is nothing to free.
///
/// # Safety
/// `db` is NULL or points to a `refloc_db` that no other thread is using.
#[no_mangle]
pub unsafe extern "C" fn refloc_db_close(db: *mut refloc_db) {
    if !db.is_null() && (db as usize) % align_of::<Handle>() == 0 {
        // SAFETY: non-null, aligned, writable, not in use (caller's contract).
        unsafe { core::ptr::addr_of_mut!((*db.cast::<Handle>()).magic).write_volatile(0) };
    }
}

fn fill(out: &mut refloc_result, fix: &Localization<'_>) {
    *out = refloc_result {
        x: fix.pose.x,
        y: fix.pose.y,
        theta: fix.pose.theta,
        sensor_x: fix.sensor_pose.x,
        sensor_y: fix.sensor_pose.y,
        sensor_theta: fix.sensor_pose.theta,
        site: fix.site,
        coarse_rank: fix.coarse_rank,
        gamma: fix.gamma,
        match_score: fix.match_score,
        inliers: fix.inliers,
        vicinity: fix.vicinity,
        vicinity_threshold: fix.vicinity_threshold,
        valid_points: fix.valid_points,
        candidates: fix.candidates.len() as u32,
        accepted: fix.accepted as u8,
        reserved: [0; 3],
        confidence: fix.confidence,
        covariance: fix.covariance.unwrap_or([0.0; 9]),
        hypothesis_count: fix.hypotheses().len() as u32,
        hypotheses: fix.hypotheses.map(|h| refloc_hypothesis {
            x: h.pose.x,
            y: h.pose.y,
            theta: h.pose.theta,
            confidence: h.confidence,
        }),
    };
}

/// Shared tail of the two localize entry points.
///
/// # Safety
/// The pointers satisfy the contracts of the public functions.
unsafe fn run(
    db: *const refloc_db,
    scan: impl FnOnce() -> Result<Scan<'static>, refloc_status>,
    prior: impl FnOnce() -> Result<Option<Prior>, refloc_status>,
    scratch: *mut u8,
    scratch_len: usize,
    out_result: *mut refloc_result,
) -> refloc_status {
    if out_result.is_null() {
        return REFLOC_ERR_NULL;
    }
    if (out_result as usize) % align_of::<refloc_result>() != 0 {
        return REFLOC_ERR_ALIGNMENT;
    }
    // SAFETY: non-null, aligned, writable (caller's contract).
    let out = unsafe { &mut *out_result };
    *out = refloc_result::default();
    // SAFETY: the caller's contract.
    let h = match unsafe { handle(db) } {
        Ok(h) => h,
        Err(s) => return s,
    };
    let scan = match scan() {
        Ok(s) => s,
        Err(s) => return s,
    };
    if scratch.is_null() {
        return REFLOC_ERR_NULL;
    }
    // SAFETY: `scratch_len` writable bytes that nothing else uses during
    // the call (caller's contract); u8 needs no alignment.
    let scratch = unsafe { core::slice::from_raw_parts_mut(scratch, scratch_len) };
    let prior = match prior() {
        Ok(p) if p.is_some_and(|p| !p.is_valid()) => return REFLOC_ERR_BAD_PRIOR,
        Ok(p) => p,
        Err(s) => return s,
    };
    match localize_with_prior(&h.db, &scan, scratch, prior) {
        Ok(fix) => {
            fill(out, &fix);
            REFLOC_OK
        }
        Err(e) => localize_status(e),
    }
}

/// A caller's float array as a slice (empty for n = 0, whatever the pointer).
///
/// # Safety
/// `p` is NULL or points to `n` readable floats that outlive the call.
unsafe fn floats<'a>(p: *const f32, n: usize) -> Result<&'a [f32], refloc_status> {
    if n == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return Err(REFLOC_ERR_NULL);
    }
    if (p as usize) % align_of::<f32>() != 0 {
        return Err(REFLOC_ERR_ALIGNMENT);
    }
    // SAFETY: non-null, aligned, `n` readable floats (caller's contract).
    Ok(unsafe { core::slice::from_raw_parts(p, n) })
}

/// Localizes one scan given as ranges (`sensor_msgs/LaserScan` layout: beam
/// `k` at angle `angle_min + k * angle_increment` in the sensor frame, rad;
/// `angle_increment < 0` for clockwise scans; ranges in metres, NaN, inf or
/// outside `[range_min, range_max)` meaning "no return"), with no initial
/// pose, using only `scratch[0..scratch_len]` (at least
/// `refloc_scratch_size(db, n)` bytes, any alignment). Writes the pose to
/// `out_result` (zeroed on error). Never allocates.
///
/// # Safety
/// `db` is NULL or points to a `refloc_db`; `ranges` points to `n` readable
/// floats (or `n` is 0); `scratch` points to `scratch_len` writable bytes no
/// one else uses during the call; `out_result` is NULL or points to a
/// writable `refloc_result`.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn refloc_localize_ranges(
    db: *const refloc_db,
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    ranges: *const f32,
    n: usize,
    scratch: *mut u8,
    scratch_len: usize,
    out_result: *mut refloc_result,
) -> refloc_status {
    // SAFETY: the caller's contract; no prior.
    unsafe {
        refloc_localize_ranges_prior(
            db,
            angle_min,
            angle_increment,
            range_min,
            range_max,
            ranges,
            n,
            core::ptr::null(),
            scratch,
            scratch_len,
            out_result,
        )
    }
}

/// As [`refloc_localize_ranges`], with a prior (`prior` NULL: none, the
/// same as [`refloc_localize_ranges`]). A prior that makes no sense is
/// `REFLOC_ERR_BAD_PRIOR`.
///
/// # Safety
/// As [`refloc_localize_ranges`]; `prior` is NULL or points to a readable
/// `refloc_prior`.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn refloc_localize_ranges_prior(
    db: *const refloc_db,
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    ranges: *const f32,
    n: usize,
    prior: *const refloc_prior,
    scratch: *mut u8,
    scratch_len: usize,
    out_result: *mut refloc_result,
) -> refloc_status {
    // SAFETY: the caller's contract.
    let read = || unsafe { read_prior(prior) };
    // SAFETY: the caller's contract.
    unsafe {
        run_ranges(
            db,
            [angle_min, angle_increment, range_min, range_max],
            ranges,
            n,
            read,
            scratch,
            scratch_len,
            out_result,
        )
    }
}

/// Shared tail of the ranges entry points: the scan geometry is
/// `[angle_min, angle_increment, range_min, range_max]`.
///
/// # Safety
/// The pointers satisfy the contracts of the public functions.
#[allow(clippy::too_many_arguments)]
unsafe fn run_ranges(
    db: *const refloc_db,
    geometry: [f32; 4],
    ranges: *const f32,
    n: usize,
    prior: impl FnOnce() -> Result<Option<Prior>, refloc_status>,
    scratch: *mut u8,
    scratch_len: usize,
    out_result: *mut refloc_result,
) -> refloc_status {
    let [angle_min, angle_increment, range_min, range_max] = geometry;
    let scan = || {
        // SAFETY: the caller's contract; the slice lives through the call.
        let ranges = unsafe { floats(ranges, n) }?;
        Ok(Scan::Ranges(RangeScan {
            angle_min,
            angle_increment,
            range_min,
            range_max,
            ranges,
        }))
    };
    // SAFETY: the caller's contract.
    unsafe { run(db, scan, prior, scratch, scratch_len, out_result) }
}

/// The caller's `refloc_prior` as a runtime prior (NULL: none).
///
/// # Safety
/// `prior` is NULL or points to a readable `refloc_prior`.
unsafe fn read_prior(prior: *const refloc_prior) -> Result<Option<Prior>, refloc_status> {
    if prior.is_null() {
        return Ok(None);
    }
    if (prior as usize) % align_of::<refloc_prior>() != 0 {
        return Err(REFLOC_ERR_ALIGNMENT);
    }
    // SAFETY: non-null, aligned, readable (caller's contract).
    let p = unsafe { *prior };
    Ok(Some(Prior {
        x: p.x,
        y: p.y,
        radius: p.radius,
        ..Prior::NONE.with_heading(p.heading, p.heading_tolerance)
    }))
}

/// As [`refloc_localize_ranges_prior`], with a polygon region: the robot
/// is inside (or on the edge of) the polygon of `polygon_len` vertices
/// whose coordinates `polygon_xy` holds as x0, y0, x1, y1, ... (m, map
/// frame; either direction around, the last vertex joins the first; for a
/// self-intersecting outline the even-odd rule decides what is inside).
/// Sites farther than 2 m outside it are not ranked. `prior` is NULL (any
/// heading) or gives the heading window; its `radius` must then be
/// `INFINITY` (one region: the polygon), else `REFLOC_ERR_BAD_PRIOR`.
/// A polygon of fewer than 3 or more than `REFLOC_MAX_POLYGON_VERTICES`
/// vertices, with a non-finite coordinate or with all vertices on one line
/// is `REFLOC_ERR_BAD_POLYGON`; `polygon_xy` NULL with `polygon_len` > 0
/// is `REFLOC_ERR_NULL`.
///
/// # Safety
/// As [`refloc_localize_ranges_prior`]; `polygon_xy` is NULL or points to
/// `2 * polygon_len` readable floats (or `polygon_len` is 0).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub unsafe extern "C" fn refloc_localize_ranges_polygon(
    db: *const refloc_db,
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    ranges: *const f32,
    n: usize,
    polygon_xy: *const f32,
    polygon_len: usize,
    prior: *const refloc_prior,
    scratch: *mut u8,
    scratch_len: usize,
    out_result: *mut refloc_result,
) -> refloc_status {
    let read = || {
        // Checked before the length is doubled, which cannot overflow then.
        if polygon_len > REFLOC_MAX_POLYGON_VERTICES {
            return Err(REFLOC_ERR_BAD_POLYGON);
        }
        // SAFETY: the caller's contract.
        let xy = unsafe { floats(polygon_xy, 2 * polygon_len) }?;
        let polygon = Polygon::from_flat(xy).map_err(|_| REFLOC_ERR_BAD_POLYGON)?;
        // SAFETY: the caller's contract.
        let p = unsafe { read_prior(prior) }?.unwrap_or(Prior::NONE);
        Ok(Some(Prior {
            polygon: Some(polygon),
            ..p
        }))
    };
    // SAFETY: the caller's contract.
    unsafe {
        run_ranges(
            db,
            [angle_min, angle_increment, range_min, range_max],
            ranges,
            n,
            read,
            scratch,
            scratch_len,
            out_result,
        )
    }
}

/// Localizes one scan given as `n` points in the sensor frame (`points` =
/// x0, y0, x1, y1, ... in metres, in scan order; non-finite points mean "no
/// return"); `range_max` (m) bounds the verification's virtual beams.
/// Otherwise as [`refloc_localize_ranges`].
///
/// # Safety
/// `points` points to `2 * n` readable floats (or `n` is 0); the other
/// pointers as for [`refloc_localize_ranges`].
#[no_mangle]
pub unsafe extern "C" fn refloc_localize_points(
    db: *const refloc_db,
    points: *const f32,
    n: usize,
    range_max: f32,
    scratch: *mut u8,
    scratch_len: usize,
    out_result: *mut refloc_result,
) -> refloc_status {
    let scan = || {
        let points: &[[f32; 2]] = if n == 0 {
            &[]
        } else if points.is_null() {
            return Err(REFLOC_ERR_NULL);
        } else if (points as usize) % align_of::<[f32; 2]>() != 0 {
            return Err(REFLOC_ERR_ALIGNMENT);
        } else {
            // SAFETY: non-null, aligned, `2 * n` readable floats laid out as
            // `n` pairs (caller's contract); lives through the call.
            unsafe { core::slice::from_raw_parts(points.cast::<[f32; 2]>(), n) }
        };
        Ok(Scan::Points { points, range_max })
    };
    // SAFETY: the caller's contract.
    unsafe { run(db, scan, || Ok(None), scratch, scratch_len, out_result) }
}

/// A static, NUL-terminated English description of a status code (never
/// NULL; unknown codes get "unknown refloc status").
#[no_mangle]
pub extern "C" fn refloc_strerror(status: i32) -> *const c_char {
    let s: &'static core::ffi::CStr = match status {
        0 => c"success",
        1 => c"a required pointer argument is NULL",
        2 => c"a pointer argument is misaligned (handle: 8 bytes, floats: 4 bytes)",
        3 => c"the handle is not open (refloc_db_open failed, was not called, or refloc_db_close was)",
        10 => c"not a .refdb file",
        11 => c"unsupported .refdb format version: rebuild the map with a matching mapc",
        12 => c"the .refdb is truncated or has trailing bytes",
        13 => c"a .refdb checksum does not match (corrupted data)",
        14 => c"the .refdb bytes must start on a 16-byte boundary (or a section is misaligned)",
        15 => c"byte order mismatch between the .refdb and this CPU",
        16 => c"the .refdb is malformed",
        20 => c"the scratch buffer is smaller than refloc_scratch_size",
        21 => c"the scan has more beams than the scratch was sized for",
        22 => c"unusable scan geometry (angles or range limits)",
        23 => c"too few valid returns in the scan",
        24 => c"no candidate site matched the scan",
        25 => c"unusable prior (finite x, y, heading; radius > 0 or INFINITY, INFINITY with a polygon; tolerance >= 0)",
        26 => c"unusable prior polygon (3 to REFLOC_MAX_POLYGON_VERTICES finite vertices, not all on one line)",
        99 => c"an error this version of the C ABI does not know",
        _ => c"unknown refloc status",
    };
    s.as_ptr()
}

/// Bare metal: the panic handler a `no_std` staticlib must bring.
#[cfg(all(target_os = "none", feature = "panic-handler", not(test)))]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    // refloc is written not to panic; if it ever does, stop here.
    loop {
        core::hint::spin_loop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strerror_covers_every_status() {
        for s in [
            REFLOC_OK,
            REFLOC_ERR_NULL,
            REFLOC_ERR_ALIGNMENT,
            REFLOC_ERR_BAD_HANDLE,
            REFLOC_ERR_DB_NOT_REFDB,
            REFLOC_ERR_DB_VERSION,
            REFLOC_ERR_DB_TRUNCATED,
            REFLOC_ERR_DB_CHECKSUM,
            REFLOC_ERR_DB_ALIGNMENT,
            REFLOC_ERR_DB_ENDIAN,
            REFLOC_ERR_DB_INVALID,
            REFLOC_ERR_SCRATCH_TOO_SMALL,
            REFLOC_ERR_TOO_MANY_BEAMS,
            REFLOC_ERR_BAD_SCAN,
            REFLOC_ERR_NOT_ENOUGH_POINTS,
            REFLOC_ERR_NO_MATCH,
            REFLOC_ERR_BAD_PRIOR,
            REFLOC_ERR_BAD_POLYGON,
            REFLOC_ERR_UNKNOWN,
        ] {
            // SAFETY: refloc_strerror returns a static C string.
            let msg = unsafe { core::ffi::CStr::from_ptr(refloc_strerror(s as i32)) };
            assert_ne!(msg.to_bytes(), b"unknown refloc status", "{s:?}");
        }
    }

    #[test]
    fn null_and_garbage_are_errors() {
        let mut h = refloc_db {
            opaque: [0; REFLOC_DB_WORDS],
        };
        unsafe {
            assert_eq!(
                refloc_db_open(core::ptr::null(), 0, &mut h),
                REFLOC_ERR_NULL
            );
            assert_eq!(refloc_db_verify(&h), REFLOC_ERR_BAD_HANDLE);
            assert_eq!(refloc_scratch_size(&h, 100), 0);
            let junk = [7u8; 64];
            assert_eq!(
                refloc_db_open(junk.as_ptr(), junk.len(), &mut h),
                REFLOC_ERR_DB_NOT_REFDB
            );
            assert_eq!(refloc_db_verify(&h), REFLOC_ERR_BAD_HANDLE);
            let mut out = refloc_result::default();
            let r = [1.0f32; 10];
            let mut scratch = [0u8; 16];
            let st = refloc_localize_ranges(
                &h,
                0.0,
                0.1,
                0.0,
                10.0,
                r.as_ptr(),
                r.len(),
                scratch.as_mut_ptr(),
                16,
                &mut out,
            );
            assert_eq!(st, REFLOC_ERR_BAD_HANDLE);
            assert_eq!(refloc_db_verify(core::ptr::null()), REFLOC_ERR_NULL);
        }
    }
}
