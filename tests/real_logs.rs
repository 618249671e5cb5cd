//! Real laser scans and the wrong-map test, on the shared data (skipped
//! with a message when absent, required in CI).
//!
//! - Every scan of the CSAIL CARMEN log (406 scans, 180 degrees, 361 beams)
//!   against the compiled CSAIL map, compared with the poses in
//!   `csail-poses-in-map.txt`, and with those poses corrected locally
//!   against the map (`mapc::tools::eval::correct_truth_locally`: the given poses
//!   come from another SLAM run than the map, and 19 of them are off by
//!   more than the tolerance where the map places the scan unambiguously).
//!   Measured when the bounds were set: 91.1% accepted and correct against
//!   the given poses (4.7% false accepts: exactly those 19 scans); against
//!   the corrected poses 95.8% and 0 false accepts (docs/results.md).
//! - Every 5th scan of the Intel and ACES logs: regression bounds against
//!   the corrected truth.
//! - Scans simulated on the ACES map, localized against the Intel database:
//!   at most 1% accepted (measured: 0 of 500).
//! - A symmetric map (tb3-world): no pose accepted at the twin place
//!   (measured: 0 false accepts of 200 before the bound was set; 15.5%
//!   without the early stop's confirmation).

mod common;

use mapc::compiler::mapfile::{Cell, OccupancyGrid};
use mapc::tools::scanio::{self, InputFormat, ReadOptions, ScanData};
use rayon::prelude::*;
use refloc::{localize, scratch_size, RangeScan, Scan};

/// What a real log gave: shares of the scans (0..=1) accepted and correct
/// and accepted and wrong, against the given poses and against the poses
/// corrected locally against the map; the median error (m) of the correct
/// ones; the share of scans whose given pose is off by more than the
/// tolerance.
struct LogResult {
    /// Scans read from the whole log (before taking every `every`-th).
    log_scans: usize,
    correct: f64,
    false_acc: f64,
    median: f64,
    correct_c: f64,
    false_c: f64,
    truth_off: f64,
    /// Median number of candidates the fine stage examined per scan.
    examined: usize,
}

/// Localizes every `every`-th scan of the shared log `name` (CARMEN, `beams`
/// beams a scan) against its map compiled with `mapc build` defaults, and
/// checks that every answer is well formed (confidence, decision,
/// hypotheses, covariance). `None` when the shared data is absent.
fn real_log(name: &str, beams: usize, every: usize) -> Option<LogResult> {
    real_log_resampled(name, beams, every, None)
}

