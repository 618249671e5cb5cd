//! Exact Euclidean distance transform and feature (nearest obstacle)
//! transform of a binary grid.
//!
//! Two separable 1-D passes (Meijster, Roerdink & Hesselink 2000, the
//! integer form of Felzenszwalb & Huttenlocher's lower envelope of
//! parabolas): first along each row (nearest obstacle column in the row),
//! then along each column (lower envelope of `y -> g(y)^2 + (y - y')^2`).
//! Both passes are linear in the number of cells and use exact integer
//! arithmetic, so the result does not depend on floating-point rounding nor
//! on the rayon thread count (each row and each column is computed by one
//! task, in a fixed order).
//!
//! Distances are between cell CENTRES, in cells: an obstacle cell has 0, its
//! 4-neighbours 1, its diagonal neighbours 2 (squared). Squared distances are
//! returned as `f32`; they are exact integers up to 2^24 (distances up to
//! 4096 cells) and rounded beyond.
//!
//! Memory: the row pass keeps one `u32` per cell, the column pass writes its
//! output per strip of columns and the strips are then copied into row-major
//! order: about 16 bytes per cell at the peak for [`nearest_obstacle`], 12
//! for [`squared_edt`].

use rayon::prelude::*;

use crate::compiler::mapfile::{Cell, OccupancyGrid};

/// "No obstacle" marker in feature (nearest obstacle index) arrays.
pub const NONE: u32 = u32::MAX;

/// The squared distance (cells^2) reported for every cell when the grid has
/// no obstacle at all: `width^2 + height^2`, larger than any squared
/// distance between two cells of the grid, and finite.
pub fn no_obstacle_sq(width: usize, height: usize) -> f32 {
    let (w, h) = (width as f64, height as f64);
    (w * w + h * h) as f32
}

/// Squared Euclidean distance (cells^2) from each cell centre to the nearest
/// obstacle cell centre of a `width x height` grid, index `cy * width + cx`.
/// `is_obstacle(index)` is called once per cell. Obstacle cells get 0; when
/// there is no obstacle at all every cell gets [`no_obstacle_sq`].
///
/// # Panics
/// When `width * height >= u32::MAX` (indices must fit in `u32`).
pub fn squared_edt(
    width: usize,
    height: usize,
    is_obstacle: impl Fn(usize) -> bool + Sync,
) -> Vec<f32> {
    transform(width, height, &is_obstacle, false).0
}

/// As [`squared_edt`], plus the index (`cy * width + cx`) of a nearest
/// obstacle cell for each cell ([`NONE`] when the grid has no obstacle).
/// Ties between equally near obstacles are broken deterministically.
///
/// # Panics
/// When `width * height >= u32::MAX` (indices must fit in `u32`).
pub fn nearest_obstacle(
    width: usize,
    height: usize,
    is_obstacle: impl Fn(usize) -> bool + Sync,
) -> (Vec<f32>, Vec<u32>) {
    transform(width, height, &is_obstacle, true)
}

/// Columns per task in the column pass.
const STRIP: usize = 32;

