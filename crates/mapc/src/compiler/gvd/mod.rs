//! Generalized Voronoi diagram (GVD) of the free space and its graph.
//!
//! The GVD is the set of free points with two or more nearest obstacle
//! points. On the grid it is extracted from the feature transform of
//! [`crate::compiler::edt`] (the nearest obstacle cell of every cell):
//!
//! 0. **Specks.** Isolated obstacle components smaller than
//!    [`GvdOptions::min_obstacle_area_m2`] (laser noise, single unknown
//!    cells, chair legs) are left out of the distance field the GVD is
//!    extracted from; otherwise each would add a small loop and two
//!    vertices. They still count for clearance, for the sites' robot-radius
//!    check and for lines of sight.
//! 1. **Candidates.** A free cell `p` whose clearance (distance from its
//!    centre to the nearest obstacle cell centre) is at least the robot
//!    radius is a candidate when one of its free 4-neighbours `q` has its
//!    nearest obstacle far from `p`'s: `|f(p) - f(q)| > max(min_separation_cells,
//!    separation_factor * clearance(p))` (cells). The absolute term ignores
//!    the jitter of neighbouring features along one wall. The relative term
//!    is off by default: it also cuts the (real) GVD branch from a door into
//!    a room whose clearance exceeds the door width over the factor, which
//!    leaves fragments; noise is left to pruning instead.
//! 2. **Holes.** A hole in the candidate set that holds no obstacle cell
//!    cannot be a Voronoi cycle (every GVD cycle encloses an obstacle); such
//!    holes are filled so that thinning does not keep spurious little loops.
//! 3. **Thinning.** Parallel two-sub-iteration thinning (Guo & Hall) of
//!    the candidate set until stable, then one-cell tips are removed and
//!    staircase corners cut: a one-cell-wide, 8-connected skeleton with the
//!    candidate set's topology, so a corridor (whose candidate band is two
//!    cells wide, one on each side of the centre line) gives one line.
//! 4. **Spur pruning.** An end branch (from an end point to a vertex of
//!    degree >= 3) is removed when it is shorter than `max(min_spur_m,
//!    spur_clearance_factor * clearance at its vertex)` (the branch into a
//!    room corner is about `sqrt(2)` times the clearance at its vertex
//!    long, a branch to a bump in a noisy wall about one clearance), or when
//!    most of its cells are closer than the robot radius to a speck (a
//!    branch through clutter, typically the ray streaks of a badly mapped
//!    area broken into specks). When every branch of a vertex qualifies,
//!    the longest is kept. Repeated (with re-thinning) until no branch
//!    qualifies.
//! 5. **Small components.** Connected pieces of the skeleton with a total
//!    length below `min_component_m`, or mostly closer than the robot radius
//!    to specks, are removed (fragments in small rooms and clutter).
//!
//! Obstacles are occupied cells, unknown cells (unless
//! [`GvdOptions::unknown_is_obstacle`] is false) and the image border ring
//! (see [`DistanceField`]).
//!
//! The graph: nodes are vertices (degree >= 3), end points (degree 1) and,
//! on a cycle with no vertex (a corridor around a closed block), one
//! synthetic node of degree 2 at the cycle's cell of largest clearance.
//! Edges carry their cell polyline from node `a` to node `b`. Every step is
//! sequential, or parallel with decisions taken on a snapshot: the result
//! does not depend on the thread count.

use std::collections::{HashMap, HashSet};

use rayon::prelude::*;

use crate::compiler::connectivity::{flood4, UnionFind};
use crate::compiler::edt::{DistanceField, NONE};
use crate::compiler::mapfile::OccupancyGrid;

/// GVD extraction settings.
#[derive(Clone, Debug, PartialEq)]
pub struct GvdOptions {
    /// GVD cells with a clearance below this are dropped (metres; default
    /// 0.2): the robot's centre cannot be there.
    pub robot_radius_m: f64,
    /// Whether unknown cells are obstacles (default true: a map's walls are
    /// often the border of the unknown area, and free "ray" streaks into the
    /// unknown are not places).
    pub unknown_is_obstacle: bool,
    /// Minimum distance between the nearest obstacle cells of two
    /// 4-neighbours for a GVD candidate (cells; default 2.0).
    pub min_separation_cells: f64,
    /// Minimum feature separation relative to the clearance (default 0.0,
    /// off; 0.35 would ask the two nearest obstacle points to be 20 degrees
    /// apart as seen from the cell, which also breaks door branches into
    /// large rooms).
    pub separation_factor: f64,
    /// End branches shorter than this are always pruned (metres; default 0.5).
    pub min_spur_m: f64,
    /// End branches shorter than this times the clearance at their vertex
    /// are pruned (default 1.5: removes room-corner branches, about 1.41 x).
    pub spur_clearance_factor: f64,
    /// Connected skeleton pieces shorter than this in total are removed
    /// (metres; default 1.0).
    pub min_component_m: f64,
    /// Isolated obstacle components (8-connected, not touching the image
    /// border) smaller than this are ignored by the GVD (square metres;
    /// default 0.05, e.g. 20 cells at 5 cm): laser noise specks, single
    /// unknown cells and chair legs would otherwise each put a small loop
    /// with two vertices into the GVD. They still count for clearance
    /// ([`GvdNode::clearance`]) and lines of sight.
    pub min_obstacle_area_m2: f64,
}

