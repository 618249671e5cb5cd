//! JSON Lines records: the reader behind [`super::read_scans`] and the
//! writer [`scan_to_json`].
//!
//! Reading is in two steps. First the line is parsed once by serde_json into
//! the [`Field`]s `scanio` knows, each kept as its JSON text (a borrowed
//! [`RawValue`]), first occurrence only; unknown fields are skipped unread.
//! Then each field's text is read as the type the field needs ([`Scalar`],
//! an array through [`Capped`], ...). These types never fail on a value of
//! the wrong kind: they say what the value was, so that the error can name
//! the field (`ranges[4] is a string, expected a number or null`).
//!
//! Numbers are read from their own text ([`Scalar`]), not through
//! serde_json's number parser, which refuses a number beyond the range of
//! f64: such a number reads as infinite, and it is then the field's checks
//! (finite, within f32, within its range) that reject it, as they reject any
//! other value out of range. A range that is infinite is no return.

use std::fmt;
use std::io;
use std::marker::PhantomData;

use serde::de::{DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize};
use serde_json::ser::{CharEscape, CompactFormatter, Formatter};
use serde_json::value::RawValue;

use super::{stored_angles, InputScan, ReadOptions, ScanData, ScanError, ScanErrorKind};

/// Magnitudes from this on are taken as infinite (a JSON number beyond f64
/// range reads as infinite too).
const JSON_HUGE: f64 = 1e308;

/// Longest accepted `id` (bytes).
pub(crate) const MAX_ID_BYTES: usize = 256;

// ---------------------------------------------------------------------------
// Reading.

/// The record fields `scanio` reads; any other name is [`Field::Other`] and
/// its value is skipped unread (`intensities`, `header`, ...).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(field_identifier, rename_all = "snake_case")]
enum Field {
    Id,
    AngleMin,
    AngleMax,
    AngleIncrement,
    RangeMin,
    RangeMax,
    Ranges,
    Points,
    Truth,
    #[serde(other)]
    Other,
}

impl Field {
    fn name(self) -> &'static str {
        match self {
            Field::Id => "id",
            Field::AngleMin => "angle_min",
            Field::AngleMax => "angle_max",
            Field::AngleIncrement => "angle_increment",
            Field::RangeMin => "range_min",
            Field::RangeMax => "range_max",
            Field::Ranges => "ranges",
            Field::Points => "points",
            Field::Truth => "truth",
            Field::Other => "?",
        }
    }
}

/// The kind of a JSON value, named as error messages name it.
fn kind(raw: &RawValue) -> &'static str {
    // serde_json keeps a raw value without the whitespace around it.
    match raw.get().as_bytes().first() {
        Some(b'n') => "null",
        Some(b't' | b'f') => "a boolean",
        Some(b'"') => "a string",
        Some(b'[') => "an array",
        Some(b'{') => "an object",
        _ => "a number",
    }
}

fn is_null(raw: &RawValue) -> bool {
    raw.get() == "null"
}

/// A JSON value where a number is expected.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    /// The number, infinite if its magnitude is at least [`JSON_HUGE`]
    /// (numbers beyond the range of f64 included).
    Num(f64),
    Null,
    /// Anything else, as "a string", "an array", ...
    Other(&'static str),
}

impl Scalar {
    fn of(raw: &RawValue) -> Scalar {
        match kind(raw) {
            "null" => Scalar::Null,
            // The text is a valid JSON number, which Rust's parser reads
            // (correctly rounded, and infinite beyond f64 range).
            "a number" => Scalar::Num(match raw.get().parse::<f64>() {
                Ok(v) if v.abs() >= JSON_HUGE => v.signum() * f64::INFINITY,
                Ok(v) => v,
                Err(_) => f64::NAN,
            }),
            other => Scalar::Other(other),
        }
    }
}

impl<'de> Deserialize<'de> for Scalar {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        <&RawValue>::deserialize(d).map(Scalar::of)
    }
}

/// Reads a JSON array keeping its first `keep` elements (as `T`) and
/// counting the rest without keeping them: `(kept, length)`. An input array
/// thus never allocates more than `keep` elements.
struct Capped<T> {
    keep: usize,
    elements: PhantomData<T>,
}

