use super::*;
use crate::compiler::mapfile::Cell;

/// A `w x h` map (0.05 m cells), all occupied, with the given free
/// rectangles `(x0, y0, x1, y1)` (inclusive-exclusive, cells) and then the
/// given occupied rectangles.
fn map(
    w: u32,
    h: u32,
    free: &[(u32, u32, u32, u32)],
    occ: &[(u32, u32, u32, u32)],
) -> OccupancyGrid {
    let mut cells = vec![Cell::Occupied; (w * h) as usize];
    for (list, c) in [(free, Cell::Free), (occ, Cell::Occupied)] {
        for &(x0, y0, x1, y1) in list {
            for y in y0..y1 {
                for x in x0..x1 {
                    cells[(y * w + x) as usize] = c;
                }
            }
        }
    }
    OccupancyGrid::from_cells(w, h, 0.05, [0.0; 3], cells)
}

fn gvd(g: &OccupancyGrid, opts: &GvdOptions) -> GvdGraph {
    let d = distance_field(g, opts);
    extract(g, &d, opts)
}

/// Cyclomatic number: independent cycles of the graph.
fn cycles(g: &GvdGraph) -> usize {
    let n = g.nodes.len();
    g.edges.len() + components(g) - n
}

/// Connected components of a GVD graph.
fn components(g: &GvdGraph) -> usize {
    let mut sets = crate::compiler::connectivity::UnionFind::new(g.nodes.len());
    for e in &g.edges {
        sets.union(e.a as usize, e.b as usize);
    }
    sets.count()
}

fn check_consistent(g: &GvdGraph) {
    let mut deg = vec![0u32; g.nodes.len()];
    for e in &g.edges {
        deg[e.a as usize] += 1;
        deg[e.b as usize] += 1;
        let na = &g.nodes[e.a as usize];
        let nb = &g.nodes[e.b as usize];
        assert_eq!(e.cells.first(), Some(&(na.cx, na.cy)));
        assert_eq!(e.cells.last(), Some(&(nb.cx, nb.cy)));
        assert!(e.length_m > 0.0);
    }
    for (n, d) in g.nodes.iter().zip(&deg) {
        assert_eq!(n.degree, *d);
        assert_ne!(n.degree, 0);
        if n.degree == 2 {
            // Only the synthetic node of a cycle has degree 2.
            assert!(g
                .edges
                .iter()
                .any(|e| e.a == e.b && (e.a as usize) < g.nodes.len()));
        }
    }
}

#[test]
fn straight_corridor_gives_one_line() {
    // A closed corridor 300 x 30 cells (15 m x 1.5 m), noisy nowhere.
    let g = map(320, 50, &[(10, 10, 310, 40)], &[]);
    let r = gvd(&g, &GvdOptions::default());
    check_consistent(&r);
    assert_eq!(r.vertex_count(), 0, "{:?}", r.nodes);
    assert_eq!(r.edges.len(), 1, "{:?}", r.nodes);
    assert_eq!(r.end_point_count(), 2);
    // One cell per column along the middle, on the centre line.
    for x in 40..280u32 {
        let col: Vec<u32> = r.cells.iter().filter(|c| c.0 == x).map(|c| c.1).collect();
        assert_eq!(col.len(), 1, "column {x}: {col:?}");
        assert!(col[0] == 24 || col[0] == 25, "column {x}: {col:?}");
    }
    assert!(r.total_length_m() > 13.0 && r.total_length_m() < 15.0);
}

#[test]
fn t_junction_has_one_vertex_of_degree_three() {
    let g = map(340, 200, &[(10, 10, 330, 40), (155, 40, 185, 190)], &[]);
    let r = gvd(&g, &GvdOptions::default());
    check_consistent(&r);
    let v: Vec<&GvdNode> = r.nodes.iter().filter(|n| n.degree >= 3).collect();
    assert_eq!(v.len(), 1, "{:?}", r.nodes);
    assert_eq!(v[0].degree, 3);
    assert!(
        (v[0].cx as i64 - 170).abs() <= 3 && (v[0].cy as i64 - 25).abs() <= 16,
        "{:?}",
        v[0]
    );
    assert_eq!(r.end_point_count(), 3);
    assert_eq!(cycles(&r), 0);
}

#[test]
fn room_with_pillar_gives_a_cycle() {
    let g = map(220, 220, &[(10, 10, 210, 210)], &[(90, 90, 130, 130)]);
    let r = gvd(&g, &GvdOptions::default());
    check_consistent(&r);
    assert_eq!(cycles(&r), 1, "{:?} {:?}", r.nodes, r.edges.len());
    // The loop passes on every side of the pillar.
    let has = |f: &dyn Fn(u32, u32) -> bool| r.cells.iter().any(|&(x, y)| f(x, y));
    assert!(has(&|x, y| x < 90 && (100..120).contains(&y)));
    assert!(has(&|x, y| x > 130 && (100..120).contains(&y)));
    assert!(has(&|x, y| y < 90 && (100..120).contains(&x)));
    assert!(has(&|x, y| y > 130 && (100..120).contains(&x)));
}

#[test]
fn cycle_without_vertex_gets_a_synthetic_node() {
    // A ring corridor around a block: the branches into the four outer
    // corners are pruned, the GVD is a plain loop.
    let g = map(220, 220, &[(10, 10, 210, 210)], &[(40, 40, 180, 180)]);
    let r = gvd(&g, &GvdOptions::default());
    check_consistent(&r);
    assert_eq!(cycles(&r), 1);
    assert_eq!(r.vertex_count(), 0, "{:?}", r.nodes);
    assert_eq!(r.nodes.len(), 1);
    assert_eq!(r.nodes[0].degree, 2);
    assert_eq!(r.edges.len(), 1);
    assert_eq!(r.edges[0].a, r.edges[0].b);
}