impl Default for GvdOptions {
    fn default() -> Self {
        GvdOptions {
            robot_radius_m: 0.2,
            unknown_is_obstacle: true,
            min_separation_cells: 2.0,
            separation_factor: 0.0,
            min_spur_m: 0.5,
            spur_clearance_factor: 1.5,
            min_component_m: 1.0,
            min_obstacle_area_m2: 0.05,
        }
    }
}

/// A node of the GVD graph.
#[derive(Clone, Debug, PartialEq)]
pub struct GvdNode {
    /// Cell column.
    pub cx: u32,
    /// Cell row (0 = bottom).
    pub cy: u32,
    /// Map-frame x of the cell centre (metres).
    pub x: f64,
    /// Map-frame y of the cell centre (metres).
    pub y: f64,
    /// Distance to the nearest obstacle cell centre (metres), specks
    /// included: where the GVD passes a speck it ignores this can be below
    /// the robot radius.
    pub clearance: f64,
    /// Number of edge ends at this node (a self-loop counts twice): 1 for an
    /// end point, >= 3 for a vertex, 2 for the synthetic node of a cycle.
    pub degree: u32,
}

/// An edge of the GVD graph.
#[derive(Clone, Debug, PartialEq)]
pub struct GvdEdge {
    /// Index of the first node.
    pub a: u32,
    /// Index of the second node (equal to `a` for a cycle).
    pub b: u32,
    /// Length of the polyline (metres).
    pub length_m: f64,
    /// Cells `(cx, cy)` from node `a`'s cell to node `b`'s cell, in order.
    pub cells: Vec<(u32, u32)>,
}

/// The GVD skeleton and its graph.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct GvdGraph {
    /// Grid width (cells).
    pub width: u32,
    /// Grid height (cells).
    pub height: u32,
    /// Nodes: vertices and end points in order of their first cell
    /// (row-major from the bottom), then the synthetic nodes of cycles.
    pub nodes: Vec<GvdNode>,
    /// Edges, in the order they were traced (by node, then direction).
    pub edges: Vec<GvdEdge>,
    /// Every skeleton cell `(cx, cy)`, sorted by `cy * width + cx`.
    pub cells: Vec<(u32, u32)>,
}

impl GvdGraph {
    /// Total length of all edges (metres).
    pub fn total_length_m(&self) -> f64 {
        self.edges.iter().map(|e| e.length_m).sum()
    }

    /// Number of vertices (nodes of degree >= 3).
    pub fn vertex_count(&self) -> usize {
        self.nodes.iter().filter(|n| n.degree >= 3).count()
    }

    /// Number of end points (nodes of degree 1).
    pub fn end_point_count(&self) -> usize {
        self.nodes.iter().filter(|n| n.degree == 1).count()
    }
}

/// The [`DistanceField`] that [`extract`] expects for these options.
pub fn distance_field(grid: &OccupancyGrid, opts: &GvdOptions) -> DistanceField {
    DistanceField::from_grid(grid, opts.unknown_is_obstacle)
}

/// Extracts the GVD of `grid` and its graph. `dist` must come from
/// [`distance_field`] (the same grid and `unknown_is_obstacle`); when its
/// `unknown_is_obstacle` differs from the options', a matching field is
/// computed here instead.
pub fn extract(grid: &OccupancyGrid, dist: &DistanceField, opts: &GvdOptions) -> GvdGraph {
    extract_with(grid, dist, opts, &mut |_| {})
}

