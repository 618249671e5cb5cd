//! `refloc::localize` never touches the heap: a counting global allocator
//! records every allocation, deallocation and reallocation made by the
//! current thread while a thread-local flag is set, and the localizer runs
//! on real compiled maps with the flag set. The counts are per thread too,
//! so tests running at the same time (one of them allocates on purpose)
//! cannot add to each other's.
//!
//! Registered as an integration test of the mapc package (it needs the
//! compiler to make its database).

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

use common::{Db, Sample};
use refloc::{localize, scratch_size, LocalizeError, Pose2};

thread_local! {
    /// Set while the current thread is being watched. `const`-initialized
    /// with no destructor, so reading it never allocates.
    static WATCHED: Cell<bool> = const { Cell::new(false) };
    /// This thread's counts while watched (allocations, deallocations,
    /// reallocations); `const`-initialized like `WATCHED`.
    static COUNTS: Cell<Counts> = const { Cell::new(Counts { allocs: 0, deallocs: 0, reallocs: 0 }) };
}

fn watched() -> bool {
    WATCHED.try_with(Cell::get).unwrap_or(false)
}

/// Adds one call to this thread's counts when it is watched.
fn note(f: fn(&mut Counts)) {
    if watched() {
        let _ = COUNTS.try_with(|c| {
            let mut v = c.get();
            f(&mut v);
            c.set(v);
        });
    }
}

/// `System`, counting the calls made by a watched thread.
struct Counting;

// SAFETY: every call is forwarded unchanged to `System`; the counting only
// touches const thread-local `Cell`s, which do not allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(|c| c.allocs += 1);
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note(|c| c.allocs += 1);
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note(|c| c.deallocs += 1);
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(|c| c.reallocs += 1);
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Counts {
    allocs: usize,
    deallocs: usize,
    reallocs: usize,
}

/// This thread's counts so far.
fn counts() -> Counts {
    COUNTS.with(Cell::get)
}

/// Runs `f` with the current thread watched; returns what it did to the heap.
fn watch<R>(f: impl FnOnce() -> R) -> (R, Counts) {
    let before = counts();
    WATCHED.with(|w| w.set(true));
    let r = f();
    WATCHED.with(|w| w.set(false));
    let after = counts();
    let d = Counts {
        allocs: after.allocs - before.allocs,
        deallocs: after.deallocs - before.deallocs,
        reallocs: after.reallocs - before.reallocs,
    };
    (r, d)
}

type Answer = Result<(Pose2, u32, bool), LocalizeError>;

/// Localizes every sample twice with the heap watched; asserts it was never
/// touched. Returns the answers.
fn localize_watched(db: &Db, samples: &[Sample]) -> Vec<Answer> {
    let rdb = db.open();
    let max = samples.iter().map(|s| s.scan.len()).max().unwrap_or(0);
    // Everything the watched region writes is allocated before it.
    let mut scratch = vec![0u8; scratch_size(rdb.params(), max)];
    let mut answers: Vec<Answer> = vec![Err(LocalizeError::BadScan("not run")); samples.len()];
    let mut repeat_same = true;
    let (_, c) = watch(|| {
        for (a, s) in answers.iter_mut().zip(samples) {
            let scan = s.scan.scan();
            *a = localize(&rdb, &scan, &mut scratch).map(|l| (l.pose, l.site, l.accepted));
            let again = localize(&rdb, &scan, &mut scratch).map(|l| (l.pose, l.site, l.accepted));
            repeat_same &= again == *a;
        }
    });
    assert_eq!(
        c,
        Counts {
            allocs: 0,
            deallocs: 0,
            reallocs: 0
        },
        "localize touched the heap"
    );
    assert!(
        repeat_same,
        "a second run on the same scratch gave a different answer"
    );
    answers
}

fn report(name: &str, samples: &[Sample], answers: &[Answer]) -> usize {
    let mut good = 0;
    for (s, a) in samples.iter().zip(answers) {
        match a {
            Ok((pose, _, _)) => {
                let (d, th) = common::error(pose, &s.truth);
                good += (d < 0.3 && th < 0.1) as usize;
            }
            Err(e) => eprintln!("{name}: {}: {e}", s.scan.describe()),
        }
    }
    let ok = answers.iter().filter(|a| a.is_ok()).count();
    eprintln!(
        "{name}: {} scans, {ok} answered, {good} within 0.3 m / 0.1 rad",
        samples.len()
    );
    ok
}

#[test]
fn the_counter_sees_allocations() {
    // The harness itself works: a watched Vec is counted, an unwatched one not.
    let (v, c) = watch(|| {
        let mut v = Vec::with_capacity(4);
        v.extend_from_slice(&[1u8, 2, 3, 4, 5]);
        v
    });
    assert!(c.allocs >= 1 && c.reallocs >= 1, "{c:?}");
    let (_, c) = watch(|| drop(v));
    assert_eq!(c.deallocs, 1);
    let before = counts();
    let unwatched: Vec<u8> = std::hint::black_box(Vec::with_capacity(100));
    drop(unwatched);
    assert_eq!(counts(), before);
}

#[test]
fn localize_does_not_allocate_on_a_synthetic_office() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let db = common::build(common::office_map(dir.path(), 400, 300, 7), 20);
    let rdb = db.open();
    let p = rdb.params();
    println!(
        "scratch_size: {} bytes for 362 beams, {} bytes for 1081 beams",
        scratch_size(p, 362),
        scratch_size(p, 1081)
    );
    let samples = common::simulate(&rdb, &db.source, 30, 11);
    let answers = localize_watched(&db, &samples);
    let ok = report("office", &samples, &answers);
    assert!(
        ok >= samples.len() / 2,
        "only {ok} of {} scans answered",
        samples.len()
    );
}

#[test]
fn localize_does_not_allocate_with_a_coarse_search_index() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let cfg = mapc::compiler::pipeline::BuildConfig {
        fit_queries: 20,
        index: mapc::compiler::index::IndexOptions {
            min_sites: 1,
            leaf_size: 4,
            leaves: 8,
            beam: 4,
            ..Default::default()
        },
        ..Default::default()
    };
    let db = common::build_with(common::office_map(dir.path(), 400, 300, 7), &cfg);
    let rdb = db.open();
    assert!(
        rdb.index().is_some_and(|i| i.node_count() > 3),
        "the index was forced"
    );
    let samples = common::simulate(&rdb, &db.source, 30, 11);
    let answers = localize_watched(&db, &samples);
    let ok = report("office with index", &samples, &answers);
    assert!(
        ok >= samples.len() / 2,
        "only {ok} of {} scans answered",
        samples.len()
    );
}

#[test]
fn localize_does_not_allocate_on_the_intel_map() {
    let yaml = Path::new(common::INTEL_YAML);
    if !yaml.is_file() {
        println!(
            "SKIPPED: the shared Intel map is absent ({}); only the synthetic map was checked",
            yaml.display()
        );
        return;
    }
    let src = mapc::compiler::mapfile::load_yaml(yaml).expect("load the Intel map");
    let db = common::build(src, 20);
    let rdb = db.open();
    println!(
        "intel scratch_size: {} bytes for 362 beams, {} bytes for 1081 beams",
        scratch_size(rdb.params(), 362),
        scratch_size(rdb.params(), 1081)
    );
    let samples = common::simulate(&rdb, &db.source, 30, 12);
    let answers = localize_watched(&db, &samples);
    let ok = report("intel", &samples, &answers);
    assert!(
        ok >= samples.len() / 2,
        "only {ok} of {} scans answered",
        samples.len()
    );
}
