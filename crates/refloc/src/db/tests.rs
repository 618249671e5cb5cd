//! The corruption suite: every way a `.refdb` can be damaged gives a typed
//! [`DbError`], never a panic, and a database that passes [`RefDb::new`] is
//! safe to use whatever its contents.
//!
//! Damaged files are made two ways: by re-encoding modified sections with
//! `format::encode` (all checksums valid, so the structural checks are
//! reached), and by patching bytes of a good file (the header checksum, or a
//! section checksum, no longer matches).

use std::format;
use std::vec;
use std::vec::Vec;

use zerocopy::little_endian::{F32, U32, U64};
use zerocopy::{FromBytes, IntoBytes};

use super::*;
use crate::format::{ParamsRecord, SiteRecord};
use crate::raycast::Occupancy;
use crate::ssm::DESC_LEN;
use crate::tests::fixture::{self, Aligned, Prng};
use crate::{localize, scratch_size, RangeScan, Scan};

type Sections = Vec<(SectionKind, Vec<u8>)>;

/// A valid tiny database (see `crate::tests::fixture`).
fn tiny_db() -> Vec<u8> {
    fixture::encode(&fixture::sections())
}

/// `RefDb::new` on a 4-byte aligned copy of `bytes`.
fn open(bytes: &[u8]) -> Result<(), DbError> {
    let buf = Aligned::new(bytes);
    RefDb::new(buf.bytes()).map(|_| ())
}

/// Kinds whose message does not name the context (it is always "header").
fn context_free(kind: DbErrorKind) -> bool {
    matches!(
        kind,
        DbErrorKind::Magic
            | DbErrorKind::Endian
            | DbErrorKind::Version
            | DbErrorKind::HeaderChecksum
            | DbErrorKind::HostEndian
    )
}

/// Checks the message of an error: non-empty, names its section or field.
fn check_message(e: &DbError) {
    let msg = e.to_string();
    assert!(!msg.is_empty(), "{e:?}");
    if !context_free(e.kind) {
        assert!(
            msg.contains(e.context),
            "message {msg:?} does not name {:?}",
            e.context
        );
    }
}

/// Asserts that `bytes` is rejected with `kind` (and `context`, if given).
#[track_caller]
fn expect(bytes: &[u8], kind: DbErrorKind, context: Option<&str>) -> DbError {
    let e = match open(bytes) {
        Err(e) => e,
        Ok(()) => panic!("accepted; expected {kind:?} {context:?}"),
    };
    assert_eq!(e.kind, kind, "{e:?}: {e}");
    if let Some(c) = context {
        assert_eq!(e.context, c, "{e:?}: {e}");
    }
    check_message(&e);
    e
}

/// Re-encodes `sections` after `edit` changed them.
fn reencode(edit: impl FnOnce(&mut Sections)) -> Vec<u8> {
    let mut s = fixture::sections();
    edit(&mut s);
    fixture::encode(&s)
}

fn section_mut(s: &mut Sections, kind: SectionKind) -> &mut Vec<u8> {
    &mut s
        .iter_mut()
        .find(|(k, _)| *k == kind)
        .expect("section present")
        .1
}

fn edit_meta(s: &mut Sections, f: impl FnOnce(&mut MetaRecord)) {
    let b = section_mut(s, SectionKind::Meta);
    let mut m = MetaRecord::read_from_bytes(b).unwrap();
    f(&mut m);
    *b = m.as_bytes().to_vec();
}

fn edit_params(s: &mut Sections, f: impl FnOnce(&mut ParamsRecord)) {
    let b = section_mut(s, SectionKind::Params);
    let mut p = ParamsRecord::read_from_bytes(b).unwrap();
    f(&mut p);
    *b = p.as_bytes().to_vec();
}

fn edit_sites(s: &mut Sections, f: impl FnOnce(&mut [SiteRecord])) {
    let b = section_mut(s, SectionKind::Sites);
    let mut sites = <[SiteRecord]>::ref_from_bytes(b).unwrap().to_vec();
    f(&mut sites);
    *b = sites.as_bytes().to_vec();
}

/// Byte range of table entry `i`.
fn entry_range(i: usize) -> Range<usize> {
    HEADER_LEN + i * ENTRY_LEN..HEADER_LEN + (i + 1) * ENTRY_LEN
}

fn entry(bytes: &[u8], i: usize) -> SectionEntry {
    SectionEntry::read_from_bytes(&bytes[entry_range(i)]).unwrap()
}

fn set_entry(bytes: &mut [u8], i: usize, e: SectionEntry) {
    bytes[entry_range(i)].copy_from_slice(e.as_bytes());
}

/// Table index of `kind` in a fixture file (sections are in `ALL` order).
fn index_of(kind: SectionKind) -> usize {
    SectionKind::ALL.iter().position(|k| *k == kind).unwrap()
}

/// Byte range of section `kind` in a fixture file.
fn section_range(bytes: &[u8], kind: SectionKind) -> Range<usize> {
    let e = entry(bytes, index_of(kind));
    e.offset.get() as usize..(e.offset.get() + e.len.get()) as usize
}

/// Recomputes the header checksum after a header or table patch.
fn fix_header_crc(bytes: &mut [u8]) {
    let mut h = Header::read_from_bytes(&bytes[..HEADER_LEN]).unwrap();
    let n = (h.section_count.get() as usize).min(MAX_SECTIONS);
    let end = (HEADER_LEN + n * ENTRY_LEN).min(bytes.len());
    h.header_crc = U32::new(format::header_crc(&h, &bytes[HEADER_LEN..end]));
    bytes[..HEADER_LEN].copy_from_slice(h.as_bytes());
}

/// Applies a header/table patch two ways: with the header checksum fixed
/// (expect `kind`) and without (expect `HeaderChecksum`, unless the patch is
/// caught before the checksum, as magic, endianness and version are).
#[track_caller]
fn patch_both(patch: impl Fn(&mut Vec<u8>), kind: DbErrorKind, context: Option<&str>) -> DbError {
    let mut raw = tiny_db();
    patch(&mut raw);
    // What the reader checks before the header checksum.
    let before_crc = matches!(
        kind,
        DbErrorKind::Magic | DbErrorKind::Endian | DbErrorKind::Version
    ) || (kind == DbErrorKind::Table
        && matches!(context, Some("header length" | "section count")));
    if before_crc {
        expect(&raw, kind, context);
    } else {
        expect(&raw, DbErrorKind::HeaderChecksum, None);
    }
    fix_header_crc(&mut raw);
    expect(&raw, kind, context)
}