/// As [`extract`], calling `lap(step)` at the end of each step
/// ("gvd.specks", "gvd.thin", ...) so that the caller can time them.
pub fn extract_with(
    grid: &OccupancyGrid,
    dist: &DistanceField,
    opts: &GvdOptions,
    lap: &mut dyn FnMut(&'static str),
) -> GvdGraph {
    let own;
    let dist = if dist.unknown_is_obstacle == opts.unknown_is_obstacle
        && dist.width == grid.width
        && dist.height == grid.height
    {
        dist
    } else {
        own = distance_field(grid, opts);
        &own
    };
    let (w, h) = (grid.width as usize, grid.height as usize);
    if w < 3 || h < 3 {
        return GvdGraph {
            width: grid.width,
            height: grid.height,
            ..Default::default()
        };
    }
    // The field the GVD is extracted from: without the specks.
    let res = grid.resolution;
    let max_speck = (opts.min_obstacle_area_m2 / (res * res)).floor();
    let cleaned;
    let gdist = match specks(dist, max_speck.clamp(0.0, (w * h) as f64) as usize) {
        Some(speck) => {
            let (sq, nearest) =
                crate::compiler::edt::nearest_obstacle(w, h, |i| dist.is_obstacle(i) && !speck[i]);
            cleaned = DistanceField {
                sq,
                nearest,
                ..dist.clone_header()
            };
            &cleaned
        }
        None => dist,
    };
    lap("gvd.specks");
    let mut sk = Skeleton {
        w,
        mask: candidates(gdist, opts),
        order: Vec::new(),
    };
    fill_empty_holes(&mut sk.mask, gdist, w, h);
    lap("gvd.candidates");
    sk.order = (0..w * h)
        .filter(|&i| sk.mask[i] != 0)
        .map(|i| i as u32)
        .collect();
    sk.thin();
    lap("gvd.thin");

    let r = (opts.robot_radius_m / res).max(0.0);
    let fields = Fields {
        gvd: gdist,
        real: dist,
        min_sq: r * r,
    };
    for _ in 0..200 {
        let raw = sk.extract(gdist);
        if !sk.prune_spurs(&raw, &fields, opts) {
            break;
        }
        sk.thin();
    }
    let raw = sk.extract(gdist);
    if sk.remove_small_components(&raw, &fields, opts.min_component_m) {
        sk.thin();
    }
    lap("gvd.prune");
    let raw = sk.extract(gdist);
    let graph = raw.into_graph(grid, dist, &sk);
    lap("gvd.graph");
    graph
}

/// The distance fields the pruning looks at.
struct Fields<'a> {
    /// The field the GVD is extracted from (specks removed).
    gvd: &'a DistanceField,
    /// The real field.
    real: &'a DistanceField,
    /// Squared robot radius (cells^2).
    min_sq: f64,
}

impl Fields<'_> {
    /// Cells of `path` closer to a real obstacle (a speck) than the robot
    /// radius.
    fn low_count(&self, path: &[u32]) -> usize {
        path.iter()
            .filter(|&&c| (self.real.sq[c as usize] as f64) < self.min_sq)
            .count()
    }

    /// Whether most of `path` runs closer to specks than the robot radius:
    /// a branch through clutter (ray streaks broken into specks, furniture
    /// legs), not a passage.
    fn cluttered(&self, path: &[u32]) -> bool {
        2 * self.low_count(path) > path.len()
    }
}

/// Flags the cells of obstacle components (8-connected) of at most
/// `max_cells` cells that do not touch the image border; `None` when there
/// is none.
fn specks(dist: &DistanceField, max_cells: usize) -> Option<Vec<bool>> {
    if max_cells == 0 {
        return None;
    }
    let (w, h) = (dist.width as usize, dist.height as usize);
    let mut seen = vec![false; w * h];
    let mut speck: Option<Vec<bool>> = None;
    let mut stack: Vec<u32> = Vec::new();
    let mut comp: Vec<u32> = Vec::new();
    for start in 0..w * h {
        if seen[start] || !dist.is_obstacle(start) {
            continue;
        }
        seen[start] = true;
        stack.push(start as u32);
        comp.clear();
        let mut size = 0usize;
        let mut border = false;
        while let Some(i) = stack.pop() {
            let i = i as usize;
            size += 1;
            if size <= max_cells {
                comp.push(i as u32);
            }
            let (x, y) = (i % w, i / w);
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                border = true;
                // Border cells have out-of-grid neighbours: visit the
                // in-grid ones only.
            }
            for (dx, dy) in DIRS {
                let (nx, ny) = (x as isize + dx, y as isize + dy);
                if nx < 0 || ny < 0 || nx >= w as isize || ny >= h as isize {
                    continue;
                }
                let j = ny as usize * w + nx as usize;
                if !seen[j] && dist.is_obstacle(j) {
                    seen[j] = true;
                    stack.push(j as u32);
                }
            }
        }
        if !border && size <= max_cells {
            let s = speck.get_or_insert_with(|| vec![false; w * h]);
            for &i in &comp {
                s[i as usize] = true;
            }
        }
    }
    speck
}

