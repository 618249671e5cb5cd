//! The `.refdb` on-disk layout (see `docs/format.md`), and its encoder.
//!
//! Everything is little-endian. The file is a 64-byte [`Header`], a table of
//! [`SectionEntry`] records, then the sections, each starting on a
//! [`SECTION_ALIGN`]-byte boundary so hot `f32`/`u32` arrays can be borrowed in
//! place. Records use zerocopy's unaligned little-endian field types; bulk
//! arrays are plain `f32`/`u32`/`u8` read in place on little-endian targets.
//!
//! The on-disk structs here are a compatibility boundary: they are never used
//! as in-memory working types, and any change to them bumps [`FORMAT_VERSION`].

pub mod crc;

use zerocopy::little_endian::{F32, U16, U32, U64};
use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout, Unaligned};

/// The first 8 bytes of every `.refdb` file.
pub const MAGIC: [u8; 8] = *b"REFLOCDB";

/// Written as a little-endian `u16`; a reader that sees `0xFFFE` is reading a
/// file with the other byte order.
pub const ENDIAN_CHECK: u16 = 0xFEFF;

/// The layout version this crate reads and writes.
///
/// Version policy: a reader accepts exactly its own version. A file with an
/// older or newer version is rejected with [`crate::DbErrorKind::Version`],
/// whose message says which version was found and which is expected, so the
/// user knows to rebuild the map with a matching `mapc` (the `.refdb` is a
/// build artifact, always reproducible from the map and the options recorded
/// in its manifest). Golden files of every released version live in
/// `tests/golden/` and the test suite checks that each is either read or
/// rejected with that message. Any change to a record or section layout
/// bumps this number.
pub const FORMAT_VERSION: u32 = 1;

/// Every section starts at a multiple of this many bytes.
pub const SECTION_ALIGN: usize = 16;

/// At most this many sections in a table (bounds the reader's work).
pub const MAX_SECTIONS: usize = 32;

/// Size of [`Header`] in bytes.
pub const HEADER_LEN: usize = 64;

/// Size of a [`SectionEntry`] in bytes.
pub const ENTRY_LEN: usize = 32;

/// The file header.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct Header {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`ENDIAN_CHECK`].
    pub endian: U16,
    /// [`HEADER_LEN`].
    pub header_len: U16,
    /// [`FORMAT_VERSION`].
    pub version: U32,
    /// Reserved flags, 0.
    pub flags: U32,
    /// Number of entries in the section table.
    pub section_count: U32,
    /// Total file length in bytes (detects truncation and appended bytes).
    pub file_len: U64,
    /// CRC-32C of the header (with this field zero) and the section table.
    pub header_crc: U32,
    /// Zero.
    pub reserved: [u8; 28],
}

/// One entry of the section table.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct SectionEntry {
    /// A [`SectionKind`] value.
    pub kind: U32,
    /// Reserved, 0.
    pub flags: U32,
    /// Byte offset from the start of the file (multiple of [`SECTION_ALIGN`]).
    pub offset: U64,
    /// Length in bytes.
    pub len: U64,
    /// CRC-32C of the section's bytes (checked by `RefDb::verify`).
    pub crc: U32,
    /// Zero.
    pub reserved: U32,
}

