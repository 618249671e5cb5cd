//! Geometry and raster helpers the generators share: metres <-> cells,
//! random draws, integer rectangles, the oriented [`Canvas`], the building
//! outline and the furniture placement rules of [`Furn`].

use super::OCCUPIED;
use crate::compiler::rng::Rng;

/// Margin between the image border and the building's outer wall (m); at
/// most 1/16 of the shorter side and at least one cell.
const MARGIN: f64 = 0.5;

/// Metres <-> cells.
#[derive(Clone, Copy, Debug)]
pub(super) struct Scale {
    /// Metres per cell.
    pub(super) res: f64,
}

impl Scale {
    /// A length in metres as a whole number of cells, at least one.
    pub(super) fn c(self, m: f64) -> i64 {
        ((m / self.res).round() as i64).max(1)
    }

    /// A length in metres as (fractional) cells.
    pub(super) fn cf(self, m: f64) -> f64 {
        m / self.res
    }

    /// A length in cells as metres.
    pub(super) fn m(self, cells: i64) -> f64 {
        cells as f64 * self.res
    }
}

/// `v` limited to `[lo, hi]`; never panics (gives `hi` when `lo > hi`).
pub(super) fn clampi(v: i64, lo: i64, hi: i64) -> i64 {
    v.max(lo).min(hi)
}

/// Uniform integer in `[lo, hi)`; `lo` when the range is empty.
pub(super) fn irange(rng: &mut Rng, lo: i64, hi: i64) -> i64 {
    if hi > lo {
        lo + rng.below((hi - lo) as u64) as i64
    } else {
        lo
    }
}

/// True with probability `p` (draws one uniform number).
pub(super) fn chance(rng: &mut Rng, p: f64) -> bool {
    rng.uniform() < p
}

/// The interval `[lo, hi)` a quantity is drawn from uniformly; its unit is
/// the unit of the constant that holds it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Span {
    lo: f64,
    hi: f64,
}

impl Span {
    /// The interval `[lo, hi)`.
    pub(super) const fn new(lo: f64, hi: f64) -> Self {
        Span { lo, hi }
    }

    /// A uniform draw from the interval.
    pub(super) fn sample(self, rng: &mut Rng) -> f64 {
        rng.range(self.lo, self.hi)
    }
}

/// Half-open integer rectangle `[x0, x1) x [y0, y1)` in cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Rect {
    pub(super) x0: i64,
    pub(super) y0: i64,
    pub(super) x1: i64,
    pub(super) y1: i64,
}

impl Rect {
    pub(super) const fn new(x0: i64, y0: i64, x1: i64, y1: i64) -> Self {
        Rect { x0, y0, x1, y1 }
    }
    pub(super) fn w(&self) -> i64 {
        self.x1 - self.x0
    }
    pub(super) fn h(&self) -> i64 {
        self.y1 - self.y0
    }
    pub(super) fn is_empty(&self) -> bool {
        self.x1 <= self.x0 || self.y1 <= self.y0
    }
    pub(super) fn shrink(&self, d: i64) -> Rect {
        Rect::new(self.x0 + d, self.y0 + d, self.x1 - d, self.y1 - d)
    }
    pub(super) fn grow(&self, d: i64) -> Rect {
        self.shrink(-d)
    }
    pub(super) fn intersects(&self, o: &Rect) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }
    pub(super) fn contains(&self, o: &Rect) -> bool {
        o.x0 >= self.x0 && o.x1 <= self.x1 && o.y0 >= self.y0 && o.y1 <= self.y1
    }
}

/// The building of a `lw` x `lh` cell layout: its outer rectangle (a margin
/// inside the map) and the interior inside its outer wall.
#[derive(Clone, Copy, Debug)]
pub(super) struct Outline {
    /// Outer edge of the outer wall (cells).
    pub(super) building: Rect,
    /// Outer wall thickness (cells).
    pub(super) wall: i64,
    /// Inside of the outer wall (cells).
    pub(super) inner: Rect,
}

impl Outline {
    /// The outline of a `lw` x `lh` cell layout with an outer wall `wall_m`
    /// metres thick (at most 1/16 of the shorter side, at least one cell).
    pub(super) fn new(lw: i64, lh: i64, s: Scale, wall_m: f64) -> Self {
        let small = lw.min(lh);
        let margin = s.c(MARGIN).min(small / 16).max(1);
        let building = Rect::new(margin, margin, lw - margin, lh - margin);
        let wall = s.c(wall_m).min(small / 16).max(1);
        Outline {
            building,
            wall,
            inner: building.shrink(wall),
        }
    }
}

/// The pixel buffer seen through a layout frame: layouts are drawn with the
/// long axis horizontal, then optionally mirrored and transposed into image
/// coordinates (which varies maps between seeds for free).
pub(super) struct Canvas {
    w: usize,
    h: usize,
    pub(super) px: Vec<u8>,
    transpose: bool,
    flip_x: bool,
    flip_y: bool,
}