/// 8-neighbour offsets, counter-clockwise from east.
const DIRS: [(isize, isize); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

/// `SIMPLE[c]`: whether a foreground cell whose 8 neighbours (bit k set
/// when `DIRS[k]` is foreground) are `c` is a simple point: Yokoi's
/// 8-connectivity number is 1.
const SIMPLE: [bool; 256] = {
    let mut t = [false; 256];
    let mut c = 0usize;
    while c < 256 {
        let mut n = 0usize;
        let mut k = 0usize;
        while k < 8 {
            let a = 1 - ((c >> k) & 1);
            let b = 1 - ((c >> ((k + 1) % 8)) & 1);
            let d = 1 - ((c >> ((k + 2) % 8)) & 1);
            n += a - a * b * d;
            k += 2;
        }
        t[c] = n == 1;
        c += 1;
    }
    t
};

/// Guo-Hall deletion tables for the odd and even sub-iterations, indexed
/// by the 8-neighbour configuration (bit k set when `DIRS[k]` is set).
const GH_ODD: [bool; 256] = guo_hall(true);
const GH_EVEN: [bool; 256] = guo_hall(false);

const fn guo_hall(odd: bool) -> [bool; 256] {
    let mut t = [false; 256];
    let mut c = 0usize;
    while c < 256 {
        // Guo-Hall's names, clockwise from north: P2 = N, P3 = NE, P4 = E,
        // P5 = SE, P6 = S, P7 = SW, P8 = W, P9 = NW.
        let (p2, p3, p4, p5) = ((c >> 2) & 1, (c >> 1) & 1, c & 1, (c >> 7) & 1);
        let (p6, p7, p8, p9) = ((c >> 6) & 1, (c >> 5) & 1, (c >> 4) & 1, (c >> 3) & 1);
        let cc = ((1 - p2) & (p3 | p4))
            + ((1 - p4) & (p5 | p6))
            + ((1 - p6) & (p7 | p8))
            + ((1 - p8) & (p9 | p2));
        let n1 = (p9 | p2) + (p3 | p4) + (p5 | p6) + (p7 | p8);
        let n2 = (p2 | p3) + (p4 | p5) + (p6 | p7) + (p8 | p9);
        let n = if n1 < n2 { n1 } else { n2 };
        let m = if odd {
            (p6 | p7 | (1 - p9)) & p8
        } else {
            (p2 | p3 | (1 - p5)) & p4
        };
        t[c] = cc == 1 && n >= 2 && n <= 3 && m == 0;
        c += 1;
    }
    t
}

/// Marks GVD candidates (step 1).
fn candidates(dist: &DistanceField, opts: &GvdOptions) -> Vec<u8> {
    let (w, h) = (dist.width as usize, dist.height as usize);
    let r = (opts.robot_radius_m / dist.resolution).max(0.0);
    let min_sq = r * r;
    let mut mask = vec![0u8; w * h];
    mask.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        if y == 0 || y + 1 == h {
            return;
        }
        for (x, slot) in row.iter_mut().enumerate().take(w - 1).skip(1) {
            let i = y * w + x;
            let s = dist.sq[i] as f64;
            let f = dist.nearest[i];
            if s == 0.0 || s < min_sq || f == NONE {
                continue;
            }
            let (fx, fy) = ((f as usize % w) as i64, (f as usize / w) as i64);
            let thr = opts
                .min_separation_cells
                .max(opts.separation_factor * s.sqrt());
            let thr2 = thr * thr;
            for j in [i + 1, i - 1, i + w, i - w] {
                let g = dist.nearest[j];
                if dist.sq[j] == 0.0 || g == NONE {
                    continue;
                }
                let (gx, gy) = ((g as usize % w) as i64, (g as usize / w) as i64);
                let sep2 = ((fx - gx) * (fx - gx) + (fy - gy) * (fy - gy)) as f64;
                if sep2 > thr2 {
                    *slot = 1;
                    break;
                }
            }
        }
    });
    mask
}

/// Fills the holes of the candidate set that contain no obstacle (step 2):
/// 4-connected components of non-candidate free cells none of which is
/// 4-adjacent to an obstacle.
fn fill_empty_holes(mask: &mut [u8], dist: &DistanceField, w: usize, h: usize) {
    const SEEN: u8 = 2;
    let mut stack: Vec<u32> = Vec::new();
    let mut comp: Vec<u32> = Vec::new();
    for start in 0..w * h {
        if mask[start] != 0 || dist.is_obstacle(start) {
            continue;
        }
        // Flood this component of free non-candidate cells.
        let mut touches_obstacle = false;
        comp.clear();
        mask[start] = SEEN;
        flood4(
            w,
            h,
            start,
            &mut stack,
            |j| {
                if dist.is_obstacle(j) {
                    touches_obstacle = true;
                    false
                } else if mask[j] == 0 {
                    mask[j] = SEEN;
                    true
                } else {
                    false
                }
            },
            |i| comp.push(i as u32),
        );
        if !touches_obstacle {
            for &i in &comp {
                mask[i as usize] = 1;
            }
        }
    }
    for m in mask.iter_mut() {
        if *m == SEEN {
            *m = 0;
        }
    }
}

