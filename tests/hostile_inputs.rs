//! Hostile scans and degenerate maps end to end (issue 6): what the unit
//! tests next to the code do not cover already (see `docs/robustness.md`
//! for the full list).
//!
//! * Scans against a database compiled by `mapc` (a small synthetic office,
//!   with the 180/270-degree windows and without): beam counts and fields of
//!   view other than the database's, huge and tiny finite values where the
//!   unit tests use NaN and infinities, combinations, and a 100,000-beam
//!   scan with a scratch sized for it. Each gives a pose with finite numbers
//!   or a typed `LocalizeError`, never a panic, and `localize` writes
//!   nothing outside the scratch it is given (checked with guard bytes
//!   around an exactly `scratch_size` scratch).
//! * Degenerate maps through `pipeline::build`: one colour, free space
//!   without a GVD vertex, 1-cell-wide corridors, unknown-only, a single free
//!   cell, free space running off the image, 16-bit PGM. Each gives a clear
//!   error or a database that reads back, verifies and localizes without a
//!   panic.
//!
//! `--nocapture` prints the tally of outcomes and the degenerate maps'
//! results; `HOSTILE_DEBUG=1` also prints every pose and whether it was
//! accepted.
//!
//! Registered as an integration test of the `mapc` package (see
//! crates/mapc/Cargo.toml).

mod common;

use std::f32::consts::PI;

use mapc::compiler::mapfile::{self, Cell, MapError, MapSource, OccupancyGrid};
use mapc::compiler::pipeline::{self, BuildConfig};
use mapc::compiler::rng::Rng;
use mapc::compiler::sim::{self, Lidar};
use refloc::{localize, scratch_size, LocalizeError, Pose2, RangeScan, RefDb, Scan};

/// Guard bytes on either side of the scratch.
const GUARD: usize = 64;
const CANARY: u8 = 0xA5;

/// What one scan gave.
#[derive(Debug)]
enum Outcome {
    /// A pose (finite), and whether it was accepted.
    Pose {
        accepted: bool,
    },
    Error(LocalizeError),
}

/// Localizes `scan` in a scratch of exactly `scratch_size` bytes between
/// guard bytes; panics (naming `what`) if a guard byte changed or a pose is
/// not finite.
fn run(db: &RefDb<&[u8]>, scan: &Scan<'_>, what: &str) -> Outcome {
    let needed = scratch_size(db.params(), scan.len());
    let mut buf = vec![CANARY; needed + 2 * GUARD];
    let out = match localize(db, scan, &mut buf[GUARD..GUARD + needed]) {
        Ok(l) => {
            let p = l.pose;
            assert!(
                p.x.is_finite() && p.y.is_finite() && p.theta.is_finite(),
                "{what}: pose {p:?}"
            );
            assert!(l.evidence.is_finite() || !l.accepted, "{what}: {l:?}");
            if std::env::var_os("HOSTILE_DEBUG").is_some() {
                eprintln!("{what}: accepted {} pose {p:?}", l.accepted);
            }
            Outcome::Pose {
                accepted: l.accepted,
            }
        }
        Err(e) => {
            assert!(!e.to_string().is_empty());
            Outcome::Error(e)
        }
    };
    assert!(
        buf[..GUARD]
            .iter()
            .chain(&buf[GUARD + needed..])
            .all(|&b| b == CANARY),
        "{what}: localize wrote outside its scratch"
    );
    out
}

impl Outcome {
    /// A short name for tallies.
    fn kind(&self) -> String {
        match self {
            Outcome::Pose { accepted: true } => "pose (accepted)".into(),
            Outcome::Pose { accepted: false } => "pose (not accepted)".into(),
            Outcome::Error(e) => {
                let s = format!("{e:?}");
                s.split([' ', '(', '{']).next().unwrap_or("").to_string()
            }
        }
    }
}

/// Counts outcomes by kind and prints them (`--nocapture`).
#[derive(Default)]
struct Tally(std::collections::BTreeMap<String, usize>);

