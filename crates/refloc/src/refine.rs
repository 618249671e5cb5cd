//! Pose refinement against the map (an addition to the paper): Gauss-Newton
//! on the squared distance from each scan point to the nearest obstacle
//! surface, read from the database's distance map with bilinear
//! interpolation. Points farther than `refine_max_dist` from any surface are
//! left out (clutter, people, unmapped objects).

use crate::format::dist_cells;
use crate::{MapFrame, Pose2};

/// The quantized distance map.
#[derive(Clone, Copy)]
pub struct DistMap<'a> {
    /// Cells per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// One byte per cell: signed distance, see [`crate::format::dist_cells`].
    pub data: &'a [u8],
    /// Grid placement.
    pub frame: MapFrame,
    /// `(sin, cos)` of the grid's yaw, computed once: [`DistMap::sample`]
    /// runs for every point of every refinement step.
    rot: (f32, f32),
    /// `1 / resolution` (cells per metre), for the same reason.
    inv_res: f32,
}

impl<'a> DistMap<'a> {
    /// The distance map stored in `db`.
    pub fn of<D: AsRef<[u8]>>(db: &'a crate::RefDb<D>) -> DistMap<'a> {
        let (width, height) = db.grid_size();
        DistMap::new(width, height, db.dist(), db.frame())
    }

    /// A distance map of `width x height` cells, one byte each in `data`
    /// (row `cy = 0` first, see [`crate::format::dist_cells`]), placed by
    /// `frame`. Cells missing from a short `data` read as far from any
    /// surface.
    pub fn new(width: u32, height: u32, data: &'a [u8], frame: MapFrame) -> DistMap<'a> {
        DistMap {
            width,
            height,
            data,
            frame,
            rot: (
                libm::sinf(frame.origin.theta),
                libm::cosf(frame.origin.theta),
            ),
            inv_res: 1.0 / frame.resolution,
        }
    }

    /// [`MapFrame::to_cells`] with the cached rotation and a multiplication
    /// by the cached `1 / resolution` (the same to rounding).
    #[inline]
    fn cells_of(&self, p: [f32; 2]) -> [f32; 2] {
        let (s, c) = self.rot;
        let f = &self.frame;
        let (dx, dy) = (p[0] - f.origin.x, p[1] - f.origin.y);
        [
            (c * dx + s * dy) * self.inv_res,
            (-s * dx + c * dy) * self.inv_res,
        ]
    }

    /// A lower bound (cells) of the distance from any point of cell `(cx,
    /// cy)` to any obstacle cell, for [`crate::raycast::cast_dir_clear`]:
    /// the stored distance less [`CLEARANCE_MARGIN_CELLS`]. Outside the
    /// grid, 0.
    #[inline]
    pub fn clearance(&self, cx: u32, cy: u32) -> f32 {
        if cx >= self.width || cy >= self.height {
            return 0.0;
        }
        let i = cy as usize * self.width as usize + cx as usize;
        self.data
            .get(i)
            .map_or(0.0, |&v| dist_cells(v) - CLEARANCE_MARGIN_CELLS)
    }

    #[inline]
    fn at(&self, cx: i64, cy: i64) -> f32 {
        if cx < 0 || cy < 0 || cx >= self.width as i64 || cy >= self.height as i64 {
            return dist_cells(255);
        }
        let i = cy as usize * self.width as usize + cx as usize;
        dist_cells(self.data.get(i).copied().unwrap_or(255))
    }

    /// The distances (cells) at `(x0, y0)`, `(x0 + 1, y0)`, `(x0, y0 + 1)`
    /// and `(x0 + 1, y0 + 1)`: read directly when all four lie inside the
    /// grid (almost always), else cell by cell ([`DistMap::at`]).
    #[inline]
    fn corners(&self, x0: i64, y0: i64) -> [f32; 4] {
        let (w, h) = (self.width as i64, self.height as i64);
        if x0 >= 0 && y0 >= 0 && x0 + 1 < w && y0 + 1 < h {
            let i = y0 as usize * self.width as usize + x0 as usize;
            let j = i + self.width as usize;
            if let (Some(a), Some(b)) = (self.data.get(i..i + 2), self.data.get(j..j + 2)) {
                return [
                    dist_cells(a[0]),
                    dist_cells(a[1]),
                    dist_cells(b[0]),
                    dist_cells(b[1]),
                ];
            }
        }
        [
            self.at(x0, y0),
            self.at(x0 + 1, y0),
            self.at(x0, y0 + 1),
            self.at(x0 + 1, y0 + 1),
        ]
    }

    /// Distance (m) to the nearest surface at map point `p` and its gradient
    /// (dimensionless), by bilinear interpolation between cell centres.
    #[inline]
    pub fn sample(&self, p: [f32; 2]) -> Option<(f32, [f32; 2])> {
        let uv = self.cells_of(p);
        let (u, v) = (uv[0] - 0.5, uv[1] - 0.5);
        if !(u.is_finite() && v.is_finite())
            || u < -1.0
            || v < -1.0
            || u > self.width as f32
            || v > self.height as f32
        {
            return None;
        }
        let (x0, y0) = (floor_i64(u), floor_i64(v));
        let (fx, fy) = (u - x0 as f32, v - y0 as f32);
        let [d00, d10, d01, d11] = self.corners(x0, y0);
        let unit = self.frame.resolution;
        let d = (d00 * (1.0 - fx) * (1.0 - fy)
            + d10 * fx * (1.0 - fy)
            + d01 * (1.0 - fx) * fy
            + d11 * fx * fy)
            * unit;
        // Gradient in cell axes (cells per cell: dimensionless, as metres per
        // metre), then turned into the map frame.
        let gu = (d10 - d00) * (1.0 - fy) + (d11 - d01) * fy;
        let gv = (d01 - d00) * (1.0 - fx) + (d11 - d10) * fx;
        let (s, c) = self.rot;
        Some((d, [c * gu - s * gv, s * gu + c * gv]))
    }
}

/// What a cell's stored distance may exceed the distance from any point of
/// the cell to any obstacle cell by (cells). The stored value is the
/// distance between the cell's centre and the nearest obstacle cell's
/// centre less half a cell (`mapc`'s `dist_section`), rounded to 1/16 of a
/// cell; a point of the cell lies within `sqrt(2) / 2` of its centre, and
/// so does any point of the obstacle cell of its own: the gap is at least
/// `D + 0.5 - sqrt(2) - 1/16 = D - 0.977`. The distance transform counts
/// every beam-stopping cell (and the grid's border) as an obstacle, so this
/// bounds the distance to the cells a cast stops at.
pub const CLEARANCE_MARGIN_CELLS: f32 = 1.0;

/// `floor(x)` of a finite `x` (bounded by the map size here) as an integer,
/// exactly, without a libm call: truncate, then step down for negatives.
#[inline]
fn floor_i64(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) > x {
        t - 1
    } else {
        t
    }
}

/// Scale of the robust (Cauchy) weight, metres: a point this far from a
/// surface counts half as much as one on it.
const ROBUST_SCALE: f32 = 0.05;

/// The robust (Cauchy-weighted) Gauss-Newton normal equations of the
/// points' distances to the map's surfaces at `pose`.
/// `N` is 3 (x, y, theta) or 4 (and the skew, [`refine_skew`]).
#[derive(Clone, Copy)]
struct NormalEquations<const N: usize = 3> {
    /// `J^T W J`.
    h: [[f32; N]; N],
    /// `J^T W d`.
    g: [f32; N],
    /// Sum of the weights.
    wsum: f32,
    /// Weighted sum of the squared distances (m^2).
    wd2: f32,
    /// Points that carried weight (within `max_dist` of a surface).
    n: u32,
}

fn normal_equations(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: &Pose2,
    max_dist: f32,
) -> NormalEquations {
    points_pass::<false, 3>(dm, pts, pose, 0.0, max_dist).1
}

/// The robust cost of `pose`, the sum over points of `c^2/2 * ln(1 +
/// (d/c)^2)` with `d` capped at `max_dist` (a point off the map counts
/// `max_dist`), and the normal equations there, in one pass over the
/// points: the refinement needs both at every pose its line search accepts.
fn cost_and_normal_equations(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: &Pose2,
    max_dist: f32,
) -> (f32, NormalEquations) {
    points_pass::<true, 3>(dm, pts, pose, 0.0, max_dist)
}

/// The one pass over the points behind [`normal_equations`],
/// [`cost_and_normal_equations`] and [`refine_skew`]; the robust cost (a
/// logarithm per point) only when `COST`, else 0. With `N` = 4 point `k`
/// of `n` is first turned by `skew * sweep_fraction(k, n)` (to second
/// order) and the fourth unknown is the skew; with `N` = 3 `skew` is
/// ignored.
fn points_pass<const COST: bool, const N: usize>(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: &Pose2,
    skew: f32,
    max_dist: f32,
) -> (f32, NormalEquations<N>) {
    let (s, c) = (libm::sinf(pose.theta), libm::cosf(pose.theta));
    let c2 = ROBUST_SCALE * ROBUST_SCALE;
    // A point at `max_dist` or beyond (or off the map) costs this.
    let far_cost = if COST {
        0.5 * c2 * libm::logf(1.0 + max_dist * max_dist / c2)
    } else {
        0.0
    };
    let n = pts.len();
    let mut total = 0.0f32;
    // The points' logarithms are summed as one logarithm of their product
    // (`LogProduct`): one `logf` per pass rather than one per point, which
    // was 60% of a pass's cycles.
    let mut near_logs = LogProduct::new();
    let mut ne = NormalEquations {
        h: [[0.0; N]; N],
        g: [0.0; N],
        wsum: 0.0,
        wd2: 0.0,
        n: 0,
    };
    for (k, p) in pts.iter().enumerate() {
        if !p[0].is_finite() {
            continue;
        }
        let (p, f) = if N == 4 {
            let f = sweep_fraction(k, n);
            let phi = skew * f;
            let (cp, sp) = (1.0 - 0.5 * phi * phi, phi);
            ([cp * p[0] - sp * p[1], sp * p[0] + cp * p[1]], f)
        } else {
            (*p, 0.0)
        };
        let m = [pose.x + c * p[0] - s * p[1], pose.y + s * p[0] + c * p[1]];
        let near = match dm.sample(m) {
            Some((d, grad)) if d < max_dist => Some((d, grad)),
            _ => None,
        };
        let Some((d, grad)) = near else {
            // Off the map or farther than `max_dist`: the capped cost only.
            if COST {
                total += far_cost;
            }
            continue;
        };
        let q = d * d / c2;
        if COST {
            near_logs.push(1.0 + q);
        }
        let wgt = 1.0 / (1.0 + q);
        let dth = grad[0] * (-s * p[0] - c * p[1]) + grad[1] * (c * p[0] - s * p[1]);
        let mut j = [0.0f32; N];
        j[..3].copy_from_slice(&[grad[0], grad[1], dth]);
        if let Some(js) = j.get_mut(3) {
            *js = f * dth;
        }
        for a in 0..N {
            ne.g[a] += wgt * j[a] * d;
            for b in 0..N {
                ne.h[a][b] += wgt * j[a] * j[b];
            }
        }
        ne.wsum += wgt;
        ne.wd2 += wgt * d * d;
        ne.n += 1;
    }
    if COST {
        total += 0.5 * c2 * near_logs.ln();
    }
    (total, ne)
}

/// `ln` of a product of factors of at least 1, kept as a mantissa in
/// `[1, 2)` times a power of two so that it never overflows: the sum of
/// the factors' logarithms with one `logf` at the end. Each factor costs a
/// multiplication and a few integer operations on the bits; the rounding
/// is that of a product (about `n` half-ulps relative, like a sum of `n`
/// rounded logarithms).
struct LogProduct {
    mantissa: f32,
    exponent: i32,
    /// A factor made the product infinite (or NaN): its `ln` is infinite,
    /// as the sum of logarithms would be.
    overflow: bool,
}

impl LogProduct {
    fn new() -> LogProduct {
        LogProduct {
            mantissa: 1.0,
            exponent: 0,
            overflow: false,
        }
    }