fn transform(
    width: usize,
    height: usize,
    is_obstacle: &(dyn Fn(usize) -> bool + Sync),
    want_nearest: bool,
) -> (Vec<f32>, Vec<u32>) {
    let n = width
        .checked_mul(height)
        .expect("edt: width * height overflows");
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    assert!(
        n < NONE as usize,
        "edt: {width} x {height} cells do not fit u32 indices"
    );

    // Pass 1, rows: the column of the nearest obstacle in the same row.
    let mut col_of = vec![NONE; n];
    col_of
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            let base = y * width;
            let mut last = NONE;
            for (x, slot) in row.iter_mut().enumerate() {
                if is_obstacle(base + x) {
                    last = x as u32;
                }
                *slot = last;
            }
            let mut next = NONE;
            for x in (0..width).rev() {
                let left = row[x];
                if left == x as u32 {
                    next = x as u32;
                    continue;
                }
                if next != NONE {
                    let dr = next as usize - x;
                    // Ties go to the left obstacle.
                    if left == NONE || dr < x - left as usize {
                        row[x] = next;
                    }
                }
            }
        });

    // Pass 2, columns, by strips of STRIP columns; each strip's output is
    // row-major within the strip.
    let inf = (width + height) as i64;
    let no_sq = no_obstacle_sq(width, height);
    let strips: Vec<(Vec<f32>, Vec<u32>)> = (0..width.div_ceil(STRIP))
        .into_par_iter()
        .map(|s| {
            let x0 = s * STRIP;
            let sw = STRIP.min(width - x0);
            // Gather the strip column-major (row-wise reads of `col_of`).
            let mut cols = vec![NONE; sw * height];
            for y in 0..height {
                let src = &col_of[y * width + x0..y * width + x0 + sw];
                for (j, &c) in src.iter().enumerate() {
                    cols[j * height + y] = c;
                }
            }
            let mut sq = vec![0f32; sw * height];
            let mut near = if want_nearest {
                vec![NONE; sw * height]
            } else {
                Vec::new()
            };
            let mut g = vec![0i64; height];
            let mut s_ = vec![0usize; height];
            let mut t_ = vec![0i64; height];
            for j in 0..sw {
                let x = (x0 + j) as i64;
                let col = &cols[j * height..(j + 1) * height];
                for (gy, &c) in g.iter_mut().zip(col) {
                    *gy = if c == NONE { inf } else { (x - c as i64).abs() };
                }
                lower_envelope(&g, &mut s_, &mut t_, |u, i| {
                    let d = u as i64 - i as i64;
                    let o = u * sw + j;
                    if g[i] >= inf {
                        sq[o] = no_sq;
                    } else {
                        sq[o] = (d * d + g[i] * g[i]) as f32;
                        if want_nearest {
                            near[o] = (i * width) as u32 + col[i];
                        }
                    }
                });
            }
            (sq, near)
        })
        .collect();

    // Copy the strips into row-major order; `col_of` becomes the output.
    let mut sq = vec![0f32; n];
    sq.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for (s, (ssq, _)) in strips.iter().enumerate() {
            let x0 = s * STRIP;
            let sw = STRIP.min(width - x0);
            row[x0..x0 + sw].copy_from_slice(&ssq[y * sw..(y + 1) * sw]);
        }
    });
    let near = if want_nearest {
        col_of
            .par_chunks_mut(width)
            .enumerate()
            .for_each(|(y, row)| {
                for (s, (_, snear)) in strips.iter().enumerate() {
                    let x0 = s * STRIP;
                    let sw = STRIP.min(width - x0);
                    row[x0..x0 + sw].copy_from_slice(&snear[y * sw..(y + 1) * sw]);
                }
            });
        col_of
    } else {
        Vec::new()
    };
    (sq, near)
}

/// Meijster's second phase on one line: `g[i]` is the 1-D distance of the
/// perpendicular pass at position `i`; calls `out(u, i)` for every `u` with
/// the `i` minimizing `(u - i)^2 + g[i]^2` (the earliest on ties of the
/// envelope). `s` and `t` are scratch buffers of `g.len()` entries.
fn lower_envelope(g: &[i64], s: &mut [usize], t: &mut [i64], mut out: impl FnMut(usize, usize)) {
    let m = g.len();
    let f = |x: i64, i: usize| {
        let d = x - i as i64;
        d * d + g[i] * g[i]
    };
    // Sep(i, u): the first x at which parabola u is strictly below parabola i
    // is 1 + Sep(i, u) (floor division; u > i).
    let sep = |i: usize, u: usize| {
        let (i2, u2) = (i as i64, u as i64);
        (u2 * u2 - i2 * i2 + g[u] * g[u] - g[i] * g[i]).div_euclid(2 * (u2 - i2))
    };
    let mut q: isize = 0;
    s[0] = 0;
    t[0] = 0;
    for u in 1..m {
        while q >= 0 && f(t[q as usize], s[q as usize]) > f(t[q as usize], u) {
            q -= 1;
        }
        if q < 0 {
            q = 0;
            s[0] = u;
        } else {
            let w = 1 + sep(s[q as usize], u);
            if w < m as i64 {
                q += 1;
                s[q as usize] = u;
                t[q as usize] = w;
            }
        }
    }
    for u in (0..m).rev() {
        out(u, s[q as usize]);
        if u as i64 == t[q as usize] {
            q -= 1;
        }
    }
}

