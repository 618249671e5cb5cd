//! Furniture of the office's rooms: the furnishing sets (desks, meeting,
//! storage, kitchen, restroom, lab, open plan, lobby, lounge), the random
//! choice of a set by room size, and the placement of each piece through
//! [`Furn`], which keeps the room's free space connected.

use super::Office;
use crate::compiler::rng::Rng;
use crate::tools::synth::draw::{chance, irange, Furn, Rect, Span};
use crate::tools::synth::OCCUPIED;

// ---------------------------------------------------------------------------
// Parameters (m: metres; probabilities are per choice)
// ---------------------------------------------------------------------------

/// Rooms below this floor area are small (m²).
const SMALL_ROOM_AREA: f64 = 7.0;
/// Rooms below this floor area are medium (m²); the rest are large.
const MEDIUM_ROOM_AREA: f64 = 32.0;
/// Furnishing of a hall.
const HALL_MIX: Mix = Mix {
    below: &[(0.6, Furnishing::OpenPlan)],
    otherwise: Furnishing::Lobby,
};
/// Furnishing of a small room.
const SMALL_MIX: Mix = Mix {
    below: &[(0.45, Furnishing::Storage), (0.85, Furnishing::Desks)],
    otherwise: Furnishing::Empty,
};
/// Furnishing of a medium room.
const MEDIUM_MIX: Mix = Mix {
    below: &[
        (0.48, Furnishing::Desks),
        (0.66, Furnishing::Meeting),
        (0.76, Furnishing::Storage),
        (0.84, Furnishing::Kitchen),
        (0.91, Furnishing::Restroom),
        (0.96, Furnishing::Lab),
    ],
    otherwise: Furnishing::Empty,
};
/// Furnishing of a large room.
const LARGE_MIX: Mix = Mix {
    below: &[
        (0.45, Furnishing::OpenPlan),
        (0.62, Furnishing::Meeting),
        (0.76, Furnishing::Lab),
        (0.88, Furnishing::Desks),
        (0.95, Furnishing::Storage),
    ],
    otherwise: Furnishing::Lobby,
};

/// Spacing of structural pillars (m).
const PILLAR_STEP: Span = Span::new(5.5, 7.5);
/// Side of a structural pillar (m).
const PILLAR_SIZE: Span = Span::new(0.35, 0.55);

/// Floor area per desk (m²).
const AREA_PER_DESK: f64 = 6.0;
/// Largest number of desks before the random extra one.
const MAX_DESKS: u64 = 6;
/// A desk against a wall.
const DESK: WallItem = WallItem {
    along: Len::Drawn(Span::new(1.2, 1.8)),
    depth: Len::Drawn(Span::new(0.6, 0.8)),
    tries: 16,
};
/// Number of filing cabinets in an office: a draw below this.
const DESK_ROOM_CABINETS: u64 = 3;
/// A filing cabinet against a wall.
const FILING_CABINET: WallItem = WallItem {
    along: Len::Drawn(Span::new(0.8, 1.2)),
    depth: Len::Fixed(0.45),
    tries: 12,
};

/// Gap between a meeting table and the walls (m, per axis).
const MEETING_MARGIN: Span = Span::new(0.9, 1.4);
/// Largest side of a meeting table (m).
const MEETING_TABLE_MAX: f64 = 6.0;
/// Smallest side of a meeting table (m).
const MEETING_TABLE_MIN: f64 = 0.8;
/// A table is square-ish when its sides differ by less than its longer
/// side divided by this.
const SQUAREISH_DIV: i64 = 4;
/// A square-ish table wider than this is replaced by a smaller one (m).
const MEETING_ROUND_MAX: f64 = 2.4;
/// Diameter of that smaller table (m).
const MEETING_ROUND_SIZE: Span = Span::new(1.4, 2.4);
/// Probability that a square-ish meeting table is round.
const MEETING_ROUND_CHANCE: f64 = 0.6;
/// Probability of a sideboard in a meeting room.
const SIDEBOARD_CHANCE: f64 = 0.6;
/// A sideboard against a wall.
const SIDEBOARD: WallItem = WallItem {
    along: Len::Drawn(Span::new(1.0, 2.0)),
    depth: Len::Fixed(0.45),
    tries: 12,
};

