//! [`RefDb`]: a validated, zero-copy view of a `.refdb` file.
//!
//! [`RefDb::new`] checks the header, the section table, every bound, every
//! alignment and every cross-section count once; after it succeeds no
//! accessor can fail or panic. [`RefDb::verify`] additionally checks every
//! checksum (O(file size)).

use core::fmt;
use core::ops::Range;

use zerocopy::FromBytes;

use crate::confidence::Decision;
use crate::format::{
    self, crc, DecisionRecord, FeaturesLayout, Header, MetaRecord, ParamsRecord, SectionEntry,
    SectionKind, SiteRecord, ENDIAN_CHECK, ENTRY_LEN, FORMAT_VERSION, HEADER_LEN, MAGIC,
    MAX_SECTIONS, SECTION_ALIGN,
};
use crate::params::Params;
use crate::raycast::BitGrid;
use crate::ssm::{DescBin, DESC_LEN, DESC_SCALE};
use crate::{MapFrame, Pose2};

/// What is wrong with a database.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum DbErrorKind {
    /// Shorter than its header or table, or shorter/longer than the header says.
    Truncated,
    /// The first bytes are not `REFLOCDB`.
    Magic,
    /// Written with the other byte order.
    Endian,
    /// A format version this reader does not read.
    Version,
    /// The header's own checksum does not match.
    HeaderChecksum,
    /// A section's checksum does not match (from `verify`).
    SectionChecksum,
    /// The section table is malformed (count, unknown or duplicate kind).
    Table,
    /// A section lies outside the file or its offset/length overflows.
    OutOfBounds,
    /// A section is not aligned to the format's alignment.
    Alignment,
    /// Two sections overlap.
    Overlap,
    /// A required section is missing.
    Missing,
    /// A section's length disagrees with the counts in other sections.
    Size,
    /// A value is out of its valid range.
    Value,
    /// This target is big-endian; the format's arrays are little-endian.
    HostEndian,
}

/// A database error: what, where, and the expected/found values if any.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DbError {
    /// The kind of problem.
    pub kind: DbErrorKind,
    /// Where: a section name, a field name, or "header".
    pub context: &'static str,
    /// Expected value, when meaningful.
    pub expected: u64,
    /// Found value, when meaningful.
    pub found: u64,
    /// For [`DbErrorKind::Value`]: the value found, bits of an f64 (integers
    /// exactly, reals as stored); see [`DbError::found_value`].
    value_bits: Option<u64>,
    /// For [`DbErrorKind::Alignment`]: the container's address is off (the
    /// file is fine; `found` is the address modulo `expected`), not the
    /// section's offset in the file.
    in_memory: bool,
}

impl DbError {
    const fn new(kind: DbErrorKind, context: &'static str, expected: u64, found: u64) -> Self {
        DbError {
            kind,
            context,
            expected,
            found,
            value_bits: None,
            in_memory: false,
        }
    }

    /// A section whose bytes lie at an address that is not a multiple of
    /// `align` in memory (the container is misaligned, not the file).
    fn misaligned_in_memory(context: &'static str, align: u64, bytes: &[u8]) -> Self {
        DbError {
            in_memory: true,
            ..DbError::new(
                DbErrorKind::Alignment,
                context,
                align,
                bytes.as_ptr() as usize as u64 % align,
            )
        }
    }

    /// A value out of its valid range in `context`, with the value found.
    fn value(context: &'static str, value: f64) -> Self {
        DbError {
            value_bits: Some(value.to_bits()),
            ..DbError::new(DbErrorKind::Value, context, 0, 0)
        }
    }

    /// A value out of its valid range where no single number says what is
    /// wrong (an inconsistent layout): the message names the context only.
    const fn invalid(context: &'static str) -> Self {
        DbError::new(DbErrorKind::Value, context, 0, 0)
    }

    /// For a [`DbErrorKind::Value`] error: the offending value, in the
    /// field's own unit (metres, radians, a count), when one number says it.
    pub fn found_value(&self) -> Option<f64> {
        self.value_bits.map(f64::from_bits)
    }
}