impl Tally {
    fn add(&mut self, o: &Outcome) {
        *self.0.entry(o.kind()).or_default() += 1;
    }
    fn total(&self) -> usize {
        self.0.values().sum()
    }
}

impl Drop for Tally {
    fn drop(&mut self) {
        eprintln!("outcomes: {:?}", self.0);
    }
}

/// The beam geometry of `lidar`, with no ranges (filled in by the caller).
fn geometry(lidar: &Lidar) -> RangeScan<'static> {
    RangeScan {
        angle_min: lidar.angle_min,
        angle_increment: lidar.angle_increment,
        range_min: lidar.range_min,
        range_max: lidar.range_max,
        ranges: &[],
    }
}

/// A small synthetic office and two databases of it: with the default
/// 180/270-degree windows and with none.
fn office() -> (MapSource, Vec<u8>, Vec<u8>) {
    let dir = tempfile::tempdir().unwrap();
    let src = common::office_map(dir.path(), 160, 120, 3);
    let build = |windows: Vec<f32>| {
        let cfg = BuildConfig {
            fit_queries: 0,
            fov_windows_deg: windows,
            ..BuildConfig::default()
        };
        let out = pipeline::build(&src, &cfg).expect("build the office");
        common::encode(&out.sections)
    };
    let with = build(vec![180.0, 270.0]);
    let without = build(vec![]);
    (src, with, without)
}

/// A 4-byte aligned copy (the reader wants aligned arrays).
fn aligned(bytes: &[u8]) -> Vec<u32> {
    let mut w = vec![0u32; bytes.len().div_ceil(4)];
    zerocopy::IntoBytes::as_mut_bytes(&mut w[..])[..bytes.len()].copy_from_slice(bytes);
    w
}

fn open(words: &[u32], len: usize) -> RefDb<&[u8]> {
    let b: &[u8] = zerocopy::IntoBytes::as_bytes(words);
    let db = RefDb::new(&b[..len]).expect("a built database reads back");
    db.verify().expect("and verifies");
    db
}

/// The office database with the windows (aligned words and byte length, for
/// [`open`]) and a free pose in it with 0.5 m clearance.
fn office_and_pose() -> (Vec<u32>, usize, Pose2) {
    let (src, with, _) = office();
    let mut rng = Rng::new(5);
    let truth = common::free_pose(&src, 0.5, &mut rng);
    (aligned(&with), with.len(), truth)
}

/// A noise-free full-turn scan of `beams` beams (30 m) at `pose`: the
/// scanner, its ranges and the same returns as points.
fn full_turn(db: &RefDb<&[u8]>, pose: &Pose2, beams: usize) -> (Lidar, Vec<f32>, Vec<[f32; 2]>) {
    let lidar = Lidar::new(beams, 2.0 * PI, 30.0);
    let ranges = sim::virtual_scan(&db.grid(), &db.frame(), pose, &lidar);
    let points = sim::to_points(&ranges, &lidar);
    (lidar, ranges, points)
}