#[test]
fn pruning_removes_a_noise_bump_spur() {
    // Corridor 2 m wide with a 4-cell bump on one wall.
    let g = map(320, 60, &[(10, 10, 310, 50)], &[(150, 10, 153, 14)]);
    let none = GvdOptions {
        min_spur_m: 0.0,
        spur_clearance_factor: 0.0,
        ..GvdOptions::default()
    };
    let raw = gvd(&g, &none);
    check_consistent(&raw);
    assert!(
        raw.vertex_count() >= 1,
        "the bump makes a spur: {:?}",
        raw.nodes
    );
    let pruned = gvd(&g, &GvdOptions::default());
    check_consistent(&pruned);
    assert_eq!(pruned.vertex_count(), 0, "{:?}", pruned.nodes);
    assert_eq!(pruned.edges.len(), 1);
}

#[test]
fn narrow_door_breaks_the_gvd_at_robot_radius() {
    // Two rooms joined by a 6-cell (0.3 m) door: too narrow for a 0.2 m
    // robot radius; a 12-cell (0.6 m) door is fine.
    for (door, pieces) in [(6u32, 2usize), (12, 1)] {
        let g = map(
            330,
            140,
            &[
                (10, 10, 150, 130),
                (180, 10, 320, 130),
                (150, 70 - door / 2, 180, 70 + door / 2),
            ],
            &[],
        );
        let r = gvd(&g, &GvdOptions::default());
        dump(&format!("door{door}"), &g, &r);
        check_consistent(&r);
        let comps = components(&r);
        assert_eq!(comps, pieces, "door {door}: {:?}", r.nodes);
        // Nothing closer to a wall than the robot radius.
        let d = distance_field(&g, &GvdOptions::default());
        for &(x, y) in &r.cells {
            assert!(d.clearance_m((y * g.width + x) as usize) >= 0.2 - 1e-9);
        }
    }
}

#[test]
fn unknown_as_free_option() {
    // A corridor whose lower wall is unknown, with unknown space below.
    let mut g = map(320, 80, &[(10, 10, 310, 70)], &[]);
    for y in 1..30 {
        for x in 1..319 {
            g.cells[y * 320 + x] = Cell::Unknown;
        }
    }
    let a = gvd(&g, &GvdOptions::default());
    let b = gvd(
        &g,
        &GvdOptions {
            unknown_is_obstacle: false,
            ..GvdOptions::default()
        },
    );
    let mean_y =
        |r: &GvdGraph| r.cells.iter().map(|c| c.1 as f64).sum::<f64>() / r.cells.len() as f64;
    // With unknown as obstacle the line is in the middle of the free part
    // (y 30..70 -> 49.5); with unknown as free it moves down (y 1..70).
    assert!((mean_y(&a) - 49.5).abs() < 3.0, "{}", mean_y(&a));
    assert!(mean_y(&b) < 45.0, "{}", mean_y(&b));
}

#[test]
fn deterministic_across_thread_counts() {
    let mut rng = crate::compiler::rng::Rng::new(5);
    let mut g = map(400, 300, &[(5, 5, 395, 295)], &[]);
    for _ in 0..60 {
        let (x, y) = (rng.below(380) as u32 + 10, rng.below(280) as u32 + 10);
        let (sx, sy) = (rng.below(20) as u32 + 1, rng.below(20) as u32 + 1);
        for yy in y..(y + sy).min(295) {
            for xx in x..(x + sx).min(395) {
                g.cells[(yy * 400 + xx) as usize] = Cell::Occupied;
            }
        }
    }
    let run = |t: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| gvd(&g, &GvdOptions::default()))
    };
    let a = run(1);
    check_consistent(&a);
    assert!(a.vertex_count() > 5);
    assert_eq!(a, run(2));
    assert_eq!(a, run(4));
}

#[test]
fn tiny_and_degenerate_grids_do_not_panic() {
    for (w, h) in [(1, 1), (2, 5), (3, 3), (5, 2)] {
        let g = OccupancyGrid::from_cells(w, h, 0.05, [0.0; 3], vec![Cell::Free; (w * h) as usize]);
        let r = gvd(&g, &GvdOptions::default());
        assert!(r.nodes.is_empty());
    }
    let g = map(50, 50, &[(1, 1, 49, 49)], &[]);
    let r = gvd(&g, &GvdOptions::default());
    check_consistent(&r);
}

/// Debug aid: `MAPC_DUMP=1` writes `/tmp/mapc-gvd/test-<name>.png`.
#[allow(dead_code)]
fn dump(name: &str, g: &OccupancyGrid, r: &GvdGraph) {
    if std::env::var_os("MAPC_DUMP").is_none() {
        return;
    }
    let (w, h) = (g.width, g.height);
    let mut img = image::RgbImage::new(w, h);
    for cy in 0..h {
        for cx in 0..w {
            let c = match g.get(cx, cy) {
                Cell::Free => [255, 255, 255],
                Cell::Occupied => [0, 0, 0],
                Cell::Unknown => [170, 170, 200],
            };
            img.put_pixel(cx, h - 1 - cy, image::Rgb(c));
        }
    }
    for &(x, y) in &r.cells {
        img.put_pixel(x, h - 1 - y, image::Rgb([230, 0, 0]));
    }
    for n in &r.nodes {
        img.put_pixel(n.cx, h - 1 - n.cy, image::Rgb([0, 0, 255]));
    }
    std::fs::create_dir_all("/tmp/mapc-gvd").unwrap();
    img.save(format!("/tmp/mapc-gvd/test-{name}.png")).unwrap();
}
