//! Reference sites on the GVD graph, and how much of the map they see.
//!
//! Following the paper, every GVD vertex is a site; we also make every end
//! point and the synthetic node of a vertex-less cycle a site, and instead
//! of one midpoint per long edge we add evenly spaced sites so that
//! consecutive sites along an edge are at most [`SiteOptions::edge_spacing_m`]
//! apart (along the edge). Consecutive sites along an edge are graph
//! neighbours.
//!
//! **Coverage** of a set of sites: among the free cells of the LARGEST
//! 4-connected region of free cells whose clearance is at least
//! `min_clearance_m` (the "considered" cells), the share that some site sees
//! along a straight, unblocked line within `range_m`. Visibility is computed
//! by sweeping rays from each site's cell centre over 360 degrees, with an
//! angular step below the angle a cell subtends at the range limit, so every
//! cell within range is crossed by at least one ray; a ray stops at the
//! first blocked cell ([`refloc::raycast::traverse`]).
//!
//! With [`SiteOptions::fill_uncovered`], "fill" sites are then added greedily
//! at the uncovered considered cell of largest clearance (ties: lowest cell
//! index), one at a time, until the coverage reaches
//! [`SiteOptions::fill_target`] or no candidate is left.
//!
//! Everything is deterministic whatever the thread count: visibility is a
//! union of bits (order-independent) and the greedy choice is sequential.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use rayon::prelude::*;
use refloc::raycast::{traverse, BitGrid, Occupancy};

use crate::compiler::connectivity::flood4;
use crate::compiler::edt::DistanceField;
use crate::compiler::gvd::GvdGraph;
use crate::compiler::mapfile::{Cell, OccupancyGrid};

/// Site placement settings.
#[derive(Clone, Debug, PartialEq)]
pub struct SiteOptions {
    /// Sites keep at least this clearance (metres; default 0.2).
    pub robot_radius_m: f64,
    /// Largest spacing between consecutive sites along a GVD edge (metres;
    /// default 2.0: a query is then rarely more than about 2 m from a site
    /// it can see, the distance at which histogram ranking still works
    /// well in the project's probes).
    pub edge_spacing_m: f64,
    /// Line-of-sight range for coverage (metres; default 8.0).
    pub coverage_range_m: f64,
    /// Add fill sites where the graph sites leave cells uncovered (default
    /// true).
    pub fill_uncovered: bool,
    /// Cells with less clearance than this are not counted in coverage
    /// (metres; default 0.25).
    pub min_clearance_m: f64,
    /// Coverage fraction at which filling stops (default 0.995).
    pub fill_target: f64,
}

impl Default for SiteOptions {
    fn default() -> Self {
        SiteOptions {
            robot_radius_m: 0.2,
            edge_spacing_m: 2.0,
            coverage_range_m: 8.0,
            fill_uncovered: true,
            min_clearance_m: 0.25,
            fill_target: 0.995,
        }
    }
}

/// Why a site is where it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SiteKind {
    /// A GVD vertex (degree >= 3).
    Vertex = 0,
    /// A GVD end point (degree 1).
    EndPoint = 1,
    /// On a GVD edge (spacing sites, and the node of a vertex-less cycle).
    Edge = 2,
    /// Added to cover what the graph sites do not see.
    Fill = 3,
}

/// One reference site.
#[derive(Clone, Debug, PartialEq)]
pub struct SitePlacement {
    /// Map-frame x of the cell centre (metres).
    pub x: f64,
    /// Map-frame y of the cell centre (metres).
    pub y: f64,
    /// Cell column.
    pub cx: u32,
    /// Cell row (0 = bottom).
    pub cy: u32,
    /// Distance to the nearest obstacle cell centre (metres).
    pub clearance_m: f64,
    /// Why the site is here.
    pub kind: SiteKind,
    /// Indices of the sites adjacent along the GVD, sorted, without
    /// duplicates (empty for fill sites).
    pub neighbours: Vec<u32>,
}

/// Coverage of a site set (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Coverage {
    /// Number of considered cells.
    pub considered: u64,
    /// Considered cells seen by at least one site.
    pub covered: u64,
    /// `covered / considered` (1.0 when nothing is considered).
    pub fraction: f64,
    /// Considered cells that no site sees, `(cx, cy)`, by cell index.
    pub uncovered: Vec<(u32, u32)>,
}