// ---------------------------------------------------------------------------

#[test]
fn fixture_is_a_valid_database() {
    let bytes = tiny_db();
    let buf = Aligned::new(&bytes);
    let db = RefDb::new(buf.bytes()).expect("valid");
    db.verify().expect("checksums");
    assert_eq!(db.grid_size(), (fixture::W, fixture::H));
    assert_eq!(db.site_count(), 3);
    assert_eq!(db.sites().len(), 3);
    assert_eq!(db.params(), &fixture::params());
    assert_eq!(db.frame(), fixture::frame());
    assert_eq!(db.neighbors(0), &[1]);
    assert_eq!(db.neighbors(1), &[0, 2]);
    assert_eq!(db.neighbors(2), &[1]);
    assert_eq!(db.neighbors(3), &[] as &[u32]);
    for i in 0..3 {
        assert_eq!(db.scan(i).len(), fixture::BEAMS as usize);
        let sum: f32 = db.hist(i).iter().sum();
        assert!((sum - 1.0).abs() < 1e-4, "hist {i} sums to {sum}");
        let xy = db.site_xy(i);
        let want = fixture::site_xy()[i];
        assert_eq!(xy, want);
    }
    assert!(db.scan(3).is_empty() && db.hist(3).is_empty() && db.site(3).is_none());
    assert_eq!(db.site_xy(99), [0.0, 0.0]);
    assert_eq!(db.dist().len(), (fixture::W * fixture::H) as usize);
    assert!(db.manifest().contains("refloc unit tests"));
    assert_eq!(db.bytes(), &bytes[..]);
    let grid = db.grid();
    for cy in 0..fixture::H {
        for cx in 0..fixture::W {
            assert_eq!(grid.blocked(cx, cy), fixture::blocked(cx, cy));
        }
    }
    for k in SectionKind::ALL {
        assert_eq!(db.section_crc(k), crc::crc32c(db.section(k)));
    }
}

#[test]
fn aligned_and_misaligned_buffers() {
    let bytes = tiny_db();
    for off in [0, 4, 8, 12] {
        let buf = Aligned::at(&bytes, off);
        let db = RefDb::new(buf.bytes()).unwrap_or_else(|e| panic!("offset {off}: {e}"));
        db.verify().unwrap();
        // Owned containers work too.
        let v: Vec<u8> = buf.bytes().to_vec();
        if v.as_ptr() as usize % 4 == 0 {
            RefDb::new(v).unwrap();
        }
    }
    for off in [1, 2, 3, 5, 7] {
        let buf = Aligned::at(&bytes, off);
        let e = RefDb::new(buf.bytes())
            .err()
            .expect("misaligned arrays are rejected");
        assert_eq!(e.kind, DbErrorKind::Alignment, "offset {off}: {e}");
        // The file is fine: the message blames the buffer, with its offset.
        assert!(
            e.to_string()
                .contains("buffer holding the database is misaligned"),
            "{e}"
        );
        assert_eq!(e.found, (off % 4) as u64, "{e}");
        assert!(
            ["grid", "scans", "hists", "neighbors"].contains(&e.context),
            "{e:?}"
        );
        assert_eq!(e.expected, 4);
        check_message(&e);
    }
}

#[test]
fn truncation_at_every_length() {
    let bytes = tiny_db();
    // Prefixes of one aligned buffer are aligned too.
    let buf = Aligned::new(&bytes);
    let table_end = HEADER_LEN + SectionKind::ALL.len() * ENTRY_LEN;
    for len in 0..bytes.len() {
        let e = RefDb::new(&buf.bytes()[..len])
            .err()
            .expect("a truncated file is rejected");
        assert_eq!(e.kind, DbErrorKind::Truncated, "length {len}: {e}");
        let where_ = if len < HEADER_LEN {
            "header"
        } else if len < table_end {
            "section table"
        } else {
            "file"
        };
        assert_eq!(e.context, where_, "length {len}");
        if len >= table_end {
            assert_eq!((e.expected, e.found), (bytes.len() as u64, len as u64));
        }
        check_message(&e);
    }
    // Appended bytes are caught the same way.
    let mut long = bytes.clone();
    long.extend_from_slice(&[0; 16]);
    let e = expect(&long, DbErrorKind::Truncated, Some("file"));
    assert_eq!(
        (e.expected, e.found),
        (bytes.len() as u64, long.len() as u64)
    );
}

#[test]
fn every_flipped_header_byte_is_caught() {
    let good = tiny_db();
    for i in 0..HEADER_LEN {
        for mask in [0x01u8, 0x80, 0xFF] {
            let mut b = good.clone();
            b[i] ^= mask;
            let e = open(&b).expect_err("a damaged header is rejected");
            use DbErrorKind::*;
            let ok = match i {
                0..8 => e.kind == Magic,
                8..10 => e.kind == Endian,
                10..12 => e.kind == Table && e.context == "header length",
                12..16 => e.kind == Version,
                // section_count: a count out of range, a table past the end,
                // or a different table under the same checksum.
                20..24 => matches!(e.kind, Table | Truncated | HeaderChecksum),
                _ => e.kind == HeaderChecksum,
            };
            assert!(ok, "byte {i} ^ {mask:#04x}: {e:?}");
            check_message(&e);
        }
    }
}

#[test]
fn every_flipped_table_byte_is_caught() {
    let good = tiny_db();
    let table_end = HEADER_LEN + SectionKind::ALL.len() * ENTRY_LEN;
    for i in HEADER_LEN..table_end {
        let mut b = good.clone();
        b[i] ^= 0x10;
        expect(&b, DbErrorKind::HeaderChecksum, None);
    }
}

/// True when a params section would hit the u32 overflow in
/// `Params::validate` (see `bin_product_overflow_is_a_value_error`): the
/// tests that damage bytes at random skip such files so the rest of their
/// coverage still runs.
fn known_overflow(params: &[u8]) -> bool {
    match ParamsRecord::read_from_bytes(params) {
        Ok(p) => {
            p.hist_rho_bins
                .get()
                .checked_mul(p.hist_theta_bins.get())
                .is_none()
                || p.win_rho_bins
                    .get()
                    .checked_mul(p.win_theta_bins.get())
                    .is_none()
        }
        Err(_) => false,
    }
}

