//! Office floors: an outer wall, horizontal corridors with rows of rooms on
//! both sides, cross corridors cutting through the blocks of rooms, halls
//! spanning a block, suites, alcoves, doors between rooms, furniture and
//! pillars.
//!
//! The layout is planned in a frame with the long axis horizontal
//! ([`Canvas`]), from the outside in: [`Office::plan_bands`] cuts the floor
//! into horizontal corridors and rows of rooms, rows are grouped into
//! blocks, [`Office::plan_verticals`] places cross corridors, every row is
//! split into rooms ([`Office::row`]) and every room is furnished
//! (`office/furnish.rs`).

use super::draw::{chance, clampi, door_approach, irange, Canvas, Outline, Rect, Scale, Span};
use super::{Stats, FREE, OCCUPIED};
use crate::compiler::rng::Rng;

use furnish::Furnishing;

mod furnish;

// ---------------------------------------------------------------------------
// Parameters (m: metres; probabilities are per choice)
// ---------------------------------------------------------------------------

/// Outer wall thickness (m).
const OUTER_WALL: f64 = 0.25;
/// Interior wall thickness (m).
const INNER_WALL: f64 = 0.15;
/// Width of an ordinary door (m).
const DOOR_WIDTH: f64 = 0.9;
/// Width of a double door: wide rooms and halls (m).
const WIDE_DOOR_WIDTH: f64 = 1.6;
/// Clearance between furniture items, and between an item and a wall it
/// does not touch (m).
const CLEARANCE: f64 = 0.6;
/// Shorter interior side (m) from which rooms get their full widths;
/// smaller buildings scale room widths down by the ratio.
const FULL_SIZE_BUILDING: f64 = 44.0;
/// Smallest room width factor of small buildings.
const MIN_ROOM_SCALE: f64 = 0.65;
/// Keep-clear zone of a door: extra width on each side of the door (m).
const DOOR_PAD: f64 = 0.3;
/// Keep-clear zone of a door: depth into the room (m).
const DOOR_REACH: f64 = 1.0;
/// Keep-clear zone of a hall door: depth into the hall (m).
const HALL_DOOR_REACH: f64 = 1.2;

/// One corridor (and its two rows of rooms) per this much floor depth (m).
const BAND_PITCH: f64 = 17.0;
/// Width of a horizontal corridor (m).
const CORRIDOR_WIDTH: Span = Span::new(1.7, 2.5);
/// Smallest depth of a row of rooms (m).
const MIN_ROW_DEPTH: f64 = 3.0;
/// Relative depth of each row of rooms (drawn per row, then normalised).
const ROW_DEPTH_WEIGHT: Span = Span::new(0.75, 1.25);
/// Corridor width of a floor too shallow for rooms on both sides (m).
const SHALLOW_CORRIDOR_WIDTH: Span = Span::new(1.4, 2.0);
/// Smallest row depth of a shallow floor (m).
const SHALLOW_MIN_ROW_DEPTH: f64 = 2.0;
/// Smallest interior width of a shallow floor with a corridor (m).
const SHALLOW_MIN_WIDTH: f64 = 4.0;

/// Floors narrower than this have no cross corridor unless needed (m).
const CROSS_MIN_FLOOR: f64 = 14.0;
/// About one cross corridor per this much floor width (m).
const CROSS_PITCH: f64 = 40.0;
/// Random addition to the number of cross corridors (before rounding down).
const CROSS_EXTRA: Span = Span::new(0.2, 1.0);
/// A cross corridor is moved at random by up to its spacing divided by
/// this (either way).
const CROSS_JITTER_DIV: i64 = 4;
/// Width of a cross corridor (m).
const CROSS_WIDTH: Span = Span::new(1.6, 2.2);
/// Smallest room width left beside a cross corridor (m).
const CROSS_MIN_ROOM: f64 = 2.5;
/// Probability that a cross corridor cuts through an outer block (one row
/// against the outer wall).
const CROSS_IN_OUTER_BLOCK: f64 = 0.3;
/// Probability that a cross corridor cuts through an inner block, besides
/// the one that always does.
const CROSS_IN_INNER_BLOCK: f64 = 0.5;
/// Shortest stretch of a block between cross corridors that gets rooms (m).
const MIN_INTERVAL: f64 = 1.0;