/// Section kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum SectionKind {
    /// One [`MetaRecord`].
    Meta = 1,
    /// One [`ParamsRecord`].
    Params = 2,
    /// Packed beam-stopping bits, `u32` words (see `raycast::BitGrid`).
    Grid = 3,
    /// Signed distance from each cell centre to the nearest obstacle
    /// surface (negative inside obstacles), `u8`: `(value - DIST_ZERO)`
    /// steps of `resolution / DIST_STEPS_PER_CELL`, saturating at 0 and 255.
    Dist = 4,
    /// `site_count` [`SiteRecord`]s.
    Sites = 5,
    /// Neighbour site indices (`u32`), sliced by each site's record.
    Neighbors = 6,
    /// Reference scans: `site_count * beams` ranges (`f32`, metres; no return
    /// is stored as `f32::INFINITY`).
    Scans = 7,
    /// PGR histograms: `site_count * (rho_bins * theta_bins)` `f32`, each
    /// histogram normalized to sum 1.
    Hists = 8,
    /// Build manifest: UTF-8 JSON written by `mapc` (input hashes, options,
    /// version). Informational; the runtime never parses it.
    Manifest = 9,
    /// Window histograms for partial fields of view: for each site, each used
    /// width and each heading, `win_rho_bins * win_theta_bins` `f32`
    /// normalized to sum 1 (empty when the database stores none).
    Windows = 10,
    /// Optional coarse-search index (see [`crate::index`]): an
    /// [`IndexHeader`], its [`IndexView`]s, every view's [`IndexNode`]s, the
    /// views' entries (`u32`), then the nodes' centroid histograms (`f32`).
    /// Absent (or empty) in small databases: the coarse stage then scores
    /// every site. Added within version 1: files without it read as before.
    Index = 11,
    /// Optional decision model: one [`DecisionRecord`] (the confidence
    /// model and the acceptance threshold, see [`crate::confidence`]).
    /// Added within version 1: a file without it keeps the acceptance rule
    /// it was built with (evidence over the threshold, free-space check,
    /// not ambiguous).
    Decision = 12,
    /// Optional reference side of spectral scan matching, per site: the
    /// prepared points, their tangents and their descriptors, exactly as
    /// the runtime computes them from the site's reference scan
    /// ([`crate::localize::reference_features`]); laid out as
    /// [`FeaturesLayout`] says. Added within version 1: a file without it
    /// reads as before and the runtime computes them per candidate.
    Features = 13,
}

impl SectionKind {
    /// All kinds, in file order.
    pub const ALL: [SectionKind; 13] = [
        SectionKind::Meta,
        SectionKind::Params,
        SectionKind::Grid,
        SectionKind::Dist,
        SectionKind::Sites,
        SectionKind::Neighbors,
        SectionKind::Scans,
        SectionKind::Hists,
        SectionKind::Manifest,
        SectionKind::Windows,
        SectionKind::Index,
        SectionKind::Decision,
        SectionKind::Features,
    ];

    /// From the raw value, if known.
    pub fn from_u32(v: u32) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| *k as u32 == v)
    }

    /// A short lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            SectionKind::Meta => "meta",
            SectionKind::Params => "params",
            SectionKind::Grid => "grid",
            SectionKind::Dist => "dist",
            SectionKind::Sites => "sites",
            SectionKind::Neighbors => "neighbors",
            SectionKind::Scans => "scans",
            SectionKind::Hists => "hists",
            SectionKind::Manifest => "manifest",
            SectionKind::Windows => "windows",
            SectionKind::Index => "index",
            SectionKind::Decision => "decision",
            SectionKind::Features => "features",
        }
    }

    /// True for a section a file may leave out (it then reads as empty).
    pub fn optional(self) -> bool {
        matches!(
            self,
            SectionKind::Index | SectionKind::Decision | SectionKind::Features
        )
    }
}

/// The decision section (32 bytes): a logistic confidence model over
/// [`crate::confidence::FEATURES`] features and the acceptance threshold.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct DecisionRecord {
    /// Intercept.
    pub bias: F32,
    /// Weights of the evidence ratio, the margin, ln support and the
    /// through share.
    pub weights: [F32; 4],
    /// Accept when the confidence is at least this (0..=1).
    pub threshold: F32,
    /// Weight of the spread (`confidence::Features::spread`); zero in files
    /// written before it, which leaves their model as it was.
    pub spread_weight: F32,
    /// Zero.
    pub reserved: U32,
}

impl DecisionRecord {
    /// The record of a model.
    pub fn of(d: &crate::confidence::Decision) -> DecisionRecord {
        let [e, m, s, t, spread] = d.weights;
        DecisionRecord {
            bias: F32::new(d.bias),
            weights: [e, m, s, t].map(F32::new),
            threshold: F32::new(d.threshold),
            spread_weight: F32::new(spread),
            reserved: U32::new(0),
        }
    }