impl fmt::Display for DbError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use DbErrorKind::*;
        let (e, g, c) = (self.expected, self.found, self.context);
        match self.kind {
            Truncated => write!(f, "truncated or padded file: {c} needs {e} bytes, found {g}"),
            Magic => write!(f, "not a .refdb file: the first 8 bytes are not 'REFLOCDB'"),
            Endian => write!(f, "byte order mismatch: endianness check is {g:#06x}, expected {e:#06x}"),
            Version => write!(
                f,
                "format version {g} is not supported: this reader reads version {e}; rebuild the map with a matching `mapc build`"
            ),
            HeaderChecksum => write!(f, "header checksum mismatch: expected {e:#010x}, computed {g:#010x}"),
            SectionChecksum => write!(f, "checksum mismatch in section '{c}': stored {e:#010x}, computed {g:#010x}"),
            Table => write!(f, "malformed section table: {c} (value {g})"),
            OutOfBounds => write!(f, "section '{c}' ends at byte {g}, past the end of the file ({e} bytes)"),
            Alignment if self.in_memory => write!(
                f,
                "section '{c}' lies at a memory address {g} bytes past a multiple of {e}: the buffer holding the database is misaligned (the file itself is fine)"
            ),
            Alignment => write!(f, "section '{c}' starts at byte {g}, not a multiple of {e}"),
            Overlap => write!(f, "section '{c}' overlaps another section at byte {g}"),
            Missing => write!(f, "required section '{c}' is missing"),
            Size => write!(f, "section '{c}' has {g} bytes, expected {e}"),
            Value => match self.found_value() {
                Some(v) => write!(f, "invalid value in {c} (found {v})"),
                None => write!(f, "invalid value in {c}"),
            },
            HostEndian => write!(f, "this build runs on a big-endian target; .refdb arrays are little-endian"),
        }
    }
}

impl core::error::Error for DbError {}

const N_KINDS: usize = SectionKind::ALL.len();

/// A validated reference database over any byte container (`&[u8]`,
/// `Vec<u8>`, an `Mmap`, a `&'static [u8]` in flash).
pub struct RefDb<D: AsRef<[u8]>> {
    data: D,
    sections: [Range<usize>; N_KINDS],
    crcs: [u32; N_KINDS],
    meta: MetaRecord,
    params: Params,
    frame: MapFrame,
    site_count: usize,
    decision: Option<Decision>,
}

fn kind_index(k: SectionKind) -> usize {
    k as usize - 1
}

impl<D: AsRef<[u8]>> RefDb<D> {
    /// Checks structure, bounds, alignment and counts; no checksums (see
    /// [`RefDb::verify`]). Never panics, never allocates.
    pub fn new(data: D) -> Result<Self, DbError> {
        let (sections, crcs, meta, params, decision) = parse(data.as_ref())?;
        let frame = MapFrame {
            resolution: meta.resolution.get(),
            origin: Pose2 {
                x: meta.origin_x.get(),
                y: meta.origin_y.get(),
                theta: meta.origin_yaw.get(),
            },
        };
        let site_count = meta.site_count.get() as usize;
        Ok(RefDb {
            data,
            sections,
            crcs,
            meta,
            params,
            frame,
            site_count,
            decision,
        })
    }

    /// Checks every section's CRC-32C. O(file size).
    pub fn verify(&self) -> Result<(), DbError> {
        for k in SectionKind::ALL {
            let got = crc::crc32c(self.section(k));
            let want = self.crcs[kind_index(k)];
            if got != want {
                return Err(DbError::new(
                    DbErrorKind::SectionChecksum,
                    k.name(),
                    want as u64,
                    got as u64,
                ));
            }
        }
        Ok(())
    }

    /// The whole file.
    pub fn bytes(&self) -> &[u8] {
        self.data.as_ref()
    }

    /// The bytes of one section (empty if absent).
    pub fn section(&self, kind: SectionKind) -> &[u8] {
        self.data
            .as_ref()
            .get(self.sections[kind_index(kind)].clone())
            .unwrap_or(&[])
    }