    /// Multiplies in `f` (at least 1).
    #[inline]
    fn push(&mut self, f: f32) {
        let m = self.mantissa * f;
        let bits = m.to_bits();
        // m >= 1 is positive and normal: its exponent field less the bias
        // is floor(log2 m), and the fraction bits with a zero exponent
        // are m / 2^that. An all-ones field is an infinity or a NaN.
        let field = (bits >> 23) & 0xff;
        self.overflow |= field == 0xff;
        self.exponent += field as i32 - 127;
        self.mantissa = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    }

    /// `ln` of the product (0 for no factor). The power of two's part,
    /// `exponent ln 2`, reaches thousands for a dense scan far off the map;
    /// it and the sum are taken in f64 (two operations per pass) so that
    /// only the final rounding to f32 is added to the mantissa's.
    fn ln(&self) -> f32 {
        if self.overflow {
            return f32::INFINITY;
        }
        (self.exponent as f64 * core::f64::consts::LN_2 + libm::logf(self.mantissa) as f64) as f32
    }
}

/// The Gauss-Newton loop's convergence: a step whose absolute entries sum
/// to less than this (m and rad: a tenth of a millimetre, a tenth of a
/// milliradian, about 500 times below a 5 cm map cell) is not tried, and
/// the loop stops after one. Before 2026-12-06 the bound was 1e-5 and
/// checked only after the line search, so a converged fit spent five
/// more passes over the points halving a step that could not lower the
/// cost (docs/performance.md, "A converged refinement stops").
pub const STEP_TOL: f32 = 1e-4;

/// Solves `h x = g` for `N` unknowns; `None` when singular.
type Solver<const N: usize> = fn(&[[f32; N]; N], &[f32; N]) -> Option<[f32; N]>;

/// The Gauss-Newton loop of [`refine`] and [`refine_skew`] over `N`
/// unknowns: from `start`, `pass` gives the robust cost and the normal
/// equations of a state; each iteration (while at least `min_used` points
/// carry weight) solves the damped system, bounds the step (0.1 in x and
/// y, 0.05 in the others) and halves it up to four times until the cost
/// falls; it stops when no step lowers the cost or the step is below
/// [`STEP_TOL`] (such a step is not tried). `moved(state, step, scale)` is `state - scale * step`. Returns
/// the state and the points that carried weight at the last iteration's
/// start.
fn gauss_newton<S: Copy, const N: usize>(
    start: S,
    iters: u32,
    min_used: u32,
    solve: Solver<N>,
    moved: impl Fn(&S, &[f32; N], f32) -> S,
    pass: impl Fn(&S) -> (f32, NormalEquations<N>),
) -> (S, u32, NormalEquations<N>) {
    let mut state = start;
    let mut used = 0;
    let (mut current, mut ne) = pass(&state);
    for _ in 0..iters {
        let (mut h, g) = (ne.h, ne.g);
        used = ne.n;
        if used < min_used {
            break;
        }
        // Levenberg damping keeps the step sane on degenerate geometry (a corridor).
        for (a, row) in h.iter_mut().enumerate() {
            row[a] += 1e-3 * (1.0 + row[a]);
        }
        let Some(step) = solve(&h, &g) else { break };
        // Bound each step: refinement corrects small errors, it does not search.
        let m = step
            .iter()
            .enumerate()
            .map(|(a, v)| libm::fabsf(*v) * if a < 2 { 1.0 } else { 2.0 })
            .fold(0.0f32, f32::max);
        let mut scale = if m > 0.1 { 0.1 / m } else { 1.0 };
        let size = step.iter().map(|v| libm::fabsf(*v)).sum::<f32>();
        let mut accepted = false;
        // A step too small to matter is not tried: the state has converged.
        for _ in 0..5 {
            if scale * size < STEP_TOL {
                break;
            }
            let cand = moved(&state, &step, scale);
            let (next, next_ne) = pass(&cand);
            if next < current {
                state = cand;
                current = next;
                ne = next_ne;
                accepted = true;
                break;
            }
            scale *= 0.5;
        }
        if !accepted || scale * size < STEP_TOL {
            break;
        }
    }
    (state, used, ne)
}

/// Refines the sensor pose `pose` (map frame) so the sensor-frame points
/// `pts` (non-finite entries skipped) fall on the map's surfaces: iteratively
/// reweighted Gauss-Newton with Cauchy weights, a step accepted only when it
/// lowers the robust cost (else halved, up to four times). Points farther
/// than `max_dist` from any surface are ignored. Returns the refined pose and
/// the number of points that carried weight in the last step.
pub fn refine(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
) -> (Pose2, u32) {
    let (pose, used, _) = refine_fit(dm, pts, pose, iters, max_dist);
    (pose, used)
}

/// [`refine`], and the normal equations at the refined pose (those of
/// its last pass, the same as [`normal_equations`] there).
fn refine_fit(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
) -> (Pose2, u32, NormalEquations) {
    gauss_newton(
        pose,
        iters,
        3,
        solve3,
        |p, step, scale| stepped(p, step, scale),
        |p| cost_and_normal_equations(dm, pts, p, max_dist),
    )
}

/// [`refine`], and the [`position_spread`] of the refined pose from the
/// refinement's own last pass (no pass more).
pub fn refine_with_spread(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
    floor_m: f32,
) -> (Pose2, Option<f32>) {
    let (pose, _, ne) = refine_fit(dm, pts, pose, iters, max_dist);
    (pose, spread_of(&ne, floor_m))
}

/// `pose` less `scale` times the first three entries of `step` (x, y,
/// theta): a Gauss-Newton step of [`refine`] and [`refine_skew`].
fn stepped(pose: &Pose2, step: &[f32], scale: f32) -> Pose2 {
    Pose2::new(
        pose.x - scale * step[0],
        pose.y - scale * step[1],
        pose.theta - scale * step[2],
    )
}

/// Largest heading change (rad) over one sweep of the scanner that
/// [`refine_skew`] fits: 1.5 rad/s over a 0.1 s sweep (a 10 Hz spinning
/// lidar on a robot turning fast), beyond what a robot turns while it
/// localizes.
pub const SKEW_MAX: f32 = 0.15;

/// The time of beam `k` of `n` (counter-clockwise order) within the sweep,
/// as a fraction from -0.5 (first) to 0.5 (last), 0 with a single beam.
#[inline]
pub fn sweep_fraction(k: usize, n: usize) -> f32 {
    if n < 2 {
        0.0
    } else {
        k as f32 / (n - 1) as f32 - 0.5
    }
}

/// [`refine`] with a fourth unknown, the scan's *skew* (rad): the heading
/// change over the sweep of a scanner that turns while it scans, so that
/// point `k` of `n` is rotated by `skew * sweep_fraction(k, n)` about the
/// sensor before the pose applies (`pose` is the sensor pose at the middle
/// of the sweep). The rotation is taken to second order (below 0.1 mm at
/// 10 m for [`SKEW_MAX`]). Starts at `pose` with no skew; the skew stays
/// within +-[`SKEW_MAX`]. Returns the refined pose and skew.
pub fn refine_skew(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
) -> (Pose2, f32) {
    gauss_newton(
        (pose, 0.0f32),
        iters,
        4,
        solve4,
        |(p, skew), step, scale| {
            (
                stepped(p, step, scale),
                (skew - scale * step[3]).clamp(-SKEW_MAX, SKEW_MAX),
            )
        },
        |(p, skew)| points_pass::<true, 4>(dm, pts, p, *skew, max_dist),
    )
    .0
}

/// Offsets (m) along a fit's weakest direction that [`slide`] tries: up
/// to 0.9 m each way, under the 1 m that makes two poses distinct
/// hypotheses ([`crate::select::DISTINCT_DISTANCE`]), so a slid answer
/// stays the hypothesis whose confidence was computed.
pub const SLIDE_OFFSETS: [f32; 8] = [-0.9, -0.6, -0.4, -0.2, 0.2, 0.4, 0.6, 0.9];

/// Unit vector (map frame) of the position direction the normal
/// equations pin least: the eigenvector of the smallest eigenvalue of the
/// x-y block of `J^T W J` (a corridor's axis). `None` when it is not
/// defined (no points, or not finite).
fn weak_direction(ne: &NormalEquations) -> Option<[f32; 2]> {
    let (a, b, d) = (ne.h[0][0], ne.h[0][1], ne.h[1][1]);
    let (low, _) = sym2_eigenvalues(a, b, d);
    // (h - low I) v = 0 has the solutions (b, low - a) and (low - d, b);
    // the longer of the two is the better conditioned.
    let (v1, v2) = ([b, low - a], [low - d, b]);
    let v = if v1[0] * v1[0] + v1[1] * v1[1] >= v2[0] * v2[0] + v2[1] * v2[1] {
        v1
    } else {
        v2
    };
    let n = libm::sqrtf(v[0] * v[0] + v[1] * v[1]);
    (n > 1e-9 && n.is_finite()).then(|| [v[0] / n, v[1] / n])
}

/// Slides a fitted sensor pose (map frame) along its fit's weakest
/// direction (the position direction the fit pins least: a corridor's
/// axis): the robust cost ([`refine`]'s) at each of [`SLIDE_OFFSETS`],
/// then [`refine`] from the lowest when it is below the pose's own.
/// Returns the refined pose when its cost is lower than `pose`'s, else
/// `None`. A refinement from the matched pose stops in the
/// nearest minimum of its cost, and along a corridor the nearest can be
/// tens of centimetres from the deepest: the door frames and ends that
/// place the scan along it pull only from close by.
pub fn slide(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
) -> Option<Pose2> {
    let (c0, ne) = cost_and_normal_equations(dm, pts, &pose, max_dist);
    let dir = weak_direction(&ne)?;
    let at = |t: f32| Pose2::new(pose.x + t * dir[0], pose.y + t * dir[1], pose.theta);
    let mut best = (c0, 0.0f32);
    for &t in SLIDE_OFFSETS.iter() {
        let c = cost_and_normal_equations(dm, pts, &at(t), max_dist).0;
        if c < best.0 {
            best = (c, t);
        }
    }
    if best.1 == 0.0 {
        return None;
    }
    let (p1, _, _) = refine_fit(dm, pts, at(best.1), iters, max_dist);
    let c1 = cost_and_normal_equations(dm, pts, &p1, max_dist).0;
    (c1 < c0).then_some(p1)
}

/// How far (m) [`corridor_search`] looks each way along a fit's weakest
/// direction: most of a long corridor as a 180-degree scan sees it.
pub const CORRIDOR_REACH: f32 = 6.0;
/// The step (m) of [`corridor_search`]'s grid along the weakest direction.
pub const CORRIDOR_STEP: f32 = 0.2;
/// How far (m) the turned pose of [`corridor_search`] looks each way
/// across the weakest direction: a pose turned end for end sits mirrored
/// about the corridor's middle, up to a corridor's width away.
pub const CORRIDOR_ACROSS: f32 = 1.5;
/// The step (m) of the turned pose's grid across the weakest direction.
pub const CORRIDOR_ACROSS_STEP: f32 = 0.3;
/// [`corridor_search`] scores its grid on every this many points.
pub const CORRIDOR_STRIDE: usize = 4;
/// A grid pose's score in [`corridor_search`]: [`refine`]'s robust cost
/// of every [`CORRIDOR_STRIDE`]th point, each distance capped at
/// `max_dist` (m; a point off the map counts the cap). Lower is better.
fn grid_score(dm: &DistMap<'_>, pts: &[[f32; 2]], pose: &Pose2, max_dist: f32) -> f32 {
    let (s, c) = (libm::sinf(pose.theta), libm::cosf(pose.theta));
    let c2 = ROBUST_SCALE * ROBUST_SCALE;
    let mut far = 0u32;
    let mut logs = LogProduct::new();
    for p in pts.iter().step_by(CORRIDOR_STRIDE) {
        if !p[0].is_finite() {
            continue;
        }
        let m = [pose.x + c * p[0] - s * p[1], pose.y + s * p[0] + c * p[1]];
        match dm.sample(m) {
            Some((d, _)) if d < max_dist => logs.push(1.0 + d * d / c2),
            _ => far += 1,
        }
    }
    0.5 * c2 * (logs.ln() + far as f32 * libm::logf(1.0 + max_dist * max_dist / c2))
}

/// Two poses near a fitted sensor pose (map frame) that a scan matched
/// along a corridor may have missed, each refined ([`refine`]) from the
/// two best poses of its grid and kept only when its robust cost is below
/// the pose's own: the best of a grid
/// along the fit's weakest direction (a corridor's axis;
/// [`CORRIDOR_REACH`] each way in steps of [`CORRIDOR_STEP`]) with the
/// same heading; and with the heading turned end for end, first the best
/// offset across that direction ([`CORRIDOR_ACROSS`] each way, a turned
/// pose sits mirrored about the corridor's middle), then the best along
/// it. A corridor's walls fit anywhere along it, and a scan matcher that
/// pairs points by their neighbourhoods pairs a wall with itself shifted
/// or turned: where people hide the door frames and ends that place a
/// scan along it, the match lands metres off or backwards, beyond any
/// refinement's reach (docs/results.md, "A corridor search in a
/// crowd").
pub fn corridor_search(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
) -> [Option<Pose2>; 2] {
    let (c0, ne) = cost_and_normal_equations(dm, pts, &pose, max_dist);
    let Some(dir) = weak_direction(&ne) else {
        return [None, None];
    };
    let across_dir = [-dir[1], dir[0]];
    let at = |p: &Pose2, ta: f32, tb: f32| {
        Pose2::new(
            p.x + ta * dir[0] + tb * across_dir[0],
            p.y + ta * dir[1] + tb * across_dir[1],
            p.theta,
        )
    };
    // The two grid poses of lowest score, best first: a grid pose half a
    // step from the right one can score worse than one a feature's width
    // off that fits half the features, so both are refined.
    let best_two = |start: &Pose2, n: i32, step: f32, along: bool| {
        let mut best = [(f32::INFINITY, *start); 2];
        for k in -n..=n {
            let t = k as f32 * step;
            let p = if along {
                at(start, t, 0.0)
            } else {
                at(start, 0.0, t)
            };
            let score = grid_score(dm, pts, &p, max_dist);
            if score < best[0].0 {
                best = [(score, p), best[0]];
            } else if score < best[1].0 {
                best[1] = (score, p);
            }
        }
        [best[0].1, best[1].1]
    };
    let along = (CORRIDOR_REACH / CORRIDOR_STEP) as i32;
    let across = (CORRIDOR_ACROSS / CORRIDOR_ACROSS_STEP) as i32;
    let straight = best_two(&pose, along, CORRIDOR_STEP, true);
    let turned = Pose2::new(
        pose.x,
        pose.y,
        crate::frame::wrap_angle(pose.theta + core::f32::consts::PI),
    );
    let [turned, _] = best_two(&turned, across, CORRIDOR_ACROSS_STEP, false);
    let turned = best_two(&turned, along, CORRIDOR_STEP, true);
    [straight, turned].map(|starts| {
        let mut best: Option<(f32, Pose2)> = None;
        for start in starts {
            let (p1, _, _) = refine_fit(dm, pts, start, iters, max_dist);
            let c1 = cost_and_normal_equations(dm, pts, &p1, max_dist).0;
            if c1 < c0 && best.is_none_or(|b| c1 < b.0) {
                best = Some((c1, p1));
            }
        }
        best.map(|b| b.1)
    })
}

/// The robust cost ([`refine`]'s) of the points at `pose` with no skew,
/// then [`refine_skew`] from there and the cost at its result: (skewed
/// pose, skew (rad), rigid cost, skewed cost). The ratio of the two costs
/// says how much of what the rigid fit leaves the scanner's turn explains.
pub fn skew_fit(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
) -> (Pose2, f32, f32, f32) {
    let rigid = points_pass::<true, 4>(dm, pts, &pose, 0.0, max_dist).0;
    let (fitted, skew) = refine_skew(dm, pts, pose, iters, max_dist);
    let cost = points_pass::<true, 4>(dm, pts, &fitted, skew, max_dist).0;
    (fitted, skew, rigid, cost)
}

/// Rotates point `k` of `pts` by `skew * sweep_fraction(k, n)` (exactly),
/// in place: the scan as a scanner that did not turn would have seen it.
pub fn deskew(pts: &mut [[f32; 2]], skew: f32) {
    let n = pts.len();
    for (k, p) in pts.iter_mut().enumerate() {
        let phi = skew * sweep_fraction(k, n);
        let (s, c) = (libm::sinf(phi), libm::cosf(phi));
        *p = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
    }
}

/// Solves the 4x4 system `h x = g` (Gaussian elimination with partial
/// pivoting); `None` when singular.
fn solve4(h: &[[f32; 4]; 4], g: &[f32; 4]) -> Option<[f32; 4]> {
    let mut m = [[0.0f32; 5]; 4];
    for r in 0..4 {
        m[r][..4].copy_from_slice(&h[r]);
        m[r][4] = g[r];
    }
    for col in 0..4 {
        let piv =
            (col..4).max_by(|&a, &b| libm::fabsf(m[a][col]).total_cmp(&libm::fabsf(m[b][col])))?;
        if !(libm::fabsf(m[piv][col]) > 1e-12) {
            return None;
        }
        m.swap(col, piv);
        let pivot = m[col];
        for row in m.iter_mut().skip(col + 1) {
            let f = row[col] / pivot[col];
            for (v, p) in row.iter_mut().zip(&pivot).skip(col) {
                *v -= f * p;
            }
        }
    }
    let mut x = [0.0f32; 4];
    for r in (0..4).rev() {
        let known: f32 = m[r][r + 1..4]
            .iter()
            .zip(&x[r + 1..])
            .map(|(a, b)| a * b)
            .sum();
        x[r] = (m[r][4] - known) / m[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Covariance (row-major 3x3, x and y in m, theta in rad) of a sensor pose
/// fitted to the points `pts` by [`refine`]: `s^2 (J^T W J)^-1` at `pose`,
/// with the Cauchy weights `W` of the fit, and `s^2` the weighted mean
/// squared distance of the points to the map's surfaces, floored at the
/// distance map's quantization (`floor_m`, m, as a standard deviation).
/// This is the local curvature of the fit (how well the geometry pins the
/// pose: large along a featureless corridor), not the chance of a wrong
/// place, which [`crate::confidence`] gives. `None` with fewer than 4
/// points carrying weight or degenerate geometry.
pub fn covariance(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: &Pose2,
    max_dist: f32,
    floor_m: f32,
) -> Option<[f32; 9]> {
    covariance_of(&normal_equations(dm, pts, pose, max_dist), floor_m)
}

/// [`covariance`] from the normal equations at the pose.
fn covariance_of(ne: &NormalEquations, floor_m: f32) -> Option<[f32; 9]> {
    let NormalEquations {
        h, wsum, wd2, n, ..
    } = *ne;
    if n < 4 || !(wsum > 0.0) {
        return None;
    }
    let var = (wd2 / wsum).max(floor_m * floor_m) * n as f32 / (n - 3) as f32;
    let mut out = [0.0f32; 9];
    for k in 0..3 {
        let mut e = [0.0f32; 3];
        e[k] = 1.0;
        let col = solve3(&h, &e)?;
        for r in 0..3 {
            out[r * 3 + k] = var * col[r];
        }
    }
    // Symmetric by construction up to rounding; make it exactly so.
    for (a, b) in [(1, 3), (2, 6), (5, 7)] {
        let m = 0.5 * (out[a] + out[b]);
        out[a] = m;
        out[b] = m;
    }
    if out.iter().all(|v| v.is_finite()) && out[0] > 0.0 && out[4] > 0.0 && out[8] > 0.0 {
        Some(out)
    } else {
        None
    }
}

/// How loosely the scan pins the position of a fitted sensor pose: the
/// standard deviation (m) along the worst direction of the position part
/// of [`covariance`], scaled to one point (times the square root of the
/// points that carried weight), so that it does not depend on the beam
/// count. Small where walls all round pin the pose and the points lie on
/// them; large along a featureless corridor, where the fit cannot tell how
/// far along it is, or where the points lie off the surfaces. `None` when
/// [`covariance`] is.
pub fn position_spread(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: &Pose2,
    max_dist: f32,
    floor_m: f32,
) -> Option<f32> {
    spread_of(&normal_equations(dm, pts, pose, max_dist), floor_m)
}

/// [`position_spread`] from the normal equations at the pose.
fn spread_of(ne: &NormalEquations, floor_m: f32) -> Option<f32> {
    let c = covariance_of(ne, floor_m)?;
    // Largest eigenvalue of the position block.
    let (_, top) = sym2_eigenvalues(c[0], c[1], c[4]);
    let spread = libm::sqrtf(top * ne.n as f32);
    spread.is_finite().then_some(spread)
}

/// The eigenvalues (smallest, largest) of the symmetric 2x2 matrix
/// `[[a, b], [b, d]]`.
fn sym2_eigenvalues(a: f32, b: f32, d: f32) -> (f32, f32) {
    let half = 0.5 * (a - d);
    let (mid, r) = (0.5 * (a + d), libm::sqrtf(half * half + b * b));
    (mid - r, mid + r)
}

/// Solves the 3x3 system `h x = g` (Cramer's rule); `None` when singular.
fn solve3(h: &[[f32; 3]; 3], g: &[f32; 3]) -> Option<[f32; 3]> {
    let det = |m: &[[f32; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(h);
    if !(libm::fabsf(d) > 1e-12) {
        return None;
    }
    let mut out = [0.0f32; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut m = *h;
        for r in 0..3 {
            m[r][k] = g[r];
        }
        *o = det(&m) / d;
    }
    if out.iter().all(|v| v.is_finite()) {
        Some(out)
    } else {
        None
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::{floor_i64, position_spread, DistMap};
    use crate::format::dist_encode;
    use crate::{MapFrame, Pose2};

    /// The frame of the test grids: 0.05 m cells, origin at (0, 0).
    fn frame_05() -> MapFrame {
        MapFrame {
            resolution: 0.05,
            origin: Pose2::new(0.0, 0.0, 0.0),
        }
    }

    /// A 60 x 60 grid at 0.05 m whose border cells are walls on the sides
    /// `walls` names (left, right, bottom, top), as the compiler encodes it:
    /// the distance between cell centres less half a cell.
    fn boxed(walls: [bool; 4]) -> Vec<u8> {
        let n = 60i32;
        let mut out = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let wall = (walls[0] && x == 0)
                    || (walls[1] && x == n - 1)
                    || (walls[2] && y == 0)
                    || (walls[3] && y == n - 1);
                let mut d = f32::INFINITY;
                for (on, v) in [
                    (walls[0], x),
                    (walls[1], n - 1 - x),
                    (walls[2], y),
                    (walls[3], n - 1 - y),
                ] {
                    if on {
                        d = d.min(v as f32);
                    }
                }
                out.push(dist_encode(if wall { -0.5 } else { d - 0.5 }));
            }
        }
        out
    }

    #[test]
    fn walls_all_round_pin_the_position_and_a_corridor_does_not() {
        let frame = frame_05();
        fn dm(data: &[u8], frame: MapFrame) -> DistMap<'_> {
            DistMap::new(60, 60, data, frame)
        }
        // Points on the inner faces of all four walls (sensor at the centre).
        let mut pts = Vec::new();
        for k in 0..40 {
            let t = -1.0 + k as f32 * 0.05;
            pts.extend([[-1.45, t], [1.45, t], [t, -1.45], [t, 1.45]]);
        }
        let centre = Pose2::new(1.5, 1.5, 0.0);
        let room = boxed([true; 4]);
        let r = position_spread(&dm(&room, frame), &pts, &centre, 0.3, 0.0144).unwrap();
        assert!(r < 0.1, "{r}");
        // The same points along a corridor open at both ends: only the
        // side walls' points count, and they say nothing along it.
        let corridor = boxed([false, false, true, true]);
        let side: Vec<[f32; 2]> = pts.iter().copied().filter(|p| p[1].abs() > 1.4).collect();
        let c = position_spread(&dm(&corridor, frame), &side, &centre, 0.3, 0.0144);
        assert!(c.is_none_or(|c| c > 10.0 * r), "{c:?} vs {r}");
    }

    /// A `w` x `h` grid whose cells `wall` says are walls, encoded as the
    /// compiler does: the distance between cell centres to the nearest wall
    /// cell, less half a cell.
    pub(crate) fn encode_walls(w: i32, h: i32, wall: impl Fn(i32, i32) -> bool) -> Vec<u8> {
        let cells: Vec<(i32, i32)> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| wall(x, y))
            .collect();
        let mut out = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let d = cells
                    .iter()
                    .map(|&(a, b)| (((a - x) * (a - x) + (b - y) * (b - y)) as f32).sqrt())
                    .fold(f32::INFINITY, f32::min);
                out.push(dist_encode(if wall(x, y) { -0.5 } else { d - 0.5 }));
            }
        }
        out
    }

    /// A corridor 5 m long and 2 m wide at 0.05 m (100 x 40 cells), open
    /// at both ends, with two pillars of 0.1 x 0.2 m standing on its walls
    /// at x = 2.0 m (top) and x = 3.5 m (bottom): the only things that
    /// place a scan along it. Encoded as the compiler does (the distance
    /// between cell centres less half a cell, to the nearest wall cell).
    fn corridor_with_pillars() -> Vec<u8> {
        let (w, h) = (100i32, 40i32);
        let wall = |x: i32, y: i32| {
            y == 0
                || y == h - 1
                || ((40..=41).contains(&x) && y >= 35)
                || ((70..=71).contains(&x) && y <= 4)
        };
        encode_walls(w, h, wall)
    }

    #[test]
    fn a_pose_off_along_a_corridor_slides_to_the_pillars_that_place_it() {
        let frame = frame_05();
        let data = corridor_with_pillars();
        let dm = DistMap::new(100, 40, &data, frame);
        // The scan from (2.5, 1.0), heading 0: the walls' inner faces
        // (y = 0.05 and 1.95) where no pillar stands, and the pillars'
        // faces, in the sensor frame.
        let truth = Pose2::new(2.5, 1.0, 0.0);
        let mut map_pts = Vec::new();
        for k in 0..41 {
            let x = 0.5 + 0.1 * k as f32;
            if !(1.95..=2.15).contains(&x) {
                map_pts.push([x, 1.95]);
            }
            if !(3.45..=3.65).contains(&x) {
                map_pts.push([x, 0.05]);
            }
        }
        for k in 0..5 {
            let t = 0.05 * k as f32;
            map_pts.extend([
                [2.0, 1.75 + t],
                [2.1, 1.75 + t],
                [3.5, 0.05 + t],
                [3.6, 0.05 + t],
            ]);
        }
        map_pts.extend([[2.05, 1.75], [3.55, 0.25]]);
        let pts: Vec<[f32; 2]> = map_pts
            .iter()
            .map(|p| [p[0] - truth.x, p[1] - truth.y])
            .collect();
        // Matched 0.5 m along the corridor: the pillars' points lie over
        // 0.3 m from any surface, so the refinement alone stays there.
        let off = Pose2::new(3.0, 1.02, 0.01);
        let refined = super::refine(&dm, &pts, off, 10, 0.3).0;
        assert!((refined.x - truth.x).abs() > 0.4, "{refined:?}");
        let slid =
            super::slide(&dm, &pts, refined, 10, 0.3).expect("a better fit along the corridor");
        assert!(
            (slid.x - truth.x).abs() < 0.03
                && (slid.y - truth.y).abs() < 0.03
                && slid.theta.abs() < 0.01,
            "{slid:?}"
        );
        // At the right pose there is nothing better to slide to.
        let right = super::refine(&dm, &pts, truth, 10, 0.3).0;
        assert!(
            super::slide(&dm, &pts, right, 10, 0.3).is_none_or(|p| (p.x - right.x).abs() < 0.02)
        );
    }

    /// A corridor 12 m long and 2 m wide at 0.05 m (240 x 40 cells), open
    /// at both ends, with pillars of 0.3 x 0.2 m on its walls at x = 4.0 m
    /// (top), 5.5 m (bottom) and 8.0 m (top), none of them mirrored by
    /// another: the scan below fits one place along it, one way round.
    /// Encoded as the compiler does.
    fn long_corridor() -> Vec<u8> {
        let (w, h) = (240i32, 40i32);
        let pillar = |x: i32, at: i32| (at..=at + 5).contains(&x);
        let wall = |x: i32, y: i32| {
            y == 0
                || y == h - 1
                || ((pillar(x, 80) || pillar(x, 160)) && y >= 35)
                || (pillar(x, 110) && y <= 4)
        };
        encode_walls(w, h, wall)
    }

    #[test]
    fn a_match_metres_along_a_corridor_or_turned_end_for_end_is_found_again() {
        let data = long_corridor();
        let dm = DistMap::new(240, 40, &data, frame_05());
        // The scan from (6.0, 0.7), heading 0.3 rad: the walls' inner faces
        // (y = 0.05 and 1.95) from x = 2 to 10 m where no pillar stands,
        // and the pillars' faces, in the sensor frame.
        let truth = Pose2::new(6.0, 0.7, 0.3);
        let mut map_pts = Vec::new();
        let in_pillar = |x: f32, at: f32| (at - 0.05..=at + 0.35).contains(&x);
        for k in 0..81 {
            let x = 2.0 + 0.1 * k as f32;
            if !(in_pillar(x, 4.0) || in_pillar(x, 8.0)) {
                map_pts.push([x, 1.95]);
            }
            if !in_pillar(x, 5.5) {
                map_pts.push([x, 0.05]);
            }
        }
        for k in 0..5 {
            let t = 0.05 * k as f32;
            for at in [4.0f32, 8.0] {
                map_pts.extend([[at, 1.75 + t], [at + 0.3, 1.75 + t]]);
            }
            map_pts.extend([[5.5, 0.05 + t], [5.8, 0.05 + t]]);
        }
        let inv = truth.inverse();
        let pts: Vec<[f32; 2]> = map_pts.iter().map(|p| inv.apply(*p)).collect();
        let near = |p: &Pose2| {
            (p.x - truth.x).abs() < 0.03
                && (p.y - truth.y).abs() < 0.03
                && crate::wrap_angle(p.theta - truth.theta).abs() < 0.01
        };
        // Matched 2.6 m along the corridor: the refinement stays there.
        let along = super::refine(&dm, &pts, Pose2::new(8.6, 0.72, 0.31), 10, 0.3).0;
        assert!((along.x - truth.x).abs() > 2.0, "{along:?}");
        let [straight, _] = super::corridor_search(&dm, &pts, along, 10, 0.3);
        assert!(straight.is_some_and(|p| near(&p)), "{straight:?}");
        // Turned end for end, mirrored about the corridor's middle (y =
        // 1.0 m) and 1.5 m along: the same walls fit, the pillars do not.
        let turned = Pose2::new(4.5, 1.3, 0.3 + core::f32::consts::PI);
        let turned = super::refine(&dm, &pts, turned, 10, 0.3).0;
        let [_, back] = super::corridor_search(&dm, &pts, turned, 10, 0.3);
        assert!(back.is_some_and(|p| near(&p)), "{back:?}");
        // At the right pose there is nothing better elsewhere to find.
        let right = super::refine(&dm, &pts, truth, 10, 0.3).0;
        let found = super::corridor_search(&dm, &pts, right, 10, 0.3);
        assert!(found.iter().flatten().all(near), "{found:?}");
    }

    /// An 80 x 80 grid at 0.05 m with walls five cells thick all round:
    /// a room of 3.5 m whose inner faces are 1.75 m from the centre
    /// (2.0, 2.0), encoded as the compiler does (the distance between cell
    /// centres less half a cell).
    fn thick_room() -> Vec<u8> {
        let (n, t) = (80i32, 5i32);
        let mut out = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let inside = [x - (t - 1), (n - t) - x, y - (t - 1), (n - t) - y];
                let d = *inside.iter().min().unwrap();
                out.push(dist_encode(d as f32 - 0.5));
            }
        }
        out
    }

    /// A scan from the centre of [`thick_room`], beam `k` of `n` at angle
    /// `-pi + 2 pi k / n`, taken by a scanner that turned by `skew` (rad)
    /// over its sweep: beam `k` really pointed `skew * sweep_fraction(k, n)`
    /// further, and its range is recorded at the nominal angle.
    fn room_scan(n: usize, skew: f32) -> Vec<[f32; 2]> {
        (0..n)
            .map(|k| {
                let a = -core::f32::consts::PI + core::f32::consts::TAU * k as f32 / n as f32;
                let real = a + skew * super::sweep_fraction(k, n);
                let r = 1.75 / libm::fabsf(libm::cosf(real)).max(libm::fabsf(libm::sinf(real)));
                [r * libm::cosf(a), r * libm::sinf(a)]
            })
            .collect()
    }

    #[test]
    fn the_skew_of_a_turning_scanner_is_fitted_and_a_still_one_has_none() {
        let frame = frame_05();
        let room = thick_room();
        let dm = DistMap::new(80, 80, &room, frame);
        let centre = Pose2::new(2.0, 2.0, 0.0);
        let start = Pose2::new(2.03, 1.98, 0.02);
        let cost = |q: &[[f32; 2]], at: &Pose2| super::cost_and_normal_equations(&dm, q, at, 0.3).0;
        for skew in [0.0f32, 0.06, -0.1] {
            let pts = room_scan(360, skew);
            let (pose, fitted) = super::refine_skew(&dm, &pts, start, 20, 0.3);
            assert!((fitted - skew).abs() < 0.01, "skew {skew}: fitted {fitted}");
            let err = (pose.x - centre.x).hypot(pose.y - centre.y);
            assert!(err < 0.01, "skew {skew}: {pose:?}");
            assert!(
                (pose.theta - centre.theta).abs() < 0.01,
                "skew {skew}: {pose:?}"
            );
            // The rigid refinement cannot take the turn out of the scan.
            if skew != 0.0 {
                let (rigid, _) = super::refine(&dm, &pts, start, 20, 0.3);
                let mut fixed = pts.clone();
                super::deskew(&mut fixed, fitted);
                assert!(
                    cost(&fixed, &pose) < 0.5 * cost(&pts, &rigid),
                    "skew {skew}"
                );
            }
        }
        // The fitted skew stays within its bound.
        let (_, far) = super::refine_skew(&dm, &room_scan(360, 0.4), start, 30, 0.3);
        assert!(far.abs() <= super::SKEW_MAX, "{far}");
    }

    #[test]
    fn solve4_solves_and_refuses_singular_systems() {
        let h = [
            [4.0, 1.0, 0.5, 0.2],
            [1.0, 3.0, 0.3, 0.1],
            [0.5, 0.3, 2.0, 0.4],
            [0.2, 0.1, 0.4, 1.0],
        ];
        let want = [1.0f32, -2.0, 0.5, 3.0];
        let g: Vec<f32> = h
            .iter()
            .map(|r| r.iter().zip(&want).map(|(a, b)| a * b).sum())
            .collect();
        let x = super::solve4(&h, &[g[0], g[1], g[2], g[3]]).unwrap();
        for (a, b) in x.iter().zip(&want) {
            assert!((a - b).abs() < 1e-5, "{x:?}");
        }
        // A zero first column needs the pivot from another row.
        let p = [
            [0.0, 1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        assert_eq!(
            super::solve4(&p, &[2.0, 3.0, 4.0, 5.0]),
            Some([3.0, 2.0, 4.0, 5.0])
        );
        let singular = [
            [1.0, 2.0, 0.0, 0.0],
            [2.0, 4.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        assert_eq!(super::solve4(&singular, &[1.0; 4]), None);
    }

    #[test]
    fn log_product_is_the_sum_of_logarithms() {
        use super::LogProduct;
        let mut seed = 3u32;
        for n in [0usize, 1, 7, 180, 1081] {
            let mut lp = LogProduct::new();
            let mut sum = 0.0f64;
            for _ in 0..n {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                // Factors of 1 + q, q up to 36 (a point 0.3 m off at the
                // robust scale 0.05 m), a few of them exactly 1.
                let f = 1.0 + (seed >> 8) as f32 / (1u32 << 24) as f32 * 36.0;
                let f = if seed % 17 == 0 { 1.0 } else { f };
                lp.push(f);
                sum += libm::log(f as f64);
            }
            let got = lp.ln() as f64;
            assert!(
                (got - sum).abs() <= 1e-6 * sum.max(1.0),
                "{n}: {got} vs {sum}"
            );
        }
        // Huge factors do not overflow the product; an infinite one makes
        // it infinite.
        let mut lp = LogProduct::new();
        for _ in 0..100 {
            lp.push(1e30);
        }
        assert!((lp.ln() - 100.0 * 1e30f32.ln()).abs() < 1e-2 * 100.0 * 1e30f32.ln());
        lp.push(f32::INFINITY);
        assert_eq!(lp.ln(), f32::INFINITY);
    }

    #[test]
    fn floor_matches_libm() {
        let mut xs: Vec<f32> = (-300_000..300_000).map(|i| i as f32 * 1e-5).collect();
        // Both neighbours of every integer from -4 to 4 (and of large ones).
        for k in [
            -4.0f32,
            -3.0,
            -2.0,
            -1.0,
            1.0,
            2.0,
            3.0,
            4.0,
            8_388_607.0,
            16_777_215.0,
        ] {
            let b = k.to_bits();
            xs.extend([k, f32::from_bits(b - 1), f32::from_bits(b + 1)]);
        }
        xs.extend([-0.0, 0.0, 1e-38, -1e-38, 3.0e7, -3.0e7]);
        for x in xs {
            assert_eq!(floor_i64(x), libm::floorf(x) as i64, "{x}");
        }
    }
}