/// A set of cell indices, one bit per grid cell: membership tests along
/// skeleton paths touch neighbouring words, where a hash set of a large
/// map's million skeleton cells misses the cache on nearly every test.
struct CellBits(Vec<u64>);

impl CellBits {
    /// An empty set for cells `0..n`.
    fn new(n: usize) -> Self {
        CellBits(vec![0; n.div_ceil(64)])
    }

    #[inline]
    fn contains(&self, i: &u32) -> bool {
        (self.0[*i as usize / 64] >> (i % 64)) & 1 == 1
    }

    /// Adds `i`; true when it was not in the set.
    #[inline]
    fn insert(&mut self, i: u32) -> bool {
        let (w, bit) = (i as usize / 64, 1u64 << (i % 64));
        let new = self.0[w] & bit == 0;
        self.0[w] |= bit;
        new
    }
}

/// Node id of a skeleton cell, for the few cells that belong to a node: a
/// bit per cell answers most lookups without touching the map.
struct NodeOf {
    bits: CellBits,
    map: HashMap<u32, usize>,
}

impl NodeOf {
    fn new(n: usize) -> Self {
        NodeOf {
            bits: CellBits::new(n),
            map: HashMap::new(),
        }
    }

    #[inline]
    fn contains_key(&self, c: &u32) -> bool {
        self.bits.contains(c)
    }

    #[inline]
    fn get(&self, c: &u32) -> Option<&usize> {
        if self.bits.contains(c) {
            self.map.get(c)
        } else {
            None
        }
    }

    fn insert(&mut self, c: u32, id: usize) {
        self.bits.insert(c);
        self.map.insert(c, id);
    }
}

/// The skeleton being thinned and pruned.
struct Skeleton {
    w: usize,
    /// 1 for skeleton cells, full grid.
    mask: Vec<u8>,
    /// Skeleton cells by increasing index.
    order: Vec<u32>,
}

impl Skeleton {
    #[inline]
    fn config(&self, i: usize) -> u8 {
        let w = self.w as isize;
        let mut c = 0u8;
        for (k, (dx, dy)) in DIRS.iter().enumerate() {
            let j = (i as isize + dx + dy * w) as usize;
            if self.mask[j] != 0 {
                c |= 1 << k;
            }
        }
        c
    }

    #[inline]
    fn neighbour(&self, i: usize, k: usize) -> usize {
        let (dx, dy) = DIRS[k];
        (i as isize + dx + dy * self.w as isize) as usize
    }

    /// Step 3: parallel thinning (Guo & Hall 1989, two sub-iterations,
    /// deletions decided on the state at the start of each sub-iteration,
    /// so the result does not depend on any visiting order) until nothing
    /// changes, then one pass that cuts the corners of 4-connected
    /// staircases, leaving a minimal 8-connected line. End points (one
    /// neighbour, or two adjacent ones) are never deleted, so branches keep
    /// their length.
    fn thin(&mut self) {
        loop {
            let mut changed = false;
            for table in [&GH_ODD, &GH_EVEN] {
                let del: Vec<u32> = self
                    .order
                    .par_iter()
                    .copied()
                    .filter(|&i| table[self.config(i as usize) as usize])
                    .collect();
                changed |= !del.is_empty();
                for i in del {
                    self.mask[i as usize] = 0;
                }
                let mask = &self.mask;
                self.order.retain(|&i| mask[i as usize] != 0);
            }
            if !changed {
                break;
            }
        }
        // One-cell tips: a cell whose only two neighbours touch each other
        // is a one-cell spur (a bump on a line) or the thick tip of a line
        // end; decided on one snapshot, so a line loses at most one cell.
        let tips: Vec<u32> = self
            .order
            .par_iter()
            .copied()
            .filter(|&i| {
                let c = self.config(i as usize);
                c.count_ones() == 2 && SIMPLE[c as usize]
            })
            .collect();
        for i in tips {
            self.mask[i as usize] = 0;
        }
        // Staircase corners: a simple cell with two perpendicular
        // 4-neighbours (which touch each other diagonally) is redundant.
        for idx in 0..self.order.len() {
            let i = self.order[idx] as usize;
            if self.mask[i] == 0 {
                continue;
            }
            let c = self.config(i);
            let (e, n, w, s) = (c & 1 != 0, c & 4 != 0, c & 16 != 0, c & 64 != 0);
            if SIMPLE[c as usize] && (n || s) && (e || w) {
                self.mask[i] = 0;
            }
        }
        let mask = &self.mask;
        self.order.retain(|&i| mask[i as usize] != 0);
    }

    /// Cells in increasing index order.
    fn cells_by_index(&self) -> Vec<u32> {
        self.order
            .iter()
            .copied()
            .filter(|&i| self.mask[i as usize] != 0)
            .collect()
    }