    /// The stored checksum of one section.
    pub fn section_crc(&self, kind: SectionKind) -> u32 {
        self.crcs[kind_index(kind)]
    }

    /// Runtime parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Map metadata record.
    pub fn meta(&self) -> &MetaRecord {
        &self.meta
    }

    /// Grid placement in the map frame.
    pub fn frame(&self) -> MapFrame {
        self.frame
    }

    /// Grid width and height in cells.
    pub fn grid_size(&self) -> (u32, u32) {
        (self.meta.width.get(), self.meta.height.get())
    }

    /// The beam-stopping grid.
    pub fn grid(&self) -> BitGrid<'_> {
        let (w, h) = self.grid_size();
        let words = <[u32]>::ref_from_bytes(self.section(SectionKind::Grid)).unwrap_or(&[]);
        BitGrid::new(w, h, words).unwrap_or(BitGrid::empty())
    }

    /// Quantized signed distance map, one byte per cell (see [`format::dist_cells`]).
    pub fn dist(&self) -> &[u8] {
        self.section(SectionKind::Dist)
    }

    /// Number of reference sites.
    pub fn site_count(&self) -> usize {
        self.site_count
    }

    /// All site records.
    pub fn sites(&self) -> &[SiteRecord] {
        <[SiteRecord]>::ref_from_bytes(self.section(SectionKind::Sites)).unwrap_or(&[])
    }

    /// Site `i` (`None` past the end).
    pub fn site(&self, i: usize) -> Option<&SiteRecord> {
        self.sites().get(i)
    }

    /// Map-frame position of site `i` (m), `[0, 0]` past the end.
    pub fn site_xy(&self, i: usize) -> [f32; 2] {
        self.site(i)
            .map(|s| [s.x.get(), s.y.get()])
            .unwrap_or([0.0, 0.0])
    }

    /// Graph neighbours of site `i`.
    pub fn neighbors(&self, i: usize) -> &[u32] {
        let all = <[u32]>::ref_from_bytes(self.section(SectionKind::Neighbors)).unwrap_or(&[]);
        match self.site(i) {
            Some(s) => {
                let a = s.neighbor_start.get() as usize;
                let n = s.neighbor_count.get() as usize;
                all.get(a..a.saturating_add(n)).unwrap_or(&[])
            }
            None => &[],
        }
    }

    /// Reference scan ranges of site `i` (m; `INFINITY` for no return).
    pub fn scan(&self, i: usize) -> &[f32] {
        let all = <[f32]>::ref_from_bytes(self.section(SectionKind::Scans)).unwrap_or(&[]);
        let b = self.params.sensor.beams as usize;
        all.get(i.saturating_mul(b)..i.saturating_add(1).saturating_mul(b))
            .unwrap_or(&[])
    }

    /// PGR histogram of site `i` (normalized to sum 1).
    pub fn hist(&self, i: usize) -> &[f32] {
        let all = <[f32]>::ref_from_bytes(self.section(SectionKind::Hists)).unwrap_or(&[]);
        let k = self.params.coarse.hist_cells();
        all.get(i.saturating_mul(k)..i.saturating_add(1).saturating_mul(k))
            .unwrap_or(&[])
    }

    /// Window histogram of site `i`, width slot `w`, heading `h` (see
    /// [`crate::coarse`]); empty when absent.
    pub fn window_hist(&self, i: usize, w: usize, h: usize) -> &[f32] {
        let p = &self.params;
        let (nw, nh, k) = (
            p.coarse.win_count(),
            p.coarse.win_headings as usize,
            p.coarse.win_cells(),
        );
        if w >= nw || h >= nh {
            return &[];
        }
        let all = <[f32]>::ref_from_bytes(self.section(SectionKind::Windows)).unwrap_or(&[]);
        let idx = (i.saturating_mul(nw).saturating_add(w))
            .saturating_mul(nh)
            .saturating_add(h);
        all.get(idx.saturating_mul(k)..idx.saturating_add(1).saturating_mul(k))
            .unwrap_or(&[])
    }

    /// The coarse-search index (see [`crate::index`]), when the database
    /// has one.
    pub fn index(&self) -> Option<crate::index::Index<'_>> {
        crate::index::Index::new(
            self.section(SectionKind::Index),
            &self.params,
            self.site_count,
        )
    }

    /// The decision model and acceptance threshold the database stores
    /// ([`crate::confidence`]); `None` in a file built before it, which
    /// keeps its evidence-threshold acceptance.
    pub fn decision(&self) -> Option<Decision> {
        self.decision
    }

    /// The build manifest (UTF-8 JSON written by mapc; may be empty).
    pub fn manifest(&self) -> &str {
        core::str::from_utf8(self.section(SectionKind::Manifest)).unwrap_or("")
    }

    /// The stored reference side of SSM for site `i` (see
    /// [`SiteFeatures`]); `None` when the database has no features section
    /// (the runtime then computes them) or `i` is past the last site.
    pub fn features(&self, i: usize) -> Option<SiteFeatures<'_>> {
        if i >= self.site_count {
            return None;
        }
        let f = FeatureArrays::of(self.section(SectionKind::Features), self.site_count).ok()?;
        let (a, b) = (*f.offsets.get(i)? as usize, *f.offsets.get(i + 1)? as usize);
        Some(SiteFeatures {
            points: f.points.get(a..b)?,
            tangents: f.tangents.get(a..b)?,
            desc: f
                .desc
                .get(a.checked_mul(DESC_LEN)?..b.checked_mul(DESC_LEN)?)?,
        })
    }
}