/// Depth of a storage shelf (m).
const SHELF_DEPTH: Span = Span::new(0.4, 0.6);
/// Probability that a storage room's wall has no shelf.
const SHELF_SKIP_CHANCE: f64 = 0.35;
/// Shortest wall shelf (m).
const SHELF_MIN_LENGTH: f64 = 0.6;
/// Random shortening of a wall shelf: a draw below a third of the wall.
const SHELF_CUT_DIV: i64 = 3;
/// Smallest aisle beside a free-standing shelf row (m; at least the
/// clearance).
const SHELF_AISLE: f64 = 1.0;
/// Smallest side of a room with free-standing shelf rows (m).
const SHELF_ROWS_MIN_ROOM: f64 = 4.0;
/// Extra aisle between free-standing shelf rows (m).
const SHELF_ROW_EXTRA_GAP: f64 = 0.4;

/// A kitchen counter against a wall.
const COUNTER: WallItem = WallItem {
    along: Len::Drawn(Span::new(2.0, 3.5)),
    depth: Len::Fixed(0.6),
    tries: 16,
};
/// Diameter of a kitchen table (m).
const KITCHEN_TABLE: Span = Span::new(0.8, 1.2);
/// Placement tries of a kitchen table.
const KITCHEN_TABLE_TRIES: usize = 24;
/// Probability of a second kitchen table.
const SECOND_TABLE_CHANCE: f64 = 0.5;

/// Length of a restroom stall partition (m).
const STALL_LENGTH: f64 = 1.5;
/// Thickness of a stall partition (m).
const STALL_THICKNESS: f64 = 0.05;
/// Stall pitch (m; at least clearance plus thickness).
const STALL_PITCH: f64 = 0.9;
/// Free wall left after the last stall (m).
const STALL_END_GAP: f64 = 0.5;
/// A wash basin counter against a wall.
const BASIN_COUNTER: WallItem = WallItem {
    along: Len::Drawn(Span::new(1.2, 2.0)),
    depth: Len::Fixed(0.55),
    tries: 12,
};

/// Number of lab benches.
const LAB_BENCHES: usize = 3;
/// A lab bench against a wall.
const LAB_BENCH: WallItem = WallItem {
    along: Len::Drawn(Span::new(1.8, 3.2)),
    depth: Len::Fixed(0.75),
    tries: 12,
};
/// Length of a lab island along the room's long axis (m).
const LAB_ISLAND_LENGTH: Span = Span::new(1.4, 2.6);
/// Width of a lab island (m).
const LAB_ISLAND_WIDTH: Span = Span::new(0.9, 1.5);
/// Placement tries of a lab island.
const LAB_ISLAND_TRIES: usize = 24;

/// Open-plan rooms above this area get pillars (m²).
const OPEN_PLAN_PILLAR_AREA: f64 = 45.0;
/// Long side of a desk cluster (m).
const CLUSTER_LONG: Span = Span::new(2.6, 3.4);
/// Short side of a desk cluster (m).
const CLUSTER_SHORT: Span = Span::new(1.3, 1.7);
/// Aisle between desk clusters (m, per axis; at least the clearance).
const CLUSTER_AISLE: Span = Span::new(1.2, 1.8);
/// Free margin around the cluster grid (m; at least the clearance).
const CLUSTER_MARGIN: f64 = 1.0;
/// Random offset of the cluster grid (m, exclusive upper bound).
const CLUSTER_JITTER: f64 = 0.5;
/// Probability that a cluster of the grid is there.
const CLUSTER_CHANCE: f64 = 0.9;
/// Number of cabinets in an open-plan room.
const OPEN_PLAN_CABINETS: usize = 2;
/// A cabinet in an open-plan room.
const OPEN_PLAN_CABINET: WallItem = WallItem {
    along: Len::Drawn(Span::new(0.8, 1.6)),
    depth: Len::Fixed(0.45),
    tries: 8,
};