    /// Builds the raw graph of the current skeleton.
    fn extract(&self, dist: &DistanceField) -> RawGraph {
        let cells = self.cells_by_index();
        let mut node_of = NodeOf::new(self.mask.len());
        let mut nodes: Vec<RawNode> = Vec::new();
        let degree = |i: u32| self.config(i as usize).count_ones();
        // Nodes: clusters of junction cells (>= 3 neighbours) and end points.
        for &c in &cells {
            if node_of.contains_key(&c) {
                continue;
            }
            let d = degree(c);
            // End points: one neighbour, or two that touch each other.
            if d <= 1 || (d == 2 && SIMPLE[self.config(c as usize) as usize]) {
                node_of.insert(c, nodes.len());
                nodes.push(RawNode {
                    rep: c,
                    cells: vec![c],
                });
            } else if d >= 3 {
                let id = nodes.len();
                let mut members = vec![c];
                node_of.insert(c, id);
                let mut k = 0;
                while k < members.len() {
                    let m = members[k] as usize;
                    for dir in 0..8 {
                        let n = self.neighbour(m, dir) as u32;
                        if self.mask[n as usize] != 0 && degree(n) >= 3 && !node_of.contains_key(&n)
                        {
                            node_of.insert(n, id);
                            members.push(n);
                        }
                    }
                    k += 1;
                }
                members.sort_unstable();
                let rep = *members
                    .iter()
                    .max_by_key(|&&m| (dist.sq[m as usize].to_bits(), std::cmp::Reverse(m)))
                    .unwrap_or(&c);
                nodes.push(RawNode {
                    rep,
                    cells: members,
                });
            }
        }
        // Edges traced from every node.
        let mut visited = CellBits::new(self.mask.len());
        let mut edges: Vec<RawEdge> = Vec::new();
        let mut direct: HashSet<(usize, usize)> = HashSet::new();
        for a in 0..nodes.len() {
            let members = nodes[a].cells.clone();
            for &c in &members {
                for dir in 0..8 {
                    let n = self.neighbour(c as usize, dir) as u32;
                    if self.mask[n as usize] == 0 {
                        continue;
                    }
                    if let Some(&b) = node_of.get(&n) {
                        if b > a && direct.insert((a, b)) {
                            edges.push(RawEdge {
                                a,
                                b,
                                path: dedup_path(vec![nodes[a].rep, c, n, nodes[b].rep]),
                            });
                        }
                        continue;
                    }
                    if visited.contains(&n) {
                        continue;
                    }
                    // Follow the line of 2-neighbour cells.
                    let mut path = vec![nodes[a].rep, c];
                    let (mut prev, mut cur) = (c, n);
                    let end = loop {
                        visited.insert(cur);
                        path.push(cur);
                        let next = (0..8)
                            .map(|k| self.neighbour(cur as usize, k) as u32)
                            .find(|&m| m != prev && self.mask[m as usize] != 0);
                        let Some(next) = next else { break None };
                        if let Some(&b) = node_of.get(&next) {
                            path.push(next);
                            path.push(nodes[b].rep);
                            break Some(b);
                        }
                        if visited.contains(&next) {
                            break None;
                        }
                        prev = cur;
                        cur = next;
                    };
                    if let Some(b) = end {
                        edges.push(RawEdge {
                            a,
                            b,
                            path: dedup_path(path),
                        });
                    }
                }
            }
        }
        // Cycles without any node: one synthetic node at the cell of
        // largest clearance.
        for &s in &cells {
            if node_of.contains_key(&s) || visited.contains(&s) {
                continue;
            }
            let mut cycle = vec![s];
            visited.insert(s);
            let (mut prev, mut cur) = (u32::MAX, s);
            loop {
                let next = (0..8)
                    .map(|k| self.neighbour(cur as usize, k) as u32)
                    .find(|&m| m != prev && self.mask[m as usize] != 0);
                match next {
                    Some(n) if n == s => break,
                    Some(n) if !visited.contains(&n) => {
                        visited.insert(n);
                        cycle.push(n);
                        prev = cur;
                        cur = n;
                    }
                    _ => break,
                }
            }
            let (k, &rep) = cycle
                .iter()
                .enumerate()
                .max_by_key(|&(_, &m)| (dist.sq[m as usize].to_bits(), std::cmp::Reverse(m)))
                .unwrap_or((0, &s));
            let id = nodes.len();
            node_of.insert(rep, id);
            nodes.push(RawNode {
                rep,
                cells: vec![rep],
            });
            let mut path: Vec<u32> = cycle[k..].iter().chain(&cycle[..k]).copied().collect();
            path.push(rep);
            edges.push(RawEdge { a: id, b: id, path });
        }
        let mut g = RawGraph { nodes, edges };
        g.dissolve_degree_two();
        g
    }

