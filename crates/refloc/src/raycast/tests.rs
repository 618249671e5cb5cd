//! `cast` and `traverse` against a slow, independent reference: march along
//! the ray in steps of 1e-3 cell (in f64), and measure each blocked cell found
//! with an exact ray/box intersection.

use super::*;
use std::vec;
use std::vec::Vec;

use core::f32::consts::{FRAC_1_SQRT_2, FRAC_PI_2, FRAC_PI_4, PI};

use crate::tests::fixture::Prng;

/// A plain boolean grid (the reference's own occupancy).
struct VecGrid {
    w: u32,
    h: u32,
    cells: Vec<bool>,
}

impl VecGrid {
    fn new(w: u32, h: u32) -> Self {
        VecGrid {
            w,
            h,
            cells: vec![false; (w * h) as usize],
        }
    }

    fn random(rng: &mut Prng, w: u32, h: u32, density: f32) -> Self {
        let mut g = VecGrid::new(w, h);
        for c in g.cells.iter_mut() {
            *c = rng.range(0.0, 1.0) < density;
        }
        g
    }

    fn set(&mut self, cx: u32, cy: u32) {
        self.cells[(cy * self.w + cx) as usize] = true;
    }

    fn get(&self, cx: i64, cy: i64) -> Option<bool> {
        if cx < 0 || cy < 0 || cx >= self.w as i64 || cy >= self.h as i64 {
            None
        } else {
            Some(self.cells[(cy * self.w as i64 + cx) as usize])
        }
    }

    /// The same cells packed as `BitGrid` words.
    fn words(&self) -> Vec<u32> {
        let mut words = vec![0u32; BitGrid::words_for(self.w, self.h)];
        for (i, &b) in self.cells.iter().enumerate() {
            if b {
                words[i / 32] |= 1 << (i % 32);
            }
        }
        words
    }
}

impl Occupancy for VecGrid {
    fn width(&self) -> u32 {
        self.w
    }
    fn height(&self) -> u32 {
        self.h
    }
    fn blocked(&self, cx: u32, cy: u32) -> bool {
        self.cells[(cy * self.w + cx) as usize]
    }
}

/// Marching step (cells).
const STEP: f64 = 1e-3;
/// A cell the ray crosses for less than this (cells) is only grazed: an exact
/// f32 traversal may or may not count it.
const GRAZE: f64 = 1e-3;
/// Tolerance on distances (cells).
const TOL: f32 = 2e-3;

/// The interval of ray parameters `t` for which the ray lies in the closed
/// box of cell `(cx, cy)`; an axis the ray runs parallel to uses the grid's
/// half-open convention `[c, c + 1)`.
fn box_interval(p: [f64; 2], d: [f64; 2], cell: [i64; 2]) -> (f64, f64) {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..2 {
        let (lo, hi) = (cell[a] as f64, cell[a] as f64 + 1.0);
        if d[a] == 0.0 {
            if !(p[a] >= lo && p[a] < hi) {
                return (f64::INFINITY, f64::NEG_INFINITY);
            }
        } else {
            let (a0, a1) = ((lo - p[a]) / d[a], (hi - p[a]) / d[a]);
            t0 = t0.max(a0.min(a1));
            t1 = t1.min(a0.max(a1));
        }
    }
    (t0, t1)
}

