//! ROS map_server input: the YAML map description and its PGM/PNG image.
//!
//! Loading follows ROS map_server (`map_server/src/image_loader.cpp`) and
//! Nav2 (`nav2_map_server/src/map_io.cpp`):
//!
//! * the YAML keys are `image`, `resolution` (m/cell), `origin` (`[x m, y m,
//!   yaw rad]`, the map-frame pose of the lower-left corner of cell (0, 0)),
//!   `negate`, `occupied_thresh`, `free_thresh` and the optional `mode`
//!   (`trinary`, the default, `scale` or `raw`). Unknown keys are ignored, as
//!   map_server does. `negate` may be omitted (false).
//! * image row 0 is the TOP of the map: grid row `cy = 0` is the LAST image row.
//! * trinary and scale modes: a pixel's colour channels are averaged (in
//!   trinary mode the alpha channel is averaged in too, as map_server does;
//!   a grey channel counts as R = G = B, so grey+alpha averages
//!   `(3 grey + alpha) / 4`),
//!   `p = (255 - avg) / 255` (`avg / 255` when `negate`), occupied when
//!   `p > occupied_thresh`, free when `p < free_thresh`, unknown otherwise.
//!   Scale mode's intermediate "probabilities" have no place in a trinary
//!   grid and become [`Cell::Unknown`]; in scale mode any pixel that is not
//!   fully opaque is unknown (Nav2).
//! * raw mode: the (colour-averaged) value itself is the occupancy in percent:
//!   0 is free, 100 is occupied, values above 100 (255 is ROS's -1) are
//!   unknown, values in between are classified by `value / 100` against the
//!   thresholds. As in Nav2, `negate` does not apply in raw mode.
//! * a fully transparent pixel (alpha 0) is unknown in every mode.
//! * 16-bit images are scaled to 8 bits (`round(v * 255 / 65535)`) first.
//!
//! Untrusted input never panics: every failure is a [`MapError`] naming the
//! offending file. Image dimensions are checked from the header before any
//! pixel buffer is allocated.

use std::fmt;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use refloc::raycast::BitGrid;
use refloc::{MapFrame, Pose2};
use saphyr::{LoadableYamlNode, Yaml};
use sha2::{Digest, Sha256};

/// Largest accepted image side, in pixels (cells).
pub const MAX_SIDE: u32 = 65535 * 4;
/// Largest accepted number of cells (`width * height`): the highest value
/// [`MapLimits::max_cells`] may take.
pub const MAX_CELLS: u64 = 1 << 31;
/// Default [`MapLimits::max_cells`]: 2^28 cells (16384 x 16384).
pub const DEFAULT_MAX_CELLS: u64 = 1 << 28;
/// Decoded image bytes allowed per cell of [`MapLimits::max_cells`] (an
/// 8-bit RGBA image of `max_cells` pixels; 16-bit or RGBA images of fewer).
pub const DECODED_BYTES_PER_CELL: u64 = 4;
/// Largest accepted YAML file, in bytes (a map description is a few lines).
pub const MAX_YAML_BYTES: u64 = 1 << 20;
/// Default `occupied_thresh` when an image is loaded without a YAML file
/// (the value of the ROS map_saver).
pub const DEFAULT_OCCUPIED_THRESH: f64 = 0.65;
/// Default `free_thresh` when an image is loaded without a YAML file (the
/// value of the ROS map_saver).
pub const DEFAULT_FREE_THRESH: f64 = 0.196;

/// How large a map image may be. Checked on the image header, before the
/// pixels are decoded: at most `max_cells` cells (`width * height`) and at
/// most `max_cells * DECODED_BYTES_PER_CELL` decoded bytes (the decoder's
/// output: pixels x channels x 1 or 2 bytes per sample).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MapLimits {
    /// Most cells; 1..=[`MAX_CELLS`] (larger values act as [`MAX_CELLS`]).
    pub max_cells: u64,
}

impl MapLimits {
    /// The cell limit, clamped to 1..=[`MAX_CELLS`].
    pub fn cells(&self) -> u64 {
        self.max_cells.clamp(1, MAX_CELLS)
    }

    /// Most decoded image bytes.
    pub fn decoded_bytes(&self) -> u64 {
        self.cells() * DECODED_BYTES_PER_CELL
    }
}

impl Default for MapLimits {
    fn default() -> Self {
        MapLimits {
            max_cells: DEFAULT_MAX_CELLS,
        }
    }
}

/// One grid cell's state.
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Cell {
    /// Known free space.
    Free = 0,
    /// Known obstacle: stops a laser beam.
    Occupied = 1,
    /// Never observed (or an intermediate occupancy).
    Unknown = 2,
}

/// A trinary occupancy grid with its placement in the map frame.
#[derive(Clone, Debug, PartialEq)]
pub struct OccupancyGrid {
    /// Width in cells.
    pub width: u32,
    /// Height in cells.
    pub height: u32,
    /// Cell side in metres (m/cell), finite and > 0.
    pub resolution: f64,
    /// Map-frame pose of the lower-left corner of cell (0, 0): x (m), y (m),
    /// yaw (rad, counter-clockwise).
    pub origin: [f64; 3],
    /// Cells, index `cy * width + cx`, `cy = 0` the bottom row.
    pub cells: Vec<Cell>,
}