/// Shortest stretch of an inner block that may hold a hall (m).
const HALL_MIN_INTERVAL: f64 = 10.0;
/// Probability of a hall in such a stretch.
const HALL_CHANCE: f64 = 0.12;
/// Width of a hall (m).
const HALL_WIDTH: Span = Span::new(8.0, 18.0);
/// A hall is widened to the end of its stretch when the room left there
/// would be narrower than this plus a wall (m).
const HALL_MIN_ROOM: f64 = 2.4;

/// Smallest room width of a row (m).
const MIN_ROOM_WIDTH: f64 = 2.6;
/// Largest ordinary room width, before the building scale (m).
const MAX_ROOM_WIDTH: f64 = 9.0;
/// Share of narrow rooms (cumulative probability).
const NARROW_ROOM_SHARE: f64 = 0.10;
/// Width of a narrow room (m).
const NARROW_ROOM_WIDTH: Span = Span::new(2.6, 3.6);
/// Share of narrow and ordinary rooms (cumulative probability); the rest
/// are wide.
const ORDINARY_ROOM_SHARE: f64 = 0.72;
/// Width of an ordinary room, before the building scale (m).
const ORDINARY_ROOM_WIDTH: Span = Span::new(4.5, 9.0);
/// Width of a wide room, before the building scale (m).
const WIDE_ROOM_WIDTH: Span = Span::new(10.0, 16.0);
/// Smallest remainder of a row that gets another room (m).
const MIN_ROOM_REST: f64 = 1.0;

/// Distance of a door near a room's end from that end (m).
const DOOR_END_GAP: f64 = 0.15;
/// Random extra distance of such a door (m, exclusive upper bound).
const DOOR_END_JIGGLE: f64 = 0.5;
/// Probability that a door is near the start of its wall.
const DOOR_NEAR_START: f64 = 0.4;
/// Probability that a door is near either end (the rest are anywhere).
const DOOR_NEAR_AN_END: f64 = 0.8;
/// Probability of a door between neighbouring rooms.
const LINK_DOOR_CHANCE: f64 = 0.15;
/// Probability of a side door from a row's end room into a cross corridor.
const SIDE_DOOR_CHANCE: f64 = 0.3;
/// Smallest room width that gets a double door (m).
const WIDE_DOOR_MIN_ROOM: f64 = 8.0;
/// Probability that such a room gets one.
const WIDE_DOOR_CHANCE: f64 = 0.5;

/// Smallest width of an open alcove (lounge) on a corridor (m).
const ALCOVE_MIN_WIDTH: f64 = 3.0;
/// Probability that an unlinked room is an alcove.
const ALCOVE_CHANCE: f64 = 0.06;
/// Wall stub left at each side of an alcove's opening (m).
const ALCOVE_STUB: f64 = 0.3;
/// Depth of the strip along an alcove's opening kept clear (m).
const ALCOVE_CLEAR_DEPTH: f64 = 1.2;

/// Smallest depth of a room split into a suite (m).
const SUITE_MIN_DEPTH: f64 = 5.5;
/// Smallest width of a room split into a suite (m).
const SUITE_MIN_WIDTH: f64 = 2.6;
/// Probability that an unlinked room is a suite.
const SUITE_CHANCE: f64 = 0.15;
/// Share of a suite's depth given to the front room.
const SUITE_FRONT_SHARE: Span = Span::new(0.45, 0.62);
/// Smallest depth of each room of a suite (m).
const SUITE_MIN_ROOM_DEPTH: f64 = 2.2;

/// Doors per corridor side of a hall: one plus a draw below this.
const HALL_EXTRA_DOORS: u64 = 2;

/// Corridors narrower than this get no items (m).
const CORRIDOR_ITEMS_MIN_WIDTH: f64 = 1.5;
/// Free corridor length kept on both sides of a corridor item (m).
const CORRIDOR_ITEM_PAD: f64 = 0.5;
/// About one corridor item per this much corridor length (m), before the
/// random factor [`CORRIDOR_ITEM_FACTOR`].
const CORRIDOR_ITEM_PITCH: f64 = 9.0;
/// Random factor on the number of corridor items.
const CORRIDOR_ITEM_FACTOR: Span = Span::new(0.5, 1.2);
/// Length of a corridor bench (m).
const BENCH_LENGTH: Span = Span::new(1.2, 2.0);
/// Depth of a corridor bench (m).
const BENCH_DEPTH: f64 = 0.45;
/// Diameter of a plant pot (m).
const PLANT_SIZE: f64 = 0.5;
/// Length of a corridor cabinet (m).
const CABINET_LENGTH: Span = Span::new(0.8, 1.2);
/// Depth of a corridor cabinet (m).
const CABINET_DEPTH: f64 = 0.5;
/// Side of a water cooler (m).
const COOLER_SIZE: f64 = 0.4;
/// Corridor items are at most this fraction of the corridor width deep.
const CORRIDOR_ITEM_MAX_DEPTH_DIV: i64 = 4;