/// [`real_log`] on the map's grid resampled by `resample` ([`finer`],
/// [`coarser`]) before it is compiled.
fn real_log_resampled(
    name: &str,
    beams: usize,
    every: usize,
    resample: Option<fn(&OccupancyGrid) -> OccupancyGrid>,
) -> Option<LogResult> {
    let (Some(map), Some(log), Some(truth)) = (
        mapc::testdata::shared(&format!("maps/{name}/{name}.yaml")),
        mapc::testdata::shared(&format!("logs/{name}/{name}-corrected.log.gz")),
        mapc::testdata::shared(&format!("logs/{name}/{name}-poses-in-map.txt")),
    ) else {
        return None;
    };
    let mut source = mapc::compiler::mapfile::load_yaml(&map).unwrap();
    if let Some(resample) = resample {
        source.grid = resample(&source.grid);
    }
    let built = common::build(source, 150);
    let db = built.open();

    let truth: std::collections::HashMap<usize, [f64; 3]> = scanio::read_poses_in_map(&truth)
        .unwrap()
        .into_iter()
        .collect();
    let scans: Vec<_> = scanio::read_scans(
        scanio::open_input(log.to_str().unwrap()).unwrap(),
        InputFormat::Auto,
        &ReadOptions::default(),
    )
    .map(|s| s.expect("every line parses"))
    .collect();
    let log_scans = scans.len();
    let scans: Vec<_> = scans
        .into_iter()
        .enumerate()
        .filter(|(k, _)| k % every == 0)
        .collect();
    // (accepted and correct, accepted and wrong, error (m); the same two
    // against the locally corrected truth; given truth off by more than the
    // tolerance).
    // Correct and wrong accepts (given truth), error, correct and wrong
    // accepts (corrected truth), given truth off, candidates examined.
    type Outcome = (bool, bool, f64, bool, bool, bool, usize);
    let results: Vec<Outcome> = scans
        .par_iter()
        .map(|(k, s)| {
            let ScanData::Ranges {
                angle_min,
                angle_increment,
                range_min,
                range_max,
                ranges,
            } = &s.data
            else {
                panic!("CARMEN gives ranges")
            };
            assert_eq!(ranges.len(), beams);
            let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
            let scan = Scan::Ranges(RangeScan {
                angle_min: *angle_min,
                angle_increment: *angle_increment,
                range_min: *range_min,
                range_max: *range_max,
                ranges,
            });
            let g = truth[k];
            let beams = s.data.beams();
            let sensor = refloc::Pose2::new(g[0] as f32, g[1] as f32, g[2] as f32)
                .compose(&db.params().sensor.offset);
            let c = mapc::tools::eval::correct_truth_locally(&db, &beams, sensor);
            let truth_off = !mapc::tools::eval::within_tolerance(&c, g);
            let c = [c.x as f64, c.y as f64, c.theta as f64];
            match localize(&db, &scan, &mut scratch) {
                Ok(l) => {
                    // The confidence and the hypotheses are well formed.
                    assert!((0.0..=1.0).contains(&l.confidence), "{}", l.confidence);
                    assert_eq!(l.accepted, l.confidence >= db.decision().unwrap().threshold);
                    let hs = l.hypotheses();
                    assert!(!hs.is_empty() && hs[0].pose == l.pose);
                    for (i, a) in hs.iter().enumerate() {
                        for b in &hs[i + 1..] {
                            let far = (a.pose.x - b.pose.x).hypot(a.pose.y - b.pose.y) > 1.0
                                || refloc::wrap_angle(a.pose.theta - b.pose.theta).abs() > 0.349;
                            assert!(far, "hypotheses not distinct: {a:?} {b:?}");
                        }
                    }
                    if let Some(c) = l.covariance {
                        assert!(c[0] > 0.0 && c[4] > 0.0 && c[8] > 0.0 && c[1] == c[3]);
                    }
                    let ok = mapc::tools::eval::within_tolerance(&l.pose, g);
                    let (e, _) = mapc::tools::eval::pose_error(&l.pose, g);
                    let ok_c = mapc::tools::eval::within_tolerance(&l.pose, c);
                    (
                        l.accepted && ok,
                        l.accepted && !ok,
                        e,
                        l.accepted && ok_c,
                        l.accepted && !ok_c,
                        truth_off,
                        l.candidates.len(),
                    )
                }
                Err(_) => (false, false, f64::NAN, false, false, truth_off, 0),
            }
        })
        .collect();
    let n = results.len() as f64;
    let share = |f: fn(&Outcome) -> bool| results.iter().filter(|r| f(r)).count() as f64 / n;
    let mut errs: Vec<f64> = results.iter().filter(|r| r.0).map(|r| r.2).collect();
    errs.sort_by(|a, b| a.total_cmp(b));
    let mut examined: Vec<usize> = results.iter().map(|r| r.6).collect();
    examined.sort_unstable();
    let r = LogResult {
        log_scans,
        correct: share(|r| r.0),
        false_acc: share(|r| r.1),
        median: errs.get(errs.len() / 2).copied().unwrap_or(f64::NAN),
        correct_c: share(|r| r.3),
        false_c: share(|r| r.4),
        truth_off: share(|r| r.5),
        examined: examined.get(examined.len() / 2).copied().unwrap_or(0),
    };
    eprintln!(
        "{name} ({} scans): accepted and correct {:.1}%, false accepts {:.1}%, median error {:.3} m; \
         against the locally corrected truth {:.1}% and {:.1}%; given truth off by more \
         than the tolerance for {:.1}% of the scans; median candidates examined {}",
        results.len(),
        100.0 * r.correct,
        100.0 * r.false_acc,
        r.median,
        100.0 * r.correct_c,
        100.0 * r.false_c,
        100.0 * r.truth_off,
        r.examined
    );
    Some(r)
}

/// `grid` with each cell split into 2 x 2 cells of the same state (the
/// same origin, half the resolution).
fn finer(grid: &OccupancyGrid) -> OccupancyGrid {
    let (w, h) = (grid.width * 2, grid.height * 2);
    let cells = (0..h)
        .flat_map(|cy| (0..w).map(move |cx| (cx / 2, cy / 2)))
        .map(|(x, y)| grid.cells[(y * grid.width + x) as usize])
        .collect();
    OccupancyGrid::from_cells(w, h, grid.resolution / 2.0, grid.origin, cells)
}