#[test]
fn scans_unlike_the_database_give_a_pose_or_a_typed_error() {
    let (src, with, without) = office();
    let (w1, w2) = (aligned(&with), aligned(&without));
    let dbs = [
        ("windows", open(&w1, with.len())),
        ("no windows", open(&w2, without.len())),
    ];
    let mut rng = Rng::new(11);
    let truth = common::free_pose(&src, 0.5, &mut rng);
    let mut tally = Tally::default();
    for (name, db) in &dbs {
        let grid = db.grid();
        let frame = db.frame();
        assert_eq!(db.params().sensor.beams, 362);
        // Beam counts other than the database's 362, over a full turn and
        // over partial fields of view (10 to 359 degrees), counter-clockwise
        // and clockwise.
        for beams in [16usize, 45, 90, 181, 361, 363, 720, 1081, 4096] {
            for fov_deg in [360.0f32, 359.0, 270.0, 180.0, 90.0, 45.0, 10.0] {
                let lidar = Lidar::new(beams, fov_deg.to_radians(), 30.0);
                let r = sim::virtual_scan(&grid, &frame, &truth, &lidar);
                let scan = RangeScan {
                    ranges: &r,
                    ..geometry(&lidar)
                };
                let what = format!("{name}: {beams} beams over {fov_deg} deg");
                tally.add(&run(db, &Scan::Ranges(scan), &what));
                let rev: Vec<f32> = r.iter().rev().copied().collect();
                let cw = RangeScan {
                    angle_min: scan.angle_min + (beams - 1) as f32 * scan.angle_increment,
                    angle_increment: -scan.angle_increment,
                    ranges: &rev,
                    ..scan
                };
                tally.add(&run(db, &Scan::Ranges(cw), &format!("{what}, clockwise")));
                // The same as points.
                let pts = sim::to_points(&r, &lidar);
                tally.add(&run(
                    db,
                    &Scan::Points {
                        points: &pts,
                        range_max: 30.0,
                    },
                    &format!("{what}, as points"),
                ));
            }
        }
    }
    assert_eq!(tally.total(), 2 * 9 * 7 * 3);
}

