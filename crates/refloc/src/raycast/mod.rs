//! Exact grid traversal ray casting (Amanatides & Woo), shared by the compiler
//! (reference scans, coverage) and the runtime (verification).
//!
//! Coordinates here are *cell units*: the grid's lower-left corner is (0, 0),
//! cell `(cx, cy)` covers `[cx, cx + 1) x [cy, cy + 1)`, `cy = 0` is the bottom
//! row (the last row of a ROS map image). Converting from the map frame is the
//! job of [`crate::MapFrame`].

/// Anything that can say whether a grid cell stops a laser beam.
pub trait Occupancy {
    /// Grid width in cells.
    fn width(&self) -> u32;
    /// Grid height in cells.
    fn height(&self) -> u32;
    /// True when cell `(cx, cy)` stops a beam. Only called with in-range indices.
    fn blocked(&self, cx: u32, cy: u32) -> bool;
}

/// A packed occupancy bit grid: bit `cy * width + cx` of the little-endian
/// `u32` words is 1 when the cell stops a beam (bit 0 of word 0 first).
#[derive(Clone, Copy, Debug)]
pub struct BitGrid<'a> {
    width: u32,
    height: u32,
    words: &'a [u32],
}

impl<'a> BitGrid<'a> {
    /// Number of `u32` words needed to hold `width * height` bits.
    pub const fn words_for(width: u32, height: u32) -> usize {
        ((width as usize) * (height as usize)).div_ceil(32)
    }

    /// Wraps `words`; `None` when `words` is shorter than
    /// [`BitGrid::words_for`]`(width, height)`.
    pub fn new(width: u32, height: u32, words: &'a [u32]) -> Option<Self> {
        if words.len() < Self::words_for(width, height) {
            return None;
        }
        Some(BitGrid {
            width,
            height,
            words,
        })
    }

    /// A 0 x 0 grid (every ray is a "no return").
    pub const fn empty() -> BitGrid<'static> {
        BitGrid {
            width: 0,
            height: 0,
            words: &[],
        }
    }

    /// The packed words.
    pub fn words(&self) -> &'a [u32] {
        self.words
    }
}

impl Occupancy for BitGrid<'_> {
    #[inline]
    fn width(&self) -> u32 {
        self.width
    }
    #[inline]
    fn height(&self) -> u32 {
        self.height
    }
    #[inline]
    fn blocked(&self, cx: u32, cy: u32) -> bool {
        let bit = cy as usize * self.width as usize + cx as usize;
        match self.words.get(bit / 32) {
            Some(w) => (w >> (bit % 32)) & 1 == 1,
            None => true,
        }
    }
}

/// Casts one ray from `(u, v)` (cell units) along `angle` (radians, counter-
/// clockwise from the grid's +x axis) and returns the distance, in cells, to
/// the boundary of the first blocked cell it enters.
///
/// Returns `None` when no blocked cell lies within `max_cells` or the ray
/// leaves the grid first (a "no return"). A start inside a blocked cell or
/// outside the grid returns `Some(0.0)` or `None` respectively.
pub fn cast<G: Occupancy + ?Sized>(
    grid: &G,
    u: f32,
    v: f32,
    angle: f32,
    max_cells: f32,
) -> Option<f32> {
    let (dy, dx) = (libm::sinf(angle), libm::cosf(angle));
    cast_dir(grid, u, v, dx, dy, max_cells)
}