    /// Step 4, one round: removes the qualifying end branches; true when
    /// something was removed.
    fn prune_spurs(&mut self, g: &RawGraph, fields: &Fields<'_>, opts: &GvdOptions) -> bool {
        let deg = g.degrees();
        let res = fields.gvd.resolution;
        let mut by_vertex: HashMap<usize, Vec<(usize, f64, bool)>> = HashMap::new();
        for (e, edge) in g.edges.iter().enumerate() {
            for (v, other) in [(edge.a, edge.b), (edge.b, edge.a)] {
                if deg[v] >= 3 {
                    let len = path_length(&edge.path, self.w) * res;
                    let is_spur = deg[other] == 1 && other != v && {
                        let clear = (fields.gvd.sq[g.nodes[v].rep as usize] as f64).sqrt() * res;
                        len < opts.min_spur_m.max(opts.spur_clearance_factor * clear)
                            || fields.cluttered(&edge.path)
                    };
                    by_vertex.entry(v).or_default().push((e, len, is_spur));
                }
            }
        }
        let mut remove: Vec<(usize, usize)> = Vec::new(); // (edge, vertex)
        let mut vertices: Vec<usize> = by_vertex.keys().copied().collect();
        vertices.sort_unstable();
        for v in vertices {
            let list = &by_vertex[&v];
            let spurs: Vec<&(usize, f64, bool)> = list.iter().filter(|t| t.2).collect();
            if spurs.is_empty() {
                continue;
            }
            let keep_longest = spurs.len() == list.len();
            let longest = spurs
                .iter()
                .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
                .map(|t| t.0);
            for t in spurs {
                if keep_longest && Some(t.0) == longest {
                    continue;
                }
                remove.push((t.0, v));
            }
        }
        if remove.is_empty() {
            return false;
        }
        let mut removed_any = false;
        for (e, v) in remove {
            let edge = &g.edges[e];
            let keep: HashSet<u32> = g.nodes[v].cells.iter().copied().collect();
            let leaf = if edge.a == v { edge.b } else { edge.a };
            for &c in edge.path.iter().chain(&g.nodes[leaf].cells) {
                if !keep.contains(&c) && self.mask[c as usize] != 0 {
                    self.mask[c as usize] = 0;
                    removed_any = true;
                }
            }
        }
        let mask = &self.mask;
        self.order.retain(|&i| mask[i as usize] != 0);
        removed_any
    }

    /// Step 5: removes connected pieces shorter than `min_len_m`; true when
    /// something was removed.
    fn remove_small_components(
        &mut self,
        g: &RawGraph,
        fields: &Fields<'_>,
        min_len_m: f64,
    ) -> bool {
        let res = fields.gvd.resolution;
        let n = g.nodes.len();
        let mut sets = UnionFind::new(n);
        for e in &g.edges {
            sets.union(e.a, e.b);
        }
        let mut len = vec![0.0f64; n];
        let mut cells = vec![0usize; n];
        let mut low = vec![0usize; n];
        for e in &g.edges {
            let r = sets.find(e.a);
            len[r] += path_length(&e.path, self.w) * res;
            cells[r] += e.path.len();
            low[r] += fields.low_count(&e.path);
        }
        let mut removed = false;
        let small: Vec<bool> = (0..n)
            .map(|v| {
                let r = sets.find(v);
                len[r] < min_len_m || 2 * low[r] > cells[r]
            })
            .collect();
        for (v, node) in g.nodes.iter().enumerate() {
            if small[v] {
                for &c in &node.cells {
                    removed |= std::mem::replace(&mut self.mask[c as usize], 0) != 0;
                }
            }
        }
        for e in &g.edges {
            if small[e.a] {
                for &c in &e.path {
                    removed |= std::mem::replace(&mut self.mask[c as usize], 0) != 0;
                }
            }
        }
        // Cells that belong to no node nor edge (isolated cells, blobs
        // without exits) go too.
        let mut covered = CellBits::new(self.mask.len());
        for &c in g
            .nodes
            .iter()
            .flat_map(|n| n.cells.iter())
            .chain(g.edges.iter().flat_map(|e| e.path.iter()))
        {
            covered.insert(c);
        }
        for &c in &self.order {
            if self.mask[c as usize] != 0 && !covered.contains(&c) {
                self.mask[c as usize] = 0;
                removed = true;
            }
        }
        let mask = &self.mask;
        self.order.retain(|&i| mask[i as usize] != 0);
        removed
    }
}

fn dedup_path(mut p: Vec<u32>) -> Vec<u32> {
    p.dedup();
    p
}