/// Places the sites: GVD nodes first (in graph node order), then the
/// spacing sites of each edge (in edge order, from node `a` to node `b`),
/// then fill sites (in the order they were chosen).
///
/// An edge of length `L` gets `ceil(L / edge_spacing_m) - 1` evenly spaced
/// sites (by arc length, snapped to the edge's cells). Every site keeps at
/// least `robot_radius_m` of clearance: where the GVD passes closer than
/// that to a speck it ignores (see [`crate::compiler::gvd`]), a spacing site moves
/// along the edge by up to a quarter of the spacing, or is dropped, and a
/// node is not a site; the neighbour links then join the sites on either
/// side.
///
/// `dist` is the distance field the GVD was built from; lines of sight for
/// filling are blocked by occupied cells, and by unknown cells when
/// `dist.unknown_is_obstacle`.
pub fn place_sites(
    grid: &OccupancyGrid,
    dist: &DistanceField,
    gvd: &GvdGraph,
    opts: &SiteOptions,
) -> Vec<SitePlacement> {
    let w = grid.width as usize;
    let res = grid.resolution;
    let min_sq = {
        let r = (opts.robot_radius_m / res).max(0.0);
        r * r
    };
    let ok = |i: usize| !dist.is_obstacle(i) && dist.sq[i] as f64 >= min_sq;
    let mut sites: Vec<SitePlacement> = Vec::new();
    let mut at: HashMap<usize, u32> = HashMap::new();
    let mut add =
        |sites: &mut Vec<SitePlacement>, cx: u32, cy: u32, kind: SiteKind| -> Option<u32> {
            let i = cy as usize * w + cx as usize;
            if cx >= grid.width || cy >= grid.height || !ok(i) {
                return None;
            }
            if let Some(&s) = at.get(&i) {
                return Some(s);
            }
            let [x, y] = grid.cell_center(cx, cy);
            let id = sites.len() as u32;
            sites.push(SitePlacement {
                x,
                y,
                cx,
                cy,
                clearance_m: dist.clearance_m(i),
                kind,
                neighbours: Vec::new(),
            });
            at.insert(i, id);
            Some(id)
        };

    let node_site: Vec<Option<u32>> = gvd
        .nodes
        .iter()
        .map(|n| {
            let kind = match n.degree {
                1 => SiteKind::EndPoint,
                d if d >= 3 => SiteKind::Vertex,
                _ => SiteKind::Edge,
            };
            add(&mut sites, n.cx, n.cy, kind)
        })
        .collect();

    let spacing = if opts.edge_spacing_m.is_finite() && opts.edge_spacing_m > 0.0 {
        opts.edge_spacing_m
    } else {
        f64::INFINITY
    };
    let mut links: Vec<(u32, u32)> = Vec::new();
    for e in &gvd.edges {
        let mut chain: Vec<u32> = Vec::new();
        chain.extend(node_site.get(e.a as usize).copied().flatten());
        // At most one site per cell of the edge: a spacing finer than the
        // grid (or a huge resolution) cannot make more sites than cells.
        let segments = if spacing.is_finite() {
            (e.length_m / spacing)
                .ceil()
                .clamp(1.0, e.cells.len().max(1) as f64) as usize
        } else {
            1
        };
        if segments > 1 && e.cells.len() > 2 {
            // Cumulative arc length (metres) at each polyline cell.
            let mut arc = Vec::with_capacity(e.cells.len());
            let mut s = 0.0;
            arc.push(0.0);
            for p in e.cells.windows(2) {
                let dx = p[1].0 as f64 - p[0].0 as f64;
                let dy = p[1].1 as f64 - p[0].1 as f64;
                s += (dx * dx + dy * dy).sqrt() * res;
                arc.push(s);
            }
            let total = s;
            let mut k0 = 0;
            for k in 1..segments {
                let target = total * k as f64 / segments as f64;
                while k0 + 1 < arc.len() && arc[k0 + 1] <= target {
                    k0 += 1;
                }
                let k1 = (k0 + 1).min(arc.len() - 1);
                let pick = if (target - arc[k0]).abs() <= (arc[k1] - target).abs() {
                    k0
                } else {
                    k1
                };
                // The GVD may pass next to a speck it ignores: take the
                // nearest cell along the edge (within a quarter of the
                // spacing) that keeps the robot radius.
                let reach = spacing / 4.0;
                let found = (0..e.cells.len())
                    .flat_map(|d| [pick.checked_sub(d), Some(pick + d)])
                    .flatten()
                    .filter(|&k| k < e.cells.len())
                    .take_while(|&k| (arc[k] - arc[pick]).abs() <= reach)
                    .find(|&k| {
                        let (cx, cy) = e.cells[k];
                        ok(cy as usize * w + cx as usize)
                    });
                if let Some(k) = found {
                    let (cx, cy) = e.cells[k];
                    chain.extend(add(&mut sites, cx, cy, SiteKind::Edge));
                }
            }
        }
        chain.extend(node_site.get(e.b as usize).copied().flatten());
        for p in chain.windows(2) {
            if p[0] != p[1] {
                links.push((p[0], p[1]));
            }
        }
    }
    for (a, b) in links {
        sites[a as usize].neighbours.push(b);
        sites[b as usize].neighbours.push(a);
    }
    for s in &mut sites {
        s.neighbours.sort_unstable();
        s.neighbours.dedup();
    }

    if opts.fill_uncovered {
        fill(grid, dist, opts, &mut sites, &mut at);
    }
    sites
}