impl OccupancyGrid {
    /// Builds a grid from cells already in grid order (index `cy * width +
    /// cx`, bottom row first). Meant for tests and synthetic maps.
    ///
    /// # Panics
    /// When `cells.len() != width * height` or `resolution` is not finite and
    /// positive (programming errors, not input errors).
    pub fn from_cells(
        width: u32,
        height: u32,
        resolution: f64,
        origin: [f64; 3],
        cells: Vec<Cell>,
    ) -> Self {
        assert_eq!(
            cells.len(),
            width as usize * height as usize,
            "OccupancyGrid::from_cells: {} cells for a {width} x {height} grid",
            cells.len()
        );
        assert!(
            resolution.is_finite() && resolution > 0.0,
            "OccupancyGrid::from_cells: resolution {resolution} m/cell"
        );
        OccupancyGrid {
            width,
            height,
            resolution,
            origin,
            cells,
        }
    }

    /// Builds a grid from text rows written as the image looks: the FIRST
    /// string is the TOP row. `#` is occupied, `?` unknown, anything else
    /// (`.`, space) free. Meant for tests and hand-drawn maps.
    ///
    /// # Panics
    /// When the rows differ in length (a programming error).
    pub fn from_ascii(rows: &[&str], resolution: f64, origin: [f64; 3]) -> Self {
        let height = rows.len() as u32;
        let width = rows.first().map_or(0, |r| r.chars().count()) as u32;
        let mut cells = Vec::with_capacity(width as usize * height as usize);
        for row in rows.iter().rev() {
            assert_eq!(
                row.chars().count(),
                width as usize,
                "OccupancyGrid::from_ascii: ragged rows"
            );
            cells.extend(row.chars().map(|c| match c {
                '#' => Cell::Occupied,
                '?' => Cell::Unknown,
                _ => Cell::Free,
            }));
        }
        Self::from_cells(width, height, resolution, origin, cells)
    }

    /// The cell at `(cx, cy)`; [`Cell::Unknown`] outside the grid.
    #[inline]
    pub fn get(&self, cx: u32, cy: u32) -> Cell {
        if cx >= self.width || cy >= self.height {
            return Cell::Unknown;
        }
        self.cells[cy as usize * self.width as usize + cx as usize]
    }

    /// The grid's placement as the runtime's [`MapFrame`] (f32).
    pub fn frame(&self) -> MapFrame {
        MapFrame {
            resolution: self.resolution as f32,
            origin: Pose2::new(
                self.origin[0] as f32,
                self.origin[1] as f32,
                self.origin[2] as f32,
            ),
        }
    }

    /// Number of [`Cell::Free`] cells.
    pub fn free_count(&self) -> usize {
        self.cells.iter().filter(|&&c| c == Cell::Free).count()
    }

    /// The grid packed as [`BitGrid`] words: bit `cy * width + cx` of the
    /// `u32` words (least significant bit first) is 1 when the cell stops a
    /// beam. Occupied cells always block; unknown cells block when
    /// `unknown_blocks` is set.
    pub fn blocked_bits(&self, unknown_blocks: bool) -> Vec<u32> {
        let mut words = vec![0u32; BitGrid::words_for(self.width, self.height)];
        for (i, &c) in self.cells.iter().enumerate() {
            let blocks = match c {
                Cell::Free => false,
                Cell::Occupied => true,
                Cell::Unknown => unknown_blocks,
            };
            if blocks {
                words[i / 32] |= 1 << (i % 32);
            }
        }
        words
    }

    /// Map-frame position (metres) of the centre of cell `(cx, cy)`.
    pub fn cell_center(&self, cx: u32, cy: u32) -> [f64; 2] {
        self.cell_to_map([cx as f64 + 0.5, cy as f64 + 0.5])
    }

    /// Continuous cell coordinates (cell units, lower-left corner of the
    /// grid at (0, 0)) to a map-frame point (metres), in f64.
    pub fn cell_to_map(&self, uv: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.origin[2].sin_cos();
        let (u, v) = (uv[0] * self.resolution, uv[1] * self.resolution);
        [
            self.origin[0] + c * u - s * v,
            self.origin[1] + s * u + c * v,
        ]
    }
}

/// How pixel values become occupancy (map_server's `mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Thresholds give free / occupied / unknown (the default).
    #[default]
    Trinary,
    /// Thresholds give free / occupied; values between them are
    /// probabilities in map_server, [`Cell::Unknown`] here.
    Scale,
    /// The pixel value is the occupancy in percent (0..=100; above is unknown).
    Raw,
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Mode::Trinary => "trinary",
            Mode::Scale => "scale",
            Mode::Raw => "raw",
        })
    }
}

/// A loaded map and where it came from.
#[derive(Clone, Debug)]
pub struct MapSource {
    /// The occupancy grid.
    pub grid: OccupancyGrid,
    /// The YAML file, when the map was described by one.
    pub yaml_path: Option<PathBuf>,
    /// The image file.
    pub image_path: PathBuf,
    /// SHA-256 of the YAML file's bytes, when there is one.
    pub yaml_sha256: Option<[u8; 32]>,
    /// SHA-256 of the image file's bytes.
    pub image_sha256: [u8; 32],
    /// Whether dark pixels mean free (map_server's `negate`).
    pub negate: bool,
    /// Occupancy probability above which a cell is occupied, in [0, 1].
    pub occupied_thresh: f64,
    /// Occupancy probability below which a cell is free, in [0, 1].
    pub free_thresh: f64,
    /// Pixel interpretation.
    pub mode: Mode,
}