impl Canvas {
    /// A `w` x `h` image filled with `v`, not yet oriented.
    pub(super) fn new(w: usize, h: usize, v: u8) -> Self {
        Canvas {
            w,
            h,
            px: vec![v; w * h],
            transpose: false,
            flip_x: false,
            flip_y: false,
        }
    }

    /// Long axis horizontal in layout coordinates, random mirroring.
    pub(super) fn orient(&mut self, rng: &mut Rng) {
        self.transpose = self.h > self.w || (self.h == self.w && chance(rng, 0.5));
        self.flip_x = chance(rng, 0.5);
        self.flip_y = chance(rng, 0.5);
    }

    /// Layout width in cells.
    pub(super) fn lw(&self) -> i64 {
        (if self.transpose { self.h } else { self.w }) as i64
    }

    /// Layout height in cells.
    pub(super) fn lh(&self) -> i64 {
        (if self.transpose { self.w } else { self.h }) as i64
    }

    fn to_image_rect(&self, r: Rect) -> Rect {
        let (lw, lh) = (self.lw(), self.lh());
        let mut r = r;
        if self.flip_x {
            r = Rect::new(lw - r.x1, r.y0, lw - r.x0, r.y1);
        }
        if self.flip_y {
            r = Rect::new(r.x0, lh - r.y1, r.x1, lh - r.y0);
        }
        if self.transpose {
            r = Rect::new(r.y0, r.x0, r.y1, r.x1);
        }
        r
    }

    /// The image cell of a layout cell, clamped to the image.
    pub(super) fn to_image_point(&self, x: i64, y: i64) -> (usize, usize) {
        let r = self.to_image_rect(Rect::new(x, y, x + 1, y + 1));
        (
            clampi(r.x0, 0, self.w as i64 - 1) as usize,
            clampi(r.y0, 0, self.h as i64 - 1) as usize,
        )
    }

    /// A layout rectangle in image cells, clipped to the image:
    /// `(x0, x1, y0, y1)`, or `None` when nothing is left.
    fn clip(&self, r: Rect) -> Option<(usize, usize, usize, usize)> {
        let r = self.to_image_rect(r);
        let x0 = clampi(r.x0, 0, self.w as i64) as usize;
        let x1 = clampi(r.x1, 0, self.w as i64) as usize;
        let y0 = clampi(r.y0, 0, self.h as i64) as usize;
        let y1 = clampi(r.y1, 0, self.h as i64) as usize;
        (x0 < x1 && y0 < y1).then_some((x0, x1, y0, y1))
    }

    /// Fills a layout rectangle (clipped to the map).
    pub(super) fn fill(&mut self, r: Rect, v: u8) {
        let Some((x0, x1, y0, y1)) = self.clip(r) else {
            return;
        };
        for y in y0..y1 {
            let o = y * self.w;
            self.px[o + x0..o + x1].fill(v);
        }
    }

    /// Whether every cell of a layout rectangle (clipped to the map) is `v`;
    /// false when the rectangle lies outside the map.
    pub(super) fn all_eq(&self, r: Rect, v: u8) -> bool {
        let Some((x0, x1, y0, y1)) = self.clip(r) else {
            return false;
        };
        (y0..y1).all(|y| {
            self.px[y * self.w + x0..y * self.w + x1]
                .iter()
                .all(|&p| p == v)
        })
    }

    /// Fills the ellipse inscribed in a layout rectangle.
    pub(super) fn fill_ellipse(&mut self, r: Rect, v: u8) {
        if r.is_empty() {
            return;
        }
        let (cx, cy) = ((r.x0 + r.x1) as f64 / 2.0, (r.y0 + r.y1) as f64 / 2.0);
        let (ax, ay) = (r.w() as f64 / 2.0, r.h() as f64 / 2.0);
        for y in r.y0..r.y1 {
            let dy = (y as f64 + 0.5 - cy) / ay;
            let q = 1.0 - dy * dy;
            if q <= 0.0 {
                continue;
            }
            let hw = ax * q.sqrt();
            let xa = (cx - hw - 0.5).ceil() as i64;
            let xb = (cx + hw - 0.5).floor() as i64 + 1;
            self.fill(Rect::new(xa.max(r.x0), y, xb.min(r.x1), y + 1), v);
        }
    }

    /// Fills the building rectangle of `outline` occupied (its outer wall;
    /// the generator then clears the inside).
    pub(super) fn fill_building(&mut self, outline: &Outline) {
        self.fill(outline.building, OCCUPIED);
    }
}

