use super::*;
use crate::compiler::gvd::{self, GvdOptions};
use crate::compiler::mapfile::{load_yaml, Cell};
use std::path::{Path, PathBuf};
use std::time::Instant;

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

struct Built {
    dist: DistanceField,
    gvd: GvdGraph,
    sites: Vec<SitePlacement>,
}

fn build(g: &OccupancyGrid, opts: &SiteOptions) -> Built {
    let gopts = GvdOptions::default();
    let dist = gvd::distance_field(g, &gopts);
    let graph = gvd::extract(g, &dist, &gopts);
    let sites = place_sites(g, &dist, &graph, opts);
    Built {
        dist,
        gvd: graph,
        sites,
    }
}

fn check_sites(g: &OccupancyGrid, b: &Built, opts: &SiteOptions) {
    for (k, s) in b.sites.iter().enumerate() {
        let i = (s.cy * g.width + s.cx) as usize;
        assert!(
            s.clearance_m >= opts.robot_radius_m - 1e-9,
            "site {k}: {s:?}"
        );
        assert_eq!(s.clearance_m, b.dist.clearance_m(i));
        assert_eq!(g.cells[i], Cell::Free);
        let c = g.cell_center(s.cx, s.cy);
        assert_eq!([s.x, s.y], c);
        assert!(s.neighbours.windows(2).all(|p| p[0] < p[1]));
        for &n in &s.neighbours {
            assert_ne!(n as usize, k);
            assert!(
                b.sites[n as usize].neighbours.contains(&(k as u32)),
                "asymmetric {k} {n}"
            );
        }
        if s.kind == SiteKind::Fill {
            assert!(s.neighbours.is_empty());
        }
    }
    // No two sites on one cell.
    let mut cells: Vec<(u32, u32)> = b.sites.iter().map(|s| (s.cx, s.cy)).collect();
    cells.sort_unstable();
    let n = cells.len();
    cells.dedup();
    assert_eq!(cells.len(), n);
}

#[test]
fn a_spacing_finer_than_the_grid_gives_at_most_a_site_per_edge_cell() {
    let g = map(320, 50, &[(10, 10, 310, 40)], &[]);
    let opts = SiteOptions {
        edge_spacing_m: 1e-12,
        ..SiteOptions::default()
    };
    let b = build(&g, &opts);
    let cells: usize = b.gvd.edges.iter().map(|e| e.cells.len()).sum();
    let on_edges = b.sites.iter().filter(|s| s.kind != SiteKind::Fill).count();
    assert!(
        on_edges <= cells + 2,
        "{on_edges} sites on {cells} edge cells"
    );
    check_sites(&g, &b, &opts);
}

#[test]
fn corridor_sites_are_evenly_spaced_and_chained() {
    // 15 m x 1.5 m corridor.
    let g = map(320, 50, &[(10, 10, 310, 40)], &[]);
    let opts = SiteOptions::default();
    let b = build(&g, &opts);
    check_sites(&g, &b, &opts);
    assert_eq!(b.gvd.edges.len(), 1);
    let len = b.gvd.edges[0].length_m;
    let graph_sites: Vec<&SitePlacement> = b
        .sites
        .iter()
        .filter(|s| s.kind != SiteKind::Fill)
        .collect();
    let want = (len / opts.edge_spacing_m).ceil() as usize + 1;
    assert_eq!(graph_sites.len(), want, "length {len}");
    assert_eq!(
        graph_sites
            .iter()
            .filter(|s| s.kind == SiteKind::EndPoint)
            .count(),
        2
    );
    // A chain: two ends with one neighbour, the rest with two, and
    // consecutive sites no farther apart than the spacing (+ a cell).
    let ends = graph_sites
        .iter()
        .filter(|s| s.neighbours.len() == 1)
        .count();
    assert_eq!(ends, 2);
    for (k, s) in b.sites.iter().enumerate() {
        for &n in &s.neighbours {
            let t = &b.sites[n as usize];
            let d = ((s.x - t.x).powi(2) + (s.y - t.y).powi(2)).sqrt();
            assert!(d <= opts.edge_spacing_m + 0.08, "{k}-{n}: {d}");
            assert!(d >= 0.5 * opts.edge_spacing_m, "{k}-{n}: {d}");
        }
    }
    let cov = coverage_of(&g, &b, &opts);
    assert!(cov.fraction >= 0.995, "{}", cov.fraction);
}