#[test]
fn extreme_finite_values_give_a_pose_or_a_typed_error() {
    let (w, len, truth) = office_and_pose();
    let db = open(&w, len);
    let grid = db.grid();
    let frame = db.frame();
    let lidar = Lidar::new(362, 2.0 * PI, 30.0);
    let good = sim::virtual_scan(&grid, &frame, &truth, &lidar);
    let base = RangeScan {
        ranges: &good,
        ..geometry(&lidar)
    };
    let n = good.len();
    let mut tally = Tally::default();

    // Range values: huge finite (with a range_max that admits them), tiny
    // and subnormal, -inf, and mixtures with a few good returns.
    let huge_max = RangeScan {
        range_max: f32::MAX,
        ..base
    };
    let mut cases: Vec<(String, Vec<f32>, RangeScan<'_>)> = Vec::new();
    for v in [1e30f32, f32::MAX, 1e19, 1e-30, 1e-45, f32::MIN_POSITIVE] {
        cases.push((format!("all {v:e}"), vec![v; n], huge_max));
        let mut mixed = good.clone();
        for (k, r) in mixed.iter_mut().enumerate() {
            if k % 3 == 0 {
                *r = v;
            }
        }
        cases.push((format!("a third {v:e}"), mixed, huge_max));
    }
    cases.push(("all -inf".into(), vec![f32::NEG_INFINITY; n], base));
    let mut soup = good.clone();
    let junk = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -1.0,
        0.0,
        -0.0,
        1e-45,
    ];
    // Runs of 10 junk beams between runs of 10 good ones (alternating
    // beams would leave no surface: isolated returns are dropped).
    for (k, r) in soup.iter_mut().enumerate() {
        if k % 20 < 10 {
            *r = junk[k % junk.len()];
        }
    }
    cases.push(("half junk".into(), soup, base));
    for (what, r, geom) in &cases {
        let scan = RangeScan { ranges: r, ..*geom };
        tally.add(&run(&db, &Scan::Ranges(scan), what));
    }
    // The mixture still localizes (about half the returns are good).
    let (_, soup, geom) = cases.last().unwrap();
    let scan = RangeScan {
        ranges: soup,
        ..*geom
    };
    let out = run(&db, &Scan::Ranges(scan), "half junk");
    assert!(matches!(out, Outcome::Pose { .. }), "half junk: {out:?}");

    // Beam geometry: angle_min far from (-pi, pi], increments too small to
    // separate beams (subnormal, 1e-30, one ulp of pi), range_min above
    // range_max, a range_min of 0 with zero ranges.
    let geometries = [
        (
            "angle_min 1e30",
            RangeScan {
                angle_min: 1e30,
                ..base
            },
        ),
        (
            "angle_min -1e30",
            RangeScan {
                angle_min: -1e30,
                ..base
            },
        ),
        (
            "angle_min 1000",
            RangeScan {
                angle_min: 1000.0,
                ..base
            },
        ),
        (
            "increment 1e-45",
            RangeScan {
                angle_increment: 1e-45,
                ..base
            },
        ),
        (
            "increment -1e-30",
            RangeScan {
                angle_increment: -1e-30,
                ..base
            },
        ),
        (
            "increment eps",
            RangeScan {
                angle_increment: f32::EPSILON,
                ..base
            },
        ),
        (
            "increment just over a turn",
            RangeScan {
                angle_increment: 2.0 * PI * 1.01 / (n - 2) as f32,
                ..base
            },
        ),
        (
            "range_min above range_max",
            RangeScan {
                range_min: 40.0,
                ..base
            },
        ),
        (
            "range_min = range_max",
            RangeScan {
                range_min: 30.0,
                ..base
            },
        ),
    ];
    for (what, scan) in geometries {
        let out = run(&db, &Scan::Ranges(scan), what);
        tally.add(&out);
        if what.starts_with("range_min") {
            // Every range is outside [range_min, range_max].
            assert!(
                matches!(
                    out,
                    Outcome::Error(LocalizeError::BadScan(_))
                        | Outcome::Error(LocalizeError::NotEnoughPoints { valid: 0, .. })
                ),
                "{what}: {out:?}"
            );
        }
        if what == "increment just over a turn" {
            assert!(
                matches!(out, Outcome::Error(LocalizeError::BadScan(_))),
                "{what}: {out:?}"
            );
        }
    }

    // Points: huge coordinates (their squares overflow f32), all at one
    // spot, the origin, mixtures with good points; range_max f32::MAX.
    let good_pts = sim::to_points(&good, &lidar);
    let mut point_cases: Vec<(String, Vec<[f32; 2]>)> = Vec::new();
    for v in [1e19f32, 1e30, f32::MAX, -f32::MAX] {
        point_cases.push((format!("all at ({v:e}, {v:e})"), vec![[v, v]; n]));
        let mut mixed = good_pts.clone();
        for (k, p) in mixed.iter_mut().enumerate() {
            if k % 4 == 0 {
                *p = [v, -v];
            }
        }
        point_cases.push((format!("a quarter at {v:e}"), mixed));
    }
    point_cases.push(("all at one spot".into(), vec![[1.0, 2.0]; n]));
    point_cases.push(("all at the origin".into(), vec![[0.0, 0.0]; n]));
    point_cases.push(("one point".into(), vec![[1.0, 2.0]]));
    point_cases.push((
        "on one line".into(),
        (0..n).map(|k| [0.01 * k as f32, 1.0]).collect(),
    ));
    for (what, pts) in &point_cases {
        for range_max in [30.0, f32::MAX] {
            let scan = Scan::Points {
                points: pts,
                range_max,
            };
            tally.add(&run(
                &db,
                &scan,
                &format!("{what}, range_max {range_max:e}"),
            ));
        }
    }
}

// ---------------------------------------------------------------------------
// Degenerate maps.

/// The map a test image describes, as `mapc build` would load it.
fn grid_map(rows: &[String]) -> MapSource {
    let refs: Vec<&str> = rows.iter().map(String::as_str).collect();
    MapSource::in_memory(OccupancyGrid::from_ascii(&refs, 0.05, [0.0; 3]), "test.pgm")
}

/// `w x h` rows, `cell(x, y)` with y = 0 the top row.
fn draw(w: usize, h: usize, cell: impl Fn(usize, usize) -> char) -> Vec<String> {
    (0..h)
        .map(|y| (0..w).map(|x| cell(x, y)).collect())
        .collect()
}