/// What the slow reference accepts as the answer of `cast`: the answer for
/// the exact ray (last entry), preceded by the answers an f32 traversal may
/// give instead where the ray only grazes a cell (a blocked cell it touches
/// for less than [`GRAZE`]: its entry distance; a grazed cell outside the
/// grid: `None`).
fn reference(g: &VecGrid, u: f32, v: f32, dx: f32, dy: f32, max_cells: f32) -> Vec<Option<f64>> {
    let p = [u as f64, v as f64];
    let d = [dx as f64, dy as f64];
    let max = max_cells as f64;
    let mut answers = Vec::new();
    if !(p[0] >= 0.0 && p[1] >= 0.0 && p[0] < g.w as f64 && p[1] < g.h as f64) {
        answers.push(None);
        return answers;
    }
    let mut cell = [p[0].floor() as i64, p[1].floor() as i64];
    if g.get(cell[0], cell[1]) == Some(true) {
        answers.push(Some(0.0));
        return answers;
    }
    let mut t = 0.0;
    loop {
        t += STEP;
        let q = [p[0] + t * d[0], p[1] + t * d[1]];
        let next = [q[0].floor() as i64, q[1].floor() as i64];
        if next == cell {
            if t > max + 2.0 {
                answers.push(None);
                return answers;
            }
            continue;
        }
        // Cells entered during this step, in order: when both indices
        // changed, the step cut past a corner and the ray may have crossed
        // one of the two side cells.
        let mut entered: Vec<[i64; 2]> = Vec::new();
        if next[0] != cell[0] && next[1] != cell[1] {
            let mut sides = [[next[0], cell[1]], [cell[0], next[1]]];
            sides.sort_by(|a, b| {
                let ta = box_interval(p, d, *a).0;
                let tb = box_interval(p, d, *b).0;
                ta.total_cmp(&tb)
            });
            entered.extend(sides);
        }
        entered.push(next);
        for c in entered {
            let (t0, t1) = box_interval(p, d, c);
            let chord = t1 - t0.max(0.0);
            let entry = t0.max(0.0);
            if chord <= -GRAZE {
                continue; // not touched at all
            }
            let grazed = chord < GRAZE;
            let answer = match g.get(c[0], c[1]) {
                None => None,                              // leaves the grid
                Some(true) if entry <= max => Some(entry), // a hit
                Some(true) => None,                        // a hit beyond max_cells
                Some(false) if entry > max => None,        // out of range
                Some(false) => continue,
            };
            answers.push(answer);
            if !grazed {
                return answers;
            }
        }
        cell = next;
    }
}

fn accepted(got: Option<f32>, answers: &[Option<f64>], tol: f32) -> bool {
    answers.iter().any(|a| match (got, a) {
        (None, None) => true,
        (Some(x), Some(y)) => (x as f64 - y).abs() <= tol as f64,
        _ => false,
    })
}

/// Compares `cast_dir` on the packed grid with the reference for one ray.
fn check_ray(g: &VecGrid, bits: &BitGrid<'_>, (u, v): (f32, f32), (dx, dy): (f32, f32), max: f32) {
    let want = reference(g, u, v, dx, dy, max);
    let got = cast_dir(bits, u, v, dx, dy, max);
    assert!(
        accepted(got, &want, TOL),
        "ray from ({u}, {v}) along ({dx}, {dy}) max {max} in a {}x{} grid: cast {got:?}, reference {want:?}",
        g.w,
        g.h
    );
    // The generic path over any `Occupancy` agrees bit for bit.
    assert_eq!(got, cast_dir(g, u, v, dx, dy, max));
}

/// A start coordinate in `[0, n)`: anywhere, or on a cell boundary / centre.
fn start_coord(rng: &mut Prng, n: u32) -> f32 {
    match rng.below(4) {
        0 => rng.below(n as usize) as f32,
        1 => rng.below(n as usize) as f32 + 0.5,
        _ => rng.range(0.0, n as f32),
    }
}

#[test]
fn cast_matches_the_marching_reference_on_random_grids() {
    let mut rng = Prng::new(11);
    let special = [
        0.0,
        FRAC_PI_2,
        PI,
        -FRAC_PI_2,
        FRAC_PI_4,
        3.0 * FRAC_PI_4,
        -FRAC_PI_4,
        -3.0 * FRAC_PI_4,
    ];
    let mut rays = 0;
    let mut hits = 0;
    for _ in 0..60 {
        let (w, h) = (1 + rng.below(40) as u32, 1 + rng.below(40) as u32);
        let density = rng.range(0.0, 0.3);
        let g = VecGrid::random(&mut rng, w, h, density);
        let words = g.words();
        let bits = BitGrid::new(w, h, &words).unwrap();
        for _ in 0..60 {
            let (u, v) = (start_coord(&mut rng, w), start_coord(&mut rng, h));
            let angle = if rng.below(3) == 0 {
                special[rng.below(special.len())]
            } else {
                rng.range(-PI, PI)
            };
            // `cast` takes the angle; the reference gets the same direction.
            let (dx, dy) = (libm::cosf(angle), libm::sinf(angle));
            let want = reference(&g, u, v, dx, dy, 1e4);
            let got = cast(&bits, u, v, angle, 1e4);
            assert!(
                accepted(got, &want, TOL),
                "angle {angle} from ({u}, {v}) in a {w}x{h} grid: cast {got:?}, reference {want:?}"
            );
            rays += 1;
            hits += got.is_some() as usize;
            // Exact axis and diagonal directions.
            let s = FRAC_1_SQRT_2;
            let dirs = [
                (1.0, 0.0),
                (0.0, 1.0),
                (-1.0, 0.0),
                (0.0, -1.0),
                (s, s),
                (-s, s),
                (s, -s),
                (-s, -s),
            ];
            let (dx, dy) = dirs[rng.below(dirs.len())];
            check_ray(&g, &bits, (u, v), (dx, dy), 1e4);
            // A range limit.
            let max = rng.range(0.0, 30.0);
            let dir = (libm::cosf(angle), libm::sinf(angle));
            check_ray(&g, &bits, (u, v), dir, max);
        }
    }
    // The random grids give both outcomes plenty of times.
    assert!(
        hits > rays / 4 && hits < rays * 9 / 10,
        "{hits} hits of {rays}"
    );
}