/// A reception desk against a wall.
const RECEPTION: WallItem = WallItem {
    along: Len::Drawn(Span::new(2.0, 3.5)),
    depth: Len::Fixed(0.7),
    tries: 16,
};
/// Round lobby tables: at least this many ...
const LOBBY_MIN_TABLES: u64 = 2;
/// ... plus a draw below this.
const LOBBY_EXTRA_TABLES: u64 = 3;
/// Diameter of a lobby table (m).
const LOBBY_TABLE: Span = Span::new(0.7, 1.1);
/// Number of lobby sofas: a draw below this.
const LOBBY_SOFAS: u64 = 3;
/// Length of a lobby sofa (m).
const LOBBY_SOFA_LENGTH: Span = Span::new(1.6, 2.2);
/// Depth of a lobby sofa (m).
const LOBBY_SOFA_DEPTH: f64 = 0.8;
/// Placement tries of lobby and lounge tables and sofas.
const LOUNGE_TRIES: usize = 16;

/// A lounge sofa against a wall.
const LOUNGE_SOFA: WallItem = WallItem {
    along: Len::Drawn(Span::new(1.6, 2.4)),
    depth: Len::Fixed(0.8),
    tries: 16,
};
/// Diameter of a lounge table (m).
const LOUNGE_TABLE: Span = Span::new(0.6, 0.9);

// ---------------------------------------------------------------------------
// Types
// ---------------------------------------------------------------------------

/// A length in metres: fixed, or drawn (one random draw).
#[derive(Clone, Copy, Debug)]
enum Len {
    /// Always this many metres.
    Fixed(f64),
    /// Drawn from this interval (m).
    Drawn(Span),
}

impl Len {
    fn sample(self, rng: &mut Rng) -> f64 {
        match self {
            Len::Fixed(m) => m,
            Len::Drawn(span) => span.sample(rng),
        }
    }
}

/// A piece of furniture flush against a wall.
#[derive(Clone, Copy, Debug)]
struct WallItem {
    /// Length along the wall (m).
    along: Len,
    /// Depth into the room (m).
    depth: Len,
    /// Placement tries before giving up.
    tries: usize,
}

/// A random choice of furnishing: the first entry whose cumulative
/// probability exceeds the draw, else `otherwise`.
struct Mix {
    below: &'static [(f64, Furnishing)],
    otherwise: Furnishing,
}

impl Mix {
    fn pick(&self, u: f64) -> Furnishing {
        self.below
            .iter()
            .find(|&&(p, _)| u < p)
            .map_or(self.otherwise, |&(_, f)| f)
    }
}

/// Furniture sets.
#[derive(Clone, Copy, Debug)]
pub(super) enum Furnishing {
    Empty,
    Desks,
    Meeting,
    Storage,
    Kitchen,
    Restroom,
    Lab,
    OpenPlan,
    Lobby,
    Lounge,
}

