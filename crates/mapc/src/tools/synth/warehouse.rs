//! Warehouses: one or more large halls separated by fire walls with
//! openings; each hall has a storage zone (rack rows with aisles, or
//! block-stacked pallets), a loading area with dock doors, staging lanes
//! and pallet groups, structural pillars and sometimes a small office
//! block. Very small buildings are a shed with a few pallet stacks.
//!
//! Each hall is laid out in a local frame with its loading area at the
//! bottom ([`Warehouse::map`] mirrors it when the loading side is on top).

use super::draw::{
    chance, clampi, door_approach, irange, Canvas, Furn, Outline, Rect, Scale, Span,
};
use super::{Stats, FREE, OCCUPIED};
use crate::compiler::rng::Rng;

// ---------------------------------------------------------------------------
// Parameters (m: metres; probabilities are per choice)
// ---------------------------------------------------------------------------

/// Outer wall thickness (m).
const OUTER_WALL: f64 = 0.3;
/// Fire wall thickness between halls (m).
const FIRE_WALL: f64 = 0.3;
/// Interior (office) wall thickness (m).
const INNER_WALL: f64 = 0.15;
/// About one hall per this much building length, per axis (m).
const HALL_LENGTH: f64 = 150.0;
/// A fire wall is moved at random by up to a hall's length divided by
/// this (either way).
const FIRE_WALL_JITTER_DIV: i64 = 6;
/// A building narrower (m) than this is a shed.
const SHED_MAX_WIDTH: f64 = 14.0;
/// A building shallower (m) than this is a shed.
const SHED_MAX_DEPTH: f64 = 10.0;
/// Free band along a shed's walls (m).
const SHED_WALL_GAP: f64 = 0.8;
/// Clearance between pallet stacks (m).
const PALLET_CLEARANCE: f64 = 1.0;
/// Floor area per shed pallet stack (m²).
const SHED_AREA_PER_PALLET: f64 = 20.0;
/// Pallet length (m).
const PALLET_LENGTH: f64 = 1.2;
/// Pallet width (m).
const PALLET_WIDTH: f64 = 1.0;

/// Width of an opening in a fire wall (m).
const OPENING_WIDTH: f64 = 4.0;
/// Smallest distance of an opening from the end of its wall (m).
const OPENING_END_GAP: f64 = 3.0;
/// Openings per fire wall section: one plus a draw below this.
const EXTRA_OPENINGS: u64 = 2;

/// Depth of the loading (staging) area (m), at least
/// [`MIN_STAGING_DEPTH`] and at most 2/5 of the hall.
const STAGING_DEPTH: Span = Span::new(8.0, 14.0);
/// Smallest depth of the loading area (m).
const MIN_STAGING_DEPTH: f64 = 4.0;
/// Perimeter aisle between the walls and the storage zone (m).
const PERIMETER_AISLE: Span = Span::new(1.8, 2.6);
/// Smallest side of a storage zone (m).
const MIN_ZONE: f64 = 4.0;
/// Probability that a storage zone has racks (else block stacking).
const RACKS_CHANCE: f64 = 0.75;

/// Probability of an office block in a loading-side corner.
const OFFICE_CHANCE: f64 = 0.7;
/// Width of the office block (m; at most a third of the hall).
const OFFICE_WIDTH: Span = Span::new(7.0, 12.0);
/// Depth of the office block (m; at most the loading depth minus
/// [`OFFICE_DEPTH_MARGIN`]).
const OFFICE_DEPTH: Span = Span::new(4.0, 6.0);
/// Loading depth the office block leaves free (m).
const OFFICE_DEPTH_MARGIN: f64 = 3.0;
/// Smallest width and depth of an office block (m).
const OFFICE_MIN_SIDE: f64 = 3.0;
/// Zone kept free of pallets and pillars around the office block (m).
const OFFICE_KEEP_CLEAR: f64 = 2.5;
/// Office rooms: one plus a draw below this.
const OFFICE_EXTRA_ROOMS: u64 = 3;
/// Smallest office room width (m).
const OFFICE_MIN_ROOM: f64 = 2.4;
/// Office door width (m).
const OFFICE_DOOR: f64 = 0.9;
/// Keep-clear zone of an office door: extra width on each side (m).
const OFFICE_DOOR_PAD: f64 = 0.3;
/// Keep-clear zone of an office door: depth into the room (m).
const OFFICE_DOOR_REACH: f64 = 1.0;
/// Clearance between office furniture (m).
const OFFICE_CLEARANCE: f64 = 0.6;
/// Desks per office room: one plus a draw below this.
const OFFICE_EXTRA_DESKS: u64 = 2;
/// Office desk length (m).
const OFFICE_DESK_LENGTH: Span = Span::new(1.2, 1.6);
/// Office desk depth (m).
const OFFICE_DESK_DEPTH: f64 = 0.7;
/// Placement tries of an office desk.
const OFFICE_DESK_TRIES: usize = 12;