/// Builds `src`; on success the database must read back, verify, and take a
/// scan from a free cell (a pose or a typed error). Returns the site count,
/// or the error.
fn build_degenerate(what: &str, src: &MapSource) -> Result<usize, String> {
    let cfg = BuildConfig {
        fit_queries: 0,
        ..BuildConfig::default()
    };
    let out = match std::panic::catch_unwind(|| pipeline::build(src, &cfg)) {
        Ok(r) => r,
        Err(_) => panic!("{what}: pipeline::build panicked"),
    };
    let out = match out {
        Ok(o) => o,
        Err(e) => {
            let e = e.to_string();
            assert!(!e.trim().is_empty(), "{what}: empty error");
            return Err(e);
        }
    };
    let bytes = common::encode(&out.sections);
    let w = aligned(&bytes);
    let db = open(&w, bytes.len());
    assert!(db.site_count() >= 1, "{what}");
    // A scan from the first free cell.
    let g = &src.grid;
    let free = g.cells.iter().position(|&c| c == Cell::Free).unwrap();
    let c = g.cell_center(free as u32 % g.width, free as u32 / g.width);
    let lidar = Lidar::new(362, 2.0 * PI, 30.0);
    let r = sim::virtual_scan(
        &db.grid(),
        &db.frame(),
        &Pose2::new(c[0] as f32, c[1] as f32, 0.3),
        &lidar,
    );
    let scan = RangeScan {
        ranges: &r,
        ..geometry(&lidar)
    };
    run(&db, &Scan::Ranges(scan), what);
    Ok(db.site_count())
}

#[test]
fn degenerate_maps_build_or_fail_clearly() {
    let mut report = Vec::new();
    let maps: Vec<(&str, Vec<String>)> = vec![
        // One colour: all free (walled only by the image border).
        ("all free 60 x 40", draw(60, 40, |_, _| '.')),
        ("all free 3 x 3", draw(3, 3, |_, _| '.')),
        ("one free cell", draw(1, 1, |_, _| '.')),
        (
            "one free cell in a wall",
            draw(9, 9, |x, y| if (x, y) == (4, 4) { '.' } else { '#' }),
        ),
        // Free space but no GVD vertex: a round room, a straight corridor
        // closed at both ends, a ring corridor.
        (
            "round room",
            draw(61, 61, |x, y| {
                let (dx, dy) = (x as f64 - 30.0, y as f64 - 30.0);
                if dx * dx + dy * dy < 27.0 * 27.0 {
                    '.'
                } else {
                    '#'
                }
            }),
        ),
        (
            "straight corridor",
            draw(120, 14, |x, y| {
                if !(2..118).contains(&x) || !(2..12).contains(&y) {
                    '#'
                } else {
                    '.'
                }
            }),
        ),
        (
            "ring corridor",
            draw(80, 80, |x, y| {
                let (dx, dy) = (x as f64 - 40.0, y as f64 - 40.0);
                let r = (dx * dx + dy * dy).sqrt();
                if (25.0..35.0).contains(&r) {
                    '.'
                } else {
                    '#'
                }
            }),
        ),
        // 1-cell-wide corridors: alone, and joining two rooms.
        (
            "1-cell corridor",
            draw(80, 9, |x, y| {
                if y == 4 && (1..79).contains(&x) {
                    '.'
                } else {
                    '#'
                }
            }),
        ),
        (
            "two rooms joined by a 1-cell corridor",
            draw(100, 40, |x, y| {
                let room = (2..38).contains(&y) && ((2..40).contains(&x) || (60..98).contains(&x));
                let corridor = y == 20 && (40..60).contains(&x);
                if room || corridor {
                    '.'
                } else {
                    '#'
                }
            }),
        ),
        (
            "diagonal 1-cell corridor",
            draw(60, 60, |x, y| {
                if x == y && (1..59).contains(&x) {
                    '.'
                } else {
                    '#'
                }
            }),
        ),
        // Free space with unknown around it (no walls at all).
        (
            "free island in unknown",
            draw(60, 60, |x, y| {
                if (20..40).contains(&x) && (20..40).contains(&y) {
                    '.'
                } else {
                    '?'
                }
            }),
        ),
        // Free space running off the image on every side, a pillar inside.
        (
            "open field with a pillar",
            draw(80, 60, |x, y| {
                if (38..42).contains(&x) && (28..32).contains(&y) {
                    '#'
                } else {
                    '.'
                }
            }),
        ),
    ];
    for (what, rows) in &maps {
        let r = build_degenerate(what, &grid_map(rows));
        report.push(format!("{what}: {r:?}"));
    }
    eprintln!("{}", report.join("\n"));
}