/// The keep-clear zone in front of a door `[dx, dx + dw)` in a horizontal
/// wall: `pad` cells wider than the door on each side, `reach` cells deep
/// into the room from `y` (downwards when `into_down`, else upwards).
pub(super) fn door_approach(
    dx: i64,
    dw: i64,
    y: i64,
    pad: i64,
    reach: i64,
    into_down: bool,
) -> Rect {
    if into_down {
        Rect::new(dx - pad, y, dx + dw + pad, y + reach)
    } else {
        Rect::new(dx - pad, y - reach, dx + dw + pad, y)
    }
}

/// Placement bookkeeping for obstacles inside one room (or yard).
///
/// Rules that keep the room's free space connected: items are rectangles
/// inside the room, pairwise at least `clr` apart, never inside a keep-clear
/// zone (door approaches), each either touching a wall or at least `clr`
/// from it, and none touching two opposite walls.
pub(super) struct Furn {
    pub(super) room: Rect,
    clr: i64,
    blocked: Vec<Rect>,
}

impl Furn {
    /// Placement in `room` (cells) keeping `keep` clear, items `clr` cells
    /// apart.
    pub(super) fn new(room: Rect, keep: &[Rect], clr: i64) -> Self {
        Furn {
            room,
            clr,
            blocked: keep.to_vec(),
        }
    }

    /// Moves an item flush against a wall when it is closer than `clr`.
    pub(super) fn snap(&self, mut r: Rect) -> Rect {
        let (rm, c) = (self.room, self.clr);
        let gl = r.x0 - rm.x0;
        let gr = rm.x1 - r.x1;
        if gl > 0 && gl < c {
            r = Rect::new(rm.x0, r.y0, rm.x0 + r.w(), r.y1);
        } else if gr > 0 && gr < c {
            r = Rect::new(rm.x1 - r.w(), r.y0, rm.x1, r.y1);
        }
        let gt = r.y0 - rm.y0;
        let gb = rm.y1 - r.y1;
        if gt > 0 && gt < c {
            r = Rect::new(r.x0, rm.y0, r.x1, rm.y0 + r.h());
        } else if gb > 0 && gb < c {
            r = Rect::new(r.x0, rm.y1 - r.h(), r.x1, rm.y1);
        }
        r
    }

    fn fits(&self, r: &Rect) -> bool {
        if r.is_empty() || !self.room.contains(r) {
            return false;
        }
        let rm = self.room;
        let g = [r.x0 - rm.x0, rm.x1 - r.x1, r.y0 - rm.y0, rm.y1 - r.y1];
        if g.iter().any(|&d| d > 0 && d < self.clr) {
            return false;
        }
        if (g[0] == 0 && g[1] == 0) || (g[2] == 0 && g[3] == 0) {
            return false;
        }
        !self.blocked.iter().any(|b| b.intersects(r))
    }

    /// Records `r` if it fits; the caller draws it.
    pub(super) fn add(&mut self, r: Rect) -> bool {
        if self.fits(&r) {
            self.blocked.push(r.grow(self.clr));
            true
        } else {
            false
        }
    }

    /// A random rectangle `along` x `depth` flush against one of the walls.
    fn wall_spot(&self, rng: &mut Rng, along: i64, depth: i64) -> Rect {
        let rm = self.room;
        match rng.below(4) {
            0 | 1 => {
                let x = irange(rng, rm.x0, rm.x1 - along + 1);
                if chance(rng, 0.5) {
                    Rect::new(x, rm.y0, x + along, rm.y0 + depth)
                } else {
                    Rect::new(x, rm.y1 - depth, x + along, rm.y1)
                }
            }
            _ => {
                let y = irange(rng, rm.y0, rm.y1 - along + 1);
                if chance(rng, 0.5) {
                    Rect::new(rm.x0, y, rm.x0 + depth, y + along)
                } else {
                    Rect::new(rm.x1 - depth, y, rm.x1, y + along)
                }
            }
        }
    }

    /// A random `w` x `h` rectangle inside the room (possibly not fitting).
    pub(super) fn random_spot(&self, rng: &mut Rng, w: i64, h: i64) -> Rect {
        let rm = self.room;
        let x = irange(rng, rm.x0, rm.x1 - w + 1);
        let y = irange(rng, rm.y0, rm.y1 - h + 1);
        Rect::new(x, y, x + w, y + h)
    }

    /// Tries up to `tries` wall spots (snapped) for an `along` x `depth`
    /// item; records and returns the first that fits (the caller draws it).
    pub(super) fn add_on_wall(
        &mut self,
        rng: &mut Rng,
        along: i64,
        depth: i64,
        tries: usize,
    ) -> Option<Rect> {
        for _ in 0..tries {
            let spot = self.wall_spot(rng, along, depth);
            let spot = self.snap(spot);
            if self.add(spot) {
                return Some(spot);
            }
        }
        None
    }
}