#[test]
fn cast_stays_exact_on_long_rays() {
    let mut rng = Prng::new(12);
    let (w, h) = (700, 700);
    let mut g = VecGrid::new(w, h);
    // A sparse scatter of obstacles and a closed border.
    for _ in 0..300 {
        g.set(rng.below(w as usize) as u32, rng.below(h as usize) as u32);
    }
    for k in 0..w {
        g.set(k, 0);
        g.set(k, h - 1);
    }
    for k in 0..h {
        g.set(0, k);
        g.set(w - 1, k);
    }
    let words = g.words();
    let bits = BitGrid::new(w, h, &words).unwrap();
    let mut worst = 0.0f64;
    for _ in 0..12 {
        let (u, v) = (rng.range(1.0, 699.0), rng.range(1.0, 699.0));
        let a = rng.range(-PI, PI);
        let (dx, dy) = (libm::cosf(a), libm::sinf(a));
        let want = reference(&g, u, v, dx, dy, 1e4);
        let got = cast_dir(&bits, u, v, dx, dy, 1e4);
        let last = want
            .last()
            .copied()
            .flatten()
            .expect("the border stops every ray");
        let t = got.expect("the border stops every ray");
        worst = worst.max((t as f64 - last).abs() / last.max(1.0));
        // f32 accumulation over hundreds of cells: relative tolerance.
        assert!(accepted(got, &want, TOL + 1e-5 * t), "{got:?} vs {want:?}");
    }
    assert!(worst < 1e-5, "relative error {worst}");
}

#[test]
fn cast_simple_cases() {
    let mut g = VecGrid::new(20, 10);
    for cy in 0..10 {
        g.set(15, cy);
    }
    g.set(3, 3);
    let words = g.words();
    let bits = BitGrid::new(20, 10, &words).unwrap();
    // Straight at the wall, from a cell centre and from a cell boundary.
    assert_eq!(cast_dir(&bits, 2.5, 5.5, 1.0, 0.0, 100.0), Some(12.5));
    assert_eq!(cast_dir(&bits, 2.0, 5.0, 1.0, 0.0, 100.0), Some(13.0));
    let t = cast(&bits, 2.5, 5.5, 0.0, 100.0).unwrap();
    assert!((t - 12.5).abs() < 1e-4);
    // The range limit is inclusive of the entry distance.
    assert_eq!(cast_dir(&bits, 2.5, 5.5, 1.0, 0.0, 12.4), None);
    assert_eq!(cast_dir(&bits, 2.5, 5.5, 1.0, 0.0, 12.5), Some(12.5));
    // Away from the wall: leaves the grid, no return.
    assert_eq!(cast_dir(&bits, 2.5, 5.5, -1.0, 0.0, 100.0), None);
    assert_eq!(cast_dir(&bits, 2.5, 5.5, 0.0, 1.0, 100.0), None);
    assert_eq!(cast(&bits, 2.5, 5.5, PI, 100.0), None);
    // Start inside a blocked cell: 0, whatever the direction.
    for a in [0.0, 1.0, 2.0, -2.5] {
        assert_eq!(cast(&bits, 3.5, 3.2, a, 100.0), Some(0.0));
        assert_eq!(cast(&bits, 15.0, 9.99, a, 100.0), Some(0.0));
    }
    // On the boundary of a blocked cell, moving into it: 0; moving away: not 0.
    assert_eq!(cast_dir(&bits, 16.0, 4.5, -1.0, 0.0, 100.0), Some(0.0));
    assert_eq!(cast_dir(&bits, 4.0, 3.5, -1.0, 0.0, 100.0), Some(0.0));
    assert_eq!(cast_dir(&bits, 4.0, 3.5, 1.0, 0.0, 100.0), Some(11.0));
    // Outside the grid or non-finite input: no return.
    for (u, v) in [
        (-0.1, 5.0),
        (20.0, 5.0),
        (5.0, 10.0),
        (5.0, -1e-7),
        (f32::NAN, 1.0),
        (1.0, f32::INFINITY),
    ] {
        assert_eq!(cast(&bits, u, v, 0.3, 100.0), None, "({u}, {v})");
    }
    assert_eq!(cast(&bits, 2.5, 5.5, f32::NAN, 100.0), None);
    assert_eq!(cast(&bits, 2.5, 5.5, 0.0, f32::NAN), None);
    // Degenerate grids.
    assert_eq!(cast(&BitGrid::empty(), 0.0, 0.0, 0.0, 100.0), None);
    assert!(BitGrid::new(20, 10, &words[..words.len() - 1]).is_none());
    assert_eq!(BitGrid::words_for(20, 10), 7);
    assert_eq!(BitGrid::words_for(0, 10), 0);
}