/// Images of one colour through the loader: black and unknown grey have no
/// free cell (a typed error naming the file), white loads.
#[test]
fn one_colour_images_load_or_fail_clearly() {
    let dir = tempfile::tempdir().unwrap();
    for (v, free) in [
        (0u8, false),
        (205, false),
        (128, false),
        (254, true),
        (255, true),
    ] {
        let p = dir.path().join(format!("c{v}.pgm"));
        let mut b = b"P5\n40 30\n255\n".to_vec();
        b.extend(std::iter::repeat_n(v, 40 * 30));
        std::fs::write(&p, b).unwrap();
        match mapfile::load_image(&p, Some(0.05), None) {
            Ok(m) => {
                assert!(free, "{v}: loaded");
                assert_eq!(m.grid.free_count(), 40 * 30);
            }
            Err(e) => {
                assert!(!free, "{v}: {e}");
                assert!(matches!(e, MapError::NoFreeCell { .. }), "{v}: {e}");
                assert!(e.to_string().contains(&format!("c{v}.pgm")), "{e}");
            }
        }
    }
}

/// Points that `localize` drops as "no return" (their norm overflows f32,
/// or exceeds `range_max`) still take part in the Points branch of
/// `load_scan` (crates/refloc/src/localize.rs) when it estimates the scan's
/// turn direction and angular coverage: every finite point votes there, not
/// only the valid ones. A point whose coordinates overflow the signed angle
/// (here `[f32::MAX, -f32::MAX]`) breaks the chain of small steps on both
/// sides, so a full-turn scan with every fourth point like that measures a
/// coverage of about 3.1 rad instead of 6.25: it is taken for a 180-degree
/// scan (window histogram, no wrap), and in this office it then gives a
/// pose 1.5 m and 180 degrees off, accepted. The same points as NaN (also
/// "no return", the same 271 valid points) give the right pose; finite
/// points beyond `range_max` inflate the coverage instead (a partial scan
/// can pass for a full turn).
#[test]
fn invalid_points_do_not_change_the_answer() {
    let (w, len, truth) = office_and_pose();
    let db = open(&w, len);
    let (_, _, good_pts) = full_turn(&db, &truth, 362);
    let answer = |bad: [f32; 2]| {
        let mut pts = good_pts.clone();
        for p in pts.iter_mut().step_by(4) {
            *p = bad;
        }
        let scan = Scan::Points {
            points: &pts,
            range_max: 30.0,
        };
        let mut scratch = vec![0u8; scratch_size(db.params(), scan.len())];
        let l = localize(&db, &scan, &mut scratch).expect("localizes");
        (l.valid_points, l.pose, l.accepted)
    };
    let reference = answer([f32::NAN, f32::NAN]);
    let (_, pose, _) = reference;
    let (err, _) = common::error(&pose, &truth);
    assert!(err < 0.1, "with NaN: {pose:?} vs truth {truth:?}");
    for bad in [[f32::MAX, -f32::MAX], [1e30, -1e30], [100.0, -100.0]] {
        assert_eq!(answer(bad), reference, "invalid points at {bad:?}");
    }
}

