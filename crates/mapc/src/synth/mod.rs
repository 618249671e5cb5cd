//! Synthetic occupancy maps the project owns: office floors, warehouses and
//! caves, generated from a seed and written in ROS map_server format
//! (binary PGM + YAML).
//!
//! Every random choice is drawn from [`crate::rng::Rng`] seeded with
//! [`SynthOptions::seed`], so the same (kind, width, height, resolution, seed)
//! always yields byte-identical pixels. Layouts are planned in metres and
//! converted to cells with the resolution (every wall, door and gap is at
//! least one cell), so a map looks physically the same at any resolution.
//!
//! Guarantees for every generated map:
//! - `pixels.len() == width * height`, values are only [`OCCUPIED`], [`FREE`]
//!   and [`UNKNOWN`];
//! - the free space is a single 4-connected region (whatever the layout cut
//!   off, e.g. a pocket behind furniture, is marked occupied);
//! - the boundary is closed: no free cell lies on the image border or is
//!   8-adjacent to an unknown cell.
//!
//! Generation writes rectangles and discs straight into the pixel buffer and
//! labels connectivity in place, so memory is about one byte per cell plus
//! small per-room bookkeeping.

use std::fmt;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use rayon::prelude::*;

use crate::rng::Rng;

#[cfg(test)]
mod tests;

/// Pixel value of an occupied cell (ROS map_saver convention).
pub const OCCUPIED: u8 = 0;
/// Pixel value of a free cell (ROS map_saver convention).
pub const FREE: u8 = 254;
/// Pixel value of an unknown cell (ROS map_saver convention).
pub const UNKNOWN: u8 = 205;
/// Default resolution of synthetic maps, in metres per cell.
pub const DEFAULT_RESOLUTION: f64 = 0.05;
/// Smallest width and height, in cells, that get a real layout. A map with
/// either side smaller is a plain box: a one-cell occupied border around free
/// space (all occupied when a side is below 3 cells, empty when it is 0).
pub const MIN_SIZE: u32 = 64;

/// Temporary label of the component being kept (connectivity pass only).
const LABEL_KEEP: u8 = 252;
/// Temporary label of other components (connectivity pass only).
const LABEL_OTHER: u8 = 253;

// ---------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------

/// Which kind of environment to generate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum SynthKind {
    /// Office floor: outer walls, a corridor network, rows of rooms of varied
    /// sizes with doors, some linked rooms, furniture and pillars.
    Office,
    /// Warehouse: one or more large halls with rack rows and aisles, pallets,
    /// pillars, a loading area with dock doors and sometimes a small office.
    Warehouse,
    /// Cave: unstructured rock (thresholded smooth noise) with chambers joined
    /// by winding tunnels, inside a bounding wall.
    Cave,
}

impl SynthKind {
    /// All kinds, in a fixed order.
    pub const ALL: [SynthKind; 3] = [SynthKind::Office, SynthKind::Warehouse, SynthKind::Cave];

    /// The lower-case name used on the command line ("office", "warehouse",
    /// "cave").
    pub fn as_str(self) -> &'static str {
        match self {
            SynthKind::Office => "office",
            SynthKind::Warehouse => "warehouse",
            SynthKind::Cave => "cave",
        }
    }
}

impl fmt::Display for SynthKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Error from parsing a [`SynthKind`] name.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown synthetic map kind {0:?} (expected office, warehouse or cave)")]
pub struct ParseSynthKindError(pub String);

impl FromStr for SynthKind {
    type Err = ParseSynthKindError;

    /// Parses "office", "warehouse" or "cave" (ASCII case-insensitive,
    /// surrounding whitespace ignored).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let t = s.trim();
        SynthKind::ALL
            .into_iter()
            .find(|k| k.as_str().eq_ignore_ascii_case(t))
            .ok_or_else(|| ParseSynthKindError(s.to_string()))
    }
}

/// Parameters of [`generate`].
#[derive(Clone, Debug, PartialEq)]
pub struct SynthOptions {
    /// Kind of environment.
    pub kind: SynthKind,
    /// Map width in cells (image columns).
    pub width: u32,
    /// Map height in cells (image rows).
    pub height: u32,
    /// Cell size in metres per cell; [`DEFAULT_RESOLUTION`] (0.05) by
    /// default. A non-finite or non-positive value is replaced by the
    /// default.
    pub resolution: f64,
    /// Seed of every random choice.
    pub seed: u64,
}

impl Default for SynthOptions {
    /// A 600 x 400 cell (30 m x 20 m) office at 0.05 m/cell, seed 0.
    fn default() -> Self {
        SynthOptions::new(SynthKind::Office, 600, 400)
    }
}

impl SynthOptions {
    /// Options for a `width` x `height` cell map of `kind` at
    /// [`DEFAULT_RESOLUTION`] with seed 0.
    pub fn new(kind: SynthKind, width: u32, height: u32) -> Self {
        SynthOptions {
            kind,
            width,
            height,
            resolution: DEFAULT_RESOLUTION,
            seed: 0,
        }
    }

    /// The `mapc synth` command line that reproduces these options, e.g.
    /// `mapc synth --kind office --width 600 --height 400 --resolution 0.05 --seed 1`.
    pub fn command_line(&self) -> String {
        format!(
            "mapc synth --kind {} --width {} --height {} --resolution {} --seed {}",
            self.kind, self.width, self.height, self.resolution, self.seed
        )
    }
}

/// A generated occupancy grid in image order.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthMap {
    /// Width in cells (image columns).
    pub width: u32,
    /// Height in cells (image rows).
    pub height: u32,
    /// Cell size in metres per cell.
    pub resolution: f64,
    /// Row-major pixels, `width * height` of them, row 0 = TOP row of the
    /// image. ROS map_saver values: [`OCCUPIED`] (0), [`FREE`] (254),
    /// [`UNKNOWN`] (205).
    pub pixels: Vec<u8>,
    /// The options that produced the map (resolution as actually used);
    /// [`write_ros_map`] records them as a comment in the YAML.
    pub options: SynthOptions,
}

impl SynthMap {
    /// Number of cells whose pixel equals `value` (e.g. [`FREE`]).
    pub fn count(&self, value: u8) -> usize {
        self.pixels.iter().filter(|&&p| p == value).count()
    }
}

/// Generates a synthetic map. Deterministic: equal options give
/// byte-identical pixels. Sizes are exact; maps smaller than [`MIN_SIZE`] on
/// a side are a plain walled box. Runs in O(cells) time and memory (about a
/// second and 1 byte per cell for 16000 x 16000).
pub fn generate(opts: &SynthOptions) -> SynthMap {
    generate_with_stats(opts).0
}

/// Writes `dir/name.pgm` (binary P5, maxval 255, the pixels as they are) and
/// `dir/name.yaml` (ROS map_server format: image, resolution in m/cell,
/// origin `[x m, y m, yaw rad]` of the lower-left pixel, negate 0,
/// occupied_thresh 0.65, free_thresh 0.196, mode trinary), with a first
/// comment line recording the generator command line. Creates `dir` if
/// needed and returns the paths (yaml, pgm).
///
/// Errors with `InvalidInput` for an empty name or one containing a path
/// separator, a non-finite origin, a bad resolution, or a pixel buffer whose
/// length is not `width * height`.
pub fn write_ros_map(
    dir: &Path,
    name: &str,
    map: &SynthMap,
    origin: [f64; 3],
) -> io::Result<(PathBuf, PathBuf)> {
    let invalid = |msg: &str| io::Error::new(io::ErrorKind::InvalidInput, msg.to_string());
    if name.is_empty() || name.contains(['/', '\\']) {
        return Err(invalid(
            "map name must be non-empty and contain no path separator",
        ));
    }
    if !origin.iter().all(|v| v.is_finite()) {
        return Err(invalid("map origin must be finite"));
    }
    if !(map.resolution.is_finite() && map.resolution > 0.0) {
        return Err(invalid("map resolution must be finite and positive"));
    }
    if map.pixels.len() as u64 != map.width as u64 * map.height as u64 {
        return Err(invalid("pixel buffer length is not width * height"));
    }
    std::fs::create_dir_all(dir)?;
    let pgm_name = format!("{name}.pgm");
    let pgm = dir.join(&pgm_name);
    let yaml = dir.join(format!("{name}.yaml"));
    {
        let mut f = BufWriter::new(File::create(&pgm)?);
        write!(f, "P5\n{} {}\n255\n", map.width, map.height)?;
        f.write_all(&map.pixels)?;
        f.flush()?;
    }
    let plain = pgm_name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'));
    let image = if plain {
        pgm_name
    } else {
        format!(
            "\"{}\"",
            pgm_name.replace('\\', "\\\\").replace('"', "\\\"")
        )
    };
    let text = format!(
        "# generated by: {}\nimage: {}\nresolution: {}\norigin: [{}, {}, {}]\nnegate: 0\n\
         occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: trinary\n",
        map.options.command_line(),
        image,
        yaml_float(map.resolution),
        yaml_float(origin[0]),
        yaml_float(origin[1]),
        yaml_float(origin[2]),
    );
    std::fs::write(&yaml, text)?;
    Ok((yaml, pgm))
}