/// Byte positions to damage in a section: all of a small one; the ends and
/// a stride through a large one.
fn positions(r: Range<usize>) -> Vec<usize> {
    if r.len() <= 4096 {
        return r.collect();
    }
    let (a, b) = (r.start, r.end);
    (a..a + 64)
        .chain((a + 64..b - 64).step_by(29))
        .chain(b - 64..b)
        .collect()
}

#[test]
fn every_flipped_section_byte_is_caught() {
    let good = tiny_db();
    let mut buf = Aligned::new(&good);
    let (mut accepted, mut rejected) = (0, 0);
    for kind in SectionKind::ALL {
        let r = section_range(&good, kind);
        assert!(!r.is_empty(), "{} is empty", kind.name());
        for i in positions(r) {
            for mask in [0x01u8, 0x80] {
                buf.bytes_mut()[i] ^= mask;
                let pr = section_range(&good, SectionKind::Params);
                if known_overflow(&buf.bytes()[pr]) {
                    buf.bytes_mut()[i] ^= mask;
                    continue;
                }
                match RefDb::new(buf.bytes()) {
                    Ok(db) => {
                        accepted += 1;
                        let e = db.verify().expect_err("verify catches every flip");
                        assert_eq!(e.kind, DbErrorKind::SectionChecksum);
                        assert_eq!(e.context, kind.name(), "byte {i} in {}", kind.name());
                        assert_eq!(e.expected, db.section_crc(kind) as u64);
                        assert_ne!(e.expected, e.found);
                        check_message(&e);
                    }
                    Err(e) => {
                        rejected += 1;
                        // Caught by a structural check of the section's content.
                        use DbErrorKind::*;
                        assert!(
                            matches!(e.kind, Size | Value | OutOfBounds),
                            "byte {i} ^ {mask:#04x} in {}: {e:?}",
                            kind.name()
                        );
                        assert!(
                            matches!(
                                kind,
                                SectionKind::Meta
                                    | SectionKind::Params
                                    | SectionKind::Sites
                                    | SectionKind::Neighbors
                                    | SectionKind::Index
                                    | SectionKind::Decision
                                    | SectionKind::Features
                            ),
                            "{} content is not checked by new(): {e:?}",
                            kind.name()
                        );
                        check_message(&e);
                    }
                }
                buf.bytes_mut()[i] ^= mask;
            }
        }
    }
    assert!(accepted > 1000 && rejected > 50, "{accepted} {rejected}");
}

#[test]
fn wrong_magic() {
    let mut b = tiny_db();
    b[7] = b'X';
    expect(&b, DbErrorKind::Magic, None);
    for other in [
        &b"\x89PNG\r\n\x1a\n0000"[..],
        b"P5\n600 400\n255\n",
        b"{\"json\": 1}",
        &[0u8; 200],
    ] {
        expect(other, DbErrorKind::Magic, None);
    }
    // A proper prefix of the magic is a truncated file, anything else is not ours.
    expect(b"REFL", DbErrorKind::Truncated, Some("header"));
    expect(b"REFX", DbErrorKind::Magic, None);
}

#[test]
fn wrong_endianness() {
    let e = patch_both(
        |b| b[8..10].copy_from_slice(&[0xFE, 0xFF]),
        DbErrorKind::Endian,
        None,
    );
    assert_eq!((e.expected, e.found), (0xFEFF, 0xFFFE));
    assert!(e.to_string().contains("0xfffe"), "{e}");
}

#[test]
fn wrong_version_names_both_versions() {
    for v in [0u32, 2, 7, u32::MAX] {
        let e = patch_both(
            |b| b[12..16].copy_from_slice(&v.to_le_bytes()),
            DbErrorKind::Version,
            None,
        );
        assert_eq!((e.expected, e.found), (FORMAT_VERSION as u64, v as u64));
        let msg = e.to_string();
        assert!(msg.contains(&format!("version {v}")), "{msg}");
        assert!(msg.contains(&format!("version {FORMAT_VERSION}")), "{msg}");
    }
}

#[test]
fn bad_header_fields() {
    use DbErrorKind::*;
    patch_both(|b| b[10] = 65, Table, Some("header length"));
    for n in [0u32, MAX_SECTIONS as u32 + 1, u32::MAX] {
        patch_both(
            |b| b[20..24].copy_from_slice(&n.to_le_bytes()),
            Table,
            Some("section count"),
        );
    }
    // Entries fewer: the last required section is missing (the optional
    // ones after it are dropped too).
    let required = SectionKind::ALL
        .iter()
        .rposition(|k| !k.optional())
        .unwrap();
    let drop = (SectionKind::ALL.len() - required) as u8;
    let last = SectionKind::ALL[required].name();
    patch_both(|b| b[20] -= drop, Missing, Some(last));
    // One entry more: the table now runs into the first section.
    let first = SectionKind::ALL[0].name();
    patch_both(|b| b[20] += 1, Overlap, Some(first));
    // A table running past the end of a short file.
    let mut b = tiny_db();
    b.truncate(HEADER_LEN + 2 * ENTRY_LEN);
    expect(&b, Truncated, Some("section table"));
    // A file length that disagrees with the real one.
    for delta in [-16i64, 16, 1 << 40] {
        patch_both(
            |b| {
                let n = (b.len() as i64 + delta) as u64;
                b[24..32].copy_from_slice(&n.to_le_bytes())
            },
            Truncated,
            Some("file"),
        );
    }
    // A stored checksum that is simply wrong.
    let mut b = tiny_db();
    b[32] ^= 1;
    let e = expect(&b, HeaderChecksum, None);
    assert_ne!(e.expected, e.found);
}