/// The reference side of spectral scan matching for one site, as stored in
/// the features section: what [`crate::localize::reference_features`]
/// computes from the site's reference scan. All three have one entry (one
/// row) per prepared point, at most `params.prep.max_points`.
#[derive(Clone, Copy, Debug)]
pub struct SiteFeatures<'a> {
    /// Prepared points in the site's sensor frame (m; the reference sensor
    /// sits on the site heading along the map's +x axis); all finite.
    pub points: &'a [[f32; 2]],
    /// Their unit tangents (dimensionless, along increasing beam index).
    pub tangents: &'a [[f32; 2]],
    /// Their descriptors, [`DESC_LEN`] bins per point in units of
    /// `1 / DESC_SCALE` ([`crate::ssm::descriptors`]); each row sums to at
    /// most `DESC_SCALE + DESC_LEN`.
    pub desc: &'a [DescBin],
}

/// The arrays of a features section, split by its [`FeaturesLayout`]
/// (sizes and memory alignment checked; values not).
struct FeatureArrays<'a> {
    offsets: &'a [u32],
    points: &'a [[f32; 2]],
    tangents: &'a [[f32; 2]],
    desc: &'a [DescBin],
}

impl<'a> FeatureArrays<'a> {
    /// Splits `bytes` (a features section of `sites` sites); `Size` when
    /// it is shorter than its offsets or not as long as they say,
    /// `Alignment` when it lies misaligned in memory.
    fn of(bytes: &'a [u8], sites: usize) -> Result<FeatureArrays<'a>, DbError> {
        const CTX: &str = "features";
        let size = |want: u64| DbError::new(DbErrorKind::Size, CTX, want, bytes.len() as u64);
        let misaligned = || DbError::misaligned_in_memory(CTX, 4, bytes);
        let n_off = sites.saturating_add(1);
        let head = (n_off as u64).saturating_mul(4);
        if (bytes.len() as u64) < head {
            return Err(size(head));
        }
        let (offsets, _) =
            <[u32]>::ref_from_prefix_with_elems(bytes, n_off).map_err(|_| misaligned())?;
        let total = offsets.last().copied().unwrap_or(0) as u64;
        let layout = FeaturesLayout::new(sites as u64, total).ok_or(size(u64::MAX))?;
        if bytes.len() != layout.len {
            return Err(size(layout.len as u64));
        }
        let pairs = |r: Range<usize>| {
            <[[f32; 2]]>::ref_from_bytes(bytes.get(r).unwrap_or(&[])).map_err(|_| misaligned())
        };
        Ok(FeatureArrays {
            offsets,
            points: pairs(layout.points_at..layout.tangents_at)?,
            tangents: pairs(layout.tangents_at..layout.desc_at)?,
            desc: <[DescBin]>::ref_from_bytes(bytes.get(layout.desc_at..).unwrap_or(&[]))
                .map_err(|_| misaligned())?,
        })
    }
}

type Parsed = (
    [Range<usize>; N_KINDS],
    [u32; N_KINDS],
    MetaRecord,
    Params,
    Option<Decision>,
);

/// Checks a whole file, in the order of the steps below; the first failure
/// is returned.
fn parse(bytes: &[u8]) -> Result<Parsed, DbError> {
    let (table, table_end) = parse_header(bytes)?;
    let (ranges, crcs) = parse_table(table, table_end, bytes.len())?;
    let sec = Sections {
        bytes,
        ranges: &ranges,
    };
    let (meta, params) = parse_records(&sec)?;
    let n_sites = check_array_sizes(&sec, &meta, &params)?;
    check_sites(&sec, n_sites)?;
    check_memory_alignment(&sec)?;
    crate::index::validate(sec.get(SectionKind::Index), &params, n_sites as usize)
        .map_err(DbError::invalid)?;
    let decision = parse_decision(&sec)?;
    check_features(&sec, &params, n_sites as usize)?;
    Ok((ranges, crcs, meta, params, decision))
}

/// The section byte ranges found by [`parse_table`], over the whole file.
struct Sections<'a, 'r> {
    bytes: &'a [u8],
    ranges: &'r [Range<usize>; N_KINDS],
}

impl<'a> Sections<'a, '_> {
    /// The bytes of section `k` (empty when an optional section is absent).
    fn get(&self, k: SectionKind) -> &'a [u8] {
        &self.bytes[self.ranges[kind_index(k)].clone()]
    }

    /// `Size` unless section `k` is exactly `want` bytes long.
    fn exact(&self, k: SectionKind, want: usize) -> Result<(), DbError> {
        let got = self.get(k).len();
        if got == want {
            Ok(())
        } else {
            Err(DbError::new(
                DbErrorKind::Size,
                k.name(),
                want as u64,
                got as u64,
            ))
        }
    }
}