    /// The model of a record (unchecked: see [`crate::confidence::Decision::is_valid`]).
    pub fn decision(&self) -> crate::confidence::Decision {
        let [e, m, s, t] = self.weights.map(|w| w.get());
        crate::confidence::Decision {
            bias: self.bias.get(),
            weights: [e, m, s, t, self.spread_weight.get()],
            threshold: self.threshold.get(),
        }
    }
}

/// Bytes a features section stores per prepared point: its position and
/// tangent (`[f32; 2]` each) and its descriptor (`DESC_LEN` `u16`s).
pub const FEATURE_POINT_BYTES: usize =
    2 * core::mem::size_of::<[f32; 2]>() + crate::ssm::DESC_LEN * core::mem::size_of::<u16>();

/// Where the arrays of a features section ([`SectionKind::Features`]) lie,
/// in bytes from the section's start: `sites + 1` `u32` offsets (prefix
/// sums of each site's prepared point count), zero padding to a multiple
/// of [`SECTION_ALIGN`], then `points` positions (`[f32; 2]`, m, sensor
/// frame of the site), `points` unit tangents (`[f32; 2]`) and `points *
/// DESC_LEN` descriptor bins (`u16`, see [`crate::ssm::descriptors`]).
/// The one description of the layout: `mapc` writes by it, the reader
/// checks and reads by it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FeaturesLayout {
    /// Bytes of the offsets (`4 * (sites + 1)`).
    pub offsets_len: usize,
    /// Start of the positions (the offsets and their padding end here).
    pub points_at: usize,
    /// Start of the tangents.
    pub tangents_at: usize,
    /// Start of the descriptors.
    pub desc_at: usize,
    /// Length of the whole section (bytes).
    pub len: usize,
}

impl FeaturesLayout {
    /// The layout for `sites` sites with `points` prepared points in all;
    /// `None` when it would not fit in memory's address range.
    pub fn new(sites: u64, points: u64) -> Option<FeaturesLayout> {
        let offsets_len = sites.checked_add(1)?.checked_mul(4)?;
        let points_at = offsets_len.checked_add(pad_len_u64(offsets_len))?;
        let pair = core::mem::size_of::<[f32; 2]>() as u64;
        let tangents_at = points_at.checked_add(points.checked_mul(pair)?)?;
        let desc_at = tangents_at.checked_add(points.checked_mul(pair)?)?;
        let len = points_at.checked_add(points.checked_mul(FEATURE_POINT_BYTES as u64)?)?;
        let us = |v: u64| usize::try_from(v).ok();
        Some(FeaturesLayout {
            offsets_len: us(offsets_len)?,
            points_at: us(points_at)?,
            tangents_at: us(tangents_at)?,
            desc_at: us(desc_at)?,
            len: us(len)?,
        })
    }
}

/// [`pad_len`] in `u64` (section lengths computed from untrusted counts).
const fn pad_len_u64(len: u64) -> u64 {
    let a = SECTION_ALIGN as u64;
    (a - len % a) % a
}

/// Start of the index section (16 bytes).
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct IndexHeader {
    /// Number of [`IndexView`] records that follow (at most
    /// `1 + win_count`).
    pub view_count: U32,
    /// Search: internal nodes kept per level (1..=[`INDEX_BEAM_MAX`]).
    pub beam: U32,
    /// Search: leaves whose entries are scored (1..=[`INDEX_LEAVES_MAX`]).
    pub leaves: U32,
    /// Zero.
    pub reserved: U32,
}

/// One searchable view of the sites (16 bytes): a tree over the full
/// histograms or over one window width's (site, heading) histograms.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct IndexView {
    /// 0: full histograms (entry = site); `1 + w`: window width slot `w`
    /// (entry = `site * win_headings + heading`).
    pub kind: U32,
    /// Nodes of this view (node 0 is its root).
    pub node_count: U32,
    /// Entries of this view.
    pub entry_count: U32,
    /// Zero.
    pub reserved: U32,
}