#[test]
fn diagonal_walls_do_not_leak_at_exact_corners() {
    // Blocked cells on the anti-diagonal cx + cy = 10: touching only at corners.
    let mut g = VecGrid::new(12, 12);
    for k in 0..=10 {
        g.set(k, 10 - k);
    }
    let words = g.words();
    let bits = BitGrid::new(12, 12, &words).unwrap();
    let s = FRAC_1_SQRT_2;
    // Rays at exactly 45 degrees through the wall's corner points.
    for (u, v) in [
        (0.5f32, 1.5f32),
        (1.5, 0.5),
        (0.5, 0.5),
        (2.0, 1.0),
        (0.0, 3.0),
    ] {
        let t = cast_dir(&bits, u, v, s, s, 100.0);
        assert!(t.is_some(), "leaked from ({u}, {v})");
        let want = reference(&g, u, v, s, s, 100.0);
        assert!(accepted(t, &want, TOL), "{t:?} vs {want:?}");
    }
}

#[test]
fn traverse_visits_edge_adjacent_cells_in_order() {
    let mut rng = Prng::new(13);
    for _ in 0..400 {
        let (w, h) = (1 + rng.below(30) as u32, 1 + rng.below(30) as u32);
        let (u, v) = (start_coord(&mut rng, w), start_coord(&mut rng, h));
        let a = if rng.below(4) == 0 {
            (rng.below(8) as f32 - 3.0) * FRAC_PI_4
        } else {
            rng.range(-PI, PI)
        };
        let (dx, dy) = (libm::cosf(a), libm::sinf(a));
        let max = if rng.below(2) == 0 {
            1e4
        } else {
            rng.range(0.0, 20.0)
        };
        let mut cells: Vec<(u32, u32, f32)> = Vec::new();
        traverse(w, h, u, v, dx, dy, max, |cx, cy, t| {
            cells.push((cx, cy, t));
            true
        });
        assert_eq!(cells[0], (u as u32, v as u32, 0.0));
        for pair in cells.windows(2) {
            let ((ax, ay, ta), (bx, by, tb)) = (pair[0], pair[1]);
            let step = (ax as i64 - bx as i64).abs() + (ay as i64 - by as i64).abs();
            assert_eq!(step, 1, "not edge-adjacent: {pair:?}");
            assert!(tb >= ta, "t decreased: {pair:?}");
            assert!(tb <= max);
            // Between two entries the ray is inside the earlier cell.
            if tb - ta > 2e-3 {
                let tm = (ta + tb) as f64 / 2.0;
                let q = [u as f64 + tm * dx as f64, v as f64 + tm * dy as f64];
                let inside = |c: u32, x: f64| x >= c as f64 - 1e-3 && x <= c as f64 + 1.0 + 1e-3;
                assert!(
                    inside(ax, q[0]) && inside(ay, q[1]),
                    "{q:?} not in {pair:?}"
                );
            }
        }
        for &(cx, cy, _) in &cells {
            assert!(cx < w && cy < h);
        }
        // Unless stopped by the range, the walk ends at the grid's edge.
        let &(lx, ly, lt) = cells.last().unwrap();
        let (t0, t1) = box_interval(
            [u as f64, v as f64],
            [dx as f64, dy as f64],
            [lx as i64, ly as i64],
        );
        let exit = t1;
        if exit + 1e-2 < max as f64 {
            let out = [
                u as f64 + (exit + 1e-2) * dx as f64,
                v as f64 + (exit + 1e-2) * dy as f64,
            ];
            let outside = out[0] < 0.0 || out[1] < 0.0 || out[0] >= w as f64 || out[1] >= h as f64;
            assert!(
                outside || t1 - t0 < 1e-2,
                "walk stopped inside the grid at ({lx}, {ly}) t {lt} (exit {exit}, max {max})"
            );
        }
        // Stopping early stops the walk.
        let mut n = 0;
        traverse(w, h, u, v, dx, dy, max, |_, _, _| {
            n += 1;
            n < 2
        });
        assert_eq!(n, cells.len().min(2));
    }
    // Nothing is visited from outside the grid.
    let mut n = 0;
    traverse(5, 5, 5.0, 1.0, -1.0, 0.0, 100.0, |_, _, _| {
        n += 1;
        true
    });
    assert_eq!(n, 0);
}