#[test]
fn section_offsets_and_lengths() {
    use DbErrorKind::*;
    let good = tiny_db();
    let file_len = good.len() as u64;
    let meta = index_of(SectionKind::Meta);
    let grid = index_of(SectionKind::Grid);
    let dist = index_of(SectionKind::Dist);
    let sites = index_of(SectionKind::Sites);
    let manifest = index_of(SectionKind::Manifest);
    let with = |i: usize, f: fn(&mut SectionEntry, u64)| {
        move |b: &mut Vec<u8>| {
            let mut e = entry(b, i);
            f(&mut e, b.len() as u64);
            set_entry(b, i, e);
        }
    };
    // Past the end of the file.
    let e = patch_both(
        with(manifest, |e, n| e.offset = U64::new(n.next_multiple_of(16))),
        OutOfBounds,
        Some("manifest"),
    );
    assert!(e.found > file_len && e.expected == file_len);
    patch_both(
        with(dist, |e, n| e.offset = U64::new(n + 4096)),
        OutOfBounds,
        Some("dist"),
    );
    patch_both(
        with(grid, |e, n| e.len = U64::new(n)),
        OutOfBounds,
        Some("grid"),
    );
    // offset + len overflowing u64.
    let e = patch_both(
        with(sites, |e, _| {
            e.offset = U64::new(u64::MAX - 15);
            e.len = U64::new(32)
        }),
        OutOfBounds,
        Some("sites"),
    );
    assert_eq!(e.found, u64::MAX);
    patch_both(
        with(sites, |e, _| {
            e.offset = U64::new(1 << 63);
            e.len = U64::new(1 << 63)
        }),
        OutOfBounds,
        Some("sites"),
    );
    patch_both(
        with(meta, |e, _| e.len = U64::new(u64::MAX)),
        OutOfBounds,
        Some("meta"),
    );
    // Misaligned offsets.
    for delta in [4u64, 1, 8] {
        let f = match delta {
            4 => with(meta, |e, _| e.offset = U64::new(e.offset.get() + 4)),
            1 => with(dist, |e, _| e.offset = U64::new(e.offset.get() + 1)),
            _ => with(sites, |e, _| e.offset = U64::new(e.offset.get() - 8)),
        };
        let e = patch_both(f, Alignment, None);
        assert_eq!(e.expected, SECTION_ALIGN as u64);
        assert!(["meta", "dist", "sites"].contains(&e.context));
    }
    // Overlaps: with the table, with an earlier section, partially.
    patch_both(
        with(grid, |e, _| e.offset = U64::new(0)),
        Overlap,
        Some("grid"),
    );
    patch_both(
        with(grid, |e, _| e.offset = U64::new(64)),
        Overlap,
        Some("grid"),
    );
    let grid_off = entry(&good, grid).offset.get();
    let dist_off = entry(&good, dist).offset.get();
    let mut b = good.clone();
    let mut e = entry(&b, dist);
    e.offset = U64::new(grid_off);
    set_entry(&mut b, dist, e);
    fix_header_crc(&mut b);
    expect(&b, Overlap, Some("dist"));
    let mut b = good.clone();
    let mut e = entry(&b, sites);
    e.offset = U64::new(dist_off + 16);
    set_entry(&mut b, sites, e);
    fix_header_crc(&mut b);
    expect(&b, Overlap, Some("sites"));
    // The same overlap without fixing the header checksum.
    let mut b = good.clone();
    set_entry(&mut b, sites, e);
    expect(&b, HeaderChecksum, None);
}

#[test]
fn section_kinds_in_the_table() {
    use DbErrorKind::*;
    let unknown = SectionKind::ALL.len() as u32 + 1;
    for raw in [0u32, unknown, 99, u32::MAX] {
        let e = patch_both(
            |b| b[HEADER_LEN..HEADER_LEN + 4].copy_from_slice(&raw.to_le_bytes()),
            Table,
            Some("unknown section kind"),
        );
        assert_eq!(e.found, raw as u64);
    }
    // Two entries of the same kind (via the table, and via the encoder).
    patch_both(
        |b| b[entry_range(1).start..entry_range(1).start + 4].copy_from_slice(&1u32.to_le_bytes()),
        Table,
        Some("duplicate section kind"),
    );
    let b = reencode(|s| {
        let meta = s[0].clone();
        s.push(meta);
    });
    expect(&b, Table, Some("duplicate section kind"));
    // Each section missing in turn: an error for a required one; an
    // optional one reads as empty.
    for k in SectionKind::ALL {
        let b = reencode(|s| s.retain(|(kk, _)| *kk != k));
        if k.optional() {
            let buf = Aligned::new(&b);
            let db = RefDb::new(buf.bytes()).expect("an optional section may be left out");
            db.verify().unwrap();
            assert!(db.section(k).is_empty());
        } else {
            expect(&b, Missing, Some(k.name()));
        }
    }
    // A kind changed to a missing one, through the table.
    let e = patch_both(
        |b| {
            let i = entry_range(index_of(SectionKind::Hists)).start;
            b[i..i + 4].copy_from_slice(&(SectionKind::Manifest as u32).to_le_bytes())
        },
        Table,
        Some("duplicate section kind"),
    );
    assert_eq!(e.found, SectionKind::Manifest as u64);
    // Section order does not matter.
    let b = reencode(|s| s.reverse());
    open(&b).expect("sections in any order");
}

#[test]
fn section_sizes() {
    use DbErrorKind::*;
    for (kind, ctx) in [
        (SectionKind::Meta, "meta"),
        (SectionKind::Params, "params"),
        (SectionKind::Grid, "grid"),
        (SectionKind::Dist, "dist"),
        (SectionKind::Sites, "sites"),
        (SectionKind::Scans, "scans"),
        (SectionKind::Hists, "hists"),
    ] {
        for delta in [-4i64, 4, -1] {
            let b = reencode(|s| {
                let v = section_mut(s, kind);
                let n = (v.len() as i64 + delta) as usize;
                v.resize(n, 0);
            });
            let e = expect(&b, Size, Some(ctx));
            assert_ne!(e.expected, e.found);
        }
        let b = reencode(|s| section_mut(s, kind).clear());
        expect(&b, Size, Some(ctx));
    }
    let b = reencode(|s| section_mut(s, SectionKind::Neighbors).push(0));
    expect(&b, Size, Some("neighbors"));
    // An empty neighbour list is fine when no site points into it.
    let b = reencode(|s| {
        section_mut(s, SectionKind::Neighbors).clear();
        edit_sites(s, |sites| {
            for st in sites {
                st.neighbor_start = U32::new(0);
                st.neighbor_count = U32::new(0);
            }
        });
    });
    open(&b).expect("no neighbours");
    // An empty manifest is fine.
    let b = reencode(|s| section_mut(s, SectionKind::Manifest).clear());
    open(&b).expect("empty manifest");
}

#[test]
fn windows_section_size_is_checked() {
    for delta in [-4i64, 4] {
        let b = reencode(|s| {
            let v = section_mut(s, SectionKind::Windows);
            let n = (v.len() as i64 + delta) as usize;
            v.resize(n, 0);
        });
        expect(&b, DbErrorKind::Size, Some("windows"));
    }
    let b = reencode(|s| section_mut(s, SectionKind::Windows).clear());
    expect(&b, DbErrorKind::Size, Some("windows"));
}