/// One tree node (16 bytes); indices are local to its view.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct IndexNode {
    /// Internal node: its first child (greater than the node's own index);
    /// leaf: its first entry.
    pub first: U32,
    /// Children (1..=[`INDEX_CHILDREN_MAX`]) or entries.
    pub count: U32,
    /// 1 for a leaf, 0 for an internal node.
    pub leaf: U32,
    /// Zero.
    pub reserved: U32,
}

/// Most internal nodes the index search keeps per level.
pub const INDEX_BEAM_MAX: usize = 32;
/// Most leaves whose entries the index search scores.
pub const INDEX_LEAVES_MAX: usize = 64;
/// Most children of an index node.
pub const INDEX_CHILDREN_MAX: usize = 64;
/// Deepest level the index search descends to (the root is level 0);
/// `mapc` builds trees no deeper than this, and the search of a deeper
/// (malformed) one stops there, so its work is bounded whatever the file.
pub const INDEX_DEPTH_MAX: usize = 48;

/// Distance-map quantization: this many steps per grid cell.
pub const DIST_STEPS_PER_CELL: f32 = 8.0;

/// Distance-map value that encodes a distance of 0 (a point on a surface):
/// values below are inside obstacles (down to -4 cells), above in free space
/// (up to ~27.9 cells).
pub const DIST_ZERO: u8 = 32;

/// Decodes a distance-map value to a signed distance in cells.
#[inline]
pub fn dist_cells(v: u8) -> f32 {
    (v as f32 - DIST_ZERO as f32) / DIST_STEPS_PER_CELL
}

/// Encodes a signed distance in cells (saturating).
#[inline]
pub fn dist_encode(cells: f32) -> u8 {
    let v = libm::roundf(cells * DIST_STEPS_PER_CELL) + DIST_ZERO as f32;
    if v.is_nan() {
        return 255;
    }
    v.clamp(0.0, 255.0) as u8
}

/// Map metadata.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct MetaRecord {
    /// Grid width in cells.
    pub width: U32,
    /// Grid height in cells.
    pub height: U32,
    /// Metres per cell.
    pub resolution: F32,
    /// Map-frame x of the grid's lower-left corner (m).
    pub origin_x: F32,
    /// Map-frame y of the grid's lower-left corner (m).
    pub origin_y: F32,
    /// Map-frame yaw of the grid (rad).
    pub origin_yaw: F32,
    /// Number of reference sites.
    pub site_count: U32,
    /// 1 when unknown cells stop beams in the grid section.
    pub unknown_blocks: U32,
    /// Free cells in the source map.
    pub free_cells: U64,
    /// Zero.
    pub reserved: [u8; 24],
}

/// One reference site.
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct SiteRecord {
    /// Map-frame x (m).
    pub x: F32,
    /// Map-frame y (m).
    pub y: F32,
    /// Distance to the nearest obstacle (m).
    pub clearance: F32,
    /// 0 GVD vertex, 1 end point, 2 on an edge, 3 coverage fill.
    pub kind: U32,
    /// First index into the neighbours section.
    pub neighbor_start: U32,
    /// Number of neighbours.
    pub neighbor_count: U32,
}