/// A finite float written so YAML reads it back as a float (always has a
/// decimal point; shortest round-trip digits).
fn yaml_float(v: f64) -> String {
    let s = format!("{v}");
    if s.contains(['.', 'e', 'E']) {
        s
    } else {
        format!("{s}.0")
    }
}

// ---------------------------------------------------------------------------
// Driver
// ---------------------------------------------------------------------------

/// Internal generation statistics (for tests and tuning).
#[derive(Clone, Copy, Debug, Default)]
struct Stats {
    /// Rooms (office rooms, halls, alcoves; warehouse office rooms; cave
    /// chambers).
    rooms: usize,
    /// Free cells outside the kept component, turned occupied.
    removed: u64,
    /// Free cells in the finished map.
    free: u64,
}

fn generate_with_stats(opts: &SynthOptions) -> (SynthMap, Stats) {
    let res = if opts.resolution.is_finite() && opts.resolution > 0.0 {
        opts.resolution
    } else {
        DEFAULT_RESOLUTION
    };
    let options = SynthOptions {
        resolution: res,
        ..opts.clone()
    };
    let (w, h) = (opts.width, opts.height);
    let mut stats = Stats::default();
    let pixels = if w < MIN_SIZE || h < MIN_SIZE {
        walled_box(w as usize, h as usize)
    } else {
        let mut rng = Rng::new(opts.seed);
        let s = Scale { res };
        let (mut px, hint) = match opts.kind {
            SynthKind::Office => {
                let mut cv = Canvas::new(w as usize, h as usize, UNKNOWN);
                cv.orient(&mut rng);
                let hint = office(&mut cv, &mut rng, s, &mut stats);
                let hint = cv.to_image_point(hint.0, hint.1);
                (cv.px, hint)
            }
            SynthKind::Warehouse => {
                let mut cv = Canvas::new(w as usize, h as usize, UNKNOWN);
                cv.orient(&mut rng);
                let hint = warehouse(&mut cv, &mut rng, s, &mut stats);
                let hint = cv.to_image_point(hint.0, hint.1);
                (cv.px, hint)
            }
            SynthKind::Cave => cave(w as usize, h as usize, &mut rng, s, &mut stats),
        };
        stats.removed = keep_largest(&mut px, w as usize, h as usize, Some(hint));
        px
    };
    stats.free = pixels.iter().filter(|&&p| p == FREE).count() as u64;
    (
        SynthMap {
            width: w,
            height: h,
            resolution: res,
            pixels,
            options,
        },
        stats,
    )
}

/// A `w` x `h` box: one-cell occupied border, free inside.
fn walled_box(w: usize, h: usize) -> Vec<u8> {
    let mut px = vec![OCCUPIED; w * h];
    if w >= 3 && h >= 3 {
        for y in 1..h - 1 {
            px[y * w + 1..y * w + w - 1].fill(FREE);
        }
    }
    px
}

// ---------------------------------------------------------------------------
// Geometry and raster helpers
// ---------------------------------------------------------------------------

/// Metres <-> cells.
#[derive(Clone, Copy, Debug)]
struct Scale {
    /// Metres per cell.
    res: f64,
}

impl Scale {
    /// A length in metres as a whole number of cells, at least one.
    fn c(self, m: f64) -> i64 {
        ((m / self.res).round() as i64).max(1)
    }

    /// A length in metres as (fractional) cells.
    fn cf(self, m: f64) -> f64 {
        m / self.res
    }

    /// A length in cells as metres.
    fn m(self, cells: i64) -> f64 {
        cells as f64 * self.res
    }
}

/// `v` limited to `[lo, hi]`; never panics (gives `hi` when `lo > hi`).
fn clampi(v: i64, lo: i64, hi: i64) -> i64 {
    v.max(lo).min(hi)
}

/// Uniform integer in `[lo, hi)`; `lo` when the range is empty.
fn irange(rng: &mut Rng, lo: i64, hi: i64) -> i64 {
    if hi > lo {
        lo + rng.below((hi - lo) as u64) as i64
    } else {
        lo
    }
}

/// Half-open integer rectangle `[x0, x1) x [y0, y1)` in cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rect {
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
}

impl Rect {
    const fn new(x0: i64, y0: i64, x1: i64, y1: i64) -> Self {
        Rect { x0, y0, x1, y1 }
    }
    fn w(&self) -> i64 {
        self.x1 - self.x0
    }
    fn h(&self) -> i64 {
        self.y1 - self.y0
    }
    fn is_empty(&self) -> bool {
        self.x1 <= self.x0 || self.y1 <= self.y0
    }
    fn shrink(&self, d: i64) -> Rect {
        Rect::new(self.x0 + d, self.y0 + d, self.x1 - d, self.y1 - d)
    }
    fn grow(&self, d: i64) -> Rect {
        self.shrink(-d)
    }
    fn intersects(&self, o: &Rect) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }
    fn contains(&self, o: &Rect) -> bool {
        o.x0 >= self.x0 && o.x1 <= self.x1 && o.y0 >= self.y0 && o.y1 <= self.y1
    }
}

/// The pixel buffer seen through a layout frame: layouts are drawn with the
/// long axis horizontal, then optionally mirrored and transposed into image
/// coordinates (which varies maps between seeds for free).
struct Canvas {
    w: usize,
    h: usize,
    px: Vec<u8>,
    transpose: bool,
    flip_x: bool,
    flip_y: bool,
}