/// The exact clearance of each cell: the distance (cells) from the cell's
/// closed box to the nearest blocked cell's, `f32::INFINITY` with none.
fn clearance_brute(g: &VecGrid) -> Vec<f32> {
    let blocked: Vec<(i64, i64)> = (0..g.h as i64)
        .flat_map(|y| (0..g.w as i64).map(move |x| (x, y)))
        .filter(|&(x, y)| g.get(x, y) == Some(true))
        .collect();
    let mut out = Vec::with_capacity((g.w * g.h) as usize);
    for cy in 0..g.h as i64 {
        for cx in 0..g.w as i64 {
            let gap = blocked
                .iter()
                .map(|&(x, y)| {
                    let gx = ((x - cx).abs() - 1).max(0) as f32;
                    let gy = ((y - cy).abs() - 1).max(0) as f32;
                    libm::sqrtf(gx * gx + gy * gy)
                })
                .fold(f32::INFINITY, f32::min);
            out.push(gap);
        }
    }
    out
}

#[test]
fn cast_dir_clear_jumps_open_space_and_matches_the_reference() {
    let mut rng = Prng::new(13);
    let mut jumps = 0usize;
    let mut rays = 0usize;
    for _ in 0..25 {
        let (w, h) = (20 + rng.below(60) as u32, 20 + rng.below(60) as u32);
        // Sparse grids leave open space to jump across.
        let density = rng.range(0.0, 0.04);
        let g = VecGrid::random(&mut rng, w, h, density);
        let words = g.words();
        let bits = BitGrid::new(w, h, &words).unwrap();
        let clear = clearance_brute(&g);
        for _ in 0..80 {
            let (u, v) = (start_coord(&mut rng, w), start_coord(&mut rng, h));
            let angle = rng.range(-PI, PI);
            let (dx, dy) = (libm::cosf(angle), libm::sinf(angle));
            let max = if rng.below(2) == 0 {
                1e4
            } else {
                rng.range(0.0, 60.0)
            };
            let want = reference(&g, u, v, dx, dy, max);
            // The tightest bound (the exact clearance) and a looser one.
            for slack in [0.0f32, 0.5] {
                let used = core::cell::Cell::new(0usize);
                let got = cast_dir_clear(&bits, u, v, dx, dy, max, 1.0, |cx, cy| {
                    used.set(used.get() + 1);
                    clear[(cy * w + cx) as usize] - slack
                });
                assert!(
                    accepted(got, &want, TOL),
                    "ray from ({u}, {v}) angle {angle} max {max} in a {w}x{h} grid \
                     (slack {slack}): got {got:?}, reference {want:?}"
                );
                jumps += used.get();
                rays += 1;
            }
        }
    }
    // Most rays start in open space and jump at least once.
    assert!(jumps > rays, "{jumps} clearance reads for {rays} rays");
}

#[test]
fn cast_dir_clear_without_jumps_is_cast_dir() {
    let mut rng = Prng::new(14);
    let g = VecGrid::random(&mut rng, 30, 30, 0.1);
    let words = g.words();
    let bits = BitGrid::new(30, 30, &words).unwrap();
    for _ in 0..200 {
        let (u, v) = (start_coord(&mut rng, 30), start_coord(&mut rng, 30));
        let angle = rng.range(-PI, PI);
        let (dx, dy) = (libm::cosf(angle), libm::sinf(angle));
        // A clearance below the least jump, or no jumps at all.
        for (min_jump, c) in [(1.0, 0.5), (0.0, 100.0), (f32::INFINITY, 100.0)] {
            let got = cast_dir_clear(&bits, u, v, dx, dy, 50.0, min_jump, |_, _| c);
            assert_eq!(got, cast_dir(&bits, u, v, dx, dy, 50.0));
        }
    }
}