/// Every parameter the runtime needs (units in each field's doc).
#[derive(Clone, Copy, Debug, FromBytes, IntoBytes, KnownLayout, Immutable, Unaligned)]
#[repr(C)]
pub struct ParamsRecord {
    /// Beams per reference scan.
    pub beams: U32,
    /// Angle of the first reference beam (rad, sensor frame).
    pub angle_min: F32,
    /// Angle between reference beams (rad).
    pub angle_increment: F32,
    /// Reference sensor maximum range (m).
    pub range_max: F32,
    /// Reference sensor minimum range (m).
    pub range_min: F32,
    /// Sensor mounting pose on the robot: x (m).
    pub sensor_x: F32,
    /// Sensor mounting pose on the robot: y (m).
    pub sensor_y: F32,
    /// Sensor mounting pose on the robot: yaw (rad).
    pub sensor_theta: F32,
    /// Scan preparation: spacing of resampled points along surfaces (m).
    pub resample_spacing: F32,
    /// Scan preparation: at most this many resampled points.
    pub max_points: U32,
    /// Scan preparation: neighbours farther apart than this are on different
    /// surfaces (m).
    pub jump_distance: F32,
    /// PGR histogram: rho bins.
    pub hist_rho_bins: U32,
    /// PGR histogram: theta bins over (-pi, pi].
    pub hist_theta_bins: U32,
    /// PGR histogram: rho range upper bound (m); longer pairs go in the last bin.
    pub hist_rho_max: F32,
    /// Coarse: fewest candidates.
    pub nc_min: U32,
    /// Coarse: most candidates.
    pub nc_max: U32,
    /// Coarse: sites whose correlation is within this of the best are kept.
    pub nc_margin: F32,
    /// SSM: point descriptor radius (m).
    pub desc_radius: F32,
    /// SSM: tentative correspondences per input point.
    pub tentative_k: U32,
    /// SSM: pairs whose rho differ by more than this have zero affinity (m).
    pub max_rho_dev: F32,
    /// SSM: logistic weights w0 (bias), w1 (rho deviation^2, 1/m^2), w2 (theta deviation^2, 1/rad^2).
    pub w: [F32; 3],
    /// SSM: power iterations at most.
    pub power_iters: U32,
    /// SSM: binarization keeps correspondences with x >= this fraction of max x.
    pub binarize_frac: F32,
    /// SSM: RANSAC iterations.
    pub ransac_iters: U32,
    /// SSM: RANSAC inlier distance (m).
    pub ransac_threshold: F32,
    /// SSM: RANSAC seed.
    pub ransac_seed: U32,
    /// SSM: fewest inliers for a pose.
    pub min_inliers: U32,
    /// Refinement against the map: Gauss-Newton iterations (0 disables).
    pub refine_iters: U32,
    /// Refinement: points farther than this from the map are ignored (m).
    pub refine_max_dist: F32,
    /// Verification: sigma_d (m).
    pub sigma_d: F32,
    /// Verification: accept when M > 4.5 * N_P * accept_ratio (paper: 0.5).
    pub accept_ratio: F32,
    /// Fewest valid points in an input scan.
    pub min_valid_points: U32,
    /// Site selection: 0 largest matching score E (paper), 1 largest vicinity score.
    pub selection: U32,
    /// With vicinity selection, stop examining candidates once one explains
    /// its non-short beams this well: `M >= 4.5 * (N_P - short) *
    /// early_accept` with at most a fifth of the beams short (see
    /// `verify::Vicinity::explained_ratio`; 0 examines them all).
    pub early_accept: F32,
    /// Partial field of view: widths (rad) of the stored window histograms,
    /// 0 for an unused slot.
    pub win_widths: [F32; 2],
    /// Partial field of view: window headings per width (evenly spaced).
    pub win_headings: U32,
    /// Partial field of view: rho bins of a window histogram.
    pub win_rho_bins: U32,
    /// Partial field of view: theta bins of a window histogram.
    pub win_theta_bins: U32,
    /// With vicinity selection, also stop after this many candidates once one
    /// passes the acceptance threshold.
    pub early_min: U32,
    /// Reject as ambiguous when a candidate with a clearly different pose
    /// (over 1 m or 20 degrees away) scores at least this share of the best M
    /// (0 disables).
    pub ambiguity_ratio: F32,
    /// SSM: most stored affinity entries per match (8 bytes each in the
    /// scratch; the main term of `scratch_size`).
    pub affinity_cap: U32,
    /// Free-space check: most beams through a wall, as a share of the beams
    /// with a return (0: off). Added within version 1 in a field that was
    /// reserved and zero, so older files read as "off".
    pub through_max: F32,
    /// Free-space check: least excess range (m) of a beam through a wall.
    pub through_excess: F32,
    /// Verification: weight of a short beam against the pose, as a share of
    /// a hit's (0: the paper's M). Added within version 1 like `through_max`.
    pub short_weight: F32,
    /// Free-space check: least run of consecutive beams through a wall that
    /// counts. Added within version 1 like `through_max`.
    pub through_run: U32,
    /// Verification: short beams cost nothing when the other beams fit at
    /// least this well (0: always). Added within version 1 like
    /// `through_max`; this used the last reserved field.
    pub occlusion_fit: F32,
}

