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