impl Canvas {
    fn new(w: usize, h: usize, v: u8) -> Self {
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
    fn orient(&mut self, rng: &mut Rng) {
        self.transpose = self.h > self.w || (self.h == self.w && rng.uniform() < 0.5);
        self.flip_x = rng.uniform() < 0.5;
        self.flip_y = rng.uniform() < 0.5;
    }

    /// Layout width in cells.
    fn lw(&self) -> i64 {
        (if self.transpose { self.h } else { self.w }) as i64
    }

    /// Layout height in cells.
    fn lh(&self) -> i64 {
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

    fn to_image_point(&self, x: i64, y: i64) -> (usize, usize) {
        let r = self.to_image_rect(Rect::new(x, y, x + 1, y + 1));
        (
            clampi(r.x0, 0, self.w as i64 - 1) as usize,
            clampi(r.y0, 0, self.h as i64 - 1) as usize,
        )
    }

    /// Fills a layout rectangle (clipped to the map).
    fn fill(&mut self, r: Rect, v: u8) {
        let r = self.to_image_rect(r);
        let x0 = clampi(r.x0, 0, self.w as i64) as usize;
        let x1 = clampi(r.x1, 0, self.w as i64) as usize;
        let y0 = clampi(r.y0, 0, self.h as i64) as usize;
        let y1 = clampi(r.y1, 0, self.h as i64) as usize;
        if x0 >= x1 || y0 >= y1 {
            return;
        }
        for y in y0..y1 {
            let o = y * self.w;
            self.px[o + x0..o + x1].fill(v);
        }
    }

    /// Whether every cell of a layout rectangle (clipped to the map) is `v`;
    /// false when the rectangle lies outside the map.
    fn all_eq(&self, r: Rect, v: u8) -> bool {
        let r = self.to_image_rect(r);
        let x0 = clampi(r.x0, 0, self.w as i64) as usize;
        let x1 = clampi(r.x1, 0, self.w as i64) as usize;
        let y0 = clampi(r.y0, 0, self.h as i64) as usize;
        let y1 = clampi(r.y1, 0, self.h as i64) as usize;
        if x0 >= x1 || y0 >= y1 {
            return false;
        }
        (y0..y1).all(|y| {
            self.px[y * self.w + x0..y * self.w + x1]
                .iter()
                .all(|&p| p == v)
        })
    }

    /// Fills the ellipse inscribed in a layout rectangle.
    fn fill_ellipse(&mut self, r: Rect, v: u8) {
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
}

/// Placement bookkeeping for obstacles inside one room (or yard).
///
/// Rules that keep the room's free space connected: items are rectangles
/// inside the room, pairwise at least `clr` apart, never inside a keep-clear
/// zone (door approaches), each either touching a wall or at least `clr`
/// from it, and none touching two opposite walls.
struct Furn {
    room: Rect,
    clr: i64,
    blocked: Vec<Rect>,
}

impl Furn {
    fn new(room: Rect, keep: &[Rect], clr: i64) -> Self {
        Furn {
            room,
            clr,
            blocked: keep.to_vec(),
        }
    }

    /// Moves an item flush against a wall when it is closer than `clr`.
    fn snap(&self, mut r: Rect) -> Rect {
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
    fn add(&mut self, r: Rect) -> bool {
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
                if rng.uniform() < 0.5 {
                    Rect::new(x, rm.y0, x + along, rm.y0 + depth)
                } else {
                    Rect::new(x, rm.y1 - depth, x + along, rm.y1)
                }
            }
            _ => {
                let y = irange(rng, rm.y0, rm.y1 - along + 1);
                if rng.uniform() < 0.5 {
                    Rect::new(rm.x0, y, rm.x0 + depth, y + along)
                } else {
                    Rect::new(rm.x1 - depth, y, rm.x1, y + along)
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Office
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

/// Furniture sets.
#[derive(Clone, Copy, Debug)]
enum Furnishing {
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

fn office(cv: &mut Canvas, rng: &mut Rng, s: Scale, stats: &mut Stats) -> (i64, i64) {
    let (lw, lh) = (cv.lw(), cv.lh());
    let small = lw.min(lh);
    let margin = s.c(0.5).min(small / 16).max(1);
    let building = Rect::new(margin, margin, lw - margin, lh - margin);
    cv.fill(building, OCCUPIED);
    let tw = s.c(0.25).min(small / 16).max(1);
    let inner = building.shrink(tw);
    let mut o = Office {
        cv,
        rng,
        s,
        ti: s.c(0.15),
        dw: s.c(0.9),
        clr: s.c(0.6),
        room_scale: (s.m(inner.w().min(inner.h())) / 44.0).clamp(0.65, 1.0),
        rooms: 0,
    };
    let hint = o.run(inner);
    stats.rooms = o.rooms;
    hint
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
        let ti = self.ti;
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

        // Group rows into blocks.
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

        // Cross corridors and which blocks they cut through.
        let need = blocks.iter().any(|b| !b.outer);
        let verts = self.plan_verticals(inner, need);
        let nv = verts.len();
        let mut active = vec![vec![false; nv]; blocks.len()];
        for (bi, b) in blocks.iter().enumerate() {
            if nv == 0 {
                break;
            }
            if b.outer {
                for a in active[bi].iter_mut() {
                    *a = self.rng.uniform() < 0.3;
                }
            } else {
                let m = self.rng.below(nv as u64) as usize;
                for (v, a) in active[bi].iter_mut().enumerate() {
                    *a = v == m || self.rng.uniform() < 0.5;
                }
            }
        }
        if nv > 0 && !need && !active.iter().flatten().any(|&a| a) && !blocks.is_empty() {
            let bi = self.rng.below(blocks.len() as u64) as usize;
            let v = self.rng.below(nv as u64) as usize;
            active[bi][v] = true;
        }

        for (bi, b) in blocks.iter().enumerate() {
            let mut cuts = Vec::new();
            for (v, &(x0, x1)) in verts.iter().enumerate() {
                if active[bi][v] {
                    let r = Rect::new(x0, b.seg_y0, x1, b.seg_y1);
                    self.cv.fill(r, FREE);
                    corridors.push(r);
                    cuts.push((x0 - ti, x1 + ti));
                }
            }
            let mut start = (inner.x0, false);
            let mut intervals = Vec::new();
            for &(a, e) in &cuts {
                intervals.push((start.0, a, start.1, true));
                start = (e, true);
            }
            intervals.push((start.0, inner.x1, start.1, false));
            for (a, e, lv, rv) in intervals {
                if e - a < self.s.c(1.0) {
                    continue;
                }
                self.block_interval(b, a, e, lv, rv);
            }
        }
        for r in corridors {
            self.corridor_items(r);
        }
        hint
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
        if width < s.c(1.5) {
            return;
        }
        let pad = s.c(0.5);
        let n = (s.m(len) / 9.0 * self.rng.range(0.5, 1.2)) as usize;
        for _ in 0..n {
            let (along, depth, round) = match self.rng.below(4) {
                0 => (s.c(self.rng.range(1.2, 2.0)), s.c(0.45), false), // bench
                1 => (s.c(0.5), s.c(0.5), true),                        // plant
                2 => (s.c(self.rng.range(0.8, 1.2)), s.c(0.5), false),  // cabinet
                _ => (s.c(0.4), s.c(0.4), false),                       // water cooler
            };
            let depth = depth.min(width / 4).max(1);
            let p = irange(self.rng, 0, len - along + 1);
            let near = self.rng.uniform() < 0.5;
            // Item, the wall strip behind it, and the corridor cross-section.
            let (item, wall, across) = if horizontal {
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
                (item, wall, Rect::new(x - pad, c.y0, x + along + pad, c.y1))
            } else {
                let y = c.y0 + p;
                let (item, wall) = if near {
                    (
                        Rect::new(c.x0, y, c.x0 + depth, y + along),
                        Rect::new(c.x0 - 1, y - pad, c.x0, y + along + pad),
                    )
                } else {
                    (
                        Rect::new(c.x1 - depth, y, c.x1, y + along),
                        Rect::new(c.x1, y - pad, c.x1 + 1, y + along + pad),
                    )
                };
                (item, wall, Rect::new(c.x0, y - pad, c.x1, y + along + pad))
            };
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
        let min_row = s.c(3.0);
        let mut k = ((s.m(d) / 17.0).round() as usize).max(1);
        loop {
            let cws: Vec<i64> = (0..k).map(|_| s.c(self.rng.range(1.7, 2.5))).collect();
            let nb = 3 * k as i64;
            let avail = d - cws.iter().sum::<i64>() - (nb - 1) * ti;
            if avail >= 2 * k as i64 * min_row {
                let weights: Vec<f64> = (0..2 * k).map(|_| self.rng.range(0.75, 1.25)).collect();
                let total: f64 = weights.iter().sum();
                let mut depths: Vec<i64> = weights
                    .iter()
                    .map(|w| (avail as f64 * w / total).floor() as i64)
                    .collect();
                let used: i64 = depths.iter().sum();
                if let Some(l) = depths.last_mut() {
                    *l += avail - used;
                }
                let mut bands = Vec::with_capacity(3 * k);
                let mut y = inner.y0;
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
                return bands;
            }
            if k == 1 {
                break;
            }
            k -= 1;
        }
        // Too shallow for rooms on both sides: one row along a corridor.
        let cw = s.c(self.rng.range(1.4, 2.0));
        let row = d - cw - ti;
        if row >= s.c(2.0) && inner.w() >= s.c(4.0) {
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

    /// Cross-corridor x extents, sorted.
    fn plan_verticals(&mut self, inner: Rect, need: bool) -> Vec<(i64, i64)> {
        let s = self.s;
        let lm = s.m(inner.w());
        let mut nv = if lm < 14.0 {
            0
        } else {
            (lm / 40.0 + self.rng.range(0.2, 1.0)).floor() as i64
        };
        if need {
            nv = nv.max(1);
        }
        let mut out: Vec<(i64, i64)> = Vec::new();
        let spacing = inner.w() / (nv + 1);
        for i in 0..nv {
            let jitter = irange(self.rng, -spacing / 4, spacing / 4 + 1);
            let center = inner.x0 + spacing * (i + 1) + jitter;
            let vcw = s.c(self.rng.range(1.6, 2.2));
            let lo = inner.x0 + s.c(2.5) + self.ti;
            let hi = inner.x1 - s.c(2.5) - self.ti - vcw;
            let mut x0 = clampi(center - vcw / 2, lo, hi);
            if let Some(&(_, px1)) = out.last() {
                x0 = x0.max(px1 + 2 * self.ti + s.c(2.5));
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
        if !b.outer && e - a >= s.c(10.0) && self.rng.uniform() < 0.12 {
            let hw = s.c(self.rng.range(8.0, 18.0)).min(e - a);
            let mut hx0 = irange(self.rng, a, e - hw + 1);
            let mut hx1 = hx0 + hw;
            let minw = s.c(2.4) + ti;
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
        let (minw, maxw) = (s.c(2.6), s.c(9.0 * k));
        let mut out = Vec::new();
        let mut x = a;
        while e - x >= s.c(1.0) {
            let rem = e - x;
            let u = self.rng.uniform();
            let mut w = if u < 0.10 {
                s.c(self.rng.range(2.6, 3.6))
            } else if u < 0.72 {
                s.c(self.rng.range(4.5, 9.0) * k)
            } else {
                s.c(self.rng.range(10.0, 16.0) * k)
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
        let e = self.s.c(0.15).min(span);
        let jiggle = irange(self.rng, 0, self.s.c(0.5));
        let u = self.rng.uniform();
        let off = if u < 0.4 {
            (e + jiggle).min(span)
        } else if u < 0.8 {
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
        let pad = s.c(0.3);
        let reach = s.c(1.0);
        let dw = self.dw.min(y1 - y0);
        // Doors between neighbouring rooms.
        for i in 0..n - 1 {
            if y1 - y0 >= dw + 2 * pad && self.rng.uniform() < 0.15 {
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
        if lv && self.rng.uniform() < 0.3 {
            let y = self.door_pos(y0, y1, dw);
            self.cv.fill(Rect::new(a - ti, y, a, y + dw), FREE);
            keeps[0].push(Rect::new(a, y - pad, a + reach, y + dw + pad));
            linked[0] = true;
        }
        if rv && self.rng.uniform() < 0.3 {
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
    /// `[dx, dx + dw)` in the corridor-side wall of `r`.
    fn front_door(&self, r: Rect, facing: Facing, dx: i64, dw: i64) -> (Rect, Rect) {
        let (pad, reach) = (self.s.c(0.3), self.s.c(1.0));
        match facing {
            Facing::Up => (
                Rect::new(dx, r.y0 - self.ti, dx + dw, r.y0),
                Rect::new(dx - pad, r.y0, dx + dw + pad, r.y0 + reach),
            ),
            Facing::Down => (
                Rect::new(dx, r.y1, dx + dw, r.y1 + self.ti),
                Rect::new(dx - pad, r.y1 - reach, dx + dw + pad, r.y1),
            ),
        }
    }

    fn room(&mut self, r: Rect, facing: Facing, keep_in: &[Rect], linked: bool) {
        let (s, ti) = (self.s, self.ti);
        self.cv.fill(r, FREE);
        let mut keep = keep_in.to_vec();
        // Open alcove (lounge) on the corridor.
        if !linked && r.w() >= s.c(3.0) && self.rng.uniform() < 0.06 {
            let stub = s.c(0.3);
            let (wall, strip) = match facing {
                Facing::Up => (
                    Rect::new(r.x0 + stub, r.y0 - ti, r.x1 - stub, r.y0),
                    Rect::new(r.x0, r.y0, r.x1, r.y0 + s.c(1.2)),
                ),
                Facing::Down => (
                    Rect::new(r.x0 + stub, r.y1, r.x1 - stub, r.y1 + ti),
                    Rect::new(r.x0, r.y1 - s.c(1.2), r.x1, r.y1),
                ),
            };
            self.cv.fill(wall, FREE);
            keep.push(strip);
            self.furnish_as(r, &keep, Furnishing::Lounge);
            self.rooms += 1;
            return;
        }
        let dw = if r.w() >= s.c(8.0) && self.rng.uniform() < 0.5 {
            s.c(1.6)
        } else {
            self.dw
        }
        .min(r.w());
        let dx = self.door_pos(r.x0, r.x1, dw);
        let (door, dkeep) = self.front_door(r, facing, dx, dw);
        self.cv.fill(door, FREE);
        keep.push(dkeep);
        // Suite: a front room off the corridor and a back room behind it.
        let depth = r.h();
        if !linked && depth >= s.c(5.5) && r.w() >= s.c(2.6) && self.rng.uniform() < 0.15 {
            let fd = (depth as f64 * self.rng.range(0.45, 0.62)) as i64;
            let bd = depth - fd - ti;
            if fd >= s.c(2.2) && bd >= s.c(2.2) {
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
                let (pad, reach) = (s.c(0.3), s.c(1.0));
                keep.push(Rect::new(
                    ix - pad,
                    wall_y - reach,
                    ix + idw + pad,
                    wall_y + ti + reach,
                ));
                self.furnish(front, &keep, false);
                self.furnish(back, &keep, false);
                self.rooms += 2;
                return;
            }
        }
        self.furnish(r, &keep, false);
        self.rooms += 1;
    }

    /// A hall spanning both rows of a block, with doors onto both corridors.
    fn hall(&mut self, r: Rect) {
        let s = self.s;
        self.cv.fill(r, FREE);
        let mut keep = Vec::new();
        let (pad, reach) = (s.c(0.3), s.c(1.2));
        let dw = s.c(1.6).min(r.w());
        for facing in [Facing::Up, Facing::Down] {
            let n = 1 + self.rng.below(2);
            for _ in 0..n {
                let dx = irange(self.rng, r.x0, r.x1 - dw + 1);
                let (door, _) = self.front_door(r, facing, dx, dw);
                self.cv.fill(door, FREE);
                keep.push(match facing {
                    Facing::Up => Rect::new(dx - pad, r.y0, dx + dw + pad, r.y0 + reach),
                    Facing::Down => Rect::new(dx - pad, r.y1 - reach, dx + dw + pad, r.y1),
                });
            }
        }
        self.furnish(r, &keep, true);
        self.rooms += 1;
    }

    fn furnish(&mut self, r: Rect, keep: &[Rect], hall: bool) {
        let area = self.s.m(r.w()) * self.s.m(r.h());
        let u = self.rng.uniform();
        let kind = if hall {
            if u < 0.6 {
                Furnishing::OpenPlan
            } else {
                Furnishing::Lobby
            }
        } else if area < 7.0 {
            if u < 0.45 {
                Furnishing::Storage
            } else if u < 0.85 {
                Furnishing::Desks
            } else {
                Furnishing::Empty
            }
        } else if area < 32.0 {
            match u {
                u if u < 0.48 => Furnishing::Desks,
                u if u < 0.66 => Furnishing::Meeting,
                u if u < 0.76 => Furnishing::Storage,
                u if u < 0.84 => Furnishing::Kitchen,
                u if u < 0.91 => Furnishing::Restroom,
                u if u < 0.96 => Furnishing::Lab,
                _ => Furnishing::Empty,
            }
        } else {
            match u {
                u if u < 0.45 => Furnishing::OpenPlan,
                u if u < 0.62 => Furnishing::Meeting,
                u if u < 0.76 => Furnishing::Lab,
                u if u < 0.88 => Furnishing::Desks,
                u if u < 0.95 => Furnishing::Storage,
                _ => Furnishing::Lobby,
            }
        };
        self.furnish_as(r, keep, kind);
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

    /// Tries up to `tries` wall spots for an `along` x `depth` item.
    fn put_on_wall(&mut self, f: &mut Furn, along: i64, depth: i64, tries: usize) -> bool {
        for _ in 0..tries {
            let spot = f.wall_spot(self.rng, along, depth);
            let spot = f.snap(spot);
            if self.put(f, spot) {
                return true;
            }
        }
        false
    }

    /// Tries up to `tries` free-standing spots for a `w` x `h` item.
    fn put_anywhere(&mut self, f: &mut Furn, w: i64, h: i64, round: bool, tries: usize) -> bool {
        let rm = f.room;
        for _ in 0..tries {
            let x = irange(self.rng, rm.x0, rm.x1 - w + 1);
            let y = irange(self.rng, rm.y0, rm.y1 - h + 1);
            let r = f.snap(Rect::new(x, y, x + w, y + h));
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
        let step = s.c(self.rng.range(5.5, 7.5));
        let ps = s.c(self.rng.range(0.35, 0.55));
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

    fn furnish_as(&mut self, r: Rect, keep: &[Rect], kind: Furnishing) {
        let s = self.s;
        let mut f = Furn::new(r, keep, self.clr);
        let area = s.m(r.w()) * s.m(r.h());
        match kind {
            Furnishing::Empty => {}
            Furnishing::Desks => {
                let n = ((area / 6.0) as u64).clamp(1, 6) + self.rng.below(2);
                for _ in 0..n {
                    let along = s.c(self.rng.range(1.2, 1.8));
                    let depth = s.c(self.rng.range(0.6, 0.8));
                    self.put_on_wall(&mut f, along, depth, 16);
                }
                for _ in 0..self.rng.below(3) {
                    let along = s.c(self.rng.range(0.8, 1.2));
                    self.put_on_wall(&mut f, along, s.c(0.45), 12);
                }
            }
            Furnishing::Meeting => {
                let mx = s.c(self.rng.range(0.9, 1.4));
                let my = s.c(self.rng.range(0.9, 1.4));
                let mut t = Rect::new(r.x0 + mx, r.y0 + my, r.x1 - mx, r.y1 - my);
                let cap = s.c(6.0);
                if t.w() > cap {
                    let cut = (t.w() - cap) / 2;
                    t = Rect::new(t.x0 + cut, t.y0, t.x1 - cut, t.y1);
                }
                if t.h() > cap {
                    let cut = (t.h() - cap) / 2;
                    t = Rect::new(t.x0, t.y0 + cut, t.x1, t.y1 - cut);
                }
                if t.w() >= s.c(0.8) && t.h() >= s.c(0.8) {
                    let squareish = (t.w() - t.h()).abs() * 4 < t.w().max(t.h());
                    if squareish && t.w() > s.c(2.4) {
                        // Round tables are small; a big square room gets a
                        // smaller round one.
                        let cut = (t.w().min(t.h()) - s.c(self.rng.range(1.4, 2.4))) / 2;
                        t = t.shrink(cut.max(0));
                    }
                    if squareish && self.rng.uniform() < 0.6 {
                        self.put_round(&mut f, t);
                    } else {
                        self.put(&mut f, t);
                    }
                }
                if self.rng.uniform() < 0.6 {
                    let along = s.c(self.rng.range(1.0, 2.0));
                    self.put_on_wall(&mut f, along, s.c(0.45), 12);
                }
            }
            Furnishing::Storage => {
                let depth = s.c(self.rng.range(0.4, 0.6));
                for side in 0..4 {
                    if self.rng.uniform() < 0.35 {
                        continue;
                    }
                    let len = if side < 2 { r.w() } else { r.h() };
                    let along = len - self.clr - irange(self.rng, 0, len / 3 + 1);
                    if along < s.c(0.6) {
                        continue;
                    }
                    let off = if self.rng.uniform() < 0.5 {
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
                    self.put(&mut f, spot);
                }
                // Free-standing shelf rows along the longer axis.
                let gap = s.c(1.0).max(self.clr);
                let inner = r.shrink(gap + depth);
                if r.w().min(r.h()) >= s.c(4.0) && !inner.is_empty() {
                    let sd = 2 * depth;
                    if r.w() >= r.h() {
                        let mut y = inner.y0;
                        while y + sd <= inner.y1 {
                            self.put(&mut f, Rect::new(inner.x0, y, inner.x1, y + sd));
                            y += sd + gap + s.c(0.4);
                        }
                    } else {
                        let mut x = inner.x0;
                        while x + sd <= inner.x1 {
                            self.put(&mut f, Rect::new(x, inner.y0, x + sd, inner.y1));
                            x += sd + gap + s.c(0.4);
                        }
                    }
                }
            }
            Furnishing::Kitchen => {
                let along = s.c(self.rng.range(2.0, 3.5));
                self.put_on_wall(&mut f, along, s.c(0.6), 16);
                let d = s.c(self.rng.range(0.8, 1.2));
                self.put_anywhere(&mut f, d, d, true, 24);
                if self.rng.uniform() < 0.5 {
                    self.put_anywhere(&mut f, d, d, true, 24);
                }
            }
            Furnishing::Restroom => {
                // Stall partitions perpendicular to one wall.
                let len = s.c(1.5);
                let thick = s.c(0.05);
                let pitch = s.c(0.9).max(self.clr + thick);
                let side = self.rng.below(4);
                let (lo, hi) = if side < 2 { (r.x0, r.x1) } else { (r.y0, r.y1) };
                let mut p = lo + pitch;
                while p + thick <= hi - s.c(0.5) {
                    let spot = match side {
                        0 => Rect::new(p, r.y0, p + thick, r.y0 + len),
                        1 => Rect::new(p, r.y1 - len, p + thick, r.y1),
                        2 => Rect::new(r.x0, p, r.x0 + len, p + thick),
                        _ => Rect::new(r.x1 - len, p, r.x1, p + thick),
                    };
                    self.put(&mut f, spot);
                    p += pitch;
                }
                let along = s.c(self.rng.range(1.2, 2.0));
                self.put_on_wall(&mut f, along, s.c(0.55), 12);
            }
            Furnishing::Lab => {
                let depth = s.c(0.75);
                for _ in 0..3 {
                    let along = s.c(self.rng.range(1.8, 3.2));
                    self.put_on_wall(&mut f, along, depth, 12);
                }
                let (iw, ih) = (s.c(self.rng.range(1.4, 2.6)), s.c(self.rng.range(0.9, 1.5)));
                let (iw, ih) = if r.w() >= r.h() { (iw, ih) } else { (ih, iw) };
                self.put_anywhere(&mut f, iw, ih, false, 24);
            }
            Furnishing::OpenPlan => {
                if area > 45.0 {
                    self.pillars(&mut f, r);
                }
                let (cw, ch) = (s.c(self.rng.range(2.6, 3.4)), s.c(self.rng.range(1.3, 1.7)));
                let (cw, ch) = if self.rng.uniform() < 0.5 {
                    (cw, ch)
                } else {
                    (ch, cw)
                };
                let ax = s.c(self.rng.range(1.2, 1.8)).max(self.clr);
                let ay = s.c(self.rng.range(1.2, 1.8)).max(self.clr);
                let area_in = r.shrink(s.c(1.0).max(self.clr));
                let mut y = area_in.y0 + irange(self.rng, 0, s.c(0.5));
                while y + ch <= area_in.y1 {
                    let mut x = area_in.x0 + irange(self.rng, 0, s.c(0.5));
                    while x + cw <= area_in.x1 {
                        if self.rng.uniform() < 0.9 {
                            self.put(&mut f, Rect::new(x, y, x + cw, y + ch));
                        }
                        x += cw + ax;
                    }
                    y += ch + ay;
                }
                for _ in 0..2 {
                    let along = s.c(self.rng.range(0.8, 1.6));
                    self.put_on_wall(&mut f, along, s.c(0.45), 8);
                }
            }
            Furnishing::Lobby => {
                self.pillars(&mut f, r);
                let along = s.c(self.rng.range(2.0, 3.5));
                self.put_on_wall(&mut f, along, s.c(0.7), 16);
                for _ in 0..2 + self.rng.below(3) {
                    let d = s.c(self.rng.range(0.7, 1.1));
                    self.put_anywhere(&mut f, d, d, true, 16);
                }
                for _ in 0..self.rng.below(3) {
                    let (a, b) = (s.c(self.rng.range(1.6, 2.2)), s.c(0.8));
                    self.put_anywhere(&mut f, a, b, false, 16);
                }
            }
            Furnishing::Lounge => {
                let along = s.c(self.rng.range(1.6, 2.4));
                self.put_on_wall(&mut f, along, s.c(0.8), 16);
                let d = s.c(self.rng.range(0.6, 0.9));
                self.put_anywhere(&mut f, d, d, true, 16);
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Warehouse
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

fn warehouse(cv: &mut Canvas, rng: &mut Rng, s: Scale, stats: &mut Stats) -> (i64, i64) {
    let (lw, lh) = (cv.lw(), cv.lh());
    let small = lw.min(lh);
    let margin = s.c(0.5).min(small / 16).max(1);
    let building = Rect::new(margin, margin, lw - margin, lh - margin);
    cv.fill(building, OCCUPIED);
    let tw = s.c(0.3).min(small / 16).max(1);
    let inner = building.shrink(tw);
    let mut wh = Warehouse {
        cv,
        rng,
        s,
        tw,
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
        if inner.w() < s.c(14.0) || inner.h() < s.c(10.0) {
            // A shed: open floor with a few pallet stacks.
            self.cv.fill(inner, FREE);
            let clr = s.c(1.0);
            let mut f = Furn::new(inner.shrink(s.c(0.8)), &[], clr);
            for _ in 0..(s.m(inner.w()) * s.m(inner.h()) / 20.0) as usize + 1 {
                let (pw, ph) = (s.c(1.2), s.c(1.0));
                let x = irange(self.rng, f.room.x0, f.room.x1 - pw + 1);
                let y = irange(self.rng, f.room.y0, f.room.y1 - ph + 1);
                let r = Rect::new(x, y, x + pw, y + ph);
                if f.add(r) {
                    self.cv.fill(r, OCCUPIED);
                }
            }
            return (inner.x0, inner.y0);
        }
        let tf = s.c(0.3);
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
        let ow = s.c(4.0);
        let end = s.c(3.0);
        for pair in xs.windows(2) {
            let (wx0, wx1) = (pair[0].1, pair[1].0);
            for &(y0, y1) in &ys {
                for _ in 0..1 + self.rng.below(2) {
                    let o = ow.min(y1 - y0 - 2);
                    let y = irange(self.rng, y0 + end, y1 - end - o + 1);
                    let y = clampi(y, y0 + 1, y1 - 1 - o);
                    self.cv.fill(Rect::new(wx0, y, wx1, y + o), FREE);
                }
            }
        }
        for pair in ys.windows(2) {
            let (wy0, wy1) = (pair[0].1, pair[1].0);
            for &(x0, x1) in &xs {
                for _ in 0..1 + self.rng.below(2) {
                    let o = ow.min(x1 - x0 - 2);
                    let x = irange(self.rng, x0 + end, x1 - end - o + 1);
                    let x = clampi(x, x0 + 1, x1 - 1 - o);
                    self.cv.fill(Rect::new(x, wy0, x + o, wy1), FREE);
                }
            }
        }
        hint
    }

    /// Splits `[lo, hi)` into halls about 150 m long separated by `tf`-thick
    /// fire walls.
    fn cuts(&mut self, lo: i64, hi: i64, tf: i64) -> Vec<(i64, i64)> {
        let n = ((self.s.m(hi - lo) / 150.0).round() as i64).max(1);
        let part = (hi - lo) / n;
        let mut out = Vec::new();
        let mut start = lo;
        for i in 1..n {
            let p = lo + part * i + irange(self.rng, -part / 6, part / 6 + 1);
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
            self.rng.uniform() < 0.5
        } else {
            outer.top
        };
        let staging_outer = if self.flip { outer.top } else { outer.bottom };
        let sd = clampi(s.c(self.rng.range(8.0, 14.0)), s.c(4.0), h.h() * 2 / 5);
        let pa = s.c(self.rng.range(1.8, 2.6));
        let zone = Rect::new(h.x0 + pa, h.y0 + pa, h.x1 - pa, h.y1 - sd);
        let ti = s.c(0.15);

        // Office block in a loading-side corner of the outer wall.
        let mut office: Option<Rect> = None;
        if staging_outer && (outer.left || outer.right) && self.rng.uniform() < 0.7 {
            let bw = s.c(self.rng.range(7.0, 12.0)).min(h.w() / 3);
            let bd = s.c(self.rng.range(4.0, 6.0)).min(sd - s.c(3.0));
            let left = if outer.left && outer.right {
                self.rng.uniform() < 0.5
            } else {
                outer.left
            };
            if bd >= s.c(3.0) && bw >= s.c(3.0) {
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
                office = Some(block);
            }
        }
        let office_keep = office.map(|b| b.grow(s.c(2.5)));

        if zone.w() >= s.c(4.0) && zone.h() >= s.c(4.0) {
            if self.rng.uniform() < 0.75 {
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
        // Staging lanes of pallets in front of some dock doors, leaving a
        // main aisle along the rack zone and an apron at the wall.
        let lane_top = h.y1 - sd + s.c(2.8);
        let apron = s.c(1.5);
        let mut blocked: Vec<Rect> = office_keep.into_iter().collect();
        for &(dx, dwk) in &docks {
            let room = h.y1 - apron - lane_top;
            if self.rng.uniform() < 0.6 && room >= s.c(1.2) {
                let len = s.c(self.rng.range(2.4, 7.0)).min(room);
                let lw = (s.c(1.2) * (1 + self.rng.below(2) as i64)).min(dwk);
                let x = dx + (dwk - lw) / 2;
                let r = Rect::new(x, h.y1 - apron - len, x + lw, h.y1 - apron);
                self.fill(r, OCCUPIED);
                blocked.push(r.grow(s.c(1.0)));
            }
        }
        // Pallet groups in the rest of the loading area.
        let yard = Rect::new(h.x0 + s.c(2.0), lane_top, h.x1 - s.c(2.0), h.y1 - s.c(1.2));
        if !yard.is_empty() {
            let mut f = Furn::new(yard, &blocked, s.c(1.0));
            let n = (s.m(yard.w()) * s.m(yard.h()) / 12.0) as usize + 1;
            for _ in 0..n {
                let nx = 1 + self.rng.below(3) as i64;
                let ny = 1 + self.rng.below(2) as i64;
                let (mut pw, mut ph) = (s.c(1.2) * nx, s.c(1.0) * ny);
                if self.rng.uniform() < 0.5 {
                    std::mem::swap(&mut pw, &mut ph);
                }
                let x = irange(self.rng, yard.x0, yard.x1 - pw + 1);
                let y = irange(self.rng, yard.y0, yard.y1 - ph + 1);
                let r = Rect::new(x, y, x + pw, y + ph);
                if f.add(r) {
                    self.fill(r, OCCUPIED);
                }
            }
        }
        // Structural pillars on a regular grid.
        let sx = s.c(self.rng.range(10.0, 13.0));
        let sy = s.c(self.rng.range(10.0, 13.0));
        let ps = s.c(self.rng.range(0.4, 0.6));
        let ox = irange(self.rng, s.c(2.0), s.c(2.0) + sx);
        let oy = irange(self.rng, s.c(2.0), s.c(2.0) + sy);
        let mut y = h.y0 + oy;
        while y + ps < h.y1 - s.c(1.5) {
            let mut x = h.x0 + ox;
            while x + ps < h.x1 - s.c(1.0) {
                let r = Rect::new(x, y, x + ps, y + ps);
                if !office_keep.is_some_and(|k| k.intersects(&r)) {
                    self.fill(r, OCCUPIED);
                }
                x += sx;
            }
            y += sy;
        }
        let p = self.map(Rect::new(h.x0, h.y0, h.x0 + 1, h.y0 + 1));
        (p.x0, p.y0)
    }

    /// Small office rooms in `area` (local frame) with doors into the hall.
    fn office_block(&mut self, block: Rect, area: Rect, ti: i64) {
        let s = self.s;
        self.fill(block, OCCUPIED);
        let n = (1 + self.rng.below(3) as i64)
            .min((area.w() + ti) / (s.c(2.4) + ti))
            .max(1);
        let rw = (area.w() - (n - 1) * ti) / n;
        let dw = s.c(0.9).min(rw);
        for i in 0..n {
            let x0 = area.x0 + i * (rw + ti);
            let x1 = if i + 1 == n { area.x1 } else { x0 + rw };
            let r = Rect::new(x0, area.y0, x1, area.y1);
            self.fill(r, FREE);
            let dx = irange(self.rng, r.x0, r.x1 - dw + 1);
            self.fill(Rect::new(dx, r.y0 - ti, dx + dw, r.y0), FREE);
            let keep = [Rect::new(
                dx - s.c(0.3),
                r.y0,
                dx + dw + s.c(0.3),
                r.y0 + s.c(1.0),
            )];
            let mut f = Furn::new(r, &keep, s.c(0.6));
            for _ in 0..1 + self.rng.below(2) {
                let along = s.c(self.rng.range(1.2, 1.6));
                for _ in 0..12 {
                    let spot = f.wall_spot(self.rng, along, s.c(0.7));
                    let spot = f.snap(spot);
                    if f.add(spot) {
                        self.fill(spot, OCCUPIED);
                        break;
                    }
                }
            }
            self.rooms += 1;
        }
    }

    /// Dock doors (recesses in the outer wall) with bumpers, along the
    /// loading side; returns each door's (x, width).
    fn docks(&mut self, h: Rect, office: Option<Rect>) -> Vec<(i64, i64)> {
        let s = self.s;
        let dwk = s.c(3.0);
        let pitch = dwk + s.c(self.rng.range(0.8, 1.8));
        let (mut lo, mut hi) = (h.x0 + s.c(3.0), h.x1 - s.c(3.0));
        if let Some(b) = office {
            if b.x0 <= h.x0 {
                lo = lo.max(b.x1 + s.c(3.0));
            } else {
                hi = hi.min(b.x0 - s.c(3.0));
            }
        }
        // Docks over a random stretch of the wall.
        let span = hi - lo;
        let mut out = Vec::new();
        if span < pitch {
            return out;
        }
        let len = (span as f64 * self.rng.range(0.4, 1.0)) as i64;
        let start = lo + irange(self.rng, 0, span - len + 1);
        let (bw, bd) = (s.c(0.25), s.c(0.45));
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
        let aisle = s.c(self.rng.range(2.6, 3.5));
        let single = s.c(self.rng.range(1.0, 1.3));
        let bay = s.c(self.rng.range(2.5, 2.9));
        let cross = s.c(self.rng.range(2.8, 3.6));
        let mut segs = Vec::new();
        let mut y = zone.y0;
        while y < zone.y1 {
            let len = s.c(self.rng.range(12.0, 25.0));
            let mut end = (y + len).min(zone.y1);
            if zone.y1 - end < s.c(6.0) {
                end = zone.y1;
            }
            segs.push((y, end));
            y = end + cross;
        }
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
                if self.rng.uniform() < 0.05 {
                    continue;
                }
                let (mut ya, mut yb) = (y0, y1);
                if self.rng.uniform() < 0.15 {
                    ya += bay * (1 + self.rng.below(2) as i64);
                }
                if self.rng.uniform() < 0.15 {
                    yb -= bay * (1 + self.rng.below(2) as i64);
                }
                let mut by = ya;
                while by < yb {
                    let mut be = (by + bay).min(yb);
                    if yb - be < bay / 2 {
                        be = yb;
                    }
                    if self.rng.uniform() >= 0.04 {
                        self.fill(Rect::new(x, by, x + rw, be), OCCUPIED);
                    }
                    by = be;
                }
                if x + rw + aisle <= zone.x1 && yb - ya > s.c(3.0) && self.rng.uniform() < 0.12 {
                    let py = irange(self.rng, ya, yb - s.c(1.2) + 1);
                    self.fill(
                        Rect::new(x + rw, py, x + rw + s.c(1.0), py + s.c(1.2)),
                        OCCUPIED,
                    );
                }
            }
        }
    }

    /// Block-stacked pallet lanes with aisles.
    fn bulk(&mut self, zone: Rect) {
        let s = self.s;
        let aisle = s.c(self.rng.range(3.0, 3.8));
        let mut x = zone.x0;
        loop {
            let bw = s.c(self.rng.range(2.4, 4.8));
            if x + bw > zone.x1 {
                break;
            }
            let mut y = zone.y0;
            while y < zone.y1 {
                let bh = s.c(self.rng.range(3.0, 9.0));
                if self.rng.uniform() >= 0.2 {
                    self.fill(Rect::new(x, y, x + bw, (y + bh).min(zone.y1)), OCCUPIED);
                }
                y += bh + s.c(self.rng.range(1.5, 3.0));
            }
            x += bw + aisle;
        }
    }
}

// ---------------------------------------------------------------------------
// Cave
// ---------------------------------------------------------------------------

/// One octave of 2-D value noise on a lattice of `sp` cells.
struct Octave {
    sp: f64,
    gw: usize,
    gh: usize,
    amp: f32,
    lat: Vec<f32>,
    ix: Vec<u32>,
    tx: Vec<f32>,
}

fn smoothstep(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

impl Octave {
    fn new(rng: &mut Rng, w: usize, h: usize, sp: f64, amp: f32) -> Self {
        let sp = sp.max(2.0);
        let gw = (w as f64 / sp) as usize + 2;
        let gh = (h as f64 / sp) as usize + 2;
        let lat = (0..gw * gh).map(|_| rng.uniform() as f32).collect();
        let mut ix = Vec::with_capacity(w);
        let mut tx = Vec::with_capacity(w);
        for x in 0..w {
            let f = (x as f64 + 0.5) / sp;
            let i = (f.floor() as usize).min(gw - 2);
            ix.push(i as u32);
            tx.push(smoothstep((f - i as f64).clamp(0.0, 1.0)) as f32);
        }
        Octave {
            sp,
            gw,
            gh,
            amp,
            lat,
            ix,
            tx,
        }
    }

    fn cell_y(&self, y: f64) -> (usize, f32) {
        let f = y / self.sp;
        let i = (f.max(0.0).floor() as usize).min(self.gh - 2);
        (i, smoothstep((f - i as f64).clamp(0.0, 1.0)) as f32)
    }

    /// Value at a point given in cells (cell centres at i + 0.5).
    fn at(&self, x: f64, y: f64) -> f32 {
        let f = x / self.sp;
        let i = (f.max(0.0).floor() as usize).min(self.gw - 2);
        let t = smoothstep((f - i as f64).clamp(0.0, 1.0)) as f32;
        let (j, u) = self.cell_y(y);
        let l = &self.lat;
        let a = l[j * self.gw + i] + (l[(j + 1) * self.gw + i] - l[j * self.gw + i]) * u;
        let b =
            l[j * self.gw + i + 1] + (l[(j + 1) * self.gw + i + 1] - l[j * self.gw + i + 1]) * u;
        self.amp * (a + (b - a) * t)
    }

    /// Adds this octave's row `y` into `out[x0..x1]`.
    fn add_row(&self, y: usize, x0: usize, x1: usize, col: &mut Vec<f32>, out: &mut [f32]) {
        let (j, u) = self.cell_y(y as f64 + 0.5);
        let (r0, r1) = (&self.lat[j * self.gw..], &self.lat[(j + 1) * self.gw..]);
        col.clear();
        col.extend((0..self.gw).map(|i| r0[i] + (r1[i] - r0[i]) * u));
        let cells = out[x0..x1]
            .iter_mut()
            .zip(&self.ix[x0..x1])
            .zip(&self.tx[x0..x1]);
        for ((o, &i), &t) in cells {
            let (a, b) = (col[i as usize], col[i as usize + 1]);
            *o += self.amp * (a + (b - a) * t);
        }
    }
}

/// Fractal value noise, normalised to [0, 1].
struct Noise {
    octaves: Vec<Octave>,
}

impl Noise {
    fn at(&self, x: f64, y: f64) -> f32 {
        self.octaves.iter().map(|o| o.at(x, y)).sum()
    }

    fn row(&self, y: usize, x0: usize, x1: usize, col: &mut Vec<f32>, out: &mut [f32]) {
        out[x0..x1].fill(0.0);
        for o in &self.octaves {
            o.add_row(y, x0, x1, col, out);
        }
    }
}

/// Extra "rockiness" near the bounding wall, so open areas rarely run flat
/// against it.
struct Fade {
    inner: Rect,
    /// Width of the fade band, cells.
    band: f64,
}

impl Fade {
    fn new(inner: Rect, band: f64) -> Self {
        Fade {
            inner,
            band: band.max(1.0),
        }
    }

    /// Added to the noise at cell (x, y).
    fn at(&self, x: i64, y: i64) -> f32 {
        let r = self.inner;
        let d = (x - r.x0).min(r.x1 - 1 - x).min(y - r.y0).min(r.y1 - 1 - y);
        let f = 1.0 - d as f64 / self.band;
        if f > 0.0 {
            (0.6 * f) as f32
        } else {
            0.0
        }
    }
}

/// A carved tunnel piece: the segment a-b swept by a radius varying from
/// `ra` to `rb` (cells), roughened by noise, with an always-carved core.
struct Capsule {
    ax: f64,
    ay: f64,
    bx: f64,
    by: f64,
    ra: f64,
    rb: f64,
    bbox: Rect,
}

/// Largest radius factor of the noise roughening.
const ROUGH_MAX: f64 = 1.8;

impl Capsule {
    /// Largest distance from the segment at which a point can be carved.
    fn reach(&self) -> f64 {
        (self.ra.max(self.rb) * ROUGH_MAX).max(1.0)
    }

    /// The x interval (cells, continuous) within [`Capsule::reach`] of the
    /// segment on the horizontal line `y = yc`, if any. The capsule is
    /// convex, so this is the hull of its two end discs and its band.
    fn span(&self, yc: f64) -> Option<(f64, f64)> {
        let rr = self.reach();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (cx, cy) in [(self.ax, self.ay), (self.bx, self.by)] {
            let dy = yc - cy;
            let q = rr * rr - dy * dy;
            if q > 0.0 {
                let h = q.sqrt();
                lo = lo.min(cx - h);
                hi = hi.max(cx + h);
            }
        }
        let (dx, dy) = (self.bx - self.ax, self.by - self.ay);
        let l2 = dx * dx + dy * dy;
        if l2 > 1e-12 {
            let l = l2.sqrt();
            // Along-segment parameter u(x) in [0, 1] and signed distance
            // p(x) in [-rr, rr] are both linear in x on this line.
            let (mut a, mut b) = (f64::NEG_INFINITY, f64::INFINITY);
            let mut clip = |k: f64, m: f64, p: f64, q: f64| {
                if k.abs() < 1e-12 {
                    if m < p || m > q {
                        b = f64::NEG_INFINITY;
                    }
                } else {
                    let (x1, x2) = ((p - m) / k, (q - m) / k);
                    a = a.max(x1.min(x2));
                    b = b.min(x1.max(x2));
                }
            };
            let ey = yc - self.ay;
            clip(dx / l2, (-self.ax * dx + ey * dy) / l2, 0.0, 1.0);
            clip(-dy / l, (self.ax * dy + ey * dx) / l, -rr, rr);
            if a <= b {
                lo = lo.min(a);
                hi = hi.max(b);
            }
        }
        (lo <= hi).then_some((lo, hi))
    }

    fn new(a: (f64, f64), b: (f64, f64), ra: f64, rb: f64) -> Self {
        let m = ra.max(rb).max(1.0) * ROUGH_MAX + 1.0;
        let bbox = Rect::new(
            (a.0.min(b.0) - m).floor() as i64,
            (a.1.min(b.1) - m).floor() as i64,
            (a.0.max(b.0) + m).ceil() as i64 + 1,
            (a.1.max(b.1) + m).ceil() as i64 + 1,
        );
        Capsule {
            ax: a.0,
            ay: a.1,
            bx: b.0,
            by: b.1,
            ra,
            rb,
            bbox,
        }
    }

    /// Whether the point (cells) is carved, given the noise value `n` there
    /// and the free threshold `t`.
    fn covers(&self, x: f64, y: f64, n: f32, t: f32) -> bool {
        let (dx, dy) = (self.bx - self.ax, self.by - self.ay);
        let l2 = dx * dx + dy * dy;
        let u = if l2 > 0.0 {
            (((x - self.ax) * dx + (y - self.ay) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (px, py) = (self.ax + u * dx - x, self.ay + u * dy - y);
        let d2 = px * px + py * py;
        let r = self.ra + (self.rb - self.ra) * u;
        let core = (0.45 * r).max(1.0);
        if d2 < core * core {
            return true;
        }
        let k = (1.0 + 2.0 * (t - n) as f64).clamp(0.0, ROUGH_MAX);
        d2 < (r * k) * (r * k)
    }
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Cave: noise-thresholded rock with chambers on a jittered grid joined by a
/// random spanning tree (plus a few loops) of winding tunnels. Returns the
/// pixels and a free point (image coordinates).
fn cave(
    w: usize,
    h: usize,
    rng: &mut Rng,
    s: Scale,
    stats: &mut Stats,
) -> (Vec<u8>, (usize, usize)) {
    let small = w.min(h) as i64;
    let margin = s.c(0.5).min(small / 16).max(1);
    let building = Rect::new(margin, margin, w as i64 - margin, h as i64 - margin);
    let tw = s.c(0.4).min(small / 16).max(1);
    let inner = building.shrink(tw);
    let (iw, ih) = (inner.w() as f64, inner.h() as f64);

    // Noise and its free threshold (a quantile, so the fraction is stable).
    let octaves = [(4.5, 1.0f32), (2.2, 0.5), (1.0, 0.25)];
    let norm: f32 = octaves.iter().map(|o| o.1).sum();
    let fade = Fade::new(inner, s.cf(2.5));
    let noise = Noise {
        octaves: octaves
            .iter()
            .map(|&(wl, amp)| Octave::new(rng, w, h, s.cf(wl), amp / norm))
            .collect(),
    };
    let mut samples: Vec<f32> = (0..4096)
        .map(|_| {
            let x = inner.x0 as f64 + rng.uniform() * iw;
            let y = inner.y0 as f64 + rng.uniform() * ih;
            noise.at(x, y) + fade.at(x as i64, y as i64)
        })
        .collect();
    samples.sort_by(|a, b| a.total_cmp(b));
    let q = rng.range(0.28, 0.36);
    let t = samples[((samples.len() as f64 * q) as usize).min(samples.len() - 1)];

    // Chamber nodes on a jittered grid.
    let rcap = (iw.min(ih) / 5.0).max(1.0);
    let spacing = s.cf(rng.range(9.0, 13.0));
    let nx = ((iw / spacing).round() as usize).max(1);
    let ny = ((ih / spacing).round() as usize).max(1);
    let (cw, ch) = (iw / nx as f64, ih / ny as f64);
    let lim = |v: f64, lo: f64, hi: f64| {
        if lo > hi {
            (lo + hi) / 2.0
        } else {
            v.clamp(lo, hi)
        }
    };
    // Keeps a point whose carved core has radius 0.45 r inside the interior.
    let keep_in = |p: (f64, f64), r: f64| {
        let pad = 0.45 * r + 1.5;
        (
            lim(p.0, inner.x0 as f64 + pad, inner.x1 as f64 - pad),
            lim(p.1, inner.y0 as f64 + pad, inner.y1 as f64 - pad),
        )
    };
    let mut nodes = Vec::with_capacity(nx * ny);
    let mut caps = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let x = inner.x0 as f64 + (i as f64 + 0.5 + rng.range(-0.3, 0.3)) * cw;
            let y = inner.y0 as f64 + (j as f64 + 0.5 + rng.range(-0.3, 0.3)) * ch;
            let r = if rng.uniform() < 0.15 {
                s.cf(rng.range(3.5, 6.0))
            } else {
                s.cf(rng.range(1.5, 3.5))
            }
            .min(rcap);
            let p = keep_in((x, y), r);
            caps.push(Capsule::new(p, p, r, r));
            nodes.push(p);
        }
    }
    stats.rooms = nodes.len();

    // Random spanning tree over grid neighbours (Kruskal), plus loops.
    let mut edges = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let k = j * nx + i;
            if i + 1 < nx {
                edges.push((k, k + 1));
            }
            if j + 1 < ny {
                edges.push((k, k + nx));
            }
        }
    }
    for i in (1..edges.len()).rev() {
        let j = rng.below(i as u64 + 1) as usize;
        edges.swap(i, j);
    }
    let mut parent: Vec<usize> = (0..nodes.len()).collect();
    for &(a, b) in &edges {
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        let tree = ra != rb;
        if tree {
            parent[ra] = rb;
        }
        if !tree && rng.uniform() >= 0.2 {
            continue;
        }
        // Winding tunnel: a random-walk bridge from a to b.
        const PIECES: usize = 6;
        let (pa, pb) = (nodes[a], nodes[b]);
        let (dx, dy) = (pb.0 - pa.0, pb.1 - pa.1);
        let len = (dx * dx + dy * dy).sqrt().max(1e-9);
        let (nx_, ny_) = (-dy / len, dx / len);
        let mut walk = [0.0f64; PIECES + 1];
        for i in 1..=PIECES {
            walk[i] = walk[i - 1] + rng.normal().clamp(-2.5, 2.5);
        }
        let radii: Vec<f64> = (0..=PIECES)
            .map(|_| s.cf(rng.range(0.6, 1.4)).min(rcap))
            .collect();
        let mut pts = vec![pa];
        for (i, wv) in walk.iter().enumerate().take(PIECES).skip(1) {
            let f = i as f64 / PIECES as f64;
            let (bx, by) = (pa.0 + dx * f, pa.1 + dy * f);
            // Shrink the sideways offset until the point is well inside (the
            // straight line between two inside nodes always is).
            let mut off = (wv - f * walk[PIECES]) * 0.09 * len;
            let mut p = (bx + nx_ * off, by + ny_ * off);
            for _ in 0..8 {
                if keep_in(p, radii[i]) == p {
                    break;
                }
                off *= 0.5;
                p = (bx + nx_ * off, by + ny_ * off);
            }
            pts.push(keep_in(p, radii[i]));
        }
        pts.push(pb);
        for k in 0..pts.len() - 1 {
            caps.push(Capsule::new(pts[k], pts[k + 1], radii[k], radii[k + 1]));
        }
    }

    // Rasterise in parallel bands; each cell is a pure function of position.
    const BAND: usize = 32;
    let nbands = h.div_ceil(BAND);
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); nbands];
    for (i, c) in caps.iter().enumerate() {
        let y0 = clampi(c.bbox.y0, inner.y0, inner.y1 - 1) as usize;
        let y1 = clampi(c.bbox.y1 - 1, inner.y0, inner.y1 - 1) as usize;
        for b in buckets.iter_mut().take(y1 / BAND + 1).skip(y0 / BAND) {
            b.push(i as u32);
        }
    }
    let mut px = vec![UNKNOWN; w * h];
    let (bx0, bx1) = (building.x0 as usize, building.x1 as usize);
    let (ix0, ix1) = (inner.x0 as usize, inner.x1 as usize);
    px.par_chunks_mut(w * BAND)
        .enumerate()
        .for_each(|(bi, chunk)| {
            let mut nrow = vec![0f32; w];
            let mut col = Vec::new();
            for (ry, row) in chunk.chunks_mut(w).enumerate() {
                let y = bi * BAND + ry;
                let yi = y as i64;
                if yi < building.y0 || yi >= building.y1 {
                    continue;
                }
                row[bx0..bx1].fill(OCCUPIED);
                if yi < inner.y0 || yi >= inner.y1 {
                    continue;
                }
                noise.row(y, ix0, ix1, &mut col, &mut nrow);
                for (x, v) in nrow.iter_mut().enumerate().take(ix1).skip(ix0) {
                    *v += fade.at(x as i64, yi);
                }
                for x in ix0..ix1 {
                    if nrow[x] < t {
                        row[x] = FREE;
                    }
                }
                let yc = y as f64 + 0.5;
                for &ci in &buckets[bi] {
                    let c = &caps[ci as usize];
                    if yi < c.bbox.y0 || yi >= c.bbox.y1 {
                        continue;
                    }
                    let Some((lo, hi)) = c.span(yc) else {
                        continue;
                    };
                    // Cells whose centre x + 0.5 lies in [lo, hi], plus one.
                    let xa = clampi((lo - 0.5).floor() as i64 - 1, inner.x0, inner.x1) as usize;
                    let xb = clampi((hi - 0.5).ceil() as i64 + 2, inner.x0, inner.x1) as usize;
                    for x in xa..xb {
                        if row[x] != FREE && c.covers(x as f64 + 0.5, yc, nrow[x], t) {
                            row[x] = FREE;
                        }
                    }
                }
            }
        });
    let hint = nodes
        .first()
        .map_or((ix0, inner.y0 as usize), |p| (p.0 as usize, p.1 as usize));
    (px, hint)
}

// ---------------------------------------------------------------------------
// Connectivity
// ---------------------------------------------------------------------------

/// 4-connected scanline flood fill of the `from`-valued region containing
/// (sx, sy), relabelled `to`; returns the number of cells relabelled.
fn flood(px: &mut [u8], w: usize, h: usize, sx: usize, sy: usize, from: u8, to: u8) -> u64 {
    if from == to || px[sy * w + sx] != from {
        return 0;
    }
    let mut n = 0u64;
    let mut stack: Vec<(u32, u32)> = vec![(sx as u32, sy as u32)];
    while let Some((x, y)) = stack.pop() {
        let (x, y) = (x as usize, y as usize);
        let row = y * w;
        if px[row + x] != from {
            continue;
        }
        let mut l = x;
        while l > 0 && px[row + l - 1] == from {
            l -= 1;
        }
        let mut r = x;
        while r + 1 < w && px[row + r + 1] == from {
            r += 1;
        }
        px[row + l..=row + r].fill(to);
        n += (r - l + 1) as u64;
        for ny in [y.wrapping_sub(1), y + 1] {
            if ny >= h {
                continue;
            }
            let nrow = ny * w;
            let mut x = l;
            while x <= r {
                if px[nrow + x] == from {
                    stack.push((x as u32, ny as u32));
                    while x <= r && px[nrow + x] == from {
                        x += 1;
                    }
                } else {
                    x += 1;
                }
            }
        }
    }
    n
}

/// Keeps the largest 4-connected free component (trying the component at
/// `hint` first: if it holds most free cells no full labelling is needed);
/// every other free cell becomes occupied. Returns how many were removed.
fn keep_largest(px: &mut [u8], w: usize, h: usize, hint: Option<(usize, usize)>) -> u64 {
    let total = px.iter().filter(|&&p| p == FREE).count() as u64;
    if total == 0 {
        return 0;
    }
    let mut kept = 0u64;
    let mut kept_at = None;
    if let Some((x, y)) = hint {
        if x < w && y < h && px[y * w + x] == FREE {
            kept = flood(px, w, h, x, y, FREE, LABEL_KEEP);
            kept_at = Some((x, y));
        }
    }
    if kept * 2 <= total {
        let mut rest = total - kept;
        let mut best: Option<(usize, u64)> = None;
        let mut i = 0;
        while i < px.len() && rest > 0 {
            if px[i] == FREE {
                let n = flood(px, w, h, i % w, i / w, FREE, LABEL_OTHER);
                rest -= n;
                if best.is_none_or(|b| n > b.1) {
                    best = Some((i, n));
                }
            }
            i += 1;
        }
        if let Some((bi, bn)) = best {
            if bn > kept {
                if let Some((x, y)) = kept_at {
                    flood(px, w, h, x, y, LABEL_KEEP, LABEL_OTHER);
                }
                flood(px, w, h, bi % w, bi / w, LABEL_OTHER, LABEL_KEEP);
                kept = bn;
            }
        }
    }
    for p in px.iter_mut() {
        *p = match *p {
            LABEL_KEEP => FREE,
            FREE | LABEL_OTHER => OCCUPIED,
            v => v,
        };
    }
    total - kept
}