/// Step 1: magic, byte order, version, header length, section count, the
/// header checksum and the file length. Returns the section table's bytes
/// and where the table ends.
fn parse_header(bytes: &[u8]) -> Result<(&[SectionEntry], usize), DbError> {
    use DbErrorKind::*;
    if cfg!(target_endian = "big") {
        return Err(DbError::new(HostEndian, "host", 0, 0));
    }
    let len = bytes.len();
    if len < 8 || bytes[..8] != MAGIC {
        if len < 8 && MAGIC.starts_with(bytes) {
            return Err(DbError::new(
                Truncated,
                "header",
                HEADER_LEN as u64,
                len as u64,
            ));
        }
        return Err(DbError::new(Magic, "header", 0, 0));
    }
    let (header, _) = Header::read_from_prefix(bytes)
        .map_err(|_| DbError::new(Truncated, "header", HEADER_LEN as u64, len as u64))?;
    let endian = header.endian.get();
    if endian != ENDIAN_CHECK {
        return Err(DbError::new(
            Endian,
            "header",
            ENDIAN_CHECK as u64,
            endian as u64,
        ));
    }
    let version = header.version.get();
    if version != FORMAT_VERSION {
        return Err(DbError::new(
            Version,
            "header",
            FORMAT_VERSION as u64,
            version as u64,
        ));
    }
    if header.header_len.get() as usize != HEADER_LEN {
        return Err(DbError::new(
            Table,
            "header length",
            HEADER_LEN as u64,
            header.header_len.get() as u64,
        ));
    }
    let count = header.section_count.get() as usize;
    if count == 0 || count > MAX_SECTIONS {
        return Err(DbError::new(
            Table,
            "section count",
            MAX_SECTIONS as u64,
            count as u64,
        ));
    }
    let table_end = HEADER_LEN + count * ENTRY_LEN;
    let table_bytes = bytes.get(HEADER_LEN..table_end).ok_or(DbError::new(
        Truncated,
        "section table",
        table_end as u64,
        len as u64,
    ))?;
    let stored_crc = header.header_crc.get();
    let computed = format::header_crc(&header, table_bytes);
    if stored_crc != computed {
        return Err(DbError::new(
            HeaderChecksum,
            "header",
            stored_crc as u64,
            computed as u64,
        ));
    }
    if header.file_len.get() != len as u64 {
        return Err(DbError::new(
            Truncated,
            "file",
            header.file_len.get(),
            len as u64,
        ));
    }
    let table = <[SectionEntry]>::ref_from_bytes(table_bytes)
        .map_err(|_| DbError::new(Table, "section table", 0, 0))?;
    Ok((table, table_end))
}