/// Width of a dock door (m).
const DOCK_WIDTH: f64 = 3.0;
/// Wall between dock doors (m).
const DOCK_GAP: Span = Span::new(0.8, 1.8);
/// Smallest distance of a dock door from a hall corner or the office
/// block (m).
const DOCK_END_GAP: f64 = 3.0;
/// Share of the free loading wall that has docks.
const DOCK_STRETCH: Span = Span::new(0.4, 1.0);
/// Width of a dock bumper (m).
const BUMPER_WIDTH: f64 = 0.25;
/// Depth of a dock bumper (m).
const BUMPER_DEPTH: f64 = 0.45;

/// Start of the staging lanes below the loading area's top (m).
const LANE_TOP: f64 = 2.8;
/// Free apron between the staging lanes and the dock wall (m).
const APRON: f64 = 1.5;
/// Probability of a staging lane in front of a dock door.
const LANE_CHANCE: f64 = 0.6;
/// Shortest staging lane (m), also the width of one pallet lane.
const LANE_MIN: f64 = 1.2;
/// Length of a staging lane (m).
const LANE_LENGTH: Span = Span::new(2.4, 7.0);
/// Pallet lanes side by side in a staging lane: one plus a draw below this.
const LANE_EXTRA_WIDTH: u64 = 2;
/// Zone kept free of yard pallets around a staging lane (m).
const LANE_KEEP_CLEAR: f64 = 1.0;
/// Free band beside the yard at the hall's side walls (m).
const YARD_SIDE_GAP: f64 = 2.0;
/// Free band below the yard at the dock wall (m).
const YARD_BOTTOM_GAP: f64 = 1.2;
/// Yard floor area per pallet group (m²).
const YARD_AREA_PER_GROUP: f64 = 12.0;
/// Pallets per group along x: one plus a draw below this.
const GROUP_EXTRA_X: u64 = 3;
/// Pallets per group along y: one plus a draw below this.
const GROUP_EXTRA_Y: u64 = 2;

/// Pillar spacing, per axis (m).
const PILLAR_STEP: Span = Span::new(10.0, 13.0);
/// Pillar side (m).
const PILLAR_SIZE: Span = Span::new(0.4, 0.6);
/// Smallest offset of the first pillar from the hall's corner (m).
const PILLAR_OFFSET: f64 = 2.0;
/// Free band of a hall's loading wall without pillars (m).
const PILLAR_BOTTOM_GAP: f64 = 1.5;
/// Free band of a hall's right wall without pillars (m).
const PILLAR_RIGHT_GAP: f64 = 1.0;

/// Aisle between rack lines (m).
const RACK_AISLE: Span = Span::new(2.6, 3.5);
/// Depth of a single rack (m); double racks are twice as deep.
const RACK_DEPTH: Span = Span::new(1.0, 1.3);
/// Length of a rack bay (m).
const RACK_BAY: Span = Span::new(2.5, 2.9);
/// Width of a cross aisle (m).
const CROSS_AISLE: Span = Span::new(2.8, 3.6);
/// Length of a rack run between cross aisles (m).
const RACK_RUN: Span = Span::new(12.0, 25.0);
/// A run ending closer than this to the zone's end reaches it (m).
const MIN_RACK_RUN: f64 = 6.0;
/// Probability that a run of a rack line is missing.
const MISSING_RUN_CHANCE: f64 = 0.05;
/// Probability that a run starts (and, again, ends) one or two bays short.
const SHORT_RUN_CHANCE: f64 = 0.15;
/// Probability that a bay is missing.
const MISSING_BAY_CHANCE: f64 = 0.04;
/// Runs longer than this may have a pallet left in the aisle (m).
const AISLE_PALLET_MIN_RUN: f64 = 3.0;
/// Probability of a pallet left in the aisle beside a run.
const AISLE_PALLET_CHANCE: f64 = 0.12;