/// As [`cast_dir`], first crossing open space in long steps: `clear(cx,
/// cy)` must return a distance (cells) such that no blocked cell comes
/// closer than that to any point of cell `(cx, cy)` (a lower bound of the
/// clearance; a negative or small value is always safe). While the cell
/// under the ray's current point has a clearance of at least `min_jump`
/// cells, the ray advances by that clearance without visiting the cells in
/// between: none of them can be blocked, so the answer is the exact
/// traversal's up to rounding. (The exact traversal sums one increment per
/// cell crossed, so over a few hundred cells its distance drifts by up to
/// ~1e-3 of a cell; the restarted one sums fewer.) The exact traversal
/// ([`cast_dir`]) takes over near surfaces.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn cast_dir_clear<G: Occupancy + ?Sized>(
    grid: &G,
    u: f32,
    v: f32,
    dx: f32,
    dy: f32,
    max_cells: f32,
    min_jump: f32,
    clear: impl Fn(u32, u32) -> f32,
) -> Option<f32> {
    let (w, h) = (grid.width() as f32, grid.height() as f32);
    let mut t = 0.0f32;
    // Each step moves at least `min_jump` (> 0) cells toward `max_cells`
    // (and stops should rounding leave `t` where it was).
    if min_jump > 0.0 {
        loop {
            let (x, y) = (u + t * dx, v + t * dy);
            if !(x >= 0.0 && y >= 0.0 && x < w && y < h) {
                break;
            }
            let c = clear(x as u32, y as u32);
            let next = t + c;
            if !(c >= min_jump && next > t) {
                break;
            }
            t = next;
            if t >= max_cells {
                // The whole reach is clear: no surface within it.
                return None;
            }
        }
    }
    if t == 0.0 {
        return cast_dir(grid, u, v, dx, dy, max_cells);
    }
    cast_dir(grid, u + t * dx, v + t * dy, dx, dy, max_cells - t).map(|s| t + s)
}

/// As [`cast`], with the direction given as a unit vector `(dx, dy)`.
pub fn cast_dir<G: Occupancy + ?Sized>(
    grid: &G,
    u: f32,
    v: f32,
    dx: f32,
    dy: f32,
    max_cells: f32,
) -> Option<f32> {
    let mut hit = None;
    traverse(
        grid.width(),
        grid.height(),
        u,
        v,
        dx,
        dy,
        max_cells,
        |cx, cy, t| {
            if grid.blocked(cx, cy) {
                hit = Some(t);
                false
            } else {
                true
            }
        },
    );
    hit
}

/// Visits, in order, every cell a ray from `(u, v)` along the unit vector
/// `(dx, dy)` passes through within `max_cells`, staying inside a
/// `width x height` grid. `visit(cx, cy, t)` gets the cell and the distance
/// `t` (cells) at which the ray enters it (0 for the start cell) and returns
/// `false` to stop. Exact traversal (Amanatides & Woo): no cell is skipped.
#[allow(clippy::too_many_arguments)]
pub fn traverse(
    width: u32,
    height: u32,
    u: f32,
    v: f32,
    dx: f32,
    dy: f32,
    max_cells: f32,
    mut visit: impl FnMut(u32, u32, f32) -> bool,
) {
    let (w, h) = (width as i64, height as i64);
    if !(u.is_finite() && v.is_finite() && dx.is_finite() && dy.is_finite()) {
        return;
    }
    if !(u >= 0.0 && v >= 0.0 && (u as f64) < w as f64 && (v as f64) < h as f64) {
        return;
    }
    let mut cx = u as i64;
    let mut cy = v as i64;
    if !visit(cx as u32, cy as u32, 0.0) {
        return;
    }
    let step_x: i64 = if dx > 0.0 { 1 } else { -1 };
    let step_y: i64 = if dy > 0.0 { 1 } else { -1 };
    // Ray parameter (cells travelled) at which the next vertical / horizontal
    // cell boundary is crossed, and the increment between successive ones.
    let t_delta_x = if dx != 0.0 {
        libm::fabsf(1.0 / dx)
    } else {
        f32::INFINITY
    };
    let t_delta_y = if dy != 0.0 {
        libm::fabsf(1.0 / dy)
    } else {
        f32::INFINITY
    };
    let mut t_max_x = if dx > 0.0 {
        ((cx + 1) as f32 - u) * t_delta_x
    } else if dx < 0.0 {
        (u - cx as f32) * t_delta_x
    } else {
        f32::INFINITY
    };
    let mut t_max_y = if dy > 0.0 {
        ((cy + 1) as f32 - v) * t_delta_y
    } else if dy < 0.0 {
        (v - cy as f32) * t_delta_y
    } else {
        f32::INFINITY
    };
    loop {
        let t = if t_max_x < t_max_y {
            cx += step_x;
            let t = t_max_x;
            t_max_x += t_delta_x;
            t
        } else {
            cy += step_y;
            let t = t_max_y;
            t_max_y += t_delta_y;
            t
        };
        if !(t <= max_cells) || cx < 0 || cy < 0 || cx >= w || cy >= h {
            return;
        }
        if !visit(cx as u32, cy as u32, t) {
            return;
        }
    }
}

#[cfg(test)]
mod tests;