impl MapSource {
    /// A map made in memory rather than read (tests, generated grids): no
    /// YAML, the map_saver's thresholds, trinary mode, and `image` as the
    /// image's name (no such file need exist; its hash is zero).
    pub fn in_memory(grid: OccupancyGrid, image: &str) -> Self {
        MapSource {
            grid,
            yaml_path: None,
            image_path: image.into(),
            yaml_sha256: None,
            image_sha256: [0; 32],
            negate: false,
            occupied_thresh: DEFAULT_OCCUPIED_THRESH,
            free_thresh: DEFAULT_FREE_THRESH,
            mode: Mode::Trinary,
        }
    }

    /// The files the map was read from (the image, and the YAML when there
    /// is one): an output must never be one of them
    /// ([`crate::compiler::writer::check_output_path`]).
    pub fn input_files(&self) -> Vec<&Path> {
        let mut v: Vec<&Path> = vec![&self.image_path];
        v.extend(self.yaml_path.as_deref());
        v
    }
}

/// Why a map could not be loaded. Every variant names the offending file.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// A file could not be read.
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The YAML file is not valid YAML (or not UTF-8, or too large).
    #[error("{}: YAML syntax error{}: {message}", path.display(), fmt_line(*line))]
    YamlSyntax {
        /// The YAML file.
        path: PathBuf,
        /// 1-based line of the error, when known.
        line: Option<usize>,
        /// What the parser said.
        message: String,
    },
    /// A required key is absent from the YAML file.
    #[error("{}: missing field `{field}`", path.display())]
    MissingField {
        /// The YAML file.
        path: PathBuf,
        /// The key.
        field: &'static str,
    },
    /// A key has a value of the wrong type or out of range.
    #[error("{}: field `{field}`: expected {expected}, found {found}", path.display())]
    BadField {
        /// The YAML file.
        path: PathBuf,
        /// The key.
        field: &'static str,
        /// What was expected.
        expected: &'static str,
        /// What was found (rendered).
        found: String,
    },
    /// The resolution is zero, negative or not finite.
    #[error("{}: resolution must be a finite number of metres per cell > 0, found {value}", path.display())]
    BadResolution {
        /// The YAML file (or the image, when the resolution came from the caller).
        path: PathBuf,
        /// The value.
        value: f64,
    },
    /// The thresholds are outside [0, 1] or `free_thresh >= occupied_thresh`.
    #[error(
        "{}: thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, found free_thresh {free}, occupied_thresh {occupied}",
        path.display()
    )]
    BadThresholds {
        /// The YAML file.
        path: PathBuf,
        /// `free_thresh`.
        free: f64,
        /// `occupied_thresh`.
        occupied: f64,
    },
    /// The image file named by the YAML file does not exist.
    #[error("{}: image file does not exist{}", path.display(), fmt_named_by(yaml.as_deref()))]
    ImageMissing {
        /// The image path.
        path: PathBuf,
        /// The YAML file that named it.
        yaml: Option<PathBuf>,
    },
    /// The image could not be decoded (format, truncation, corruption).
    #[error("{}: cannot decode image: {message}", path.display())]
    ImageDecode {
        /// The image file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The image header declares more cells or decoded bytes than the
    /// [`MapLimits`] allow (or a side longer than [`MAX_SIDE`]).
    #[error(
        "{}: image is {width} x {height} pixels ({} cells{}); the limit is {} cells, {} decoded \
         bytes and {MAX_SIDE} pixels per side (--max-cells raises it, up to {MAX_CELLS})",
        path.display(),
        *width as u64 * *height as u64,
        decoded.map(|d| format!(", {d} bytes decoded")).unwrap_or_default(),
        limits.cells(),
        limits.decoded_bytes()
    )]
    ImageTooLarge {
        /// The image file.
        path: PathBuf,
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// Decoded bytes the header declares, when the pixel format was read.
        decoded: Option<u64>,
        /// The limits in force.
        limits: MapLimits,
    },
    /// The map has no free cell at all (wrong thresholds or `negate`?).
    #[error(
        "{}: the map has no free cell (check negate, free_thresh and mode)",
        path.display()
    )]
    NoFreeCell {
        /// The image (or YAML) file.
        path: PathBuf,
    },
    /// An image was given alone, without a YAML file beside it nor a resolution.
    #[error(
        "{}: no {} beside {}; pass --resolution (m/cell) and optionally --origin x,y,yaw",
        path.display(), file_name(yaml), file_name(path)
    )]
    NoYamlBeside {
        /// The image file.
        path: PathBuf,
        /// The YAML file that was looked for.
        yaml: PathBuf,
    },
    /// The YAML file beside an image describes another image.
    #[error("{}: describes image {}, not {}", path.display(), named.display(), image.display())]
    ImageMismatch {
        /// The YAML file.
        path: PathBuf,
        /// The image it names.
        named: PathBuf,
        /// The image that was asked for.
        image: PathBuf,
    },
    /// A resolution or origin was given on the command line and disagrees
    /// with the YAML file beside the image.
    #[error("{}: {field} {yaml_value} disagrees with the given {given}", path.display())]
    Conflict {
        /// The YAML file.
        path: PathBuf,
        /// `resolution` or `origin`.
        field: &'static str,
        /// The YAML's value (rendered).
        yaml_value: String,
        /// The caller's value (rendered).
        given: String,
    },
}