impl Office<'_> {
    /// Furnishes `r` with a set chosen by its size (or as a hall).
    pub(super) fn furnish(&mut self, r: Rect, keep: &[Rect], hall: bool) {
        let area = self.s.m(r.w()) * self.s.m(r.h());
        let u = self.rng.uniform();
        let mix = if hall {
            &HALL_MIX
        } else if area < SMALL_ROOM_AREA {
            &SMALL_MIX
        } else if area < MEDIUM_ROOM_AREA {
            &MEDIUM_MIX
        } else {
            &LARGE_MIX
        };
        self.furnish_as(r, keep, mix.pick(u));
    }

    /// Draws `r` occupied if the furnisher accepts it.
    fn put(&mut self, f: &mut Furn, r: Rect) -> bool {
        if f.add(r) {
            self.cv.fill(r, OCCUPIED);
            true
        } else {
            false
        }
    }

    /// Draws the ellipse inscribed in `r` if the furnisher accepts `r`.
    fn put_round(&mut self, f: &mut Furn, r: Rect) -> bool {
        if f.add(r) {
            self.cv.fill_ellipse(r, OCCUPIED);
            true
        } else {
            false
        }
    }

    /// Draws `item` where the furnisher finds a spot on a wall (its length
    /// is drawn before its depth).
    fn put_on_wall(&mut self, f: &mut Furn, item: WallItem) {
        let along = self.s.c(item.along.sample(self.rng));
        let depth = self.s.c(item.depth.sample(self.rng));
        if let Some(spot) = f.add_on_wall(self.rng, along, depth, item.tries) {
            self.cv.fill(spot, OCCUPIED);
        }
    }

    /// Tries up to `tries` free-standing spots for a `w` x `h` item.
    fn put_anywhere(&mut self, f: &mut Furn, w: i64, h: i64, round: bool, tries: usize) -> bool {
        for _ in 0..tries {
            let r = f.snap(f.random_spot(self.rng, w, h));
            let ok = if round {
                self.put_round(f, r)
            } else {
                self.put(f, r)
            };
            if ok {
                return true;
            }
        }
        false
    }

    /// Square pillars on a regular grid (structural columns).
    fn pillars(&mut self, f: &mut Furn, r: Rect) {
        let s = self.s;
        let step = s.c(PILLAR_STEP.sample(self.rng));
        let ps = s.c(PILLAR_SIZE.sample(self.rng));
        let (nx, ny) = (r.w() / step, r.h() / step);
        if nx < 1 || ny < 1 {
            return;
        }
        let ox = r.x0 + (r.w() - (nx - 1) * step) / 2 - ps / 2;
        let oy = r.y0 + (r.h() - (ny - 1) * step) / 2 - ps / 2;
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = (ox + i * step, oy + j * step);
                self.put(f, Rect::new(x, y, x + ps, y + ps));
            }
        }
    }

    /// Furnishes `r` (keeping `keep` clear) with the set `kind`.
    pub(super) fn furnish_as(&mut self, r: Rect, keep: &[Rect], kind: Furnishing) {
        let mut f = Furn::new(r, keep, self.clr);
        let f = &mut f;
        let area = self.s.m(r.w()) * self.s.m(r.h());
        match kind {
            Furnishing::Empty => {}
            Furnishing::Desks => self.desks(f, area),
            Furnishing::Meeting => self.meeting(f, r),
            Furnishing::Storage => self.storage(f, r),
            Furnishing::Kitchen => self.kitchen(f),
            Furnishing::Restroom => self.restroom(f, r),
            Furnishing::Lab => self.lab(f, r),
            Furnishing::OpenPlan => self.open_plan(f, r, area),
            Furnishing::Lobby => self.lobby(f, r),
            Furnishing::Lounge => self.lounge(f),
        }
    }

    /// Desks against the walls (one per [`AREA_PER_DESK`]) and a few
    /// filing cabinets.
    fn desks(&mut self, f: &mut Furn, area: f64) {
        let n = ((area / AREA_PER_DESK) as u64).clamp(1, MAX_DESKS) + self.rng.below(2);
        for _ in 0..n {
            self.put_on_wall(f, DESK);
        }
        for _ in 0..self.rng.below(DESK_ROOM_CABINETS) {
            self.put_on_wall(f, FILING_CABINET);
        }
    }

    /// A table in the middle (round when the room is square-ish) and
    /// perhaps a sideboard.
    fn meeting(&mut self, f: &mut Furn, r: Rect) {
        let s = self.s;
        let mx = s.c(MEETING_MARGIN.sample(self.rng));
        let my = s.c(MEETING_MARGIN.sample(self.rng));
        let mut t = Rect::new(r.x0 + mx, r.y0 + my, r.x1 - mx, r.y1 - my);
        let cap = s.c(MEETING_TABLE_MAX);
        if t.w() > cap {
            let cut = (t.w() - cap) / 2;
            t = Rect::new(t.x0 + cut, t.y0, t.x1 - cut, t.y1);
        }
        if t.h() > cap {
            let cut = (t.h() - cap) / 2;
            t = Rect::new(t.x0, t.y0 + cut, t.x1, t.y1 - cut);
        }
        let min = s.c(MEETING_TABLE_MIN);
        if t.w() >= min && t.h() >= min {
            let squareish = (t.w() - t.h()).abs() * SQUAREISH_DIV < t.w().max(t.h());
            if squareish && t.w() > s.c(MEETING_ROUND_MAX) {
                // Round tables are small; a big square room gets a
                // smaller round one.
                let cut = (t.w().min(t.h()) - s.c(MEETING_ROUND_SIZE.sample(self.rng))) / 2;
                t = t.shrink(cut.max(0));
            }
            if squareish && chance(self.rng, MEETING_ROUND_CHANCE) {
                self.put_round(f, t);
            } else {
                self.put(f, t);
            }
        }
        if chance(self.rng, SIDEBOARD_CHANCE) {
            self.put_on_wall(f, SIDEBOARD);
        }
    }

    /// Shelves along most walls and, in bigger rooms, free-standing shelf
    /// rows along the longer axis.
    fn storage(&mut self, f: &mut Furn, r: Rect) {
        let s = self.s;
        let depth = s.c(SHELF_DEPTH.sample(self.rng));
        for side in 0..4 {
            if chance(self.rng, SHELF_SKIP_CHANCE) {
                continue;
            }
            let len = if side < 2 { r.w() } else { r.h() };
            let along = len - self.clr - irange(self.rng, 0, len / SHELF_CUT_DIV + 1);
            if along < s.c(SHELF_MIN_LENGTH) {
                continue;
            }
            let off = if chance(self.rng, 0.5) {
                0
            } else {
                len - along
            };
            let spot = match side {
                0 => Rect::new(r.x0 + off, r.y0, r.x0 + off + along, r.y0 + depth),
                1 => Rect::new(r.x0 + off, r.y1 - depth, r.x0 + off + along, r.y1),
                2 => Rect::new(r.x0, r.y0 + off, r.x0 + depth, r.y0 + off + along),
                _ => Rect::new(r.x1 - depth, r.y0 + off, r.x1, r.y0 + off + along),
            };
            self.put(f, spot);
        }
        let gap = s.c(SHELF_AISLE).max(self.clr);
        let inner = r.shrink(gap + depth);
        if r.w().min(r.h()) >= s.c(SHELF_ROWS_MIN_ROOM) && !inner.is_empty() {
            let sd = 2 * depth;
            let step = sd + gap + s.c(SHELF_ROW_EXTRA_GAP);
            if r.w() >= r.h() {
                let mut y = inner.y0;
                while y + sd <= inner.y1 {
                    self.put(f, Rect::new(inner.x0, y, inner.x1, y + sd));
                    y += step;
                }
            } else {
                let mut x = inner.x0;
                while x + sd <= inner.x1 {
                    self.put(f, Rect::new(x, inner.y0, x + sd, inner.y1));
                    x += step;
                }
            }
        }
    }

    /// A counter and one or two round tables.
    fn kitchen(&mut self, f: &mut Furn) {
        self.put_on_wall(f, COUNTER);
        let d = self.s.c(KITCHEN_TABLE.sample(self.rng));
        self.put_anywhere(f, d, d, true, KITCHEN_TABLE_TRIES);
        if chance(self.rng, SECOND_TABLE_CHANCE) {
            self.put_anywhere(f, d, d, true, KITCHEN_TABLE_TRIES);
        }
    }

    /// Stall partitions perpendicular to one wall and a basin counter.
    fn restroom(&mut self, f: &mut Furn, r: Rect) {
        let s = self.s;
        let len = s.c(STALL_LENGTH);
        let thick = s.c(STALL_THICKNESS);
        let pitch = s.c(STALL_PITCH).max(self.clr + thick);
        let side = self.rng.below(4);
        let (lo, hi) = if side < 2 { (r.x0, r.x1) } else { (r.y0, r.y1) };
        let mut p = lo + pitch;
        while p + thick <= hi - s.c(STALL_END_GAP) {
            let spot = match side {
                0 => Rect::new(p, r.y0, p + thick, r.y0 + len),
                1 => Rect::new(p, r.y1 - len, p + thick, r.y1),
                2 => Rect::new(r.x0, p, r.x0 + len, p + thick),
                _ => Rect::new(r.x1 - len, p, r.x1, p + thick),
            };
            self.put(f, spot);
            p += pitch;
        }
        self.put_on_wall(f, BASIN_COUNTER);
    }

    /// Benches on the walls and an island along the long axis.
    fn lab(&mut self, f: &mut Furn, r: Rect) {
        let s = self.s;
        for _ in 0..LAB_BENCHES {
            self.put_on_wall(f, LAB_BENCH);
        }
        let iw = s.c(LAB_ISLAND_LENGTH.sample(self.rng));
        let ih = s.c(LAB_ISLAND_WIDTH.sample(self.rng));
        let (iw, ih) = if r.w() >= r.h() { (iw, ih) } else { (ih, iw) };
        self.put_anywhere(f, iw, ih, false, LAB_ISLAND_TRIES);
    }

    /// Pillars (big rooms), a grid of desk clusters and a few cabinets.
    fn open_plan(&mut self, f: &mut Furn, r: Rect, area: f64) {
        let s = self.s;
        if area > OPEN_PLAN_PILLAR_AREA {
            self.pillars(f, r);
        }
        let cw = s.c(CLUSTER_LONG.sample(self.rng));
        let ch = s.c(CLUSTER_SHORT.sample(self.rng));
        let (cw, ch) = if chance(self.rng, 0.5) {
            (cw, ch)
        } else {
            (ch, cw)
        };
        let ax = s.c(CLUSTER_AISLE.sample(self.rng)).max(self.clr);
        let ay = s.c(CLUSTER_AISLE.sample(self.rng)).max(self.clr);
        let area_in = r.shrink(s.c(CLUSTER_MARGIN).max(self.clr));
        let mut y = area_in.y0 + irange(self.rng, 0, s.c(CLUSTER_JITTER));
        while y + ch <= area_in.y1 {
            let mut x = area_in.x0 + irange(self.rng, 0, s.c(CLUSTER_JITTER));
            while x + cw <= area_in.x1 {
                if chance(self.rng, CLUSTER_CHANCE) {
                    self.put(f, Rect::new(x, y, x + cw, y + ch));
                }
                x += cw + ax;
            }
            y += ch + ay;
        }
        for _ in 0..OPEN_PLAN_CABINETS {
            self.put_on_wall(f, OPEN_PLAN_CABINET);
        }
    }

    /// Pillars, a reception desk, round tables and sofas.
    fn lobby(&mut self, f: &mut Furn, r: Rect) {
        let s = self.s;
        self.pillars(f, r);
        self.put_on_wall(f, RECEPTION);
        for _ in 0..LOBBY_MIN_TABLES + self.rng.below(LOBBY_EXTRA_TABLES) {
            let d = s.c(LOBBY_TABLE.sample(self.rng));
            self.put_anywhere(f, d, d, true, LOUNGE_TRIES);
        }
        for _ in 0..self.rng.below(LOBBY_SOFAS) {
            let (a, b) = (
                s.c(LOBBY_SOFA_LENGTH.sample(self.rng)),
                s.c(LOBBY_SOFA_DEPTH),
            );
            self.put_anywhere(f, a, b, false, LOUNGE_TRIES);
        }
    }

    /// A sofa on a wall and a round table.
    fn lounge(&mut self, f: &mut Furn) {
        self.put_on_wall(f, LOUNGE_SOFA);
        let d = self.s.c(LOUNGE_TABLE.sample(self.rng));
        self.put_anywhere(f, d, d, true, LOUNGE_TRIES);
    }
}