/// Step 2: every table entry names a known kind once, lies inside the file
/// after the table, is aligned and overlaps no other; every required kind
/// is present. Returns each kind's byte range and stored CRC.
fn parse_table(
    table: &[SectionEntry],
    table_end: usize,
    len: usize,
) -> Result<([Range<usize>; N_KINDS], [u32; N_KINDS]), DbError> {
    use DbErrorKind::*;
    let mut sections: [Range<usize>; N_KINDS] = Default::default();
    let mut present = [false; N_KINDS];
    let mut crcs = [0u32; N_KINDS];
    let mut spans: [(usize, usize); MAX_SECTIONS] = [(0, 0); MAX_SECTIONS];
    for (n, e) in table.iter().enumerate() {
        let raw = e.kind.get();
        let kind = SectionKind::from_u32(raw).ok_or(DbError::new(
            Table,
            "unknown section kind",
            0,
            raw as u64,
        ))?;
        let ki = kind_index(kind);
        if present[ki] {
            return Err(DbError::new(Table, "duplicate section kind", 0, raw as u64));
        }
        let off = e.offset.get();
        let slen = e.len.get();
        let end = off.checked_add(slen).ok_or(DbError::new(
            OutOfBounds,
            kind.name(),
            len as u64,
            u64::MAX,
        ))?;
        if end > len as u64 {
            return Err(DbError::new(OutOfBounds, kind.name(), len as u64, end));
        }
        if off % SECTION_ALIGN as u64 != 0 {
            return Err(DbError::new(
                Alignment,
                kind.name(),
                SECTION_ALIGN as u64,
                off,
            ));
        }
        if off < table_end as u64 {
            return Err(DbError::new(Overlap, kind.name(), table_end as u64, off));
        }
        let (off, end) = (off as usize, end as usize);
        for &(a, b) in &spans[..n] {
            if off < b && a < end && slen > 0 && b > a {
                return Err(DbError::new(Overlap, kind.name(), 0, off as u64));
            }
        }
        spans[n] = (off, end);
        present[ki] = true;
        sections[ki] = off..end;
        crcs[ki] = e.crc.get();
    }
    for k in SectionKind::ALL {
        if !present[kind_index(k)] && !k.optional() {
            return Err(DbError::new(Missing, k.name(), 0, 0));
        }
    }
    Ok((sections, crcs))
}