/// The fixture's features section split into offsets (`u32`s), points
/// and tangents (`f32`s) and descriptors (`u16`s), to edit and join again.
struct FeatureParts {
    offsets: Vec<u32>,
    points: Vec<f32>,
    tangents: Vec<f32>,
    desc: Vec<u16>,
}

impl FeatureParts {
    fn of(s: &Sections) -> FeatureParts {
        let b = &s
            .iter()
            .find(|(k, _)| *k == SectionKind::Features)
            .unwrap()
            .1;
        let sites = fixture::SITE_CELLS.len();
        let offsets = <[u32]>::ref_from_bytes(&b[..4 * (sites + 1)])
            .unwrap()
            .to_vec();
        let l = format::FeaturesLayout::new(sites as u64, offsets[sites] as u64).unwrap();
        let f32s = |r: Range<usize>| <[f32]>::ref_from_bytes(&b[r]).unwrap().to_vec();
        FeatureParts {
            points: f32s(l.points_at..l.tangents_at),
            tangents: f32s(l.tangents_at..l.desc_at),
            desc: <[u16]>::ref_from_bytes(&b[l.desc_at..]).unwrap().to_vec(),
            offsets,
        }
    }

    /// The section: these parts laid out as the format says (the offsets
    /// as they are, so a malformed list gives a malformed section).
    fn bytes(&self) -> Vec<u8> {
        let mut out = self.offsets.as_bytes().to_vec();
        out.resize(out.len() + format::pad_len(out.len()), 0);
        out.extend_from_slice(self.points.as_bytes());
        out.extend_from_slice(self.tangents.as_bytes());
        out.extend_from_slice(self.desc.as_bytes());
        out
    }
}

/// The fixture with its features section edited by `f`.
fn edit_features(f: impl FnOnce(&mut FeatureParts)) -> Vec<u8> {
    reencode(|s| {
        let mut parts = FeatureParts::of(s);
        f(&mut parts);
        *section_mut(s, SectionKind::Features) = parts.bytes();
    })
}

#[test]
fn features_are_read_in_place_and_absent_reads_as_none() {
    let bytes = tiny_db();
    let buf = Aligned::new(&bytes);
    let db = RefDb::new(buf.bytes()).unwrap();
    let p = db.params();
    let parts = FeatureParts::of(&fixture::sections());
    for i in 0..db.site_count() {
        let f = db.features(i).expect("the fixture stores features");
        let n = f.points.len();
        assert_eq!(n, (parts.offsets[i + 1] - parts.offsets[i]) as usize);
        assert!(n >= 8 && n <= p.prep.max_points as usize, "{n}");
        assert_eq!(f.tangents.len(), n);
        assert_eq!(f.desc.len(), n * DESC_LEN);
        // In place: the slices point into the file's bytes.
        let sec = db.section(SectionKind::Features).as_ptr_range();
        assert!(sec.contains(&(f.points.as_ptr() as *const u8)));
        assert!(sec.contains(&(f.desc.as_ptr() as *const u8)));
    }
    assert!(db.features(db.site_count()).is_none());
    assert!(db.features(usize::MAX).is_none());
    // Without the section: a valid file, no features.
    let b = reencode(|s| s.retain(|(k, _)| *k != SectionKind::Features));
    let buf = Aligned::new(&b);
    let db = RefDb::new(buf.bytes()).expect("features are optional");
    db.verify().unwrap();
    assert!((0..3).all(|i| db.features(i).is_none()));
    // An empty one reads the same.
    let b = reencode(|s| section_mut(s, SectionKind::Features).clear());
    let buf = Aligned::new(&b);
    assert!(RefDb::new(buf.bytes()).unwrap().features(0).is_none());
}

#[test]
fn malformed_features_are_typed_errors() {
    use DbErrorKind::*;
    let ctx = "features";
    // Truncated or padded: the length is exactly what the offsets say.
    for delta in [-4i64, -16, 4, 16, -1] {
        let b = reencode(|s| {
            let v = section_mut(s, SectionKind::Features);
            let n = (v.len() as i64 + delta) as usize;
            v.resize(n, 0);
        });
        let e = expect(&b, Size, Some(ctx));
        assert_ne!(e.expected, e.found);
    }
    // Shorter than its offsets.
    let b = reencode(|s| section_mut(s, SectionKind::Features).truncate(8));
    expect(&b, Size, Some(ctx));
    // A last offset that promises more points than the file holds.
    let b = edit_features(|f| f.offsets[3] += 1);
    expect(&b, Size, Some(ctx));
    // Offsets that do not start at 0, or decrease.
    let b = edit_features(|f| f.offsets[0] = 1);
    let e = expect(&b, Value, Some("features offsets[0]"));
    assert_eq!(e.found_value(), Some(1.0));
    let b = edit_features(|f| f.offsets[2] = f.offsets[1] - 1);
    let e = expect(&b, Value, None);
    assert!(e.context.starts_with("features offsets"), "{e}");
    // A site with more points than max_points.
    let b = edit_features(|f| {
        let max = fixture::params().prep.max_points;
        let add = max + 1 - (f.offsets[1] - f.offsets[0]);
        for o in &mut f.offsets[1..] {
            *o += add;
        }
        f.points.resize(f.points.len() + 2 * add as usize, 1.0);
        f.tangents.resize(f.tangents.len() + 2 * add as usize, 0.0);
        f.desc.resize(f.desc.len() + DESC_LEN * add as usize, 0);
    });
    let e = expect(&b, Value, None);
    assert!(e.context.starts_with("features point count"), "{e}");
    assert_eq!(e.expected, fixture::params().prep.max_points as u64);
    // Non-finite points and tangents, tangents that are not unit vectors.
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let b = edit_features(|f| f.points[5] = bad);
        let e = expect(&b, Value, Some("features point"));
        assert_eq!(e.found_value().map(|v| v.is_nan()), Some(bad.is_nan()));
        let b = edit_features(|f| f.tangents[3] = bad);
        expect(&b, Value, None);
    }
    let b = edit_features(|f| {
        f.tangents[0] *= 1.01;
        f.tangents[1] *= 1.01;
    });
    let e = expect(&b, Value, None);
    assert!(e.context.starts_with("features tangent"), "{e}");
    let b = edit_features(|f| {
        f.tangents[0] = 0.0;
        f.tangents[1] = 0.0;
    });
    expect(&b, Value, None);
    // A descriptor row whose bins sum over DESC_SCALE (plus rounding).
    let b = edit_features(|f| {
        f.desc[DESC_LEN..2 * DESC_LEN].fill(u16::MAX);
    });
    let e = expect(&b, Value, None);
    assert!(e.context.starts_with("features descriptor"), "{e}");
    assert_eq!(e.found_value(), Some(DESC_LEN as f64 * 65535.0));
    // At the bound it is fine: nothing downstream can overflow.
    let b = edit_features(|f| {
        let row = &mut f.desc[..DESC_LEN];
        row.fill(0);
        row[0] = u16::MAX;
        row[1] = DESC_LEN as u16;
    });
    open(&b).expect("a row summing to DESC_SCALE + DESC_LEN");
    // A site with no point at all is fine (SSM finds no pose there).
    let b = edit_features(|f| {
        let n = f.offsets[1] as usize;
        f.points.drain(..2 * n);
        f.tangents.drain(..2 * n);
        f.desc.drain(..n * DESC_LEN);
        for o in &mut f.offsets[1..] {
            *o -= n as u32;
        }
    });
    let buf = Aligned::new(&b);
    let db = RefDb::new(buf.bytes()).expect("an empty site");
    assert!(db.features(0).unwrap().points.is_empty());
    assert_eq!(
        db.features(1).unwrap().desc.len(),
        db.features(1).unwrap().points.len() * DESC_LEN
    );
}