// ---------------------------------------------------------------------------
// Types
// ---------------------------------------------------------------------------

/// Which side of a row of rooms the corridor is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Facing {
    /// Corridor above (door in the room's top wall, y0).
    Up,
    /// Corridor below (door in the room's bottom wall, y1).
    Down,
}

#[derive(Clone, Copy, Debug)]
enum BandKind {
    Corridor,
    Row(Facing),
}

/// A horizontal strip of the floor: a corridor or a row of rooms.
#[derive(Clone, Copy, Debug)]
struct Band {
    y0: i64,
    y1: i64,
    kind: BandKind,
}

/// One or two rows of rooms between corridors (or a corridor and the outer
/// wall); cross corridors cut through blocks.
struct Block {
    rows: Vec<(Band, Facing)>,
    /// Extent of a cross-corridor segment through this block.
    seg_y0: i64,
    seg_y1: i64,
    outer: bool,
}

struct Office<'a> {
    cv: &'a mut Canvas,
    rng: &'a mut Rng,
    s: Scale,
    /// Interior wall thickness, cells.
    ti: i64,
    /// Door width, cells.
    dw: i64,
    /// Furniture clearance, cells.
    clr: i64,
    /// Room width factor: small buildings get smaller rooms.
    room_scale: f64,
    rooms: usize,
}

/// Draws an office floor on `cv`; returns a free point (layout cells) in
/// the main corridor.
pub(super) fn office(cv: &mut Canvas, rng: &mut Rng, s: Scale, stats: &mut Stats) -> (i64, i64) {
    let outline = Outline::new(cv.lw(), cv.lh(), s, OUTER_WALL);
    cv.fill_building(&outline);
    let inner = outline.inner;
    let mut o = Office {
        cv,
        rng,
        s,
        ti: s.c(INNER_WALL),
        dw: s.c(DOOR_WIDTH),
        clr: s.c(CLEARANCE),
        room_scale: (s.m(inner.w().min(inner.h())) / FULL_SIZE_BUILDING).clamp(MIN_ROOM_SCALE, 1.0),
        rooms: 0,
    };
    let hint = o.run(inner);
    stats.rooms = o.rooms;
    hint
}

/// Groups the rows of `bands` into blocks: a row facing up and the row
/// right below it facing down share a block; a row alone is an outer block.
fn group_blocks(bands: &[Band], ti: i64) -> Vec<Block> {
    let mut blocks: Vec<Block> = Vec::new();
    let mut i = 0;
    while i < bands.len() {
        let BandKind::Row(f) = bands[i].kind else {
            i += 1;
            continue;
        };
        let mut rows = vec![(bands[i], f)];
        if f == Facing::Up {
            if let Some(nb) = bands.get(i + 1) {
                if let BandKind::Row(f2) = nb.kind {
                    rows.push((*nb, f2));
                    i += 1;
                }
            }
        }
        i += 1;
        let (first, ff) = rows[0];
        let (last, lf) = rows[rows.len() - 1];
        let seg_y0 = if ff == Facing::Up {
            first.y0 - ti
        } else {
            first.y0
        };
        let seg_y1 = if lf == Facing::Down {
            last.y1 + ti
        } else {
            last.y1
        };
        let outer = rows.len() == 1;
        blocks.push(Block {
            rows,
            seg_y0,
            seg_y1,
            outer,
        });
    }
    blocks
}