impl<'de, T: Deserialize<'de>> DeserializeSeed<'de> for Capped<T> {
    type Value = (Vec<T>, usize);
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de, T: Deserialize<'de>> Visitor<'de> for Capped<T> {
    type Value = (Vec<T>, usize);

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an array")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        let mut kept = Vec::new();
        while kept.len() < self.keep {
            match seq.next_element::<T>()? {
                Some(v) => kept.push(v),
                None => {
                    let n = kept.len();
                    return Ok((kept, n));
                }
            }
        }
        let mut n = kept.len();
        while seq.next_element::<IgnoredAny>()?.is_some() {
            n = n.saturating_add(1);
        }
        Ok((kept, n))
    }
}

/// The array `raw` as its first `keep` elements and its length, or `Err`
/// with its kind if it is not an array.
fn array<'a, T: Deserialize<'a>>(
    raw: &'a RawValue,
    keep: usize,
) -> Result<(Vec<T>, usize), &'static str> {
    if kind(raw) != "an array" {
        return Err(kind(raw));
    }
    let capped = Capped {
        keep,
        elements: PhantomData,
    };
    // The text was checked when the line was parsed, and nothing read from
    // it can fail: a raw value is borrowed, a scalar is classified.
    capped.deserialize(raw).map_err(|_| "an unreadable array")
}

/// An array of exactly `N` numbers (`[x, y]`, `[x, y, theta]`), or what
/// it is instead.
fn numbers<const N: usize>(raw: &RawValue) -> Result<[f64; N], &'static str> {
    let (kept, n) = array::<Scalar>(raw, N)?;
    if n != N {
        return Err(if N == 2 {
            "an array of length other than 2"
        } else {
            "an array of length other than 3"
        });
    }
    let mut out = [0.0; N];
    for (o, v) in out.iter_mut().zip(kept) {
        match v {
            Scalar::Num(v) => *o = v,
            _ => return Err("an array with a non-number"),
        }
    }
    Ok(out)
}

/// The fields of one record as read, before the checks of
/// [`build_json_scan`].
#[derive(Default)]
struct Record {
    id: Option<String>,
    angle_min: Option<f64>,
    angle_max: Option<f64>,
    angle_increment: Option<f64>,
    range_min: Option<f64>,
    range_max: Option<f64>,
    ranges: Option<Vec<f32>>,
    points: Option<Vec<[f32; 2]>>,
    truth: Option<[f64; 3]>,
}

/// Collects the known fields of one JSON object, in input order, as their
/// JSON text: each field's first occurrence, plus the first repeated one
/// (so that the error can name it). What was collected before a syntax
/// error is kept (an error still names the `id` read so far).
struct Members<'r, 'a>(&'r mut Vec<(Field, &'a RawValue)>);

impl<'de> DeserializeSeed<'de> for Members<'_, 'de> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_map(self)
    }
}

impl<'de> Visitor<'de> for Members<'_, 'de> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a JSON object (one scan per line)")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut repeated = false;
        while let Some(field) = map.next_key::<Field>()? {
            let seen = self.0.iter().any(|&(f, _)| f == field);
            if field == Field::Other || (seen && repeated) {
                map.next_value::<IgnoredAny>()?;
            } else {
                repeated |= seen;
                self.0.push((field, map.next_value::<&RawValue>()?));
            }
        }
        Ok(())
    }
}

/// The text of a numeric `id`: integers as written (in u64 or i64 range),
/// others as the f64 they read as (`1.0` is `1`, numbers beyond f64 range
/// are clamped to `±1e308`).
fn number_id(text: &str) -> String {
    if let Ok(u) = text.parse::<u64>() {
        return u.to_string();
    }
    if let Ok(i) = text.parse::<i64>() {
        if i < 0 {
            return i.to_string();
        }
    }
    match text.parse::<f64>() {
        Ok(v) if v.is_infinite() => (v.signum() * JSON_HUGE).to_string(),
        Ok(v) => v.to_string(),
        Err(_) => text.to_owned(),
    }
}