/// Adds fill sites (see the module documentation).
fn fill(
    grid: &OccupancyGrid,
    dist: &DistanceField,
    opts: &SiteOptions,
    sites: &mut Vec<SitePlacement>,
    at: &mut HashMap<usize, u32>,
) {
    let words = grid.blocked_bits(dist.unknown_is_obstacle);
    let Some(blocked) = BitGrid::new(grid.width, grid.height, &words) else {
        return;
    };
    let state = CoverageState::new(grid, dist, opts.min_clearance_m);
    if state.considered == 0 {
        return;
    }
    let range = opts.coverage_range_m / grid.resolution;
    let seen = Bits::new(state.n);
    let covered = AtomicU64::new(0);
    sites.par_iter().for_each(|s| {
        let c = sweep(
            &blocked,
            s.cx,
            s.cy,
            range,
            &seen,
            &state.considered_bits,
            false,
        );
        covered.fetch_add(c, Ordering::Relaxed);
    });
    let mut covered = covered.into_inner();
    let target = opts.fill_target;
    if covered as f64 >= target * state.considered as f64 {
        return;
    }
    let min_sq = {
        let r = (opts.robot_radius_m.max(opts.min_clearance_m) / grid.resolution).max(0.0);
        r * r
    };
    let w = grid.width as usize;
    let mut cand: Vec<u32> = (0..state.n)
        .filter(|&i| state.considered_bits.get(i) && !seen.get(i) && dist.sq[i] as f64 >= min_sq)
        .map(|i| i as u32)
        .collect();
    cand.sort_unstable_by_key(|&i| (std::cmp::Reverse(dist.sq[i as usize].to_bits()), i));
    for &c in &cand {
        if covered as f64 >= target * state.considered as f64 {
            break;
        }
        let i = c as usize;
        if seen.get(i) || at.contains_key(&i) {
            continue;
        }
        let (cx, cy) = ((i % w) as u32, (i / w) as u32);
        covered += sweep(&blocked, cx, cy, range, &seen, &state.considered_bits, true);
        let [x, y] = grid.cell_center(cx, cy);
        at.insert(i, sites.len() as u32);
        sites.push(SitePlacement {
            x,
            y,
            cx,
            cy,
            clearance_m: dist.clearance_m(i),
            kind: SiteKind::Fill,
            neighbours: Vec::new(),
        });
    }
}

/// Computes the coverage of `sites` (see the module documentation):
/// considered cells are the free cells of the largest 4-connected free
/// region with a clearance (from `dist`) of at least `min_clearance_m`;
/// a cell is covered when a ray from a site's cell centre reaches it
/// within `range_m` metres without entering a cell `blocked` marks.
pub fn coverage(
    grid: &OccupancyGrid,
    blocked: &BitGrid,
    dist: &DistanceField,
    sites: &[SitePlacement],
    min_clearance_m: f64,
    range_m: f64,
) -> Coverage {
    let state = CoverageState::new(grid, dist, min_clearance_m);
    let seen = Bits::new(state.n);
    let range = range_m / grid.resolution;
    let covered: u64 = sites
        .par_iter()
        .map(|s| {
            sweep(
                blocked,
                s.cx,
                s.cy,
                range,
                &seen,
                &state.considered_bits,
                false,
            )
        })
        .sum();
    let w = grid.width as usize;
    let uncovered = (0..state.n)
        .filter(|&i| state.considered_bits.get(i) && !seen.get(i))
        .map(|i| ((i % w) as u32, (i / w) as u32))
        .collect();
    Coverage {
        considered: state.considered,
        covered,
        fraction: if state.considered == 0 {
            1.0
        } else {
            covered as f64 / state.considered as f64
        },
        uncovered,
    }
}