/// Polyline length in cells.
fn path_length(path: &[u32], w: usize) -> f64 {
    path.windows(2)
        .map(|p| {
            let (a, b) = (p[0] as usize, p[1] as usize);
            let dx = (a % w) as f64 - (b % w) as f64;
            let dy = (a / w) as f64 - (b / w) as f64;
            (dx * dx + dy * dy).sqrt()
        })
        .sum()
}

struct RawNode {
    /// Representative cell (largest clearance in the cluster).
    rep: u32,
    /// All cells of the node (a junction cluster may have several).
    cells: Vec<u32>,
}

struct RawEdge {
    a: usize,
    b: usize,
    /// Cells from `rep(a)` to `rep(b)`.
    path: Vec<u32>,
}

struct RawGraph {
    nodes: Vec<RawNode>,
    edges: Vec<RawEdge>,
}

impl RawGraph {
    fn degrees(&self) -> Vec<u32> {
        let mut d = vec![0u32; self.nodes.len()];
        for e in &self.edges {
            d[e.a] += 1;
            d[e.b] += 1;
        }
        d
    }

    /// Joins the two edges of every node of degree 2 that is not the only
    /// node of a cycle (junction clusters that turned out to be a bend), and
    /// drops nodes without edges (isolated specks).
    fn dissolve_degree_two(&mut self) {
        let n = self.nodes.len();
        let mut alive_e = vec![true; self.edges.len()];
        let mut inc: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (k, e) in self.edges.iter().enumerate() {
            inc[e.a].push(k);
            inc[e.b].push(k);
        }
        let mut alive_n = vec![true; n];
        for v in 0..n {
            let list: Vec<usize> = inc[v].iter().copied().filter(|&k| alive_e[k]).collect();
            if list.len() != 2 || list[0] == list[1] {
                continue;
            }
            let (e1, e2) = (list[0], list[1]);
            // Orient e1 to end at v and e2 to start at v.
            let mut p1 = self.edges[e1].path.clone();
            let x = if self.edges[e1].b == v {
                self.edges[e1].a
            } else {
                p1.reverse();
                self.edges[e1].b
            };
            let mut p2 = self.edges[e2].path.clone();
            let y = if self.edges[e2].a == v {
                self.edges[e2].b
            } else {
                p2.reverse();
                self.edges[e2].a
            };
            p1.extend_from_slice(&p2[1..]);
            alive_e[e1] = false;
            alive_e[e2] = false;
            alive_n[v] = false;
            let k = self.edges.len();
            self.edges.push(RawEdge {
                a: x,
                b: y,
                path: dedup_path(p1),
            });
            alive_e.push(true);
            // For a cycle (x == y) both pushes go to the same list: the
            // edge counts twice there, as a self-loop should.
            for u in [x, y] {
                inc[u].retain(|&q| q != e1 && q != e2);
                inc[u].push(k);
            }
        }
        let mut remap = vec![usize::MAX; n];
        let mut nodes = Vec::new();
        for (v, node) in std::mem::take(&mut self.nodes).into_iter().enumerate() {
            let has_edge = inc[v].iter().any(|&k| alive_e[k]);
            if alive_n[v] && has_edge {
                remap[v] = nodes.len();
                nodes.push(node);
            }
        }
        let edges = std::mem::take(&mut self.edges)
            .into_iter()
            .zip(alive_e)
            .filter(|(_, alive)| *alive)
            .map(|(mut e, _)| {
                e.a = remap[e.a];
                e.b = remap[e.b];
                e
            })
            .collect();
        self.nodes = nodes;
        self.edges = edges;
    }

    fn into_graph(self, grid: &OccupancyGrid, dist: &DistanceField, sk: &Skeleton) -> GvdGraph {
        let w = sk.w;
        let deg = self.degrees();
        let res = grid.resolution;
        let xy = |i: u32| ((i as usize % w) as u32, (i as usize / w) as u32);
        let nodes = self
            .nodes
            .iter()
            .zip(&deg)
            .map(|(n, &d)| {
                let (cx, cy) = xy(n.rep);
                let [x, y] = grid.cell_center(cx, cy);
                GvdNode {
                    cx,
                    cy,
                    x,
                    y,
                    clearance: dist.clearance_m(n.rep as usize),
                    degree: d,
                }
            })
            .collect();
        let edges = self
            .edges
            .iter()
            .map(|e| GvdEdge {
                a: e.a as u32,
                b: e.b as u32,
                length_m: path_length(&e.path, w) * res,
                cells: e.path.iter().map(|&i| xy(i)).collect(),
            })
            .collect();
        let cells = sk.cells_by_index().into_iter().map(xy).collect();
        GvdGraph {
            width: grid.width,
            height: grid.height,
            nodes,
            edges,
            cells,
        }
    }
}

#[cfg(test)]
mod tests;