#[test]
fn localizing_with_and_without_stored_features_gives_identical_answers() {
    let with = tiny_db();
    let without = reencode(|s| s.retain(|(k, _)| *k != SectionKind::Features));
    let (ba, bb) = (Aligned::new(&with), Aligned::new(&without));
    let (a, b) = (
        RefDb::new(ba.bytes()).unwrap(),
        RefDb::new(bb.bytes()).unwrap(),
    );
    assert!(a.features(0).is_some() && b.features(0).is_none());
    let mut answers = 0;
    for (k, pose) in [
        (0.9, 2.8, 0.7),
        (3.5, 4.0, -1.0),
        (2.0, 2.0, 2.5),
        (4.5, 1.2, 0.0),
    ]
    .into_iter()
    .enumerate()
    {
        let ranges = fixture::full_scan_at(crate::Pose2::new(pose.0, pose.1, pose.2), 240);
        let scan = Scan::Ranges(RangeScan {
            angle_min: -core::f32::consts::PI,
            angle_increment: 2.0 * core::f32::consts::PI / ranges.len() as f32,
            range_min: 0.05,
            range_max: fixture::RANGE_MAX,
            ranges: &ranges,
        });
        let mut scratch = vec![0u8; scratch_size(a.params(), ranges.len())];
        // Debug prints every float to its shortest round-trip form: equal
        // strings are equal bits (the candidates included).
        let la = format!("{:?}", localize(&a, &scan, &mut scratch));
        let lb = format!("{:?}", localize(&b, &scan, &mut scratch));
        assert_eq!(la, lb, "scan {k}");
        answers += la.starts_with("Ok(") as usize;
    }
    assert!(answers >= 3, "{answers}");
}

#[test]
fn absurd_grid_and_site_counts() {
    use DbErrorKind::*;
    let (w, h) = (fixture::W, fixture::H);
    for (nw, nh) in [
        (65536, 65536),
        (u32::MAX, u32::MAX),
        (u32::MAX, 1),
        (1, u32::MAX),
        (w + 1, h),
        (w, h * 2),
    ] {
        let b = reencode(|s| {
            edit_meta(s, |m| {
                m.width = U32::new(nw);
                m.height = U32::new(nh)
            })
        });
        let e = expect(&b, Size, Some("grid"));
        assert_eq!(e.found, (w * h).div_ceil(32) as u64 * 4, "{nw} x {nh}");
    }
    for (nw, nh) in [(0, h), (w, 0), (0, 0)] {
        let b = reencode(|s| {
            edit_meta(s, |m| {
                m.width = U32::new(nw);
                m.height = U32::new(nh)
            })
        });
        expect(&b, Value, Some("grid size"));
    }
    for n in [4u32, 1000, u32::MAX] {
        let b = reencode(|s| edit_meta(s, |m| m.site_count = U32::new(n)));
        let e = expect(&b, Size, Some("sites"));
        assert_eq!(e.expected, n as u64 * 24);
    }
    let b = reencode(|s| edit_meta(s, |m| m.site_count = U32::new(0)));
    expect(&b, Value, Some("site count"));
    // The same through a raw patch of the meta section: its checksum is now
    // stale, but the structural check answers first.
    let mut b = tiny_db();
    let r = section_range(&b, SectionKind::Meta);
    b[r.start..r.start + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    expect(&b, Size, Some("grid"));
}

#[test]
fn meta_values() {
    use DbErrorKind::*;
    for res in [0.0f32, -0.05, f32::NAN, f32::INFINITY] {
        let b = reencode(|s| edit_meta(s, |m| m.resolution = F32::new(res)));
        let e = expect(&b, Value, Some("resolution"));
        // The message prints the value found, not its bits.
        let found = e
            .found_value()
            .expect("a resolution error carries its value");
        assert!(found.to_bits() == (res as f64).to_bits(), "{e}");
        assert!(
            e.to_string().contains(&format!("found {}", res as f64)),
            "{e}"
        );
    }
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let b = reencode(|s| edit_meta(s, |m| m.origin_yaw = F32::new(bad)));
        let e = expect(&b, Value, Some("origin"));
        assert!(
            e.to_string().contains(&format!("found {}", bad as f64)),
            "{e}"
        );
        let b = reencode(|s| edit_meta(s, |m| m.origin_x = F32::new(bad)));
        expect(&b, Value, Some("origin"));
    }
}

#[test]
fn parameter_errors_print_the_value_found() {
    use DbErrorKind::*;
    type Edit = fn(&mut ParamsRecord);
    let cases: [(Edit, &str, &str); 5] = [
        (|p| p.beams = U32::new(5000), "beams", "found 5000"),
        (|p| p.sigma_d = F32::new(-0.25), "sigma_d", "found -0.25"),
        (
            |p| p.range_max = F32::new(-1.0),
            "range_max/range_min",
            "found -1",
        ),
        (|p| p.w[2] = F32::new(f32::INFINITY), "w", "found inf"),
        (|p| p.selection = U32::new(7), "selection", "found 7"),
    ];
    for (edit, ctx, text) in cases {
        let b = reencode(|s| edit_params(s, edit));
        let e = expect(&b, Value, Some(ctx));
        assert!(e.to_string().contains(text), "{ctx}: {e}");
    }
}

