//! Property tests (proptest) of the compiler's map kernels: random inputs,
//! and on failure a shrunk counterexample. The seeded tests next to the code
//! (`src/compiler/edt/tests.rs`, `src/compiler/mapfile/tests.rs`) cover fixed sizes and
//! densities; these add random shapes (scattered cells plus rectangles and
//! lines, which exercise the lower envelope differently from noise).
//!
//! * `edt::squared_edt` / `nearest_obstacle` equal brute force, and each
//!   nearest index is an obstacle at exactly that distance;
//! * `DistanceField::from_grid` equals brute force over its definition of an
//!   obstacle (occupied, unknown when asked, and the image border);
//! * an image loads to the same cells whether it is stored as 8- or 16-bit
//!   PGM or PNG (the loader's 16-to-8-bit narrowing and row order).
//!
//! Case counts are kept small (the whole suite runs in CI on 2 cores); set
//! `PROPTEST_CASES` for a longer run.

use mapc::compiler::edt::{self, DistanceField, NONE};
use mapc::compiler::mapfile::{self, Cell, OccupancyGrid};
use proptest::collection::vec;
use proptest::prelude::*;

fn cases(n: u32) -> ProptestConfig {
    ProptestConfig {
        cases: n,
        ..ProptestConfig::default()
    }
}

/// A `w x h` obstacle mask: scattered cells at a random density, plus up to
/// four filled rectangles (a 1-wide one is a wall).
fn mask() -> impl Strategy<Value = (usize, usize, Vec<bool>)> {
    (1usize..=32, 1usize..=32, 0.0f64..0.3).prop_flat_map(|(w, h, p)| {
        (
            Just(w),
            Just(h),
            vec(prop::bool::weighted(p), w * h),
            vec((0..w, 0..h, 1..=w, 1..=h), 0..4),
        )
            .prop_map(|(w, h, mut cells, rects)| {
                for (x0, y0, rw, rh) in rects {
                    for y in y0..(y0 + rh).min(h) {
                        for x in x0..(x0 + rw).min(w) {
                            cells[y * w + x] = true;
                        }
                    }
                }
                (w, h, cells)
            })
    })
}

use mapc::compiler::edt::brute_force_sq as brute;

/// Checks a feature transform against the squared distances `want`.
fn check_nearest(
    w: usize,
    obst: &[bool],
    want: &[f32],
    sq: &[f32],
    near: &[u32],
) -> Result<(), TestCaseError> {
    prop_assert_eq!(sq, want);
    for (i, &j) in near.iter().enumerate() {
        if j == NONE {
            prop_assert!(
                !obst.iter().any(|&o| o),
                "cell {} has no nearest obstacle",
                i
            );
            continue;
        }
        let j = j as usize;
        prop_assert!(obst[j], "nearest of {} is {}, not an obstacle", i, j);
        let (dx, dy) = (
            (i % w) as i64 - (j % w) as i64,
            (i / w) as i64 - (j / w) as i64,
        );
        prop_assert_eq!((dx * dx + dy * dy) as f32, sq[i], "cell {}", i);
    }
    Ok(())
}

proptest! {
    #![proptest_config(cases(96))]

    #[test]
    fn edt_matches_brute_force((w, h, obst) in mask()) {
        let want = brute(w, h, &obst);
        prop_assert_eq!(edt::squared_edt(w, h, |i| obst[i]), want.clone());
        let (sq, near) = edt::nearest_obstacle(w, h, |i| obst[i]);
        check_nearest(w, &obst, &want, &sq, &near)?;
    }

    #[test]
    fn distance_field_matches_brute_force(
        (w, h, cells) in (1usize..=24, 1usize..=24).prop_flat_map(|(w, h)| {
            (Just(w), Just(h), vec(prop_oneof![
                6 => Just(Cell::Free),
                1 => Just(Cell::Occupied),
                1 => Just(Cell::Unknown),
            ], w * h))
        }),
        unknown_is_obstacle in any::<bool>(),
    ) {
        let grid = OccupancyGrid::from_cells(w as u32, h as u32, 0.05, [0.0; 3], cells.clone());
        let field = DistanceField::from_grid(&grid, unknown_is_obstacle);
        let obst: Vec<bool> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                x == 0 || y == 0 || x + 1 == w || y + 1 == h
                    || cells[i] == Cell::Occupied
                    || (unknown_is_obstacle && cells[i] == Cell::Unknown)
            })
            .collect();
        let want = brute(w, h, &obst);
        check_nearest(w, &obst, &want, &field.sq, &field.nearest)?;
        for (i, &o) in obst.iter().enumerate() {
            prop_assert_eq!(field.is_obstacle(i), o);
        }
    }
}

proptest! {
    #![proptest_config(cases(32))]

    /// One image, four encodings: 8-bit PGM, 16-bit PGM (`v * 257`), 8-bit
    /// grey PNG and 16-bit grey PNG all load to the same cells (grey levels
    /// drawn from the classes' edges and anywhere in 0..=255).
    #[test]
    fn eight_and_sixteen_bit_images_load_alike(
        (w, h, px) in (1u32..=40, 1u32..=30).prop_flat_map(|(w, h)| {
            (Just(w), Just(h), vec(prop_oneof![
                Just(0u8), Just(254), Just(205), Just(166), Just(167),
                Just(89), Just(90), any::<u8>(),
            ], (w * h) as usize))
        }),
    ) {
        // At least one free pixel, or every encoding fails alike.
        let mut px = px;
        px[0] = 254;
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let mut pgm8 = format!("P5\n{w} {h}\n255\n").into_bytes();
        pgm8.extend_from_slice(&px);
        std::fs::write(d.join("a.pgm"), pgm8).unwrap();
        let wide: Vec<u16> = px.iter().map(|&v| v as u16 * 257).collect();
        let mut pgm16 = format!("P5\n{w} {h}\n65535\n").into_bytes();
        for v in &wide {
            pgm16.extend_from_slice(&v.to_be_bytes());
        }
        std::fs::write(d.join("b.pgm"), pgm16).unwrap();
        image::save_buffer(d.join("c.png"), &px, w, h, image::ExtendedColorType::L8).unwrap();
        let wide_bytes: Vec<u8> = wide.iter().flat_map(|v| v.to_ne_bytes()).collect();
        image::save_buffer(d.join("d.png"), &wide_bytes, w, h, image::ExtendedColorType::L16)
            .unwrap();
        let load = |name: &str| {
            mapfile::load_image(&d.join(name), Some(0.05), None)
                .unwrap_or_else(|e| panic!("{e}"))
                .grid
        };
        let a = load("a.pgm");
        prop_assert_eq!((a.width, a.height), (w, h));
        // Rows flipped: image row 0 is the top, grid row 0 the bottom.
        for (k, &v) in px.iter().enumerate() {
            let (ix, iy) = (k as u32 % w, k as u32 / w);
            let occ = (255.0 - v as f64) / 255.0;
            let want = if occ > mapfile::DEFAULT_OCCUPIED_THRESH {
                Cell::Occupied
            } else if occ < mapfile::DEFAULT_FREE_THRESH {
                Cell::Free
            } else {
                Cell::Unknown
            };
            prop_assert_eq!(a.get(ix, h - 1 - iy), want, "pixel ({}, {}) = {}", ix, iy, v);
        }
        for name in ["b.pgm", "c.png", "d.png"] {
            prop_assert_eq!(&load(name).cells, &a.cells, "{}", name);
        }
    }
}