fn fmt_line(line: Option<usize>) -> String {
    line.map(|l| format!(" at line {l}")).unwrap_or_default()
}

fn fmt_named_by(yaml: Option<&Path>) -> String {
    yaml.map(|y| format!(" (named by {})", y.display()))
        .unwrap_or_default()
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

/// Loads a ROS map_server YAML file and the image it names (relative to the
/// YAML's directory unless absolute), within the default [`MapLimits`].
pub fn load_yaml(path: &Path) -> Result<MapSource, MapError> {
    load_yaml_within(path, &MapLimits::default())
}

/// [`load_yaml`] within the given [`MapLimits`].
pub fn load_yaml_within(path: &Path, limits: &MapLimits) -> Result<MapSource, MapError> {
    let bytes = read_limited(path, MAX_YAML_BYTES, || MapError::YamlSyntax {
        path: path.to_path_buf(),
        line: None,
        message: format!("file is larger than {MAX_YAML_BYTES} bytes; not a map description"),
    })?;
    let yaml_sha = sha256(&bytes);
    let text = std::str::from_utf8(&bytes).map_err(|e| MapError::YamlSyntax {
        path: path.to_path_buf(),
        line: None,
        message: format!("not UTF-8 ({e})"),
    })?;
    let desc = parse_description(path, text)?;
    let image_path = if desc.image.is_absolute() {
        desc.image.clone()
    } else {
        path.parent()
            .unwrap_or_else(|| Path::new(""))
            .join(&desc.image)
    };
    if !image_path.is_file() {
        return Err(MapError::ImageMissing {
            path: image_path,
            yaml: Some(path.to_path_buf()),
        });
    }
    let pixels = Params {
        negate: desc.negate,
        occupied_thresh: desc.occupied_thresh,
        free_thresh: desc.free_thresh,
        mode: desc.mode,
    };
    let (grid_cells, width, height, image_sha) = load_pixels(&image_path, &pixels, limits)?;
    let grid = OccupancyGrid {
        width,
        height,
        resolution: desc.resolution,
        origin: desc.origin,
        cells: grid_cells,
    };
    if grid.free_count() == 0 {
        return Err(MapError::NoFreeCell { path: image_path });
    }
    Ok(MapSource {
        grid,
        yaml_path: Some(path.to_path_buf()),
        image_path,
        yaml_sha256: Some(yaml_sha),
        image_sha256: image_sha,
        negate: desc.negate,
        occupied_thresh: desc.occupied_thresh,
        free_thresh: desc.free_thresh,
        mode: desc.mode,
    })
}

/// Checks a `--resolution` and `--origin` given on the command line against
/// the YAML that describes the map (`yaml`, already loaded as `src`): equal
/// values are fine, a different one is a [`MapError::Conflict`] naming both,
/// so a value the user gave is never silently ignored.
pub fn check_given(
    src: &MapSource,
    yaml: &Path,
    resolution: Option<f64>,
    origin: Option<[f64; 3]>,
) -> Result<(), MapError> {
    if let Some(r) = resolution {
        if (r - src.grid.resolution).abs() > 1e-12 * r.abs().max(1.0) || !r.is_finite() {
            return Err(MapError::Conflict {
                path: yaml.to_path_buf(),
                field: "resolution",
                yaml_value: src.grid.resolution.to_string(),
                given: r.to_string(),
            });
        }
    }
    if let Some(o) = origin {
        let differs = o
            .iter()
            .zip(src.grid.origin.iter())
            .any(|(a, b)| !a.is_finite() || (a - b).abs() > 1e-9);
        if differs {
            return Err(MapError::Conflict {
                path: yaml.to_path_buf(),
                field: "origin",
                yaml_value: format!("{:?}", src.grid.origin),
                given: format!("{o:?}"),
            });
        }
    }
    Ok(())
}

/// Loads a map given by its image, as `mapc build lab.pgm` does.
///
/// When `lab.yaml` exists beside `lab.pgm` it is loaded with [`load_yaml`];
/// it must name this image, and a `resolution` / `origin` given here must
/// agree with it. Otherwise `resolution` (m/cell) is required, `origin`
/// defaults to `[0, 0, 0]`, and the ROS map_saver thresholds
/// ([`DEFAULT_OCCUPIED_THRESH`], [`DEFAULT_FREE_THRESH`]), `negate: 0` and
/// trinary mode apply.
///
/// The default [`MapLimits`] apply; [`load_image_within`] takes others.
pub fn load_image(
    path: &Path,
    resolution: Option<f64>,
    origin: Option<[f64; 3]>,
) -> Result<MapSource, MapError> {
    load_image_within(path, resolution, origin, &MapLimits::default())
}

/// [`load_image`] within the given [`MapLimits`].
pub fn load_image_within(
    path: &Path,
    resolution: Option<f64>,
    origin: Option<[f64; 3]>,
    limits: &MapLimits,
) -> Result<MapSource, MapError> {
    let yaml = path.with_extension("yaml");
    if yaml.is_file() {
        let src = load_yaml_within(&yaml, limits)?;
        if !same_file(&src.image_path, path) {
            return Err(MapError::ImageMismatch {
                path: yaml,
                named: src.image_path,
                image: path.to_path_buf(),
            });
        }
        check_given(&src, &yaml, resolution, origin)?;
        return Ok(src);
    }
    let Some(resolution) = resolution else {
        return Err(MapError::NoYamlBeside {
            path: path.to_path_buf(),
            yaml,
        });
    };
    if !(resolution.is_finite() && resolution > 0.0) {
        return Err(MapError::BadResolution {
            path: path.to_path_buf(),
            value: resolution,
        });
    }
    let origin = origin.unwrap_or([0.0; 3]);
    if origin.iter().any(|v| !v.is_finite()) {
        return Err(MapError::BadField {
            path: path.to_path_buf(),
            field: "origin",
            expected: "three finite numbers [x m, y m, yaw rad]",
            found: format!("{origin:?}"),
        });
    }
    if !path.is_file() {
        return Err(MapError::ImageMissing {
            path: path.to_path_buf(),
            yaml: None,
        });
    }
    let params = Params {
        negate: false,
        occupied_thresh: DEFAULT_OCCUPIED_THRESH,
        free_thresh: DEFAULT_FREE_THRESH,
        mode: Mode::Trinary,
    };
    let (cells, width, height, image_sha) = load_pixels(path, &params, limits)?;
    let grid = OccupancyGrid {
        width,
        height,
        resolution,
        origin,
        cells,
    };
    if grid.free_count() == 0 {
        return Err(MapError::NoFreeCell {
            path: path.to_path_buf(),
        });
    }
    Ok(MapSource {
        grid,
        yaml_path: None,
        image_path: path.to_path_buf(),
        yaml_sha256: None,
        image_sha256: image_sha,
        negate: params.negate,
        occupied_thresh: params.occupied_thresh,
        free_thresh: params.free_thresh,
        mode: params.mode,
    })
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

fn sha256(bytes: &[u8]) -> [u8; 32] {
    let mut h = Sha256::new();
    h.update(bytes);
    h.finalize().into()
}

/// Reads a whole file, refusing files larger than `limit` bytes with the
/// error `too_large` makes.
fn read_limited(
    path: &Path,
    limit: u64,
    too_large: impl FnOnce() -> MapError,
) -> Result<Vec<u8>, MapError> {
    use std::io::Read;
    let io = |source| MapError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(too_large());
    }
    Ok(bytes)
}

/// The parsed YAML map description.
struct Description {
    image: PathBuf,
    resolution: f64,
    origin: [f64; 3],
    negate: bool,
    occupied_thresh: f64,
    free_thresh: f64,
    mode: Mode,
}

/// How pixels become cells.
struct Params {
    negate: bool,
    occupied_thresh: f64,
    free_thresh: f64,
    mode: Mode,
}

/// Strips user-defined tags.
fn untag<'a, 'b>(mut y: &'a Yaml<'b>) -> &'a Yaml<'b> {
    while let Yaml::Tagged(_, inner) = y {
        y = inner;
    }
    y
}

fn render(y: &Yaml<'_>) -> String {
    let y = untag(y);
    if let Some(s) = y.as_str() {
        return format!("string {s:?}");
    }
    if let Some(b) = y.as_bool() {
        return format!("boolean {b}");
    }
    if let Some(i) = y.as_integer() {
        return format!("integer {i}");
    }
    if let Some(f) = y.as_floating_point() {
        return format!("number {f}");
    }
    if y.is_null() {
        return "null".into();
    }
    if let Some(s) = y.as_sequence() {
        return format!("a list of {} items", s.len());
    }
    if y.is_mapping() {
        return "a mapping".into();
    }
    if y.is_alias() {
        return "an alias".into();
    }
    "an unparsable value".into()
}

/// A number: YAML float or integer, or (as yaml-cpp would convert it) a
/// string holding one.
fn as_number(y: &Yaml<'_>) -> Option<f64> {
    let y = untag(y);
    if let Some(f) = y.as_floating_point() {
        return Some(f);
    }
    if let Some(i) = y.as_integer() {
        return Some(i as f64);
    }
    if let Some(s) = y.as_str() {
        return s.trim().parse::<f64>().ok();
    }
    if let Yaml::Representation(s, _, _) = y {
        return s.trim().parse::<f64>().ok();
    }
    None
}

/// The YAML's `resolution`: a finite positive number of metres per cell.
fn field_resolution(path: &Path, node: &Yaml) -> Result<f64, MapError> {
    match as_number(node) {
        Some(r) if r.is_finite() && r > 0.0 => Ok(r),
        Some(r) => Err(MapError::BadResolution {
            path: path.to_path_buf(),
            value: r,
        }),
        None => Err(MapError::BadField {
            path: path.to_path_buf(),
            field: "resolution",
            expected: "a number of metres per cell",
            found: render(node),
        }),
    }
}

/// The YAML's `origin`: three finite numbers `[x m, y m, yaw rad]`.
fn field_origin(path: &Path, node: &Yaml) -> Result<[f64; 3], MapError> {
    let bad = |found: String| MapError::BadField {
        path: path.to_path_buf(),
        field: "origin",
        expected: "three finite numbers [x m, y m, yaw rad]",
        found,
    };
    let seq = match node.as_sequence() {
        Some(seq) if seq.len() == 3 => seq,
        _ => return Err(bad(render(node))),
    };
    let mut o = [0.0; 3];
    for (slot, v) in o.iter_mut().zip(seq.iter()) {
        match as_number(v) {
            Some(x) if x.is_finite() => *slot = x,
            _ => return Err(bad(format!("an item that is {}", render(v)))),
        }
    }
    Ok(o)
}

/// The YAML's `negate`: 0, 1, true or false (also as a string).
fn field_negate(path: &Path, v: &Yaml) -> Result<bool, MapError> {
    if let Some(b) = v.as_bool() {
        Ok(b)
    } else if let Some(i) = v.as_integer() {
        Ok(i != 0)
    } else if let Some(i) = v.as_str().and_then(|s| s.trim().parse::<i64>().ok()) {
        Ok(i != 0)
    } else {
        Err(MapError::BadField {
            path: path.to_path_buf(),
            field: "negate",
            expected: "0, 1, true or false",
            found: render(v),
        })
    }
}

/// The YAML's `mode`: trinary, scale or raw (any case).
fn field_mode(path: &Path, v: &Yaml) -> Result<Mode, MapError> {
    match v.as_str().map(|s| s.trim().to_ascii_lowercase()) {
        Some(s) if s == "trinary" => Ok(Mode::Trinary),
        Some(s) if s == "scale" => Ok(Mode::Scale),
        Some(s) if s == "raw" => Ok(Mode::Raw),
        _ => Err(MapError::BadField {
            path: path.to_path_buf(),
            field: "mode",
            expected: "trinary, scale or raw",
            found: render(v),
        }),
    }
}

fn parse_description(path: &Path, text: &str) -> Result<Description, MapError> {
    let p = || path.to_path_buf();
    let docs = Yaml::load_from_str(text).map_err(|e| MapError::YamlSyntax {
        path: p(),
        line: Some(e.marker().line()),
        message: e.info().to_string(),
    })?;
    let Some(doc) = docs.first() else {
        return Err(MapError::YamlSyntax {
            path: p(),
            line: None,
            message: "empty document".into(),
        });
    };
    let doc = untag(doc);
    if !doc.is_mapping() {
        return Err(MapError::YamlSyntax {
            path: p(),
            line: None,
            message: format!(
                "expected a mapping of keys to values, found {}",
                render(doc)
            ),
        });
    }
    let get = |field: &'static str| doc.as_mapping_get(field).map(untag);
    let required =
        |field: &'static str| get(field).ok_or(MapError::MissingField { path: p(), field });
    let number = |field: &'static str, expected: &'static str| -> Result<f64, MapError> {
        let v = required(field)?;
        match as_number(v) {
            Some(x) if x.is_finite() => Ok(x),
            _ => Err(MapError::BadField {
                path: p(),
                field,
                expected,
                found: render(v),
            }),
        }
    };

    let image_node = required("image")?;
    let image = match image_node.as_str() {
        Some(s) if !s.trim().is_empty() => PathBuf::from(s.trim()),
        _ => {
            return Err(MapError::BadField {
                path: p(),
                field: "image",
                expected: "a non-empty file name",
                found: render(image_node),
            })
        }
    };

    let resolution = field_resolution(path, required("resolution")?)?;
    let origin = field_origin(path, required("origin")?)?;
    let negate = get("negate").map_or(Ok(false), |v| field_negate(path, v))?;
    let occupied_thresh = number("occupied_thresh", "a number in [0, 1]")?;
    let free_thresh = number("free_thresh", "a number in [0, 1]")?;
    if !((0.0..=1.0).contains(&occupied_thresh)
        && (0.0..=1.0).contains(&free_thresh)
        && free_thresh < occupied_thresh)
    {
        return Err(MapError::BadThresholds {
            path: p(),
            free: free_thresh,
            occupied: occupied_thresh,
        });
    }

    let mode = get("mode").map_or(Ok(Mode::Trinary), |v| field_mode(path, v))?;

    Ok(Description {
        image,
        resolution,
        origin,
        negate,
        occupied_thresh,
        free_thresh,
        mode,
    })
}

/// Memory the decoders may use besides the pixel buffer (row buffers,
/// compressed and ancillary chunk data), in bytes.
const DECODER_WORKSPACE: u64 = 64 << 20;

/// Bits per pixel of a PNG's raw scanlines, from its `IHDR` (colour type and
/// bit depth); 1, the least any PNG uses, when the header cannot be read.
fn png_bits_per_pixel(bytes: &[u8]) -> u64 {
    if bytes.get(12..16) != Some(&b"IHDR"[..]) {
        return 1;
    }
    let (Some(&depth), Some(&colour)) = (bytes.get(24), bytes.get(25)) else {
        return 1;
    };
    let channels = match colour {
        0 | 3 => 1, // grey; palette index
        4 => 2,     // grey + alpha
        2 => 3,     // RGB
        6 => 4,     // RGBA
        _ => 1,
    };
    (channels * depth as u64).max(1)
}

/// A cheap lower bound on the file size an image of `width x height` needs,
/// so that a small file claiming a huge image is refused before the pixel
/// buffer (`decoded_bytes`, the decoder's output) is allocated. Never
/// rejects a valid file.
fn minimum_file_bytes(bytes: &[u8], width: u64, height: u64, decoded_bytes: u64) -> u64 {
    let cells = width * height;
    match bytes.get(..2) {
        // Plain (ASCII) formats: a digit per sample, separated from the
        // next one (P1 needs no separator).
        Some(b"P1") => cells,
        Some(b"P2") => 2 * cells - 1,
        Some(b"P3") => 6 * cells - 1,
        Some(b"P4") => height * width.div_ceil(8),
        // Binary samples of 1 or 2 bytes, stored as the decoder outputs them.
        Some(b"P5") | Some(b"P6") | Some(b"P7") => decoded_bytes,
        // PNG: the raw scanlines hold the bits per pixel the header
        // declares (colour type x bit depth, up to 64), and deflate cannot
        // compress better than 1032:1. So the decoded buffer is at most
        // 1032 x 32 (a 1-bit palette expanded to RGBA) times the file.
        Some(b"\x89P") => (cells * png_bits_per_pixel(bytes)).div_ceil(8) / 1032,
        _ => 0,
    }
}

/// Decodes the image and classifies its pixels; returns the cells in grid
/// order, the dimensions and the SHA-256 of the file.
///
/// Memory: the header is read first; the dimensions must be within
/// [`MAX_SIDE`] and the [`MapLimits`] (cells, then decoded bytes) and the file large enough for the pixels it
/// declares ([`minimum_file_bytes`]) before the pixel buffer (the decoder's
/// output: width x height x channels x 1 or 2 bytes) is allocated, and that
/// allocation is fallible (an error, not an abort, when it cannot be had).
/// The decoders' own working memory is capped at [`DECODER_WORKSPACE`].
fn load_pixels(
    path: &Path,
    params: &Params,
    limits: &MapLimits,
) -> Result<(Vec<Cell>, u32, u32, [u8; 32]), MapError> {
    use image::{ColorType, ImageDecoder};
    let decode_err = |message: String| MapError::ImageDecode {
        path: path.to_path_buf(),
        message,
    };
    // No image within the limits needs a file larger than this (stored,
    // uncompressed PNG data is the decoded bytes plus a few per row and
    // block; PGM is the decoded bytes plus a header).
    let file_limit = limits.decoded_bytes().saturating_mul(2) + (1 << 20);
    let bytes = read_limited(path, file_limit, || {
        decode_err(format!(
            "file is larger than {file_limit} bytes, more than any image within {} cells \
             needs (--max-cells raises it)",
            limits.cells()
        ))
    })?;
    let sha = sha256(&bytes);
    let mut r = image::ImageReader::new(Cursor::new(&bytes[..]))
        .with_guessed_format()
        .map_err(|e| decode_err(e.to_string()))?;
    if r.format().is_none() {
        return Err(decode_err(
            "unrecognized image format (PGM/PNM and PNG are supported)".into(),
        ));
    }
    // No dimension limits here (the check below gives the typed
    // `ImageTooLarge`); the pixel buffer is allocated by this function, not
    // by the decoder, so `max_alloc` only bounds the decoder's working memory.
    let mut decoder_limits = image::Limits::no_limits();
    decoder_limits.max_alloc = Some(DECODER_WORKSPACE);
    r.limits(decoder_limits);
    let decoder = r.into_decoder().map_err(|e| decode_err(e.to_string()))?;
    let (width, height) = decoder.dimensions();
    if width == 0 || height == 0 {
        return Err(decode_err(format!("image is {width} x {height} pixels")));
    }
    let too_large = |decoded| MapError::ImageTooLarge {
        path: path.to_path_buf(),
        width,
        height,
        decoded,
        limits: *limits,
    };
    if width > MAX_SIDE || height > MAX_SIDE || width as u64 * height as u64 > limits.cells() {
        return Err(too_large(None));
    }
    let (channels, sample_bytes, has_alpha) = match decoder.color_type() {
        ColorType::L8 => (1, 1, false),
        ColorType::La8 => (2, 1, true),
        ColorType::Rgb8 => (3, 1, false),
        ColorType::Rgba8 => (4, 1, true),
        ColorType::L16 => (1, 2, false),
        ColorType::La16 => (2, 2, true),
        ColorType::Rgb16 => (3, 2, false),
        ColorType::Rgba16 => (4, 2, true),
        other => {
            return Err(decode_err(format!(
                "unsupported pixel format {other:?} (8 or 16 bits per channel expected)"
            )))
        }
    };
    let decoded = width as u64 * height as u64 * channels * sample_bytes;
    if decoded > limits.decoded_bytes() {
        return Err(too_large(Some(decoded)));
    }
    if decoder.total_bytes() != decoded {
        return Err(decode_err(format!(
            "the decoder reports {} bytes for {width} x {height} pixels of {channels} x {sample_bytes} bytes",
            decoder.total_bytes()
        )));
    }
    let need = minimum_file_bytes(&bytes, width as u64, height as u64, decoded);
    if (bytes.len() as u64) < need {
        return Err(decode_err(format!(
            "truncated: the header claims {width} x {height} pixels but the file has only {} \
             bytes, fewer than the {need} they need at least",
            bytes.len()
        )));
    }
    let no_memory = || {
        decode_err(format!(
            "not enough memory for the {decoded} bytes of {width} x {height} decoded pixels"
        ))
    };
    let len = usize::try_from(decoded).map_err(|_| no_memory())?;
    // Fallible: a size the allocator cannot provide is an error, not an
    // abort. Probed with `try_reserve_exact`, then allocated zeroed (calloc:
    // pages the decoder never writes, when the data turns out to be cut off,
    // are never touched).
    let mut probe: Vec<u8> = Vec::new();
    probe.try_reserve_exact(len).map_err(|_| no_memory())?;
    drop(probe);
    let mut samples = vec![0u8; len];
    decoder
        .read_image(&mut samples)
        .map_err(|e| decode_err(e.to_string()))?;
    if sample_bytes == 2 {
        narrow_16_to_8(&mut samples);
    }
    let cells = classify(
        &samples,
        width as usize,
        height as usize,
        channels as usize,
        has_alpha,
        params,
    );
    Ok((cells, width, height, sha))
}

/// 16-bit samples (native byte order, as the decoders output them) to
/// 8 bits (`round(v * 255 / 65535)`), in place: the buffer halves.
fn narrow_16_to_8(buf: &mut Vec<u8>) {
    let n = buf.len() / 2;
    for i in 0..n {
        let v = u16::from_ne_bytes([buf[2 * i], buf[2 * i + 1]]);
        buf[i] = ((v as u32 * 255 + 32767) / 65535) as u8;
    }
    buf.truncate(n);
}

/// Classifies one pixel (8-bit channels, alpha last when `has_alpha`).
fn classify_pixel(px: &[u8], has_alpha: bool, params: &Params) -> Cell {
    let n = px.len();
    let alpha = if has_alpha { px[n - 1] } else { 255 };
    if alpha == 0 {
        return Cell::Unknown;
    }
    let colour = if has_alpha { &px[..n - 1] } else { px };
    // The colour average; a grey channel stands for R = G = B, as map_server
    // (SDL / GraphicsMagick) expands grey images to RGB.
    let colour_sum: u32 = colour.iter().map(|&v| v as u32).sum();
    let colour_n = colour.len() as u32;
    let (rgb_sum, rgb_n) = if colour_n == 1 {
        (3 * colour_sum, 3)
    } else {
        (colour_sum, colour_n)
    };
    match params.mode {
        Mode::Raw => {
            let v = (rgb_sum as f64 / rgb_n as f64).round();
            if v == 0.0 {
                Cell::Free
            } else if v == 100.0 {
                Cell::Occupied
            } else if v > 100.0 {
                Cell::Unknown
            } else {
                threshold(v / 100.0, params)
            }
        }
        Mode::Trinary | Mode::Scale => {
            if params.mode == Mode::Scale && alpha != 255 {
                return Cell::Unknown;
            }
            // map_server averages alpha in with R, G, B in trinary mode.
            let avg = if params.mode == Mode::Trinary && has_alpha {
                (rgb_sum + alpha as u32) as f64 / (rgb_n + 1) as f64
            } else {
                rgb_sum as f64 / rgb_n as f64
            };
            let occ = if params.negate {
                avg / 255.0
            } else {
                (255.0 - avg) / 255.0
            };
            threshold(occ, params)
        }
    }
}

fn threshold(occ: f64, params: &Params) -> Cell {
    if occ > params.occupied_thresh {
        Cell::Occupied
    } else if occ < params.free_thresh {
        Cell::Free
    } else {
        Cell::Unknown
    }
}

/// Classifies all pixels (`w x h`, `ch` 8-bit channels each, alpha last
/// when `has_alpha`, top image row first) and flips rows (image top row =
/// grid row `h - 1`).
fn classify(
    samples: &[u8],
    w: usize,
    h: usize,
    ch: usize,
    has_alpha: bool,
    params: &Params,
) -> Vec<Cell> {
    use rayon::prelude::*;
    // A 256-entry table for the common single-channel case.
    let lut: Option<Vec<Cell>> = (ch == 1).then(|| {
        (0..=255u8)
            .map(|v| classify_pixel(&[v], false, params))
            .collect()
    });
    let mut cells = vec![Cell::Unknown; w * h];
    cells
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(cy, row)| {
            let iy = h - 1 - cy;
            let src = &samples[iy * w * ch..(iy + 1) * w * ch];
            match &lut {
                Some(lut) => {
                    for (c, &v) in row.iter_mut().zip(src) {
                        *c = lut[v as usize];
                    }
                }
                None => {
                    for (c, px) in row.iter_mut().zip(src.chunks_exact(ch)) {
                        *c = classify_pixel(px, has_alpha, params);
                    }
                }
            }
        });
    cells
}

#[cfg(test)]
mod tests;
