use super::brute_force_sq as brute;
use super::*;
use crate::compiler::rng::Rng;

fn check(w: usize, h: usize, obst: &[bool]) {
    let want = brute(w, h, obst);
    let plain = squared_edt(w, h, |i| obst[i]);
    assert_eq!(plain, want, "{w}x{h}");
    let (sq, near) = nearest_obstacle(w, h, |i| obst[i]);
    assert_eq!(sq, want, "{w}x{h}");
    for i in 0..w * h {
        if near[i] == NONE {
            assert!(!obst.iter().any(|&o| o), "NONE with obstacles present");
            assert_eq!(sq[i], no_obstacle_sq(w, h));
            continue;
        }
        let j = near[i] as usize;
        assert!(obst[j], "{w}x{h}: nearest of {i} is {j}, not an obstacle");
        let (dx, dy) = (
            (i % w) as i64 - (j % w) as i64,
            (i / w) as i64 - (j / w) as i64,
        );
        assert_eq!((dx * dx + dy * dy) as f32, sq[i], "{w}x{h}: cell {i}");
    }
}

#[test]
fn matches_brute_force_on_random_grids() {
    let mut rng = Rng::new(7);
    let sizes = [
        (1, 1),
        (1, 17),
        (23, 1),
        (2, 2),
        (5, 9),
        (31, 33),
        (33, 31),
        (64, 3),
        (70, 41),
        (97, 66),
    ];
    for &(w, h) in &sizes {
        for density in [0.0, 0.002, 0.02, 0.1, 0.5, 0.95, 1.0] {
            let obst: Vec<bool> = (0..w * h).map(|_| rng.uniform() < density).collect();
            check(w, h, &obst);
        }
        // A single obstacle in a corner, and one in the middle.
        let mut obst = vec![false; w * h];
        obst[0] = true;
        check(w, h, &obst);
        let mut obst = vec![false; w * h];
        obst[(h / 2) * w + w / 2] = true;
        check(w, h, &obst);
    }
}

#[test]
fn no_obstacle_and_all_obstacles() {
    let sq = squared_edt(10, 4, |_| false);
    assert!(sq.iter().all(|&v| v == 116.0 && v.is_finite()));
    let (sq, near) = nearest_obstacle(10, 4, |_| true);
    assert!(sq.iter().all(|&v| v == 0.0));
    assert!(near.iter().enumerate().all(|(i, &j)| i == j as usize));
    assert!(squared_edt(0, 5, |_| true).is_empty());
}

#[test]
fn deterministic_across_thread_counts() {
    let mut rng = Rng::new(11);
    let (w, h) = (301, 257);
    let obst: Vec<bool> = (0..w * h).map(|_| rng.uniform() < 0.01).collect();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| nearest_obstacle(w, h, |i| obst[i]))
    };
    let a = run(1);
    let b = run(2);
    let c = run(5);
    assert!(a == b && b == c);
}

#[test]
fn distance_field_walls_the_border() {
    let g = OccupancyGrid::from_ascii(
        &[
            "?????????", //
            "?.......?",
            "?.......?",
            "?...#...?",
            "?.......?",
            "?.......?",
            ".........",
        ],
        0.1,
        [0.0; 3],
    );
    let d = DistanceField::from_grid(&g, true);
    let at = |x: usize, y: usize| y * 9 + x;
    // The bottom row is free but is the image border: an obstacle.
    assert!(d.is_obstacle(at(4, 0)));
    assert_eq!(d.sq[at(4, 1)], 1.0);
    assert_eq!(d.sq[at(4, 2)], 1.0); // next to the pillar at (4, 3)
    assert_eq!(d.sq[at(2, 3)], 4.0);
    assert!((d.clearance_m(at(2, 3)) - 0.2).abs() < 1e-12);
    let d2 = DistanceField::from_grid(&g, false);
    // Unknown cells are free now, but the ring is still an obstacle.
    assert_eq!(d2.sq[at(1, 5)], 1.0);
}

/// The runtime's verification casts jump across open space by
/// `refloc::refine::DistMap::clearance` (refloc::raycast::cast_dir_clear):
/// on the distance section the compiler writes, that must never exceed the
/// true gap between a cell and the nearest beam-stopping cell.
#[test]
fn the_distance_section_bounds_the_runtime_clearance() {
    use refloc::raycast::{BitGrid, Occupancy};
    let mut rng = Rng::new(21);
    let mut jumpable = 0;
    for round in 0..12 {
        let (w, h) = (10 + rng.below(50) as u32, 10 + rng.below(50) as u32);
        let density = [0.002, 0.01, 0.05][round % 3];
        let cells = (0..w * h)
            .map(|_| {
                let x = rng.uniform();
                if x < density {
                    Cell::Occupied
                } else if x < 2.0 * density {
                    Cell::Unknown
                } else {
                    Cell::Free
                }
            })
            .collect();
        let grid = OccupancyGrid::from_cells(w, h, 0.05, [0.0; 3], cells);
        for unknown_blocks in [false, true] {
            // As the pipeline and compile::compile_with do.
            let df = DistanceField::from_grid(&grid, unknown_blocks);
            let words = grid.blocked_bits(unknown_blocks);
            let bits = BitGrid::new(w, h, &words).unwrap();
            let (wu, hu) = (w as usize, h as usize);
            let sq_in = squared_edt(wu, hu, |i| !bits.blocked((i % wu) as u32, (i / wu) as u32));
            let bytes = crate::compiler::compile::dist_section(&df.sq, &sq_in);
            let frame = refloc::MapFrame {
                resolution: 0.05,
                origin: refloc::Pose2::new(0.0, 0.0, 0.0),
            };
            let dm = refloc::refine::DistMap::new(w, h, &bytes, frame);
            let blocked: Vec<(i64, i64)> = (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .filter(|&(x, y)| bits.blocked(x, y))
                .map(|(x, y)| (x as i64, y as i64))
                .collect();
            for cy in 0..h {
                for cx in 0..w {
                    let c = dm.clearance(cx, cy);
                    if c <= 0.0 {
                        continue;
                    }
                    jumpable += 1;
                    let gap = blocked
                        .iter()
                        .map(|&(x, y)| {
                            let gx = ((x - cx as i64).abs() - 1).max(0) as f32;
                            let gy = ((y - cy as i64).abs() - 1).max(0) as f32;
                            (gx * gx + gy * gy).sqrt()
                        })
                        .fold(f32::INFINITY, f32::min);
                    assert!(
                        c <= gap,
                        "{w}x{h} unknown_blocks {unknown_blocks}: cell ({cx}, {cy}) \
                         clearance {c} > gap {gap}"
                    );
                }
            }
        }
    }
    assert!(jumpable > 1000, "{jumpable} cells with a clearance");
}
