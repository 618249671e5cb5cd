//! refloc on a Cortex-M4F: global localization of a handful of laser scans
//! against a compiled map held in flash, with the scratch memory in a
//! `static` and no heap at all (nothing links `alloc`: there is no
//! `#[global_allocator]`, so the link would fail if anything needed one).
//!
//! Built for `thumbv7em-none-eabihf` and run on QEMU's `mps2-an386`
//! machine; output and the exit status go to the host through semihosting.
//! Exit status 0: every scan was accepted within 0.3 m / 5 deg of its true
//! pose; 1 otherwise (or on a panic).
//!
//! The inputs in `data/` are generated, never committed:
//! `data/map.refdb` by `mapc build` and `data/scans.rs` by `refloc-scangen
//! firmware` (see `scripts/firmware-demo.sh`).
#![no_std]
#![no_main]

use core::cell::UnsafeCell;
use core::ptr::{addr_of, addr_of_mut};
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
use refloc::{localize, scratch_size, wrap_angle, RangeScan, RefDb, Scan};

/// Acceptance bounds of the demo (those of `mapc eval`).
const MAX_POS_ERR_M: f32 = 0.3;
const MAX_THETA_ERR_RAD: f32 = 5.0 * core::f32::consts::PI / 180.0;

/// Gives `include_bytes!` data the alignment the `.refdb` reader needs for
/// its in-place `u32`/`f32` arrays (sections are 16-byte aligned in the
/// file, so the file must start 16-byte aligned in memory).
#[repr(C, align(16))]
struct Aligned<B: ?Sized>(B);

/// The compiled map, in flash.
static MAP: &Aligned<[u8]> = &Aligned(*include_bytes!("../data/map.refdb"));

/// One test scan as `sensor_msgs/LaserScan` fields, with its true robot pose.
struct TestScan {
    label: &'static str,
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    ranges: &'static [f32],
    /// x (m), y (m), theta (rad) in the map frame.
    truth: [f32; 3],
}

/// The generated test data: `DB_LEN`, `MAX_BEAMS`, `SCRATCH_BYTES`, `SCANS`.
#[allow(clippy::approx_constant, clippy::excessive_precision)]
mod data {
    use super::TestScan;
    include!("../data/scans.rs");
}
use data::{DB_LEN, MAX_BEAMS, SCANS, SCRATCH_BYTES};

/// A static buffer that is handed out as `&mut` at most once.
struct Once<const N: usize> {
    buf: UnsafeCell<[u8; N]>,
    taken: AtomicBool,
}

// SAFETY: the only access to `buf` is through `take`, which the atomic flag
// lets succeed once, so no two references to the buffer ever exist, on any
// thread or interrupt.
unsafe impl<const N: usize> Sync for Once<N> {}

impl<const N: usize> Once<N> {
    const fn new() -> Self {
        Once {
            buf: UnsafeCell::new([0; N]),
            taken: AtomicBool::new(false),
        }
    }