#[test]
fn params_out_of_range() {
    use DbErrorKind::*;
    type Edit = fn(&mut ParamsRecord);
    let cases: [(Edit, &str); 14] = [
        (|p| p.beams = U32::new(0), "beams"),
        (|p| p.beams = U32::new(u32::MAX), "beams"),
        (|p| p.sigma_d = F32::new(f32::NAN), "sigma_d"),
        (|p| p.sigma_d = F32::new(0.0), "sigma_d"),
        (
            |p| p.angle_increment = F32::new(f32::NAN),
            "angle_increment",
        ),
        (|p| p.angle_increment = F32::new(1.0), "angle_increment"),
        (|p| p.range_max = F32::new(-1.0), "range_max/range_min"),
        (|p| p.max_points = U32::new(100_000), "max_points"),
        (|p| p.hist_rho_bins = U32::new(0), "histogram bins"),
        (|p| p.hist_theta_bins = U32::new(1 << 20), "histogram bins"),
        (|p| p.nc_max = U32::new(0), "nc_min/nc_max"),
        (|p| p.tentative_k = U32::new(1000), "tentative_k"),
        (|p| p.w[1] = F32::new(f32::INFINITY), "w"),
        (|p| p.selection = U32::new(7), "selection"),
    ];
    for (edit, ctx) in cases {
        let b = reencode(|s| edit_params(s, edit));
        expect(&b, Value, Some(ctx));
        // The same as a raw patch of the params section.
        let mut raw = tiny_db();
        let r = section_range(&raw, SectionKind::Params);
        let mut p = ParamsRecord::read_from_bytes(&raw[r.clone()]).unwrap();
        edit(&mut p);
        raw[r].copy_from_slice(p.as_bytes());
        expect(&raw, Value, Some(ctx));
    }
    // Valid but different histogram dimensions: the hists section no longer fits.
    let b = reencode(|s| edit_params(s, |p| p.hist_rho_bins = U32::new(16)));
    expect(&b, Size, Some("hists"));
    let b = reencode(|s| edit_params(s, |p| p.beams = U32::new(90)));
    expect(&b, Size, Some("scans"));
}

#[test]
fn bin_product_overflow_is_a_value_error() {
    use DbErrorKind::*;
    let b = reencode(|s| {
        edit_params(s, |p| {
            p.hist_rho_bins = U32::new(1 << 31);
            p.hist_theta_bins = U32::new(2)
        })
    });
    expect(&b, Value, Some("histogram bins"));
    let b = reencode(|s| {
        edit_params(s, |p| {
            p.win_rho_bins = U32::new(1 << 31);
            p.win_theta_bins = U32::new(2)
        })
    });
    expect(&b, Value, Some("window histogram layout"));
}

#[test]
fn neighbours_and_sites() {
    use DbErrorKind::*;
    for bad in [3u32, 4, u32::MAX] {
        let b = reencode(|s| {
            let nb = section_mut(s, SectionKind::Neighbors);
            nb[8..12].copy_from_slice(&bad.to_le_bytes());
        });
        expect(&b, Value, Some("neighbor index"));
    }
    // A site whose slice runs past the neighbour list.
    type Edit = fn(&mut [SiteRecord]);
    let slices: [Edit; 3] = [
        |s| s[2].neighbor_count = U32::new(2),
        |s| s[0].neighbor_start = U32::new(5),
        |s| {
            s[1].neighbor_start = U32::new(u32::MAX);
            s[1].neighbor_count = U32::new(u32::MAX)
        },
    ];
    for edit in slices {
        let b = reencode(|s| edit_sites(s, edit));
        expect(&b, OutOfBounds, Some("site neighbours"));
    }
    for bad in [f32::NAN, f32::INFINITY] {
        let b = reencode(|s| edit_sites(s, |st| st[1].x = F32::new(bad)));
        expect(&b, Value, Some("site position"));
        let b = reencode(|s| edit_sites(s, |st| st[2].clearance = F32::new(bad)));
        expect(&b, Value, Some("site position"));
    }
    // Raw patch of the neighbours section: caught by new(); verify would
    // also have caught it.
    let mut b = tiny_db();
    let r = section_range(&b, SectionKind::Neighbors);
    b[r.start..r.start + 4].copy_from_slice(&7u32.to_le_bytes());
    expect(&b, Value, Some("neighbor index"));
}

#[test]
fn data_sections_damaged_in_place_fail_verify() {
    // Content that new() does not interpret: a raw patch passes new() and
    // verify() names the section.
    for kind in [
        SectionKind::Grid,
        SectionKind::Dist,
        SectionKind::Scans,
        SectionKind::Hists,
        SectionKind::Manifest,
        SectionKind::Windows,
    ] {
        let mut b = tiny_db();
        let r = section_range(&b, kind);
        b[r.start + r.len() / 2] ^= 0x40;
        let buf = Aligned::new(&b);
        let db = RefDb::new(buf.bytes()).expect("structure intact");
        let e = db.verify().expect_err("checksum mismatch");
        assert_eq!(e.kind, DbErrorKind::SectionChecksum);
        assert_eq!(e.context, kind.name());
        assert!(e.to_string().contains(kind.name()));
    }
}

#[test]
fn every_error_kind_has_a_message() {
    use DbErrorKind::*;
    let kinds = [
        Truncated,
        Magic,
        Endian,
        Version,
        HeaderChecksum,
        SectionChecksum,
        Table,
        OutOfBounds,
        Alignment,
        Overlap,
        Missing,
        Size,
        Value,
        HostEndian,
    ];
    for kind in kinds {
        for k in SectionKind::ALL {
            let e = DbError::new(kind, k.name(), 16, 3);
            check_message(&e);
            let msg = e.to_string();
            assert!(msg.len() > 10, "{kind:?}: {msg}");
        }
    }
    // Errors are usable as `dyn Error`.
    let e: &dyn core::error::Error = &DbError::new(Size, "grid", 1, 2);
    assert!(e.to_string().contains("grid"));
}

// ---------------------------------------------------------------------------
// Fuzz-like: mutated but re-encoded files
// ---------------------------------------------------------------------------