/// The considered cells.
struct CoverageState {
    n: usize,
    considered_bits: Bits,
    considered: u64,
}

impl CoverageState {
    fn new(grid: &OccupancyGrid, dist: &DistanceField, min_clearance_m: f64) -> Self {
        let n = grid.cells.len();
        let region = largest_free_region(grid);
        let r = (min_clearance_m / grid.resolution).max(0.0);
        let min_sq = r * r;
        let bits = Bits::new(n);
        let mut considered = 0;
        for (i, &in_region) in region.iter().enumerate() {
            if in_region && !dist.is_obstacle(i) && dist.sq[i] as f64 >= min_sq {
                bits.set(i);
                considered += 1;
            }
        }
        CoverageState {
            n,
            considered_bits: bits,
            considered,
        }
    }
}

/// The largest 4-connected region of [`Cell::Free`] cells (ties: the region
/// holding the lowest cell index), as a per-cell flag.
pub fn largest_free_region(grid: &OccupancyGrid) -> Vec<bool> {
    let (w, h) = (grid.width as usize, grid.height as usize);
    let n = w * h;
    let mut seen = vec![false; n];
    let mut stack: Vec<u32> = Vec::new();
    let flood = |start: usize, seen: &mut [bool], stack: &mut Vec<u32>| -> u64 {
        let mut count = 0;
        seen[start] = true;
        flood4(
            w,
            h,
            start,
            stack,
            |j| {
                let take = !seen[j] && grid.cells[j] == Cell::Free;
                seen[j] |= take;
                take
            },
            |_| count += 1,
        );
        count
    };
    let mut best: Option<(u64, usize)> = None;
    for i in 0..n {
        if grid.cells[i] == Cell::Free && !seen[i] {
            let c = flood(i, &mut seen, &mut stack);
            if best.is_none_or(|(bc, _)| c > bc) {
                best = Some((c, i));
            }
        }
    }
    seen.iter_mut().for_each(|s| *s = false);
    if let Some((_, start)) = best {
        flood(start, &mut seen, &mut stack);
    }
    seen
}

/// A shared bitmap (bits set atomically; setting is order-independent).
struct Bits(Vec<AtomicU32>);

impl Bits {
    fn new(n: usize) -> Self {
        Bits((0..n.div_ceil(32)).map(|_| AtomicU32::new(0)).collect())
    }
    #[inline]
    fn get(&self, i: usize) -> bool {
        (self.0[i / 32].load(Ordering::Relaxed) >> (i % 32)) & 1 == 1
    }
    /// Sets bit `i`; true when it was clear.
    #[inline]
    fn set(&self, i: usize) -> bool {
        let bit = 1u32 << (i % 32);
        self.0[i / 32].fetch_or(bit, Ordering::Relaxed) & bit == 0
    }
}

/// Marks in `seen` every cell a site at cell `(cx, cy)` sees within `range`
/// cells; returns how many `considered` cells it newly marked.
fn sweep(
    blocked: &BitGrid,
    cx: u32,
    cy: u32,
    range: f64,
    seen: &Bits,
    considered: &Bits,
    parallel: bool,
) -> u64 {
    if range.is_nan() || range <= 0.0 || cx >= blocked.width() || cy >= blocked.height() {
        return 0;
    }
    let (w, _) = (blocked.width() as usize, ());
    // Angular step 0.8 / range: a cell at distance r <= range spans at least
    // about 1 / r radians, so every cell within range is crossed by a ray.
    let rays = ((std::f64::consts::TAU * range / 0.8).ceil() as usize).max(8);
    let (u, v) = (cx as f32 + 0.5, cy as f32 + 0.5);
    let one_ray = |k: usize| -> u64 {
        let a = std::f64::consts::TAU * k as f64 / rays as f64;
        let (dy, dx) = a.sin_cos();
        let mut newly = 0;
        traverse(
            blocked.width(),
            blocked.height(),
            u,
            v,
            dx as f32,
            dy as f32,
            range as f32,
            |x, y, _| {
                if blocked.blocked(x, y) {
                    return false;
                }
                let i = y as usize * w + x as usize;
                if seen.set(i) && considered.get(i) {
                    newly += 1;
                }
                true
            },
        );
        newly
    };
    if parallel {
        (0..rays).into_par_iter().map(one_ray).sum()
    } else {
        (0..rays).map(one_ray).sum()
    }
}

#[cfg(test)]
mod tests;