/// A 100,000-beam full-turn scan with a scratch sized for it (the unit test
/// `localize_rejects_a_scan_larger_than_the_scratch` gives it one sized for
/// 362 beams: `TooManyBeams`). The scan is thinned to `max_points` before
/// any pairwise work, so the scratch stays small and the answer is the one
/// a 362-beam scan gives: right, as ranges and as points.
#[test]
fn a_100000_beam_scan_localizes_in_a_scratch_sized_for_it() {
    let (w, len, truth) = office_and_pose();
    let db = open(&w, len);
    let (lidar, r, pts) = full_turn(&db, &truth, 100_000);
    let needed = scratch_size(db.params(), r.len());
    assert!(
        needed < 16 << 20,
        "scratch for 100,000 beams: {needed} bytes"
    );
    let scans = [
        (
            "100,000 beams",
            Scan::Ranges(RangeScan {
                ranges: &r,
                ..geometry(&lidar)
            }),
        ),
        (
            "100,000 points",
            Scan::Points {
                points: &pts,
                range_max: 30.0,
            },
        ),
    ];
    for (what, scan) in &scans {
        let t = std::time::Instant::now();
        let out = run(&db, scan, what);
        assert!(
            matches!(out, Outcome::Pose { accepted: true }),
            "{what}: {out:?}"
        );
        let mut scratch = vec![0u8; needed];
        let pose = localize(&db, scan, &mut scratch).unwrap().pose;
        let (err, _) = common::error(&pose, &truth);
        assert!(err < 0.1, "{what}: {pose:?} vs truth {truth:?}");
        eprintln!("{what}: scratch {needed} bytes, {:?}", t.elapsed());
    }
}

/// 16-bit PGM maps (maxval 65535, and 1000: any maxval over 255 is two bytes
/// a sample) load to the same cells as the 8-bit image and build the same
/// reference sites; a 16-bit header claiming 40000 x 40000 in a 23-byte file is
/// refused ("truncated") before any pixel buffer is allocated.
#[test]
fn sixteen_bit_pgm_maps_load_and_build_like_8_bit_ones() {
    let dir = tempfile::tempdir().unwrap();
    // A room with a pillar, unknown outside.
    let (w, h) = (70usize, 50usize);
    let px: Vec<u8> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            if !(5..65).contains(&x) || !(5..45).contains(&y) {
                205
            } else if !(7..63).contains(&x)
                || !(7..43).contains(&y)
                || (30..36).contains(&x) && (20..26).contains(&y)
            {
                0
            } else {
                254
            }
        })
        .collect();
    let load = |name: &str, bytes: Vec<u8>| {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        mapfile::load_image(&p, Some(0.05), None)
    };
    let mut pgm8 = format!("P5\n{w} {h}\n255\n").into_bytes();
    pgm8.extend_from_slice(&px);
    let m8 = load("m8.pgm", pgm8).unwrap();
    let sites = build_degenerate("8-bit PGM", &m8).unwrap();
    for maxval in [65535u32, 1000] {
        let mut pgm16 = format!("P5\n{w} {h}\n{maxval}\n").into_bytes();
        for &v in &px {
            let s = ((v as u32 * maxval + 127) / 255) as u16;
            pgm16.extend_from_slice(&s.to_be_bytes());
        }
        let what = format!("16-bit PGM, maxval {maxval}");
        let m16 = load(&format!("m{maxval}.pgm"), pgm16).unwrap();
        assert!(m16.grid.cells == m8.grid.cells, "{what}: cells differ");
        assert_eq!(build_degenerate(&what, &m16), Ok(sites), "{what}");
    }
    // 40000^2 16-bit: over the default --max-cells, refused from the
    // header; under the largest limit, refused as truncated.
    let e = load("huge.pgm", b"P5\n40000 40000\n65535\n\x00\x00".to_vec()).unwrap_err();
    assert!(matches!(e, MapError::ImageTooLarge { .. }), "{e}");
    let widest = mapfile::MapLimits {
        max_cells: mapfile::MAX_CELLS,
    };
    let e = mapfile::load_image_within(&dir.path().join("huge.pgm"), Some(0.05), None, &widest)
        .unwrap_err();
    assert!(matches!(e, MapError::ImageDecode { .. }), "{e}");
    assert!(e.to_string().contains("truncated"), "{e}");
}