/// Distance to the nearest obstacle for every cell of an [`OccupancyGrid`].
///
/// Obstacles are [`Cell::Occupied`] cells, [`Cell::Unknown`] cells when
/// `unknown_is_obstacle`, and every cell of the grid's outermost ring (the
/// image border): what lies beyond the image is unknown, so free space that
/// runs off the image is treated as walled there.
#[derive(Clone, Debug)]
pub struct DistanceField {
    /// Width in cells.
    pub width: u32,
    /// Height in cells.
    pub height: u32,
    /// Metres per cell.
    pub resolution: f64,
    /// Whether unknown cells counted as obstacles.
    pub unknown_is_obstacle: bool,
    /// Squared distance (cells^2) from each cell centre to the nearest
    /// obstacle cell centre, index `cy * width + cx`; 0 on obstacles.
    pub sq: Vec<f32>,
    /// Index of a nearest obstacle cell, [`NONE`] when there is none.
    pub nearest: Vec<u32>,
}

impl DistanceField {
    /// Computes the field (see the type's documentation for what counts as
    /// an obstacle).
    pub fn from_grid(grid: &OccupancyGrid, unknown_is_obstacle: bool) -> Self {
        let (w, h) = (grid.width as usize, grid.height as usize);
        let cells = &grid.cells;
        let (sq, nearest) = nearest_obstacle(w, h, |i| {
            let (x, y) = (i % w, i / w);
            x == 0
                || y == 0
                || x + 1 == w
                || y + 1 == h
                || match cells[i] {
                    Cell::Free => false,
                    Cell::Occupied => true,
                    Cell::Unknown => unknown_is_obstacle,
                }
        });
        DistanceField {
            width: grid.width,
            height: grid.height,
            resolution: grid.resolution,
            unknown_is_obstacle,
            sq,
            nearest,
        }
    }

    /// A copy of the header fields with empty `sq` and `nearest`.
    pub fn clone_header(&self) -> Self {
        DistanceField {
            width: self.width,
            height: self.height,
            resolution: self.resolution,
            unknown_is_obstacle: self.unknown_is_obstacle,
            sq: Vec::new(),
            nearest: Vec::new(),
        }
    }

    /// Whether cell `i` (index `cy * width + cx`) is an obstacle.
    #[inline]
    pub fn is_obstacle(&self, i: usize) -> bool {
        self.sq[i] == 0.0
    }

    /// Distance (cells) from the centre of cell `i` to the nearest obstacle
    /// cell centre.
    #[inline]
    pub fn clearance_cells(&self, i: usize) -> f64 {
        (self.sq[i] as f64).sqrt()
    }

    /// Distance (metres) from the centre of cell `i` to the nearest obstacle
    /// cell centre. This is half a cell more than the distance to the
    /// obstacle cell's near edge for an axis-aligned neighbour.
    #[inline]
    pub fn clearance_m(&self, i: usize) -> f64 {
        self.clearance_cells(i) * self.resolution
    }
}

#[cfg(test)]
mod tests;

/// Squared distances (cells^2) from every cell of a `w x h` grid to the
/// nearest cell where `obst` is true, by brute force (O(cells x
/// obstacles)): the reference the tests compare the transform with.
/// [`no_obstacle_sq`] everywhere when there is no obstacle.
#[doc(hidden)]
pub fn brute_force_sq(w: usize, h: usize, obst: &[bool]) -> Vec<f32> {
    let pts: Vec<(i64, i64)> = (0..w * h)
        .filter(|&i| obst[i])
        .map(|i| ((i % w) as i64, (i / w) as i64))
        .collect();
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            pts.iter()
                .map(|&(a, b)| (a - x) * (a - x) + (b - y) * (b - y))
                .min()
                .map_or(no_obstacle_sq(w, h), |d| d as f32)
        })
        .collect()
}