impl Record {
    /// Reads one field's value into the record.
    fn set(&mut self, field: Field, raw: &RawValue, max_beams: usize) -> Result<(), ScanErrorKind> {
        let wrong = |found, expected| ScanErrorKind::WrongType {
            field: field.name().into(),
            found,
            expected,
        };
        match field {
            Field::Id => self.id = read_id(raw)?,
            Field::Ranges => self.ranges = Some(read_ranges(raw, max_beams)?),
            Field::Points => self.points = Some(read_points(raw, max_beams)?),
            Field::Truth if is_null(raw) => {}
            Field::Truth => match numbers::<3>(raw) {
                Ok(p) if p.iter().all(|v| v.is_finite()) => self.truth = Some(p),
                Ok(_) => return Err(ScanErrorKind::NotFinite("truth".into())),
                Err(k) => return Err(wrong(k, "[x, y, theta] (metres, radians)")),
            },
            Field::Other => {}
            _ => {
                let value = match Scalar::of(raw) {
                    Scalar::Num(v) => Some(v),
                    Scalar::Null if matches!(field, Field::AngleMin | Field::AngleIncrement) => {
                        return Err(wrong("null", "a number"));
                    }
                    Scalar::Null => None,
                    Scalar::Other(k) => return Err(wrong(k, "a number")),
                };
                *match field {
                    Field::AngleMin => &mut self.angle_min,
                    Field::AngleMax => &mut self.angle_max,
                    Field::AngleIncrement => &mut self.angle_increment,
                    Field::RangeMin => &mut self.range_min,
                    _ => &mut self.range_max,
                } = value;
            }
        }
        Ok(())
    }
}

fn read_id(raw: &RawValue) -> Result<Option<String>, ScanErrorKind> {
    let id = match kind(raw) {
        "null" => return Ok(None),
        "a number" => number_id(raw.get()),
        "a string" => String::deserialize(raw).map_err(|e| ScanErrorKind::Json(e.to_string()))?,
        other => {
            return Err(ScanErrorKind::WrongType {
                field: "id".into(),
                found: other,
                expected: "a string or a number",
            })
        }
    };
    if id.len() > MAX_ID_BYTES {
        return Err(ScanErrorKind::IdTooLong(id.len()));
    }
    if id.chars().any(char::is_control) {
        return Err(ScanErrorKind::IdControlCharacter);
    }
    Ok(Some(id))
}

/// The array of a `ranges` or `points` field, at most `max_beams` entries.
fn list<'a, T: Deserialize<'a>>(
    raw: &'a RawValue,
    field: &'static str,
    max_beams: usize,
    expected: &'static str,
) -> Result<Vec<T>, ScanErrorKind> {
    let (kept, n) = array::<T>(raw, max_beams).map_err(|found| ScanErrorKind::WrongType {
        field: field.into(),
        found,
        expected,
    })?;
    if n > max_beams {
        return Err(ScanErrorKind::TooManyEntries {
            field,
            count: n,
            max: max_beams,
        });
    }
    Ok(kept)
}

fn read_ranges(raw: &RawValue, max_beams: usize) -> Result<Vec<f32>, ScanErrorKind> {
    let values = list::<Scalar>(raw, "ranges", max_beams, "an array of numbers or null")?;
    let mut ranges = Vec::with_capacity(values.len());
    for (k, v) in values.into_iter().enumerate() {
        ranges.push(match v {
            Scalar::Num(v) => v as f32,
            Scalar::Null => f32::NAN,
            Scalar::Other(found) => {
                return Err(ScanErrorKind::WrongType {
                    field: format!("ranges[{k}]"),
                    found,
                    expected: "a number or null",
                })
            }
        });
    }
    Ok(ranges)
}

fn read_points(raw: &RawValue, max_beams: usize) -> Result<Vec<[f32; 2]>, ScanErrorKind> {
    let values = list::<&RawValue>(raw, "points", max_beams, "an array of [x, y] pairs")?;
    let mut points = Vec::with_capacity(values.len());
    for (k, v) in values.into_iter().enumerate() {
        match numbers::<2>(v) {
            Ok([x, y]) if (x as f32).is_finite() && (y as f32).is_finite() => {
                points.push([x as f32, y as f32]);
            }
            Ok(_) => return Err(ScanErrorKind::NotFinite(format!("points[{k}]"))),
            Err(found) => {
                return Err(ScanErrorKind::WrongType {
                    field: format!("points[{k}]"),
                    found,
                    expected: "an [x, y] pair of numbers",
                })
            }
        }
    }
    Ok(points)
}