/// Aisle between block-stacked lanes (m).
const BULK_AISLE: Span = Span::new(3.0, 3.8);
/// Width of a block-stacked lane (m).
const BULK_WIDTH: Span = Span::new(2.4, 4.8);
/// Length of a block stack (m).
const BULK_LENGTH: Span = Span::new(3.0, 9.0);
/// Gap between block stacks (m).
const BULK_GAP: Span = Span::new(1.5, 3.0);
/// Probability that a block stack is missing.
const MISSING_STACK_CHANCE: f64 = 0.2;

// ---------------------------------------------------------------------------
// Generator
// ---------------------------------------------------------------------------

/// Which sides of a hall are the building's outer wall.
#[derive(Clone, Copy, Debug)]
struct Outer {
    left: bool,
    right: bool,
    top: bool,
    bottom: bool,
}

struct Warehouse<'a> {
    cv: &'a mut Canvas,
    rng: &'a mut Rng,
    s: Scale,
    /// Outer wall thickness, cells.
    tw: i64,
    /// Current hall, and whether its local frame is mirrored vertically
    /// (local frame: loading area at the bottom).
    hall: Rect,
    flip: bool,
    rooms: usize,
}

/// Draws a warehouse on `cv`; returns a free point (layout cells).
pub(super) fn warehouse(cv: &mut Canvas, rng: &mut Rng, s: Scale, stats: &mut Stats) -> (i64, i64) {
    let outline = Outline::new(cv.lw(), cv.lh(), s, OUTER_WALL);
    cv.fill_building(&outline);
    let inner = outline.inner;
    let mut wh = Warehouse {
        cv,
        rng,
        s,
        tw: outline.wall,
        hall: inner,
        flip: false,
        rooms: 0,
    };
    let hint = wh.run(inner);
    stats.rooms = wh.rooms;
    hint
}