impl Office<'_> {
    fn run(&mut self, inner: Rect) -> (i64, i64) {
        let bands = self.plan_bands(inner);
        if bands.is_empty() {
            self.cv.fill(inner, FREE);
            self.furnish(inner, &[], false);
            self.rooms += 1;
            return (inner.x0, inner.y0);
        }
        let mut corridors = Vec::new();
        for b in &bands {
            if let BandKind::Corridor = b.kind {
                let r = Rect::new(inner.x0, b.y0, inner.x1, b.y1);
                self.cv.fill(r, FREE);
                corridors.push(r);
            }
        }
        let hint = bands
            .iter()
            .find(|b| matches!(b.kind, BandKind::Corridor))
            .map_or((inner.x0, inner.y0), |b| (inner.x0, b.y0));
        let blocks = group_blocks(&bands, self.ti);
        let need = blocks.iter().any(|b| !b.outer);
        let verts = self.plan_verticals(inner, need);
        let active = self.choose_crossings(&blocks, verts.len(), need);
        for (b, act) in blocks.iter().zip(&active) {
            self.block(inner, b, &verts, act, &mut corridors);
        }
        for r in corridors {
            self.corridor_items(r);
        }
        hint
    }

    /// Which of the `nv` cross corridors cut through each block: each inner
    /// block is cut by at least one, and some block always is.
    fn choose_crossings(&mut self, blocks: &[Block], nv: usize, need: bool) -> Vec<Vec<bool>> {
        let mut active = vec![vec![false; nv]; blocks.len()];
        for (bi, b) in blocks.iter().enumerate() {
            if nv == 0 {
                break;
            }
            if b.outer {
                for a in active[bi].iter_mut() {
                    *a = chance(self.rng, CROSS_IN_OUTER_BLOCK);
                }
            } else {
                let m = self.rng.below(nv as u64) as usize;
                for (v, a) in active[bi].iter_mut().enumerate() {
                    *a = v == m || chance(self.rng, CROSS_IN_INNER_BLOCK);
                }
            }
        }
        if nv > 0 && !need && !active.iter().flatten().any(|&a| a) && !blocks.is_empty() {
            let bi = self.rng.below(blocks.len() as u64) as usize;
            let v = self.rng.below(nv as u64) as usize;
            active[bi][v] = true;
        }
        active
    }

    /// Cuts block `b` with its active cross corridors (added to
    /// `corridors`) and fills the stretches between them with rooms.
    fn block(
        &mut self,
        inner: Rect,
        b: &Block,
        verts: &[(i64, i64)],
        active: &[bool],
        corridors: &mut Vec<Rect>,
    ) {
        let ti = self.ti;
        let mut cuts = Vec::new();
        for (&(x0, x1), _) in verts.iter().zip(active).filter(|(_, &a)| a) {
            let r = Rect::new(x0, b.seg_y0, x1, b.seg_y1);
            self.cv.fill(r, FREE);
            corridors.push(r);
            cuts.push((x0 - ti, x1 + ti));
        }
        let mut start = (inner.x0, false);
        let mut intervals = Vec::new();
        for &(a, e) in &cuts {
            intervals.push((start.0, a, start.1, true));
            start = (e, true);
        }
        intervals.push((start.0, inner.x1, start.1, false));
        for (a, e, lv, rv) in intervals {
            if e - a < self.s.c(MIN_INTERVAL) {
                continue;
            }
            self.block_interval(b, a, e, lv, rv);
        }
    }

    /// Benches, plants, cabinets and the like against corridor walls, never
    /// in front of a door or opening, never facing another item.
    fn corridor_items(&mut self, c: Rect) {
        let s = self.s;
        let horizontal = c.w() >= c.h();
        let (len, width) = if horizontal {
            (c.w(), c.h())
        } else {
            (c.h(), c.w())
        };
        if width < s.c(CORRIDOR_ITEMS_MIN_WIDTH) {
            return;
        }
        let pad = s.c(CORRIDOR_ITEM_PAD);
        let n = (s.m(len) / CORRIDOR_ITEM_PITCH * CORRIDOR_ITEM_FACTOR.sample(self.rng)) as usize;
        for _ in 0..n {
            let (along, depth, round) = match self.rng.below(4) {
                0 => (s.c(BENCH_LENGTH.sample(self.rng)), s.c(BENCH_DEPTH), false),
                1 => (s.c(PLANT_SIZE), s.c(PLANT_SIZE), true),
                2 => (
                    s.c(CABINET_LENGTH.sample(self.rng)),
                    s.c(CABINET_DEPTH),
                    false,
                ),
                _ => (s.c(COOLER_SIZE), s.c(COOLER_SIZE), false),
            };
            let depth = depth.min(width / CORRIDOR_ITEM_MAX_DEPTH_DIV).max(1);
            let p = irange(self.rng, 0, len - along + 1);
            let near = chance(self.rng, 0.5);
            let (item, wall, across) =
                corridor_item_rects(c, horizontal, near, p, along, depth, pad);
            if self.cv.all_eq(wall, OCCUPIED) && self.cv.all_eq(across, FREE) {
                if round {
                    self.cv.fill_ellipse(item, OCCUPIED);
                } else {
                    self.cv.fill(item, OCCUPIED);
                }
            }
        }
    }

    /// Horizontal bands: row, corridor, (row, row, corridor)*, row.
    fn plan_bands(&mut self, inner: Rect) -> Vec<Band> {
        let (s, ti) = (self.s, self.ti);
        let d = inner.h();
        let mut k = ((s.m(d) / BAND_PITCH).round() as usize).max(1);
        loop {
            let cws: Vec<i64> = (0..k)
                .map(|_| s.c(CORRIDOR_WIDTH.sample(self.rng)))
                .collect();
            let nb = 3 * k as i64;
            let avail = d - cws.iter().sum::<i64>() - (nb - 1) * ti;
            if avail >= 2 * k as i64 * s.c(MIN_ROW_DEPTH) {
                let depths = self.row_depths(avail, 2 * k);
                return stack_bands(inner.y0, ti, &cws, &depths);
            }
            if k == 1 {
                break;
            }
            k -= 1;
        }
        // Too shallow for rooms on both sides: one row along a corridor.
        let cw = s.c(SHALLOW_CORRIDOR_WIDTH.sample(self.rng));
        let row = d - cw - ti;
        if row >= s.c(SHALLOW_MIN_ROW_DEPTH) && inner.w() >= s.c(SHALLOW_MIN_WIDTH) {
            vec![
                Band {
                    y0: inner.y0,
                    y1: inner.y0 + row,
                    kind: BandKind::Row(Facing::Down),
                },
                Band {
                    y0: inner.y1 - cw,
                    y1: inner.y1,
                    kind: BandKind::Corridor,
                },
            ]
        } else {
            Vec::new()
        }
    }

    /// Splits `avail` cells of depth into `n` rows of random relative
    /// depths (the last one takes the rounding remainder).
    fn row_depths(&mut self, avail: i64, n: usize) -> Vec<i64> {
        let weights: Vec<f64> = (0..n).map(|_| ROW_DEPTH_WEIGHT.sample(self.rng)).collect();
        let total: f64 = weights.iter().sum();
        let mut depths: Vec<i64> = weights
            .iter()
            .map(|w| (avail as f64 * w / total).floor() as i64)
            .collect();
        let used: i64 = depths.iter().sum();
        if let Some(l) = depths.last_mut() {
            *l += avail - used;
        }
        depths
    }

    /// Cross-corridor x extents, sorted.
    fn plan_verticals(&mut self, inner: Rect, need: bool) -> Vec<(i64, i64)> {
        let s = self.s;
        let lm = s.m(inner.w());
        let mut nv = if lm < CROSS_MIN_FLOOR {
            0
        } else {
            (lm / CROSS_PITCH + CROSS_EXTRA.sample(self.rng)).floor() as i64
        };
        if need {
            nv = nv.max(1);
        }
        let mut out: Vec<(i64, i64)> = Vec::new();
        let spacing = inner.w() / (nv + 1);
        let beside = s.c(CROSS_MIN_ROOM);
        for i in 0..nv {
            let jitter = irange(
                self.rng,
                -spacing / CROSS_JITTER_DIV,
                spacing / CROSS_JITTER_DIV + 1,
            );
            let center = inner.x0 + spacing * (i + 1) + jitter;
            let vcw = s.c(CROSS_WIDTH.sample(self.rng));
            let lo = inner.x0 + beside + self.ti;
            let hi = inner.x1 - beside - self.ti - vcw;
            let mut x0 = clampi(center - vcw / 2, lo, hi);
            if let Some(&(_, px1)) = out.last() {
                x0 = x0.max(px1 + 2 * self.ti + beside);
            }
            if x0 + vcw > inner.x1 - self.ti {
                break;
            }
            out.push((x0, x0 + vcw));
        }
        out
    }

    /// Rooms of one block over `[a, e)`; `lv`/`rv`: a cross corridor lies
    /// beyond the left/right end.
    fn block_interval(&mut self, b: &Block, a: i64, e: i64, lv: bool, rv: bool) {
        let s = self.s;
        let ti = self.ti;
        if !b.outer && e - a >= s.c(HALL_MIN_INTERVAL) && chance(self.rng, HALL_CHANCE) {
            let hw = s.c(HALL_WIDTH.sample(self.rng)).min(e - a);
            let mut hx0 = irange(self.rng, a, e - hw + 1);
            let mut hx1 = hx0 + hw;
            let minw = s.c(HALL_MIN_ROOM) + ti;
            if hx0 - a < minw {
                hx0 = a;
            }
            if e - hx1 < minw {
                hx1 = e;
            }
            let (top, _) = b.rows[0];
            let (bot, _) = b.rows[b.rows.len() - 1];
            self.hall(Rect::new(hx0, top.y0, hx1, bot.y1));
            for &(row, f) in &b.rows {
                if hx0 > a {
                    self.row(row, f, a, hx0 - ti, lv, false);
                }
                if hx1 < e {
                    self.row(row, f, hx1 + ti, e, false, rv);
                }
            }
            return;
        }
        for &(row, f) in &b.rows {
            self.row(row, f, a, e, lv, rv);
        }
    }

    /// Splits `[a, e)` into room widths separated by walls.
    fn split_row(&mut self, a: i64, e: i64) -> Vec<(i64, i64)> {
        let s = self.s;
        let k = self.room_scale;
        let (minw, maxw) = (s.c(MIN_ROOM_WIDTH), s.c(MAX_ROOM_WIDTH * k));
        let mut out = Vec::new();
        let mut x = a;
        while e - x >= s.c(MIN_ROOM_REST) {
            let rem = e - x;
            let u = self.rng.uniform();
            let mut w = if u < NARROW_ROOM_SHARE {
                s.c(NARROW_ROOM_WIDTH.sample(self.rng))
            } else if u < ORDINARY_ROOM_SHARE {
                s.c(ORDINARY_ROOM_WIDTH.sample(self.rng) * k)
            } else {
                s.c(WIDE_ROOM_WIDTH.sample(self.rng) * k)
            };
            if rem - w - self.ti < minw {
                w = if rem > 2 * maxw {
                    (rem - self.ti) / 2
                } else {
                    rem
                };
            }
            out.push((x, x + w));
            x += w + self.ti;
        }
        out
    }

    /// Door start in `[lo, hi - dw]`: usually near one end, sometimes anywhere.
    fn door_pos(&mut self, lo: i64, hi: i64, dw: i64) -> i64 {
        let span = hi - lo - dw;
        if span <= 0 {
            return lo;
        }
        let e = self.s.c(DOOR_END_GAP).min(span);
        let jiggle = irange(self.rng, 0, self.s.c(DOOR_END_JIGGLE));
        let u = self.rng.uniform();
        let off = if u < DOOR_NEAR_START {
            (e + jiggle).min(span)
        } else if u < DOOR_NEAR_AN_END {
            span - (e + jiggle).min(span)
        } else {
            irange(self.rng, 0, span + 1)
        };
        lo + off
    }

    /// One row of rooms over `[a, e)`.
    fn row(&mut self, band: Band, facing: Facing, a: i64, e: i64, lv: bool, rv: bool) {
        let (s, ti) = (self.s, self.ti);
        let (y0, y1) = (band.y0, band.y1);
        let spans = self.split_row(a, e);
        let n = spans.len();
        if n == 0 {
            return;
        }
        let mut keeps: Vec<Vec<Rect>> = vec![Vec::new(); n];
        let mut linked = vec![false; n];
        let pad = s.c(DOOR_PAD);
        let reach = s.c(DOOR_REACH);
        let dw = self.dw.min(y1 - y0);
        // Doors between neighbouring rooms.
        for i in 0..n - 1 {
            if y1 - y0 >= dw + 2 * pad && chance(self.rng, LINK_DOOR_CHANCE) {
                let y = self.door_pos(y0, y1, dw);
                let (xl, xr) = (spans[i].1, spans[i + 1].0);
                self.cv.fill(Rect::new(xl, y, xr, y + dw), FREE);
                keeps[i].push(Rect::new(xl - reach, y - pad, xl, y + dw + pad));
                keeps[i + 1].push(Rect::new(xr, y - pad, xr + reach, y + dw + pad));
                linked[i] = true;
                linked[i + 1] = true;
            }
        }
        // Side doors into cross corridors.
        if lv && chance(self.rng, SIDE_DOOR_CHANCE) {
            let y = self.door_pos(y0, y1, dw);
            self.cv.fill(Rect::new(a - ti, y, a, y + dw), FREE);
            keeps[0].push(Rect::new(a, y - pad, a + reach, y + dw + pad));
            linked[0] = true;
        }
        if rv && chance(self.rng, SIDE_DOOR_CHANCE) {
            let y = self.door_pos(y0, y1, dw);
            let xr = spans[n - 1].1;
            self.cv.fill(Rect::new(xr, y, xr + ti, y + dw), FREE);
            keeps[n - 1].push(Rect::new(xr - reach, y - pad, xr, y + dw + pad));
            linked[n - 1] = true;
        }
        for (i, &(x0, x1)) in spans.iter().enumerate() {
            self.room(Rect::new(x0, y0, x1, y1), facing, &keeps[i], linked[i]);
        }
    }

    /// Door (wall cells) and keep-clear zone (room cells) for a door at
    /// `[dx, dx + dw)` in the corridor-side wall of `r`, the zone `reach`
    /// cells deep.
    fn front_door(&self, r: Rect, facing: Facing, dx: i64, dw: i64, reach: i64) -> (Rect, Rect) {
        let pad = self.s.c(DOOR_PAD);
        match facing {
            Facing::Up => (
                Rect::new(dx, r.y0 - self.ti, dx + dw, r.y0),
                door_approach(dx, dw, r.y0, pad, reach, true),
            ),
            Facing::Down => (
                Rect::new(dx, r.y1, dx + dw, r.y1 + self.ti),
                door_approach(dx, dw, r.y1, pad, reach, false),
            ),
        }
    }

    /// One room of a row: an alcove, a suite or a plain room with a door
    /// onto the corridor; `keep_in`: zones of its other doors.
    fn room(&mut self, r: Rect, facing: Facing, keep_in: &[Rect], linked: bool) {
        let s = self.s;
        self.cv.fill(r, FREE);
        let mut keep = keep_in.to_vec();
        if !linked && r.w() >= s.c(ALCOVE_MIN_WIDTH) && chance(self.rng, ALCOVE_CHANCE) {
            self.alcove(r, facing, keep);
            return;
        }
        let dw = if r.w() >= s.c(WIDE_DOOR_MIN_ROOM) && chance(self.rng, WIDE_DOOR_CHANCE) {
            s.c(WIDE_DOOR_WIDTH)
        } else {
            self.dw
        }
        .min(r.w());
        let dx = self.door_pos(r.x0, r.x1, dw);
        let (door, dkeep) = self.front_door(r, facing, dx, dw, s.c(DOOR_REACH));
        self.cv.fill(door, FREE);
        keep.push(dkeep);
        let depth = r.h();
        if !linked
            && depth >= s.c(SUITE_MIN_DEPTH)
            && r.w() >= s.c(SUITE_MIN_WIDTH)
            && chance(self.rng, SUITE_CHANCE)
            && self.suite(r, facing, &mut keep)
        {
            return;
        }
        self.furnish(r, &keep, false);
        self.rooms += 1;
    }

    /// An open alcove (lounge) on the corridor: the corridor wall removed
    /// but for a stub at each side.
    fn alcove(&mut self, r: Rect, facing: Facing, mut keep: Vec<Rect>) {
        let (s, ti) = (self.s, self.ti);
        let stub = s.c(ALCOVE_STUB);
        let strip_depth = s.c(ALCOVE_CLEAR_DEPTH);
        let (wall, strip) = match facing {
            Facing::Up => (
                Rect::new(r.x0 + stub, r.y0 - ti, r.x1 - stub, r.y0),
                Rect::new(r.x0, r.y0, r.x1, r.y0 + strip_depth),
            ),
            Facing::Down => (
                Rect::new(r.x0 + stub, r.y1, r.x1 - stub, r.y1 + ti),
                Rect::new(r.x0, r.y1 - strip_depth, r.x1, r.y1),
            ),
        };
        self.cv.fill(wall, FREE);
        keep.push(strip);
        self.furnish_as(r, &keep, Furnishing::Lounge);
        self.rooms += 1;
    }

    /// Splits room `r` into a front room off the corridor and a back room
    /// behind it, joined by a door, and furnishes both; false (nothing
    /// drawn) when either would be too shallow.
    fn suite(&mut self, r: Rect, facing: Facing, keep: &mut Vec<Rect>) -> bool {
        let (s, ti) = (self.s, self.ti);
        let depth = r.h();
        let fd = (depth as f64 * SUITE_FRONT_SHARE.sample(self.rng)) as i64;
        let bd = depth - fd - ti;
        if fd < s.c(SUITE_MIN_ROOM_DEPTH) || bd < s.c(SUITE_MIN_ROOM_DEPTH) {
            return false;
        }
        let (front, wall_y, back) = match facing {
            Facing::Down => (
                Rect::new(r.x0, r.y1 - fd, r.x1, r.y1),
                r.y1 - fd - ti,
                Rect::new(r.x0, r.y0, r.x1, r.y1 - fd - ti),
            ),
            Facing::Up => (
                Rect::new(r.x0, r.y0, r.x1, r.y0 + fd),
                r.y0 + fd,
                Rect::new(r.x0, r.y0 + fd + ti, r.x1, r.y1),
            ),
        };
        self.cv
            .fill(Rect::new(r.x0, wall_y, r.x1, wall_y + ti), OCCUPIED);
        let idw = self.dw.min(r.w());
        let ix = self.door_pos(r.x0, r.x1, idw);
        self.cv
            .fill(Rect::new(ix, wall_y, ix + idw, wall_y + ti), FREE);
        let (pad, reach) = (s.c(DOOR_PAD), s.c(DOOR_REACH));
        keep.push(Rect::new(
            ix - pad,
            wall_y - reach,
            ix + idw + pad,
            wall_y + ti + reach,
        ));
        self.furnish(front, keep, false);
        self.furnish(back, keep, false);
        self.rooms += 2;
        true
    }

    /// A hall spanning both rows of a block, with doors onto both corridors.
    fn hall(&mut self, r: Rect) {
        let s = self.s;
        self.cv.fill(r, FREE);
        let mut keep = Vec::new();
        let reach = s.c(HALL_DOOR_REACH);
        let dw = s.c(WIDE_DOOR_WIDTH).min(r.w());
        for facing in [Facing::Up, Facing::Down] {
            let n = 1 + self.rng.below(HALL_EXTRA_DOORS);
            for _ in 0..n {
                let dx = irange(self.rng, r.x0, r.x1 - dw + 1);
                let (door, dkeep) = self.front_door(r, facing, dx, dw, reach);
                self.cv.fill(door, FREE);
                keep.push(dkeep);
            }
        }
        self.furnish(r, &keep, true);
        self.rooms += 1;
    }
}