    // A `&mut` out of `&self` is the point: the flag makes it unique.
    #[allow(clippy::mut_from_ref)]
    fn take(&'static self) -> Option<&'static mut [u8; N]> {
        if self.taken.swap(true, Ordering::AcqRel) {
            return None;
        }
        // SAFETY: the flag was clear, so this is the first and only time a
        // reference to `buf` is made; it lives as long as the static.
        Some(unsafe { &mut *self.buf.get() })
    }
}

/// refloc's working memory: zero-initialized, so it lives in `.bss` and
/// costs no flash.
static SCRATCH: Once<SCRATCH_BYTES> = Once::new();

/// Word written over the free stack before the run, to measure its peak.
const PAINT: u32 = 0xA5C3_5A3C;

extern "C" {
    /// End of `.bss` (cortex-m-rt's linker script): the lowest address the
    /// stack can grow down to.
    static mut __sheap: u32;
    /// Top of the stack (cortex-m-rt's linker script).
    static _stack_start: u32;
}

/// Fills the free stack below the caller's frame with `PAINT`.
#[inline(never)]
fn paint_stack() {
    let lo = addr_of_mut!(__sheap) as usize;
    // Stay well below this function's own frame.
    let hi = (cortex_m::register::msp::read() as usize - 1024) & !3;
    let mut p = lo;
    while p < hi {
        // SAFETY: [__sheap, hi) is RAM that holds no Rust object: it lies
        // between the end of .bss and the live stack, interrupts are off,
        // and word-aligned by the linker script and the mask above.
        unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

/// Deepest stack use since `paint_stack` (bytes).
fn stack_peak() -> usize {
    let lo = addr_of_mut!(__sheap) as usize;
    let top = addr_of!(_stack_start) as usize;
    let mut p = lo;
    // SAFETY: as in `paint_stack`; reads only.
    while p < top && unsafe { core::ptr::read_volatile(p as *const u32) } == PAINT {
        p += 4;
    }
    top - p
}

/// Prints an f32 with `d` decimals (core's float formatting).
struct F(f32, usize);
impl core::fmt::Display for F {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:.*}", self.1, self.0)
    }
}

#[entry]
fn main() -> ! {
    paint_stack();
    let ok = run();
    hprintln!("stack peak: {} bytes", stack_peak());
    if ok {
        hprintln!("FIRMWARE PASS");
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        hprintln!("FIRMWARE FAIL");
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {
        cortex_m::asm::wfi();
    }
}

fn run() -> bool {
    let bytes: &'static [u8] = &MAP.0;
    hprintln!(
        "refloc firmware demo: Cortex-M4F, map {} bytes in flash at {:#010x}",
        bytes.len(),
        bytes.as_ptr() as usize
    );
    if bytes.len() != DB_LEN {
        hprintln!(
            "data/scans.rs was made for a {}-byte map: regenerate data/",
            DB_LEN
        );
        return false;
    }
    let db = match RefDb::new(bytes) {
        Ok(db) => db,
        Err(e) => {
            hprintln!("map rejected: {}", e);
            return false;
        }
    };
    if let Err(e) = db.verify() {
        hprintln!("map checksum: {}", e);
        return false;
    }
    let (w, h) = db.grid_size();
    let params = db.params();
    hprintln!(
        "map: {}x{} cells, {} sites, {} reference beams; checksums ok",
        w,
        h,
        db.site_count(),
        params.sensor.beams
    );
    let Some(scratch) = SCRATCH.take() else {
        hprintln!("scratch already taken");
        return false;
    };
    let needed = scratch_size(params, MAX_BEAMS);
    hprintln!(
        "scratch: {} bytes static at {:#010x}, {} needed for {} beams",
        scratch.len(),
        scratch.as_ptr() as usize,
        needed,
        MAX_BEAMS
    );
    if needed > scratch.len() {
        hprintln!("the scratch is too small: data/ was generated by another refloc; rerun scripts/firmware-demo.sh");
        return false;
    }
    let mut passed = 0;
    for (i, t) in SCANS.iter().enumerate() {
        let scan = Scan::Ranges(RangeScan {
            angle_min: t.angle_min,
            angle_increment: t.angle_increment,
            range_min: t.range_min,
            range_max: t.range_max,
            ranges: t.ranges,
        });
        hprintln!("scan {}: {} ({} beams)", i, t.label, t.ranges.len());
        match localize(&db, &scan, &mut scratch[..]) {
            Ok(fix) => {
                let p = fix.pose;
                let [tx, ty, tt] = t.truth;
                let dp = libm::hypotf(p.x - tx, p.y - ty);
                let dt = libm::fabsf(wrap_angle(p.theta - tt));
                let ok = fix.accepted && dp < MAX_POS_ERR_M && dt < MAX_THETA_ERR_RAD;
                passed += ok as usize;
                hprintln!(
                    "  pose  {} {} {}  truth {} {} {}",
                    F(p.x, 3),
                    F(p.y, 3),
                    F(p.theta, 4),
                    F(tx, 3),
                    F(ty, 3),
                    F(tt, 4)
                );
                hprintln!(
                    "  error {} m {} deg; site {} (rank {}), E {}, M {} > {}: {}; {} candidates",
                    F(dp, 3),
                    F(dt.to_degrees(), 2),
                    fix.site,
                    fix.coarse_rank,
                    F(fix.match_score, 2),
                    F(fix.vicinity, 1),
                    F(fix.vicinity_threshold, 1),
                    if fix.accepted { "accepted" } else { "rejected" },
                    fix.candidates.len()
                );
                // One line per scan for the host script to compare.
                hprintln!(
                    "RESULT {} {} {} {} {} {}",
                    i,
                    F(p.x, 6),
                    F(p.y, 6),
                    F(p.theta, 6),
                    fix.accepted as u8,
                    if ok { "ok" } else { "WRONG" }
                );
            }
            Err(e) => {
                hprintln!("  error: {}", e);
                hprintln!("RESULT {} error", i);
            }
        }
    }
    hprintln!(
        "{} of {} scans localized within 0.3 m / 5 deg and accepted",
        passed,
        SCANS.len()
    );
    passed == SCANS.len()
}