impl Warehouse<'_> {
    /// Local hall rectangle -> layout rectangle.
    fn map(&self, r: Rect) -> Rect {
        if self.flip {
            let h = self.hall;
            Rect::new(r.x0, h.y0 + h.y1 - r.y1, r.x1, h.y0 + h.y1 - r.y0)
        } else {
            r
        }
    }

    fn fill(&mut self, r: Rect, v: u8) {
        let r = self.map(r);
        self.cv.fill(r, v);
    }

    fn run(&mut self, inner: Rect) -> (i64, i64) {
        let s = self.s;
        if inner.w() < s.c(SHED_MAX_WIDTH) || inner.h() < s.c(SHED_MAX_DEPTH) {
            self.shed(inner);
            return (inner.x0, inner.y0);
        }
        let tf = s.c(FIRE_WALL);
        let xs = self.cuts(inner.x0, inner.x1, tf);
        let ys = self.cuts(inner.y0, inner.y1, tf);
        let mut hint = (inner.x0, inner.y0);
        for (j, &(y0, y1)) in ys.iter().enumerate() {
            for (i, &(x0, x1)) in xs.iter().enumerate() {
                let outer = Outer {
                    left: i == 0,
                    right: i + 1 == xs.len(),
                    top: j == 0,
                    bottom: j + 1 == ys.len(),
                };
                let p = self.layout_hall(Rect::new(x0, y0, x1, y1), outer);
                if i == 0 && j == 0 {
                    hint = p;
                }
            }
        }
        // Openings in the fire walls between halls.
        for pair in xs.windows(2) {
            let (wx0, wx1) = (pair[0].1, pair[1].0);
            for &(y0, y1) in &ys {
                for _ in 0..1 + self.rng.below(EXTRA_OPENINGS) {
                    let (y, o) = self.opening(y0, y1);
                    self.cv.fill(Rect::new(wx0, y, wx1, y + o), FREE);
                }
            }
        }
        for pair in ys.windows(2) {
            let (wy0, wy1) = (pair[0].1, pair[1].0);
            for &(x0, x1) in &xs {
                for _ in 0..1 + self.rng.below(EXTRA_OPENINGS) {
                    let (x, o) = self.opening(x0, x1);
                    self.cv.fill(Rect::new(x, wy0, x + o, wy1), FREE);
                }
            }
        }
        hint
    }

    /// A shed: open floor with a few pallet stacks.
    fn shed(&mut self, inner: Rect) {
        let s = self.s;
        self.cv.fill(inner, FREE);
        let clr = s.c(PALLET_CLEARANCE);
        let mut f = Furn::new(inner.shrink(s.c(SHED_WALL_GAP)), &[], clr);
        let n = (s.m(inner.w()) * s.m(inner.h()) / SHED_AREA_PER_PALLET) as usize + 1;
        for _ in 0..n {
            let (pw, ph) = (s.c(PALLET_LENGTH), s.c(PALLET_WIDTH));
            let r = f.random_spot(self.rng, pw, ph);
            if f.add(r) {
                self.cv.fill(r, OCCUPIED);
            }
        }
    }

    /// A random opening in a fire wall section spanning `[lo, hi)`: its
    /// start and width (cells).
    fn opening(&mut self, lo: i64, hi: i64) -> (i64, i64) {
        let s = self.s;
        let end = s.c(OPENING_END_GAP);
        let o = s.c(OPENING_WIDTH).min(hi - lo - 2);
        let p = irange(self.rng, lo + end, hi - end - o + 1);
        (clampi(p, lo + 1, hi - 1 - o), o)
    }

    /// Splits `[lo, hi)` into halls about [`HALL_LENGTH`] long separated by
    /// `tf`-thick fire walls.
    fn cuts(&mut self, lo: i64, hi: i64, tf: i64) -> Vec<(i64, i64)> {
        let n = ((self.s.m(hi - lo) / HALL_LENGTH).round() as i64).max(1);
        let part = (hi - lo) / n;
        let mut out = Vec::new();
        let mut start = lo;
        for i in 1..n {
            let jitter = part / FIRE_WALL_JITTER_DIV;
            let p = lo + part * i + irange(self.rng, -jitter, jitter + 1);
            out.push((start, p));
            start = p + tf;
        }
        out.push((start, hi));
        out
    }

    /// Lays out one hall; returns a free point (layout coordinates).
    fn layout_hall(&mut self, h: Rect, outer: Outer) -> (i64, i64) {
        let s = self.s;
        self.hall = h;
        self.flip = false;
        self.cv.fill(h, FREE);
        self.flip = if outer.bottom == outer.top {
            chance(self.rng, 0.5)
        } else {
            outer.top
        };
        let staging_outer = if self.flip { outer.top } else { outer.bottom };
        let sd = clampi(
            s.c(STAGING_DEPTH.sample(self.rng)),
            s.c(MIN_STAGING_DEPTH),
            h.h() * 2 / 5,
        );
        let pa = s.c(PERIMETER_AISLE.sample(self.rng));
        let zone = Rect::new(h.x0 + pa, h.y0 + pa, h.x1 - pa, h.y1 - sd);
        let office =
            if staging_outer && (outer.left || outer.right) && chance(self.rng, OFFICE_CHANCE) {
                self.office_corner(h, outer, sd)
            } else {
                None
            };
        let office_keep = office.map(|b| b.grow(s.c(OFFICE_KEEP_CLEAR)));
        if zone.w() >= s.c(MIN_ZONE) && zone.h() >= s.c(MIN_ZONE) {
            if chance(self.rng, RACKS_CHANCE) {
                self.racks(zone);
            } else {
                self.bulk(zone);
            }
        }
        let docks = if staging_outer {
            self.docks(h, office)
        } else {
            Vec::new()
        };
        let lane_top = h.y1 - sd + s.c(LANE_TOP);
        let mut blocked: Vec<Rect> = office_keep.into_iter().collect();
        self.staging_lanes(h, lane_top, &docks, &mut blocked);
        self.yard(h, lane_top, &blocked);
        self.pillars(h, office_keep);
        let p = self.map(Rect::new(h.x0, h.y0, h.x0 + 1, h.y0 + 1));
        (p.x0, p.y0)
    }

    /// An office block in a loading-side corner of hall `h` (loading depth
    /// `sd` cells) on the outer wall; returns the block, if it fits.
    fn office_corner(&mut self, h: Rect, outer: Outer, sd: i64) -> Option<Rect> {
        let s = self.s;
        let ti = s.c(INNER_WALL);
        let bw = s.c(OFFICE_WIDTH.sample(self.rng)).min(h.w() / 3);
        let bd = s
            .c(OFFICE_DEPTH.sample(self.rng))
            .min(sd - s.c(OFFICE_DEPTH_MARGIN));
        let left = if outer.left && outer.right {
            chance(self.rng, 0.5)
        } else {
            outer.left
        };
        let min = s.c(OFFICE_MIN_SIDE);
        if bd < min || bw < min {
            return None;
        }
        let (block, area) = if left {
            (
                Rect::new(h.x0, h.y1 - bd, h.x0 + bw, h.y1),
                Rect::new(h.x0, h.y1 - bd + ti, h.x0 + bw - ti, h.y1),
            )
        } else {
            (
                Rect::new(h.x1 - bw, h.y1 - bd, h.x1, h.y1),
                Rect::new(h.x1 - bw + ti, h.y1 - bd + ti, h.x1, h.y1),
            )
        };
        self.office_block(block, area, ti);
        Some(block)
    }

    /// Staging lanes of pallets in front of some dock doors, leaving a main
    /// aisle along the rack zone and an apron at the wall; their keep-clear
    /// zones are added to `blocked`.
    fn staging_lanes(
        &mut self,
        h: Rect,
        lane_top: i64,
        docks: &[(i64, i64)],
        blocked: &mut Vec<Rect>,
    ) {
        let s = self.s;
        let apron = s.c(APRON);
        for &(dx, dwk) in docks {
            let room = h.y1 - apron - lane_top;
            if chance(self.rng, LANE_CHANCE) && room >= s.c(LANE_MIN) {
                let len = s.c(LANE_LENGTH.sample(self.rng)).min(room);
                let lw = (s.c(LANE_MIN) * (1 + self.rng.below(LANE_EXTRA_WIDTH) as i64)).min(dwk);
                let x = dx + (dwk - lw) / 2;
                let r = Rect::new(x, h.y1 - apron - len, x + lw, h.y1 - apron);
                self.fill(r, OCCUPIED);
                blocked.push(r.grow(s.c(LANE_KEEP_CLEAR)));
            }
        }
    }

    /// Pallet groups in the rest of the loading area, outside `blocked`.
    fn yard(&mut self, h: Rect, lane_top: i64, blocked: &[Rect]) {
        let s = self.s;
        let yard = Rect::new(
            h.x0 + s.c(YARD_SIDE_GAP),
            lane_top,
            h.x1 - s.c(YARD_SIDE_GAP),
            h.y1 - s.c(YARD_BOTTOM_GAP),
        );
        if yard.is_empty() {
            return;
        }
        let mut f = Furn::new(yard, blocked, s.c(PALLET_CLEARANCE));
        let n = (s.m(yard.w()) * s.m(yard.h()) / YARD_AREA_PER_GROUP) as usize + 1;
        for _ in 0..n {
            let nx = 1 + self.rng.below(GROUP_EXTRA_X) as i64;
            let ny = 1 + self.rng.below(GROUP_EXTRA_Y) as i64;
            let (mut pw, mut ph) = (s.c(PALLET_LENGTH) * nx, s.c(PALLET_WIDTH) * ny);
            if chance(self.rng, 0.5) {
                std::mem::swap(&mut pw, &mut ph);
            }
            let r = f.random_spot(self.rng, pw, ph);
            if f.add(r) {
                self.fill(r, OCCUPIED);
            }
        }
    }

    /// Structural pillars on a regular grid, none in `office_keep`.
    fn pillars(&mut self, h: Rect, office_keep: Option<Rect>) {
        let s = self.s;
        let sx = s.c(PILLAR_STEP.sample(self.rng));
        let sy = s.c(PILLAR_STEP.sample(self.rng));
        let ps = s.c(PILLAR_SIZE.sample(self.rng));
        let off = s.c(PILLAR_OFFSET);
        let ox = irange(self.rng, off, off + sx);
        let oy = irange(self.rng, off, off + sy);
        let mut y = h.y0 + oy;
        while y + ps < h.y1 - s.c(PILLAR_BOTTOM_GAP) {
            let mut x = h.x0 + ox;
            while x + ps < h.x1 - s.c(PILLAR_RIGHT_GAP) {
                let r = Rect::new(x, y, x + ps, y + ps);
                if !office_keep.is_some_and(|k| k.intersects(&r)) {
                    self.fill(r, OCCUPIED);
                }
                x += sx;
            }
            y += sy;
        }
    }

    /// Small office rooms in `area` (local frame) with doors into the hall.
    fn office_block(&mut self, block: Rect, area: Rect, ti: i64) {
        let s = self.s;
        self.fill(block, OCCUPIED);
        let n = (1 + self.rng.below(OFFICE_EXTRA_ROOMS) as i64)
            .min((area.w() + ti) / (s.c(OFFICE_MIN_ROOM) + ti))
            .max(1);
        let rw = (area.w() - (n - 1) * ti) / n;
        let dw = s.c(OFFICE_DOOR).min(rw);
        for i in 0..n {
            let x0 = area.x0 + i * (rw + ti);
            let x1 = if i + 1 == n { area.x1 } else { x0 + rw };
            let r = Rect::new(x0, area.y0, x1, area.y1);
            self.fill(r, FREE);
            let dx = irange(self.rng, r.x0, r.x1 - dw + 1);
            self.fill(Rect::new(dx, r.y0 - ti, dx + dw, r.y0), FREE);
            let (pad, reach) = (s.c(OFFICE_DOOR_PAD), s.c(OFFICE_DOOR_REACH));
            let keep = [door_approach(dx, dw, r.y0, pad, reach, true)];
            let mut f = Furn::new(r, &keep, s.c(OFFICE_CLEARANCE));
            for _ in 0..1 + self.rng.below(OFFICE_EXTRA_DESKS) {
                let along = s.c(OFFICE_DESK_LENGTH.sample(self.rng));
                let depth = s.c(OFFICE_DESK_DEPTH);
                if let Some(spot) = f.add_on_wall(self.rng, along, depth, OFFICE_DESK_TRIES) {
                    self.fill(spot, OCCUPIED);
                }
            }
            self.rooms += 1;
        }
    }

    /// Dock doors (recesses in the outer wall) with bumpers, along the
    /// loading side; returns each door's (x, width).
    fn docks(&mut self, h: Rect, office: Option<Rect>) -> Vec<(i64, i64)> {
        let s = self.s;
        let dwk = s.c(DOCK_WIDTH);
        let pitch = dwk + s.c(DOCK_GAP.sample(self.rng));
        let end = s.c(DOCK_END_GAP);
        let (mut lo, mut hi) = (h.x0 + end, h.x1 - end);
        if let Some(b) = office {
            if b.x0 <= h.x0 {
                lo = lo.max(b.x1 + end);
            } else {
                hi = hi.min(b.x0 - end);
            }
        }
        // Docks over a random stretch of the wall.
        let span = hi - lo;
        let mut out = Vec::new();
        if span < pitch {
            return out;
        }
        let len = (span as f64 * DOCK_STRETCH.sample(self.rng)) as i64;
        let start = lo + irange(self.rng, 0, span - len + 1);
        let (bw, bd) = (s.c(BUMPER_WIDTH), s.c(BUMPER_DEPTH));
        let recess = self.tw / 2;
        let mut x = start;
        while x + dwk <= start + len {
            if recess >= 1 {
                self.fill(Rect::new(x, h.y1, x + dwk, h.y1 + recess), FREE);
            }
            self.fill(Rect::new(x - bw, h.y1 - bd, x, h.y1), OCCUPIED);
            self.fill(Rect::new(x + dwk, h.y1 - bd, x + dwk + bw, h.y1), OCCUPIED);
            out.push((x, dwk));
            x += pitch;
        }
        out
    }

    /// Rack rows (long in y) with aisles, cross aisles, missing sections and
    /// bays, and the odd pallet left in an aisle.
    fn racks(&mut self, zone: Rect) {
        let s = self.s;
        let aisle = s.c(RACK_AISLE.sample(self.rng));
        let single = s.c(RACK_DEPTH.sample(self.rng));
        let bay = s.c(RACK_BAY.sample(self.rng));
        let cross = s.c(CROSS_AISLE.sample(self.rng));
        let segs = self.rack_runs(zone, cross);
        // Rack lines: single against the zone edges, double in between,
        // the pattern centred in the zone.
        let mut lines = Vec::new();
        let mut x = 0;
        loop {
            let rem = zone.w() - x;
            let rw = if lines.is_empty() || rem < 3 * single + aisle {
                single
            } else {
                2 * single
            };
            if rw > rem {
                break;
            }
            lines.push((x, rw));
            x += rw + aisle;
        }
        let used = lines.last().map_or(0, |&(x, rw)| x + rw);
        let shift = zone.x0 + (zone.w() - used) / 2;
        for (lx, rw) in lines {
            let x = lx + shift;
            for &(y0, y1) in &segs {
                if chance(self.rng, MISSING_RUN_CHANCE) {
                    continue;
                }
                self.rack_run(zone, (x, rw), (y0, y1), bay, aisle);
            }
        }
    }

    /// The runs `[y0, y1)` of the rack lines between cross aisles `cross`
    /// cells wide.
    fn rack_runs(&mut self, zone: Rect, cross: i64) -> Vec<(i64, i64)> {
        let s = self.s;
        let mut segs = Vec::new();
        let mut y = zone.y0;
        while y < zone.y1 {
            let len = s.c(RACK_RUN.sample(self.rng));
            let mut end = (y + len).min(zone.y1);
            if zone.y1 - end < s.c(MIN_RACK_RUN) {
                end = zone.y1;
            }
            segs.push((y, end));
            y = end + cross;
        }
        segs
    }

    /// One run `[y0, y1)` of the rack line `(x, rw)` (start and depth,
    /// cells), in bays of `bay` cells, perhaps shortened, with a pallet
    /// perhaps left in the aisle (`aisle` cells) beside it.
    fn rack_run(&mut self, zone: Rect, line: (i64, i64), run: (i64, i64), bay: i64, aisle: i64) {
        let s = self.s;
        let ((x, rw), (y0, y1)) = (line, run);
        let (mut ya, mut yb) = (y0, y1);
        if chance(self.rng, SHORT_RUN_CHANCE) {
            ya += bay * (1 + self.rng.below(2) as i64);
        }
        if chance(self.rng, SHORT_RUN_CHANCE) {
            yb -= bay * (1 + self.rng.below(2) as i64);
        }
        let mut by = ya;
        while by < yb {
            let mut be = (by + bay).min(yb);
            if yb - be < bay / 2 {
                be = yb;
            }
            if !chance(self.rng, MISSING_BAY_CHANCE) {
                self.fill(Rect::new(x, by, x + rw, be), OCCUPIED);
            }
            by = be;
        }
        if x + rw + aisle <= zone.x1
            && yb - ya > s.c(AISLE_PALLET_MIN_RUN)
            && chance(self.rng, AISLE_PALLET_CHANCE)
        {
            let (pw, pl) = (s.c(PALLET_WIDTH), s.c(PALLET_LENGTH));
            let py = irange(self.rng, ya, yb - pl + 1);
            self.fill(Rect::new(x + rw, py, x + rw + pw, py + pl), OCCUPIED);
        }
    }

    /// Block-stacked pallet lanes with aisles.
    fn bulk(&mut self, zone: Rect) {
        let s = self.s;
        let aisle = s.c(BULK_AISLE.sample(self.rng));
        let mut x = zone.x0;
        loop {
            let bw = s.c(BULK_WIDTH.sample(self.rng));
            if x + bw > zone.x1 {
                break;
            }
            let mut y = zone.y0;
            while y < zone.y1 {
                let bh = s.c(BULK_LENGTH.sample(self.rng));
                if !chance(self.rng, MISSING_STACK_CHANCE) {
                    self.fill(Rect::new(x, y, x + bw, (y + bh).min(zone.y1)), OCCUPIED);
                }
                y += bh + s.c(BULK_GAP.sample(self.rng));
            }
            x += bw + aisle;
        }
    }
}