/// Step 3: the meta and parameter records, and the values in them.
fn parse_records(sec: &Sections<'_, '_>) -> Result<(MetaRecord, Params), DbError> {
    use DbErrorKind::Size;
    sec.exact(SectionKind::Meta, core::mem::size_of::<MetaRecord>())?;
    sec.exact(SectionKind::Params, core::mem::size_of::<ParamsRecord>())?;
    let meta = MetaRecord::read_from_bytes(sec.get(SectionKind::Meta))
        .map_err(|_| DbError::new(Size, "meta", 0, 0))?;
    let pr = ParamsRecord::read_from_bytes(sec.get(SectionKind::Params))
        .map_err(|_| DbError::new(Size, "params", 0, 0))?;
    let bad_param = |b: crate::BadParam| DbError::value(b.field, b.value);
    let params = Params::from_record(&pr).map_err(bad_param)?;
    params.validate().map_err(bad_param)?;

    let (w, h) = (meta.width.get() as usize, meta.height.get() as usize);
    if w == 0 || h == 0 {
        return Err(DbError::value("grid size", w.min(h) as f64));
    }
    let res = meta.resolution.get();
    if !(res.is_finite() && res > 0.0) {
        return Err(DbError::value("resolution", res as f64));
    }
    let origin = [
        meta.origin_x.get(),
        meta.origin_y.get(),
        meta.origin_yaw.get(),
    ];
    if let Some(v) = origin.iter().find(|v| !v.is_finite()) {
        return Err(DbError::value("origin", *v as f64));
    }
    Ok((meta, params))
}

/// Step 4: the grid, distance map and per-site arrays are exactly as long
/// as the meta record's counts and the parameters make them. Returns the
/// site count (at least 1).
fn check_array_sizes(
    sec: &Sections<'_, '_>,
    meta: &MetaRecord,
    params: &Params,
) -> Result<u64, DbError> {
    let (w, h) = (meta.width.get() as u64, meta.height.get() as u64);
    // Sizes computed in u64/u128 so absurd dimensions cannot overflow; the
    // comparison with the real section length bounds everything.
    let cells = w * h;
    sec.exact(
        SectionKind::Grid,
        (cells.div_ceil(32) * 4).min(usize::MAX as u64) as usize,
    )?;
    sec.exact(SectionKind::Dist, cells.min(usize::MAX as u64) as usize)?;
    let n_sites = meta.site_count.get() as u64;
    if n_sites == 0 {
        return Err(DbError::value("site count", 0.0));
    }
    let sz = |n: u64, each: u64| (n as u128 * each as u128).min(usize::MAX as u128) as usize;
    sec.exact(
        SectionKind::Sites,
        sz(n_sites, core::mem::size_of::<SiteRecord>() as u64),
    )?;
    sec.exact(
        SectionKind::Scans,
        sz(n_sites, params.sensor.beams as u64 * 4),
    )?;
    sec.exact(
        SectionKind::Hists,
        sz(n_sites, params.coarse.hist_cells() as u64 * 4),
    )?;
    let per_site_windows = params.coarse.win_count() as u64
        * params.coarse.win_headings as u64
        * params.coarse.win_cells() as u64
        * 4;
    sec.exact(SectionKind::Windows, sz(n_sites, per_site_windows))?;
    Ok(n_sites)
}

/// Step 5: neighbour lists point at existing sites and lie inside the
/// neighbour section; site positions are finite.
fn check_sites(sec: &Sections<'_, '_>, n_sites: u64) -> Result<(), DbError> {
    use DbErrorKind::*;
    let nb_bytes = sec.get(SectionKind::Neighbors);
    let nb_len = nb_bytes.len();
    if nb_len % 4 != 0 {
        return Err(DbError::new(
            Size,
            "neighbors",
            (nb_len - nb_len % 4) as u64,
            nb_len as u64,
        ));
    }
    let nb = <[u32]>::ref_from_bytes(nb_bytes)
        .map_err(|_| DbError::misaligned_in_memory("neighbors", 4, nb_bytes))?;
    if let Some(v) = nb.iter().find(|&&v| v as u64 >= n_sites) {
        return Err(DbError {
            expected: n_sites,
            ..DbError::value("neighbor index", *v as f64)
        });
    }
    let sites = <[SiteRecord]>::ref_from_bytes(sec.get(SectionKind::Sites))
        .map_err(|_| DbError::new(Size, "sites", 0, 0))?;
    for s in sites {
        let (a, n) = (s.neighbor_start.get() as u64, s.neighbor_count.get() as u64);
        if a + n > nb.len() as u64 {
            return Err(DbError::new(
                OutOfBounds,
                "site neighbours",
                nb.len() as u64,
                a + n,
            ));
        }
        let coords = [s.x.get(), s.y.get(), s.clearance.get()];
        if let Some(v) = coords.iter().find(|v| !v.is_finite()) {
            return Err(DbError::value("site position", *v as f64));
        }
    }
    Ok(())
}