/// Bands stacked from `y0` down, `ti` apart: a row facing down, then per
/// corridor width in `cws` the corridor, a row facing up and (but after
/// the last corridor) a row facing down; `depths` are the rows' depths.
fn stack_bands(y0: i64, ti: i64, cws: &[i64], depths: &[i64]) -> Vec<Band> {
    let k = cws.len();
    let mut bands = Vec::with_capacity(3 * k);
    let mut y = y0;
    let mut push = |len: i64, kind: BandKind| {
        bands.push(Band {
            y0: y,
            y1: y + len,
            kind,
        });
        y += len + ti;
    };
    push(depths[0], BandKind::Row(Facing::Down));
    for (i, &cw) in cws.iter().enumerate() {
        push(cw, BandKind::Corridor);
        push(depths[2 * i + 1], BandKind::Row(Facing::Up));
        if i + 1 < k {
            push(depths[2 * i + 2], BandKind::Row(Facing::Down));
        }
    }
    bands
}

/// A corridor item at `p` cells along corridor `c` on its near (low) or
/// far side: the item, the wall strip behind it (must be wall) and the
/// corridor cross-section in front of it (must be free), each `pad` cells
/// longer at both ends.
fn corridor_item_rects(
    c: Rect,
    horizontal: bool,
    near: bool,
    p: i64,
    along: i64,
    depth: i64,
    pad: i64,
) -> (Rect, Rect, Rect) {
    // Worked out for a horizontal corridor, then transposed back.
    let c = if horizontal { c } else { transpose(c) };
    let x = c.x0 + p;
    let (item, wall) = if near {
        (
            Rect::new(x, c.y0, x + along, c.y0 + depth),
            Rect::new(x - pad, c.y0 - 1, x + along + pad, c.y0),
        )
    } else {
        (
            Rect::new(x, c.y1 - depth, x + along, c.y1),
            Rect::new(x - pad, c.y1, x + along + pad, c.y1 + 1),
        )
    };
    let across = Rect::new(x - pad, c.y0, x + along + pad, c.y1);
    if horizontal {
        (item, wall, across)
    } else {
        (transpose(item), transpose(wall), transpose(across))
    }
}

/// `r` mirrored at the diagonal (x and y swapped).
fn transpose(r: Rect) -> Rect {
    Rect::new(r.y0, r.x0, r.y1, r.x1)
}