/// The number of padding bytes that bring `len` to a multiple of [`SECTION_ALIGN`].
pub const fn pad_len(len: usize) -> usize {
    (SECTION_ALIGN - len % SECTION_ALIGN) % SECTION_ALIGN
}

/// Lays out a file from its sections (in the order given) and streams it to
/// `sink`, computing every checksum on the way. Returns the file length.
///
/// This is the only writer of the format; `mapc` builds the section bytes and
/// calls it.
pub fn encode<E>(
    sections: &[(SectionKind, &[u8])],
    mut sink: impl FnMut(&[u8]) -> Result<(), E>,
) -> Result<u64, E> {
    let n = sections.len().min(MAX_SECTIONS);
    let table_end = HEADER_LEN + n * ENTRY_LEN;
    let mut offset = table_end + pad_len(table_end);
    let mut entries = [SectionEntry {
        kind: U32::new(0),
        flags: U32::new(0),
        offset: U64::new(0),
        len: U64::new(0),
        crc: U32::new(0),
        reserved: U32::new(0),
    }; MAX_SECTIONS];
    for (e, (kind, bytes)) in entries.iter_mut().zip(&sections[..n]) {
        e.kind = U32::new(*kind as u32);
        e.offset = U64::new(offset as u64);
        e.len = U64::new(bytes.len() as u64);
        e.crc = U32::new(crc::crc32c(bytes));
        offset += bytes.len() + pad_len(bytes.len());
    }
    let mut header = Header {
        magic: MAGIC,
        endian: U16::new(ENDIAN_CHECK),
        header_len: U16::new(HEADER_LEN as u16),
        version: U32::new(FORMAT_VERSION),
        flags: U32::new(0),
        section_count: U32::new(n as u32),
        file_len: U64::new(offset as u64),
        header_crc: U32::new(0),
        reserved: [0; 28],
    };
    header.header_crc = U32::new(header_crc(&header, entries[..n].as_bytes()));
    const ZEROS: [u8; SECTION_ALIGN] = [0; SECTION_ALIGN];
    sink(header.as_bytes())?;
    sink(entries[..n].as_bytes())?;
    sink(&ZEROS[..pad_len(table_end)])?;
    for (_, bytes) in &sections[..n] {
        sink(bytes)?;
        sink(&ZEROS[..pad_len(bytes.len())])?;
    }
    Ok(offset as u64)
}

/// CRC-32C over the header with `header_crc` zeroed, then the table bytes.
pub fn header_crc(header: &Header, table: &[u8]) -> u32 {
    let mut h = *header;
    h.header_crc = U32::new(0);
    let mut c = crc::Crc32c::new();
    c.update(h.as_bytes());
    c.update(table);
    c.finish()
}

const _: () = assert!(core::mem::size_of::<Header>() == HEADER_LEN);
const _: () = assert!(core::mem::size_of::<SectionEntry>() == ENTRY_LEN);
const _: () = assert!(core::mem::size_of::<MetaRecord>() == 64);
const _: () = assert!(core::mem::size_of::<SiteRecord>() == 24);
const _: () = assert!(core::mem::size_of::<IndexHeader>() == 16);
const _: () = assert!(core::mem::size_of::<IndexView>() == 16);
const _: () = assert!(core::mem::size_of::<IndexNode>() == 16);
const _: () = assert!(core::mem::size_of::<DecisionRecord>() == 32);