/// Step 6: arrays read in place must be aligned in memory too (the
/// container may not start on an aligned address).
fn check_memory_alignment(sec: &Sections<'_, '_>) -> Result<(), DbError> {
    for k in [
        SectionKind::Grid,
        SectionKind::Scans,
        SectionKind::Hists,
        SectionKind::Neighbors,
        SectionKind::Windows,
        SectionKind::Index,
    ] {
        let s = sec.get(k);
        if <[u32]>::ref_from_bytes(s).is_err() {
            return Err(DbError::misaligned_in_memory(k.name(), 4, s));
        }
    }
    Ok(())
}

/// Step 8 (after the index, step 7): the optional decision model.
fn parse_decision(sec: &Sections<'_, '_>) -> Result<Option<Decision>, DbError> {
    let d = sec.get(SectionKind::Decision);
    if d.is_empty() {
        return Ok(None);
    }
    sec.exact(
        SectionKind::Decision,
        core::mem::size_of::<DecisionRecord>(),
    )?;
    let r = DecisionRecord::read_from_bytes(d)
        .map_err(|_| DbError::new(DbErrorKind::Size, "decision", 0, 0))?;
    let m = r.decision();
    if !(0.0..=1.0).contains(&m.threshold) {
        return Err(DbError::value("decision threshold", m.threshold as f64));
    }
    if !m.is_valid() {
        return Err(DbError::invalid("decision model (a non-finite weight)"));
    }
    Ok(Some(m))
}

/// Step 9: the optional features section. Its length is what its offsets
/// say ([`FeaturesLayout`]); the offsets start at 0 and no site has more
/// than `max_points` points; every point and tangent is finite, every
/// tangent a unit vector (to 1e-3), and every descriptor row sums to at
/// most `DESC_SCALE + DESC_LEN` (the rounding of its bins). O(section).
fn check_features(sec: &Sections<'_, '_>, params: &Params, n_sites: usize) -> Result<(), DbError> {
    let bytes = sec.get(SectionKind::Features);
    if bytes.is_empty() {
        return Ok(());
    }
    // The offsets first: the layout (and so the size check) depends on the
    // last one, but a decreasing or oversized count is the clearer error.
    let head = n_sites.saturating_add(1).saturating_mul(4);
    if let Some(Ok((offsets, _))) = bytes
        .get(..head)
        .map(|h| <[u32]>::ref_from_prefix_with_elems(h, n_sites + 1))
    {
        if offsets[0] != 0 {
            return Err(DbError::value("features offsets[0]", offsets[0] as f64));
        }
        let max = params.prep.max_points;
        for w in offsets.windows(2) {
            let count = w[1].checked_sub(w[0]).ok_or(DbError::invalid(
                "features offsets (decreasing: a negative point count)",
            ))?;
            if count > max {
                return Err(DbError {
                    expected: max as u64,
                    ..DbError::value("features point count (over max_points)", count as f64)
                });
            }
        }
    }
    let f = FeatureArrays::of(bytes, n_sites)?;
    if let Some(v) = f.points.iter().flatten().find(|v| !v.is_finite()) {
        return Err(DbError::value("features point", *v as f64));
    }
    for t in f.tangents {
        let n2 = t[0] * t[0] + t[1] * t[1];
        if !(libm::fabsf(n2 - 1.0) <= 2e-3) {
            return Err(DbError::value(
                "features tangent (not a unit vector)",
                libm::sqrtf(n2) as f64,
            ));
        }
    }
    let bound = DESC_SCALE + DESC_LEN as u32;
    for row in f.desc.chunks_exact(DESC_LEN) {
        let sum: u32 = row.iter().map(|&v| v as u32).sum();
        if sum > bound {
            return Err(DbError {
                expected: bound as u64,
                ..DbError::value("features descriptor (bins sum over DESC_SCALE)", sum as f64)
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