fn coverage_of(g: &OccupancyGrid, b: &Built, opts: &SiteOptions) -> Coverage {
    let words = g.blocked_bits(true);
    let bg = BitGrid::new(g.width, g.height, &words).unwrap();
    coverage(
        g,
        &bg,
        &b.dist,
        &b.sites,
        opts.min_clearance_m,
        opts.coverage_range_m,
    )
}

#[test]
fn t_junction_vertex_is_a_site_with_three_neighbours() {
    let g = map(340, 200, &[(10, 10, 330, 40), (155, 40, 185, 190)], &[]);
    let opts = SiteOptions::default();
    let b = build(&g, &opts);
    check_sites(&g, &b, &opts);
    let v: Vec<&SitePlacement> = b
        .sites
        .iter()
        .filter(|s| s.kind == SiteKind::Vertex)
        .collect();
    assert_eq!(v.len(), 1);
    assert_eq!(v[0].neighbours.len(), 3);
    // Graph order: the nodes come first.
    assert!(b.sites[..b.gvd.nodes.len()]
        .iter()
        .all(|s| s.kind != SiteKind::Edge));
}

#[test]
fn coverage_counts_line_of_sight_within_range() {
    // An open room 4 m x 4 m; one site in the middle; 1 m range.
    let g = map(100, 100, &[(10, 10, 90, 90)], &[]);
    let dist = DistanceField::from_grid(&g, true);
    let words = g.blocked_bits(true);
    let bg = BitGrid::new(100, 100, &words).unwrap();
    let site = SitePlacement {
        x: 2.525,
        y: 2.525,
        cx: 50,
        cy: 50,
        clearance_m: dist.clearance_m(50 * 100 + 50),
        kind: SiteKind::Fill,
        neighbours: vec![],
    };
    let cov = coverage(&g, &bg, &dist, std::slice::from_ref(&site), 0.25, 1.0);
    // Considered: free cells with clearance >= 5 cells: 14..=85 -> 72 x 72.
    assert_eq!(cov.considered, 72 * 72);
    let unc: std::collections::HashSet<(u32, u32)> = cov.uncovered.iter().copied().collect();
    for y in 14..86u32 {
        for x in 14..86u32 {
            let d = ((x as f64 - 50.0).powi(2) + (y as f64 - 50.0).powi(2)).sqrt();
            if d <= 19.0 {
                assert!(
                    !unc.contains(&(x, y)),
                    "{x},{y} at {d} cells should be seen"
                );
            }
            if d >= 21.5 {
                assert!(
                    unc.contains(&(x, y)),
                    "{x},{y} at {d} cells is out of range"
                );
            }
        }
    }
    assert_eq!(cov.covered + cov.uncovered.len() as u64, cov.considered);
    // A wall across the room hides its far side.
    let g2 = map(100, 100, &[(10, 10, 90, 90)], &[(10, 60, 90, 62)]);
    let dist2 = DistanceField::from_grid(&g2, true);
    let words2 = g2.blocked_bits(true);
    let bg2 = BitGrid::new(100, 100, &words2).unwrap();
    let cov2 = coverage(&g2, &bg2, &dist2, std::slice::from_ref(&site), 0.25, 8.0);
    // The largest region is the lower part (y 10..60), fully seen.
    assert_eq!(cov2.fraction, 1.0);
    assert!(cov2.considered < cov.considered);
}

#[test]
fn fill_sites_cover_a_hidden_room() {
    // A corridor with a small (1.5 m) side room behind a narrow (0.3 m)
    // door: the GVD does not pass the door (too narrow for the robot), the
    // room's own GVD is too small to keep, the door lets the laser see only
    // a sliver of the room: a fill site covers the rest.
    let g = map(
        330,
        200,
        &[(10, 10, 320, 40), (145, 46, 175, 76), (157, 40, 163, 46)],
        &[],
    );
    let opts = SiteOptions::default();
    let no_fill = build(
        &g,
        &SiteOptions {
            fill_uncovered: false,
            ..opts.clone()
        },
    );
    let before = coverage_of(&g, &no_fill, &opts);
    let b = build(&g, &opts);
    check_sites(&g, &b, &opts);
    let after = coverage_of(&g, &b, &opts);
    assert!(
        after.fraction >= opts.fill_target,
        "{} -> {}",
        before.fraction,
        after.fraction
    );
    let fills = b.sites.iter().filter(|s| s.kind == SiteKind::Fill).count();
    assert!(fills >= 1);
    // The graph sites are unchanged and come first.
    assert_eq!(&b.sites[..no_fill.sites.len()], &no_fill.sites[..]);
}