/// Values that tend to reach edge cases when written over a field.
const INTERESTING: [u32; 14] = [
    0,
    1,
    2,
    3,
    0xFF,
    0xFFFF,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
    0x7FC0_0000, // NaN
    0x7F80_0000, // +inf
    0xFF80_0000, // -inf
    0x8000_0000, // -0.0
    0x7149_F2CA, // 1e30
];

fn mutate(rng: &mut Prng, s: &mut Sections) {
    let k = rng.below(s.len());
    let v = &mut s[k].1;
    match rng.below(8) {
        0 | 1 if !v.is_empty() => {
            let i = rng.below(v.len());
            v[i] ^= 1 << rng.below(8);
        }
        2 if !v.is_empty() => {
            let i = rng.below(v.len());
            v[i] = rng.next_u64() as u8;
        }
        3 | 4 if v.len() >= 4 => {
            let i = rng.below(v.len() / 4) * 4;
            let x = INTERESTING[rng.below(INTERESTING.len())];
            v[i..i + 4].copy_from_slice(&x.to_le_bytes());
        }
        5 if v.len() >= 8 => {
            let n = 2 + rng.below(7);
            let i = rng.below(v.len() - n + 1);
            for b in &mut v[i..i + n] {
                *b = rng.next_u64() as u8;
            }
        }
        6 => {
            // Grow or shrink a section by a word.
            if rng.below(2) == 0 || v.len() < 4 {
                v.extend_from_slice(&[0, 0, 0x80, 0x3F]);
            } else {
                let n = v.len() - 4;
                v.truncate(n);
            }
        }
        _ if v.len() >= 4 => {
            // A small integer in a u32 field (counts, indices, sizes).
            let i = rng.below(v.len() / 4) * 4;
            let x = rng.below(600) as u32;
            v[i..i + 4].copy_from_slice(&x.to_le_bytes());
        }
        _ => {}
    }
}

/// Touches everything a validated database offers, and localizes a scan.
fn exercise(db: &RefDb<&[u8]>, scans: &[Vec<f32>], scratch: &mut Vec<u8>) -> bool {
    db.verify().expect("re-encoded files have valid checksums");
    for k in SectionKind::ALL {
        let _ = (db.section(k).len(), db.section_crc(k));
    }
    let _ = (
        db.meta(),
        db.params(),
        db.frame(),
        db.manifest().len(),
        db.bytes().len(),
    );
    let (w, h) = db.grid_size();
    let grid = db.grid();
    let mut blocked = 0usize;
    for cy in 0..h.min(64) {
        for cx in 0..w.min(64) {
            blocked += grid.blocked(cx, cy) as usize;
        }
    }
    let _ = blocked;
    let _ = crate::raycast::cast(&grid, w as f32 / 2.0, h as f32 / 2.0, 0.3, 1e3);
    assert!(db.dist().len() as u64 == w as u64 * h as u64);
    let n = db.site_count();
    assert_eq!(db.sites().len(), n);
    for i in 0..n + 2 {
        let _ = (db.site(i), db.site_xy(i));
        for &j in db.neighbors(i) {
            assert!((j as usize) < n);
        }
        if i < n {
            assert_eq!(db.scan(i).len(), db.params().sensor.beams as usize);
            assert_eq!(db.hist(i).len(), db.params().coarse.hist_cells());
        } else {
            assert!(db.scan(i).is_empty() && db.hist(i).is_empty());
        }
    }
    let p = db.params();
    for i in 0..n + 1 {
        for w in 0..p.coarse.win_count() + 1 {
            for h in 0..p.coarse.win_headings as usize + 1 {
                let wh = db.window_hist(i, w, h);
                assert!(wh.is_empty() || wh.len() == p.coarse.win_cells());
            }
        }
    }
    let mut any_ok = false;
    for ranges in scans {
        let need = scratch_size(db.params(), ranges.len());
        if scratch.len() < need {
            scratch.resize(need, 0);
        }
        let scan = Scan::Ranges(RangeScan {
            angle_min: -core::f32::consts::PI,
            angle_increment: 2.0 * core::f32::consts::PI / ranges.len() as f32,
            range_min: 0.05,
            range_max: fixture::RANGE_MAX,
            ranges,
        });
        if let Ok(l) = localize(db, &scan, scratch) {
            any_ok = true;
            // The first ranking's N_C, then at most BACKGROUND_MAX more
            // and, for a crowded scan, DEEPER_MAX more.
            let nc = db.params().coarse.nc_max as usize;
            let most = nc + nc.min(crate::localize::BACKGROUND_MAX) + crate::localize::DEEPER_MAX;
            assert!(l.candidates.len() <= most);
            assert!((l.site as usize) < n);
        }
    }
    any_ok
}

#[test]
fn mutated_databases_never_panic() {
    let mut rng = Prng::new(21);
    let scans = [
        fixture::full_scan_at(crate::Pose2::new(0.9, 2.8, 0.7), 90),
        fixture::full_scan_at(crate::Pose2::new(3.5, 4.0, -1.0), 120),
    ];
    let mut scratch = Vec::new();
    let (mut valid, mut localized) = (0, 0);
    let mut kinds = std::collections::BTreeMap::new();
    let base = fixture::sections();
    for round in 0..2000 {
        let mut s = base.clone();
        for _ in 0..1 + round % 3 {
            mutate(&mut rng, &mut s);
        }
        if known_overflow(&s[index_of(SectionKind::Params)].1) {
            continue;
        }
        let bytes = fixture::encode(&s);
        let buf = Aligned::new(&bytes);
        match RefDb::new(buf.bytes()) {
            Ok(db) => {
                valid += 1;
                let scan = &scans[round % scans.len()..][..1];
                localized += exercise(&db, scan, &mut scratch) as usize;
            }
            Err(e) => {
                check_message(&e);
                *kinds.entry(format!("{:?}", e.kind)).or_insert(0) += 1;
            }
        }
    }
    std::eprintln!("mutations: {valid} accepted ({localized} localized), rejected: {kinds:?}");
    assert!(valid > 500 && kinds.len() >= 3, "{valid} {kinds:?}");
}

#[test]
fn the_unmutated_fixture_localizes_in_the_fuzz_harness() {
    let bytes = tiny_db();
    let buf = Aligned::new(&bytes);
    let db = RefDb::new(buf.bytes()).unwrap();
    let scans = [fixture::full_scan_at(crate::Pose2::new(0.9, 2.8, 0.7), 90)];
    assert!(exercise(&db, &scans, &mut vec![]));
}