/// `grid` with each 2 x 2 cells merged into one of twice the size
/// (occupied when any was, free when all were, else unknown; the same
/// origin; an odd last row or column is dropped).
fn coarser(grid: &OccupancyGrid) -> OccupancyGrid {
    let (w, h) = (grid.width / 2, grid.height / 2);
    let cells = (0..h)
        .flat_map(|cy| (0..w).map(move |cx| (cx, cy)))
        .map(|(cx, cy)| {
            let four = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .map(|(dx, dy)| grid.cells[((2 * cy + dy) * grid.width + 2 * cx + dx) as usize]);
            if four.contains(&Cell::Occupied) {
                Cell::Occupied
            } else if four.iter().all(|&c| c == Cell::Free) {
                Cell::Free
            } else {
                Cell::Unknown
            }
        })
        .collect();
    OccupancyGrid::from_cells(w, h, grid.resolution * 2.0, grid.origin, cells)
}

#[test]
fn csail_log_against_csail_map() {
    let Some(r) = real_log("csail", 361, 1) else {
        return;
    };
    assert_eq!(r.log_scans, 406);
    // Measured with the default decision model (not fitted on CSAIL):
    // 92.9% / 4.7% against the given poses, 97.5% / 0.0% against the
    // corrected ones (docs/results.md).
    assert!(r.correct >= 0.91, "accepted and correct {}", r.correct);
    // The false accepts against the given poses cannot fall below the share
    // of scans whose given pose is off (4.7%); guard just above it.
    assert!(r.false_acc <= 0.055, "false accepts {}", r.false_acc);
    assert!(r.median < 0.12, "median error {}", r.median);
    assert!(
        r.correct_c >= 0.96,
        "accepted and correct (corrected truth) {}",
        r.correct_c
    );
    assert!(
        r.false_c <= 0.01,
        "false accepts (corrected truth) {}",
        r.false_c
    );
}

/// Regression bounds on every 5th scan of the Intel and ACES logs (182 and
/// 88 scans; the whole logs take too long for CI). Measured when set
/// (2026-12-04, against the corrected truth): Intel 81.9% / 4.4%, ACES
/// 76.1% / 2.3%; with the confidence's spread feature (2026-12-06):
/// Intel 81.3% / 3.8%, ACES 77.3% / 2.3%, and Intel's false-accept bound
/// went from 6% to 5%. With the settled-answer stop (2026-12-06): Intel
/// 80.8% / 3.8%, ACES 75.0% / 2.3%, and a bound on the median number of
/// candidates examined (Intel 16, ACES 28). With the firm-answer stop
/// (2026-12-06, sixth session): Intel 81.3% / 3.8%, ACES 76.1% / 3.4%
/// (one scan more of 88), candidates Intel 16, ACES 19. The bounds leave a
/// few scans of slack, except ACES's false accepts: 3 of 88 against a bound
/// of 3.5%, so one more fails it (kept: the whole log stays at 1.8%). With the
/// slide along the corridor (fourteenth session) these scans give Intel
/// 84.1% / 3.3% and ACES 78.4% / 3.4%, and the accepted-and-correct bounds
/// were raised from 78% and 72% to 81% and 75% (fifteenth session): five
/// and three scans of slack, as the others. Both logs were
/// used to fit the decision model (docs/confidence.md), so these guard
/// against regressions; they are not held-out figures.
#[test]
fn intel_and_aces_logs_do_not_regress() {
    if let Some(r) = real_log("intel", 180, 5) {
        assert!(
            r.correct_c >= 0.81,
            "Intel accepted and correct {}",
            r.correct_c
        );
        assert!(r.false_c <= 0.05, "Intel false accepts {}", r.false_c);
        // The cost of the search, counted, not timed: 16 when set.
        assert!(r.examined <= 22, "Intel median candidates {}", r.examined);
    }
    if let Some(r) = real_log("aces", 180, 5) {
        assert!(
            r.correct_c >= 0.75,
            "ACES accepted and correct {}",
            r.correct_c
        );
        assert!(r.false_c <= 0.035, "ACES false accepts {}", r.false_c);
        // 28 when set (2026-12-06, with the settled-answer stop; on the whole
        // log the median went from 41 to 28 with it); 19 with the firm-answer
        // stop (sixth session; the whole log 28 -> 22).
        assert!(r.examined <= 24, "ACES median candidates {}", r.examined);
    }
}

/// The decision depends little on the map's cell size: every 3rd scan of
/// the CSAIL log against the CSAIL map with each cell split in four (0.025
/// m). With the spread feature measured in cells, as before, the same fits
/// looked twice as loose on the finer map and the whole log fell from
/// 98.0% to 60.8% accepted and correct (corrected truth); with its unit a
/// quarter power of the cell, 94.3% / 0.5% (docs/results.md, "Maps of
/// other resolutions"). Measured on these 136 scans when set: 91.9% /
/// 0.0% (60.3% / 0.0% in cells).
#[test]
fn a_finer_map_of_the_same_building_gives_the_same_decisions() {
    let Some(r) = real_log_resampled("csail", 361, 3, Some(finer)) else {
        return;
    };
    assert!(
        r.correct_c >= 0.89,
        "accepted and correct (corrected truth) on the 0.025 m map {}",
        r.correct_c
    );
    assert!(
        r.false_c <= 0.015,
        "false accepts (corrected truth) on the 0.025 m map {}",
        r.false_c
    );
}