/// Reads one JSON Lines record (a line without its newline, trimmed).
pub(super) fn parse_json_line(
    text: &[u8],
    line: usize,
    opts: &ReadOptions,
) -> Result<InputScan, ScanError> {
    let mut members = Vec::new();
    let mut de = serde_json::Deserializer::from_slice(text);
    let parsed = Members(&mut members)
        .deserialize(&mut de)
        .and_then(|()| de.end());
    let mut record = Record::default();
    let mut problem = None;
    for (k, &(field, raw)) in members.iter().enumerate() {
        let res = if members[..k].iter().any(|&(f, _)| f == field) {
            Err(ScanErrorKind::DuplicateField(field.name()))
        } else if parsed.is_err() && field != Field::Id {
            // A syntax error: only the id is of use.
            Ok(())
        } else {
            record.set(field, raw, opts.max_beams)
        };
        if let Err(e) = res {
            problem.get_or_insert(e);
        }
    }
    let id = record.id.take();
    let fail = |kind| {
        Err(ScanError {
            id: id.clone(),
            line,
            kind,
        })
    };
    if let Err(e) = parsed {
        return fail(json_error(&e));
    }
    if let Some(kind) = problem {
        return fail(kind);
    }
    match build_json_scan(record, opts) {
        Ok((data, truth)) => Ok(InputScan {
            id: id.unwrap_or_else(|| format!("line {line}")),
            line,
            data,
            truth,
            stamp: None,
        }),
        Err(kind) => fail(kind),
    }
}

/// A serde_json syntax error, with the column but not the line (always 1).
fn json_error(e: &serde_json::Error) -> ScanErrorKind {
    let s = e.to_string();
    let base = match s.rfind(" at line ") {
        Some(i) => &s[..i],
        None => &s[..],
    };
    ScanErrorKind::Json(if e.column() > 0 {
        format!("{base} at column {}", e.column())
    } else {
        base.to_owned()
    })
}

fn build_json_scan(
    raw: Record,
    opts: &ReadOptions,
) -> Result<(ScanData, Option<[f64; 3]>), ScanErrorKind> {
    let invalid = ScanErrorKind::Invalid;
    let range_max = match raw.range_max {
        Some(r) if r.is_finite() && r > 0.0 && (r as f32).is_finite() => r as f32,
        Some(r) => {
            return Err(invalid(format!(
                "range_max ({r}) is not a positive finite number of metres"
            )))
        }
        None => super::range_max_from_opts(opts)?,
    };
    let data = match (raw.ranges, raw.points) {
        (Some(_), Some(_)) => return Err(ScanErrorKind::RangesAndPoints),
        (None, None) => return Err(ScanErrorKind::MissingField("ranges (or points)")),
        (Some(ranges), None) => {
            let angle_min = raw
                .angle_min
                .ok_or(ScanErrorKind::MissingField("angle_min"))?;
            let inc = raw
                .angle_increment
                .ok_or(ScanErrorKind::MissingField("angle_increment"))?;
            if ranges.is_empty() {
                return Err(ScanErrorKind::Empty("ranges"));
            }
            let (min32, inc32) = stored_angles(
                angle_min,
                inc,
                ranges.len(),
                ["angle_min", "angle_increment"],
            )?;
            check_angle_max(raw.angle_max, min32, inc32, ranges.len())?;
            let range_min = match raw.range_min {
                None => 0.0,
                Some(r) if r.is_finite() && r >= 0.0 && (r as f32) < range_max => r as f32,
                Some(r) => {
                    return Err(invalid(format!(
                        "range_min ({r}) is not a finite number of metres in [0, range_max)"
                    )));
                }
            };
            let ranges = ranges
                .into_iter()
                .map(|r| {
                    if r > 0.0 && r >= range_min && r <= range_max {
                        r
                    } else {
                        f32::NAN
                    }
                })
                .collect();
            ScanData::Ranges {
                angle_min: min32,
                angle_increment: inc32,
                range_min,
                range_max,
                ranges,
            }
        }
        (None, Some(points)) => {
            if points.is_empty() {
                return Err(ScanErrorKind::Empty("points"));
            }
            ScanData::Points { points, range_max }
        }
    };
    Ok((data, raw.truth))
}

