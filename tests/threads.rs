//! A `RefDb` is shared by threads: it is `Send + Sync` over every container,
//! and two threads localizing at once against one memory-mapped database
//! (each with its own scratch) get exactly the single-threaded answers.
//!
//! Registered as an integration test of the mapc package.

mod common;

use std::sync::Barrier;

use refloc::{localize, open_mmap, scratch_size, Candidate, LocalizeError, Pose2, RefDb, Scan};

fn assert_send_sync<T: Send + Sync>() {}

#[test]
fn refdb_is_send_and_sync() {
    assert_send_sync::<RefDb<&[u8]>>();
    assert_send_sync::<RefDb<&'static [u8]>>();
    assert_send_sync::<RefDb<Vec<u8>>>();
    assert_send_sync::<RefDb<memmap2::Mmap>>();
    assert_send_sync::<refloc::Params>();
    assert_send_sync::<refloc::DbError>();
    assert_send_sync::<LocalizeError>();
}

type Answer = Result<(Pose2, u32, Vec<Candidate>), LocalizeError>;

fn run<D: AsRef<[u8]>>(db: &RefDb<D>, scan: &Scan<'_>, scratch: &mut [u8]) -> Answer {
    localize(db, scan, scratch).map(|l| (l.pose, l.site, l.candidates.to_vec()))
}

#[test]
fn two_threads_localize_against_one_mapped_database() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let db = common::build(common::office_map(dir.path(), 300, 220, 3), 20);
    let path = dir.path().join("office.refdb");
    std::fs::write(&path, db.bytes()).expect("write the database");
    let mapped = open_mmap(&path).expect("open the mapped database");
    mapped.verify().expect("checksums");
    assert_eq!(mapped.bytes(), db.bytes());

    let samples = common::simulate(&db.open(), &db.source, 16, 5);
    let max = samples.iter().map(|s| s.scan.len()).max().unwrap();
    let size = scratch_size(mapped.params(), max);

    // Single-threaded reference answers.
    let mut scratch = vec![0u8; size];
    let want: Vec<Answer> = samples
        .iter()
        .map(|s| run(&mapped, &s.scan.scan(), &mut scratch))
        .collect();
    assert!(want.iter().filter(|a| a.is_ok()).count() >= samples.len() / 2);

    // Two threads at once: one takes the even scans, the other the odd ones.
    let start = Barrier::new(2);
    let (mapped, samples, start) = (&mapped, &samples, &start);
    let got: Vec<Vec<(usize, Answer)>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..2)
            .map(|t| {
                s.spawn(move || {
                    let mut scratch = vec![0u8; size];
                    start.wait();
                    (t..samples.len())
                        .step_by(2)
                        .map(|i| (i, run(mapped, &samples[i].scan.scan(), &mut scratch)))
                        .collect()
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect()
    });
    let mut seen = 0;
    for (i, a) in got.into_iter().flatten() {
        assert_eq!(a, want[i], "scan {i} ({})", samples[i].scan.describe());
        seen += 1;
    }
    assert_eq!(seen, samples.len());
}