/// A coarser map is not trusted more: every 5th scan of the Intel log
/// against the Intel map with each 2 x 2 cells merged (0.1 m, walls placed
/// to within 5 cm). With the spread in cells the whole log had 9.7% false
/// accepts there (3.1% at 0.05 m); with its unit a quarter power of the
/// cell 62.0% / 2.7% (docs/results.md). Measured on these 182 scans when
/// set: 59.3% / 4.9% (76.9% / 9.9% in cells).
#[test]
fn a_coarser_map_is_not_trusted_more() {
    let Some(r) = real_log_resampled("intel", 180, 5, Some(coarser)) else {
        return;
    };
    assert!(
        r.false_c <= 0.07,
        "false accepts (corrected truth) on the 0.1 m map {}",
        r.false_c
    );
    assert!(
        r.correct_c >= 0.5,
        "accepted and correct (corrected truth) on the 0.1 m map {}",
        r.correct_c
    );
}

#[test]
fn scans_of_another_map_are_not_accepted() {
    let (Some(intel), Some(aces)) = (
        mapc::testdata::shared("maps/intel/intel.yaml"),
        mapc::testdata::shared("maps/aces/aces.yaml"),
    ) else {
        return;
    };
    let built = common::build(mapc::compiler::mapfile::load_yaml(&intel).unwrap(), 150);
    let db = built.open();
    // 360-degree, 362-beam scans simulated at free poses of the ACES map.
    let foreign = mapc::compiler::mapfile::load_yaml(&aces).unwrap();
    let g = &foreign.grid;
    let bits = g.blocked_bits(true);
    let grid = refloc::raycast::BitGrid::new(g.width, g.height, &bits).unwrap();
    let frame = g.frame();
    let df = mapc::compiler::edt::DistanceField::from_grid(g, true);
    let poses = mapc::tools::eval::sample_poses_where(
        g.width,
        g.height,
        &frame,
        |i| df.clearance_m(i) >= 0.3,
        300,
        7,
    );
    let lidar = mapc::compiler::sim::Lidar::new(362, std::f32::consts::TAU, 30.0);
    let accepted: Vec<bool> = poses
        .par_iter()
        .map(|p| {
            let ranges = mapc::compiler::sim::virtual_scan(&grid, &frame, p, &lidar);
            let scan = Scan::Ranges(RangeScan {
                angle_min: lidar.angle_min,
                angle_increment: lidar.angle_increment,
                range_min: lidar.range_min,
                range_max: lidar.range_max,
                ranges: &ranges,
            });
            let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
            localize(&db, &scan, &mut scratch).is_ok_and(|l| l.accepted)
        })
        .collect();
    let n = accepted.iter().filter(|a| **a).count();
    eprintln!(
        "wrong map: {n} of {} ACES scans accepted on Intel",
        poses.len()
    );
    assert!(
        n * 100 <= poses.len(),
        "{n} of {} scans of another map accepted",
        poses.len()
    );
}

#[test]
fn symmetric_map_is_not_accepted_at_the_twin_place() {
    let Some(map) = mapc::testdata::shared("maps/tb3-world/tb3-world.yaml") else {
        return;
    };
    let built = common::build(mapc::compiler::mapfile::load_yaml(&map).unwrap(), 150);
    let db = built.open();
    let poses = mapc::tools::eval::sample_poses(&db, 200, 0.3, 1);
    let spec = mapc::tools::eval::ScanSpec {
        beams: 362,
        fov: std::f32::consts::TAU,
        range_max: 30.0,
        noise: 0.0,
        short_outliers: 0,
        swap_outliers: 0,
        disturbance: None,
        prior_radius: 0.0,
        prior_heading_tol: 0.0,
    };
    let trials = mapc::tools::eval::run_e4(&db, &poses, &spec, 1, None, &|| {});
    let s = mapc::tools::eval::summarize(&trials);
    eprintln!(
        "tb3-world: {} of {} accepted and correct, {} false accepts",
        s.correct, s.n, s.false_accepts
    );
    assert!(
        s.false_accepts * 100 <= s.n,
        "{} false accepts of {}",
        s.false_accepts,
        s.n
    );
    assert!(
        s.correct * 100 >= 95 * s.n,
        "{} correct of {}",
        s.correct,
        s.n
    );
}