#[test]
fn deterministic_across_thread_counts() {
    let mut rng = crate::compiler::rng::Rng::new(9);
    let mut g = map(400, 300, &[(5, 5, 395, 295)], &[]);
    for _ in 0..80 {
        let (x, y) = (rng.below(380) as u32 + 10, rng.below(280) as u32 + 10);
        let (sx, sy) = (rng.below(30) as u32 + 1, rng.below(30) as u32 + 1);
        for yy in y..(y + sy).min(295) {
            for xx in x..(x + sx).min(395) {
                g.cells[(yy * 400 + xx) as usize] = Cell::Occupied;
            }
        }
    }
    let opts = SiteOptions::default();
    let run = |t: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| {
                let b = build(&g, &opts);
                let c = coverage_of(&g, &b, &opts);
                (b.sites, c)
            })
    };
    let a = run(1);
    assert!(a.0.len() > 10);
    assert_eq!(a, run(2));
    assert_eq!(a, run(3));
}

/// The shared maps, when present.
fn shared_maps() -> Option<Vec<PathBuf>> {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/maps"));
    let Ok(rd) = std::fs::read_dir(dir) else {
        eprintln!("skipping: shared maps not found at {}", dir.display());
        return None;
    };
    let mut yamls: Vec<PathBuf> = rd
        .flatten()
        .filter_map(|e| std::fs::read_dir(e.path()).ok())
        .flat_map(|inner| inner.flatten().map(|f| f.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    yamls.sort();
    Some(yamls)
}

/// Builds every shared map and prints the table of the report; asserts the
/// coverage target. `cargo test --release -p mapc --lib sites -- --nocapture`.
#[test]
fn shared_maps_report() {
    let Some(yamls) = shared_maps() else { return };
    let opts = SiteOptions::default();
    let gopts = GvdOptions::default();
    eprintln!(
        "{:<16} {:>9} {:>8} {:>8} {:>5} {:>5} {:>5} {:>5} {:>5} {:>8} {:>8} {:>8} {:>8}",
        "map",
        "cells",
        "free",
        "gvd_m",
        "vert",
        "comps",
        "sites",
        "fill",
        "cover",
        "edt_ms",
        "gvd_ms",
        "site_ms",
        "total_ms"
    );
    for y in &yamls {
        let src = load_yaml(y).unwrap();
        let g = &src.grid;
        let t0 = Instant::now();
        let dist = gvd::distance_field(g, &gopts);
        let t1 = Instant::now();
        let graph = gvd::extract(g, &dist, &gopts);
        let t2 = Instant::now();
        let sites = place_sites(g, &dist, &graph, &opts);
        let t3 = Instant::now();
        let b = Built {
            dist,
            gvd: graph,
            sites,
        };
        check_sites(g, &b, &opts);
        let cov = coverage_of(g, &b, &opts);
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        let name = y.file_stem().unwrap().to_string_lossy().into_owned();
        eprintln!(
            "{:<16} {:>9} {:>8} {:>8.1} {:>5} {:>5} {:>5} {:>5} {:>5.3} {:>8.1} {:>8.1} {:>8.1} {:>8.1}",
            name,
            g.cells.len(),
            g.free_count(),
            b.gvd.total_length_m(),
            b.gvd.vertex_count(),
            components(&b.gvd),
            b.sites.len(),
            b.sites.iter().filter(|s| s.kind == SiteKind::Fill).count(),
            cov.fraction,
            ms(t0, t1),
            ms(t1, t2),
            ms(t2, t3),
            ms(t0, t3)
        );
        assert!(cov.fraction >= 0.99, "{name}: coverage {}", cov.fraction);
        if std::env::var_os("MAPC_DUMP").is_some() {
            dump(&name, g, &b, &cov);
        }
    }
}

/// Connected components of a GVD graph.
fn components(g: &GvdGraph) -> usize {
    let mut sets = crate::compiler::connectivity::UnionFind::new(g.nodes.len());
    for e in &g.edges {
        sets.union(e.a as usize, e.b as usize);
    }
    sets.count()
}

/// The whole build of a real map (Intel) is the same with 1 and 2 threads.
#[test]
fn shared_map_deterministic_across_thread_counts() {
    let Some(yamls) = shared_maps() else { return };
    let Some(y) = yamls.iter().find(|p| p.ends_with("intel/intel.yaml")) else {
        eprintln!("skipping: no intel map");
        return;
    };
    let g = load_yaml(y).unwrap().grid;
    let opts = SiteOptions::default();
    let run = |t: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap()
            .install(|| {
                let b = build(&g, &opts);
                let c = coverage_of(&g, &b, &opts);
                (b.dist.sq, b.dist.nearest, b.gvd, b.sites, c)
            })
    };
    let a = run(1);
    let b = run(2);
    assert!(a == b);
}

/// Writes `/tmp/mapc-gvd/<name>.png`: free white, occupied black, unknown
/// grey-blue, uncovered cells pink, GVD red, sites (3x3) green / blue
/// (vertex) / orange (fill).
fn dump(name: &str, g: &OccupancyGrid, b: &Built, cov: &Coverage) {
    let (w, h) = (g.width, g.height);
    let mut img = image::RgbImage::new(w, h);
    let mut put = |x: u32, y: u32, c: [u8; 3]| {
        if x < w && y < h {
            img.put_pixel(x, h - 1 - y, image::Rgb(c));
        }
    };
    for cy in 0..h {
        for cx in 0..w {
            let c = match g.get(cx, cy) {
                Cell::Free => [255, 255, 255],
                Cell::Occupied => [0, 0, 0],
                Cell::Unknown => [170, 170, 200],
            };
            put(cx, cy, c);
        }
    }
    for &(x, y) in &cov.uncovered {
        put(x, y, [255, 170, 200]);
    }
    for &(x, y) in &b.gvd.cells {
        put(x, y, [230, 0, 0]);
    }
    for s in &b.sites {
        let c = match s.kind {
            SiteKind::Vertex => [0, 0, 255],
            SiteKind::EndPoint | SiteKind::Edge => [0, 170, 0],
            SiteKind::Fill => [255, 140, 0],
        };
        for dy in -1i32..=1 {
            for dx in -1i32..=1 {
                put((s.cx as i32 + dx) as u32, (s.cy as i32 + dy) as u32, c);
            }
        }
    }
    std::fs::create_dir_all("/tmp/mapc-gvd").unwrap();
    img.save(format!("/tmp/mapc-gvd/{name}.png")).unwrap();
    // MAPC_CROP=name,x0,y0,size,scale: an enlarged crop (image coordinates).
    if let Some(spec) = std::env::var_os("MAPC_CROP") {
        let spec = spec.to_string_lossy().into_owned();
        let f: Vec<&str> = spec.split(',').collect();
        if f.len() == 5 && f[0] == name {
            let v: Vec<u32> = f[1..].iter().map(|x| x.parse().unwrap()).collect();
            let (x0, y0, size, k) = (v[0], v[1], v[2], v[3]);
            let mut out = image::RgbImage::new(size * k, size * k);
            for y in 0..size * k {
                for x in 0..size * k {
                    let (sx, sy) = (x0 + x / k, y0 + y / k);
                    if sx < w && sy < h {
                        out.put_pixel(x, y, *img.get_pixel(sx, sy));
                    }
                }
            }
            out.save(format!("/tmp/mapc-gvd/{name}-crop.png")).unwrap();
        }
    }
}

/// Peak memory and time of the whole build on a big map: the Intel map
/// tiled `MAPC_TILES` x `MAPC_TILES` times (default 6: 5328 x 5088 cells).
/// `cargo test --release -p mapc --lib big_map -- --ignored --nocapture`.
#[test]
#[ignore]
fn big_map_memory_and_time() {
    let Some(yamls) = shared_maps() else { return };
    let Some(y) = yamls.iter().find(|p| p.ends_with("intel/intel.yaml")) else {
        return;
    };
    let tiles: u32 = std::env::var("MAPC_TILES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(6);
    let src = load_yaml(y).unwrap().grid;
    let (w, h) = (src.width * tiles, src.height * tiles);
    let mut cells = Vec::with_capacity((w * h) as usize);
    for cy in 0..h {
        for cx in 0..w {
            cells.push(src.get(cx % src.width, cy % src.height));
        }
    }
    drop(src);
    let g = OccupancyGrid::from_cells(w, h, 0.05, [0.0; 3], cells);
    let hwm = || {
        std::fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("VmHWM"))
                    .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
            })
            .unwrap_or(0)
            * 1024
    };
    let before = hwm();
    let t = Instant::now();
    let opts = SiteOptions::default();
    let b = build(&g, &opts);
    let secs = t.elapsed().as_secs_f64();
    let cells_n = (w as u64) * (h as u64);
    eprintln!(
        "{w} x {h} = {cells_n} cells: {:.2} s, {} sites, gvd {:.0} m; peak RSS {:.1} MB before, {:.1} MB after ({:.1} bytes/cell)",
        secs,
        b.sites.len(),
        b.gvd.total_length_m(),
        before as f64 / 1e6,
        hwm() as f64 / 1e6,
        hwm() as f64 / cells_n as f64
    );
}
