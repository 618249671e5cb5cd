//! Synthetic occupancy maps the project owns: office floors, warehouses and
//! caves, generated from a seed and written in ROS map_server format
//! (binary PGM + YAML).
//!
//! Every random choice is drawn from [`crate::compiler::rng::Rng`] seeded with
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
//!
//! Code map: this module holds the public types, the driver
//! ([`generate`]) and the writer ([`write_ros_map`]). One module per
//! generator (`office`, with its furniture in `office::furnish`;
//! `warehouse`; `cave`) holds its layout rules, their parameters named
//! constants at the top. `draw` holds the geometry the generators share
//! (metres <-> cells, rectangles, the oriented canvas, the building
//! outline, furniture placement); `connect` keeps the largest free
//! component (flood fill).

use std::fmt;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::compiler::rng::Rng;

use connect::keep_largest;
use draw::{Canvas, Scale};

mod cave;
mod connect;
mod draw;
mod office;
mod warehouse;

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
            SynthKind::Office => on_canvas(w, h, &mut rng, s, &mut stats, office::office),
            SynthKind::Warehouse => on_canvas(w, h, &mut rng, s, &mut stats, warehouse::warehouse),
            SynthKind::Cave => cave::cave(w as usize, h as usize, &mut rng, s, &mut stats),
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

/// A layout generator drawing on an oriented canvas; returns a free point
/// in layout cells.
type Layout = fn(&mut Canvas, &mut Rng, Scale, &mut Stats) -> (i64, i64);

/// Runs `layout` on a `w` x `h` canvas of unknown cells, oriented at
/// random; returns the pixels and the layout's free point in image cells.
fn on_canvas(
    w: u32,
    h: u32,
    rng: &mut Rng,
    s: Scale,
    stats: &mut Stats,
    layout: Layout,
) -> (Vec<u8>, (usize, usize)) {
    let mut cv = Canvas::new(w as usize, h as usize, UNKNOWN);
    cv.orient(rng);
    let hint = layout(&mut cv, rng, s, stats);
    let hint = cv.to_image_point(hint.0, hint.1);
    (cv.px, hint)
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