/// Checks `angle_max` (if given) against the angles the scan keeps.
fn check_angle_max(
    angle_max: Option<f64>,
    min32: f32,
    inc32: f32,
    n: usize,
) -> Result<(), ScanErrorKind> {
    let Some(angle_max) = angle_max else {
        return Ok(());
    };
    let (angle_min, inc) = (min32 as f64, inc32 as f64);
    let expected = angle_min + (n - 1) as f64 * inc;
    // Loose: some drivers write angle_min + n * increment.
    if !angle_max.is_finite() || (angle_max - expected).abs() > inc.abs() * (1.0 + 1e-3) + 1e-6 {
        return Err(ScanErrorKind::Invalid(format!(
            "angle_max ({angle_max}) disagrees with angle_min + (n - 1) * angle_increment = {expected} \
             (n = {n}) by more than one increment"
        )));
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// Writing.

/// The record [`scan_to_json`] writes for a `Ranges` scan; the fields in
/// this order.
#[derive(Serialize)]
struct RangesRecord<'a> {
    id: &'a str,
    angle_min: f32,
    angle_max: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    ranges: &'a [f32],
    #[serde(skip_serializing_if = "Option::is_none")]
    truth: Option<[f64; 3]>,
}

/// The record [`scan_to_json`] writes for a `Points` scan.
#[derive(Serialize)]
struct PointsRecord<'a> {
    id: &'a str,
    range_max: f32,
    points: &'a [[f32; 2]],
    #[serde(skip_serializing_if = "Option::is_none")]
    truth: Option<[f64; 3]>,
}

/// serde_json's compact output with the text `scan_to_json` has always
/// written: a finite float as Rust's `{:?}` writes it, the shortest text
/// that reads back as the same value (`1.0`, `1e-7`, `1e16`, `-0.0`), where
/// serde_json's own formatting differs for some magnitudes (`1e16` is
/// `10000000000000000.0` there); and backspace, form feed and DEL escaped
/// as `\u0008`, `\u000c` and `\u007f`. (serde_json writes `null` for a
/// float that is not finite itself.)
struct Compact;

impl Formatter for Compact {
    fn write_f32<W: ?Sized + io::Write>(&mut self, w: &mut W, v: f32) -> io::Result<()> {
        write!(w, "{v:?}")
    }

    fn write_f64<W: ?Sized + io::Write>(&mut self, w: &mut W, v: f64) -> io::Result<()> {
        write!(w, "{v:?}")
    }

    fn write_char_escape<W: ?Sized + io::Write>(
        &mut self,
        w: &mut W,
        escape: CharEscape,
    ) -> io::Result<()> {
        match escape {
            CharEscape::Backspace => w.write_all(b"\\u0008"),
            CharEscape::FormFeed => w.write_all(b"\\u000c"),
            other => CompactFormatter.write_char_escape(w, other),
        }
    }

    fn write_string_fragment<W: ?Sized + io::Write>(
        &mut self,
        w: &mut W,
        fragment: &str,
    ) -> io::Result<()> {
        for (k, part) in fragment.split('\u{7f}').enumerate() {
            if k > 0 {
                w.write_all(b"\\u007f")?;
            }
            w.write_all(part.as_bytes())?;
        }
        Ok(())
    }
}

fn to_json<T: Serialize>(record: &T) -> String {
    let mut out = Vec::with_capacity(256);
    let mut ser = serde_json::Serializer::with_formatter(&mut out, Compact);
    // Writing plain structs of strings and numbers to memory cannot fail,
    // and serde_json writes UTF-8.
    match record.serialize(&mut ser) {
        Ok(()) => String::from_utf8(out).unwrap_or_default(),
        Err(_) => String::new(),
    }
}

/// One JSON Lines record for `scan` (no trailing newline), readable by
/// [`read_scans`](super::read_scans): `NaN` and infinite ranges are written
/// as `null`, `ranges` records also get the matching `angle_max`, and
/// `truth` (if any) is written as `[x, y, theta]` (metres, radians).
/// Reading the record back gives the same scan, bit for bit, as long as the
/// ranges lie within `[range_min, range_max]` (others read back as `NaN`).
pub fn scan_to_json(scan: &ScanData, id: &str, truth: Option<[f64; 3]>) -> String {
    match scan.as_scan() {
        refloc::Scan::Ranges(r) => {
            let last = r.ranges.len().saturating_sub(1) as f64;
            let angle_max = (r.angle_min as f64 + last * r.angle_increment as f64) as f32;
            to_json(&RangesRecord {
                id,
                angle_min: r.angle_min,
                angle_max,
                angle_increment: r.angle_increment,
                range_min: r.range_min,
                range_max: r.range_max,
                ranges: r.ranges,
                truth,
            })
        }
        refloc::Scan::Points { points, range_max } => to_json(&PointsRecord {
            id,
            range_max,
            points,
            truth,
        }),
    }
}
