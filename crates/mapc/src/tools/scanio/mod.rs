//! Readers for the laser scans `mapc localize` takes, and a JSON Lines writer.
//!
//! Two input formats, one scan per line, plain or gzip-compressed
//! ([`open_input`]):
//!
//! * **JSON Lines** ([`InputFormat::JsonLines`]): one object per line with the
//!   `sensor_msgs/LaserScan` field names (`angle_min`, `angle_increment`,
//!   `range_min`, `range_max`, `ranges`, optional `angle_max`), or `points`
//!   (`[[x, y], ...]`, metres, sensor frame) instead of `ranges`; optional `id`
//!   (string or number) and `truth` (`[x, y, theta]`, metres and radians).
//!   `intensities`, `header` and unknown fields are ignored. Blank lines and
//!   lines starting with `#` are skipped.
//! * **CARMEN logs** ([`InputFormat::Carmen`]): `FLASER`, `RLASER` and
//!   `ROBOTLASERk` lines are scans; `PARAM robot_front_laser_max` /
//!   `robot_rear_laser_max` set the maximum range of the `FLASER` / `RLASER`
//!   lines after them; every other keyword line (`ODOM`, `PARAM`, `SYNC`,
//!   `TRUEPOS`, `RAWLASERk`, ...) and `#` comments are skipped (a log
//!   with `RAWLASERk` lines and no scan line ends with a
//!   [`ScanErrorKind::RawLaserOnly`] item rather than looking empty). See
//!   [`carmen_angle_increment`] for the beam geometry of `FLASER`/`RLASER`.
//!
//! This is a hostile-input reader: it never panics, never buffers a line
//! beyond [`ReadOptions::max_line_bytes`], and never allocates from a count
//! written in the input (beam counts are bounded by
//! [`ReadOptions::max_beams`] and by the fields actually present). A
//! malformed line yields one [`ScanError`] and reading goes on with the next
//! line; only an I/O error (e.g. a truncated gzip stream) ends the stream.

use std::f64::consts::{PI, TAU};
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;
use std::str::FromStr;

use flate2::read::MultiGzDecoder;

pub mod bag;
pub mod cdr;
mod jsonl;
#[cfg(test)]
mod tests;

pub use jsonl::scan_to_json;

/// One scan read from the input.
#[derive(Clone, Debug, PartialEq)]
pub struct InputScan {
    /// The scan's name: the JSON `id` (a number is rendered as text), else
    /// `"line N"` for JSON Lines, or `"scan K"` for CARMEN logs, where `K`
    /// is the 0-based index of the line among the log's laser lines (the
    /// `scan_index` of the shared `*-poses-in-map.txt` files).
    pub id: String,
    /// 1-based line number of the scan in the input.
    pub line: usize,
    /// The measurements.
    pub data: ScanData,
    /// Ground-truth sensor pose `[x (m), y (m), theta (rad)]` if the input
    /// carries one: JSON `truth`, or the laser pose fields of a CARMEN line
    /// (in the log's own frame, not the map's).
    pub truth: Option<[f64; 3]>,
    /// The header stamp and frame of a scan read from a ROS 2 bag
    /// ([`bag`]); `None` for the line formats.
    pub stamp: Option<bag::Stamp>,
}

/// The measurements of one scan, in the sensor frame (x forward, y left,
/// angles counter-clockwise from +x).
#[derive(Clone, Debug, PartialEq)]
pub enum ScanData {
    /// Ranges at evenly spaced bearings: beam `k` points at
    /// `angle_min + k * angle_increment`.
    Ranges {
        /// Bearing of the first beam (rad).
        angle_min: f32,
        /// Bearing step between consecutive beams (rad, non-zero, may be
        /// negative).
        angle_increment: f32,
        /// Minimum valid range (m).
        range_min: f32,
        /// Maximum range of the sensor (m).
        range_max: f32,
        /// One range per beam (m); `NaN` for no return (or an invalid
        /// reading). Never empty.
        ranges: Vec<f32>,
    },
    /// Explicit end points.
    Points {
        /// End points `[x, y]` (m, sensor frame), all finite. Never empty.
        points: Vec<[f32; 2]>,
        /// Maximum range of the sensor (m).
        range_max: f32,
    },
}

impl ScanData {
    /// The sensor's maximum range (m).
    pub fn range_max(&self) -> f32 {
        match self {
            ScanData::Ranges { range_max, .. } | ScanData::Points { range_max, .. } => *range_max,
        }
    }

    /// Number of beams (`Ranges`, including no-return beams) or points.
    pub fn len(&self) -> usize {
        match self {
            ScanData::Ranges { ranges, .. } => ranges.len(),
            ScanData::Points { points, .. } => points.len(),
        }
    }

    /// True if the scan has no beams or points (never the case for scans
    /// returned by [`read_scans`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The runtime's view of the scan (borrowing its ranges or points).
    pub fn as_scan(&self) -> refloc::Scan<'_> {
        match self {
            ScanData::Ranges {
                angle_min,
                angle_increment,
                range_min,
                range_max,
                ranges,
            } => refloc::Scan::Ranges(refloc::RangeScan {
                angle_min: *angle_min,
                angle_increment: *angle_increment,
                range_min: *range_min,
                range_max: *range_max,
                ranges,
            }),
            ScanData::Points { points, range_max } => refloc::Scan::Points {
                points,
                range_max: *range_max,
            },
        }
    }
    /// The beams as (bearing in the sensor frame (rad), range (m)) pairs:
    /// a range outside `[range_min, range_max)` or non-finite (no return,
    /// as [`refloc::RangeScan`] reads it) becomes infinite; points give their bearing and distance.
    pub fn beams(&self) -> Vec<(f32, f32)> {
        match self {
            ScanData::Ranges {
                angle_min,
                angle_increment,
                range_min,
                range_max,
                ranges,
            } => ranges
                .iter()
                .enumerate()
                .map(|(i, &r)| {
                    let ok = refloc::localize::is_return(r, *range_min, *range_max);
                    (
                        angle_min + i as f32 * angle_increment,
                        if ok { r } else { f32::INFINITY },
                    )
                })
                .collect(),
            ScanData::Points { points, .. } => points
                .iter()
                .map(|p| (p[1].atan2(p[0]), p[0].hypot(p[1])))
                .collect(),
        }
    }
}

/// Why one input line could not be read as a scan.
///
/// Displays as `line 12 (id scan-3): ranges[4] is a string, expected a number
/// or null`, or `line 12: ...` when the line's id is unknown.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("line {line}{}: {kind}", .id.as_ref().map(|id| format!(" (id {id})")).unwrap_or_default())]
pub struct ScanError {
    /// The scan's id if it is known (the JSON `id`, or `"scan K"` for a
    /// CARMEN laser line, `"msg K"` for a bag message).
    pub id: Option<String>,
    /// 1-based line number in the input (message number in a bag).
    pub line: usize,
    /// What is wrong, naming the field.
    pub kind: ScanErrorKind,
}

impl ScanError {
    /// What is wrong, as text (the error's display without the line and id).
    pub fn message(&self) -> String {
        self.kind.to_string()
    }
}

/// What is wrong with one input line (or bag message): [`ScanError::kind`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ScanErrorKind {
    /// Reading the input failed (the stream ends here).
    #[error("read error: {0}")]
    Read(String),
    /// The line is longer than [`ReadOptions::max_line_bytes`].
    #[error("line is {len} bytes long, more than max_line_bytes = {max}")]
    LineTooLong {
        /// Its length (bytes).
        len: u64,
        /// The limit.
        max: usize,
    },
    /// [`InputFormat::Auto`] could not tell the format from the line (its
    /// start, escaped).
    #[error(
        "cannot tell the input format from {0}: expected '{{' (JSON Lines) or an uppercase \
         CARMEN keyword such as FLASER"
    )]
    UnknownFormat(String),
    /// Not valid JSON, or not an object (serde_json's message and column).
    #[error("invalid JSON: {0}")]
    Json(String),
    /// A field of a JSON record appears twice.
    #[error("field {0} appears more than once")]
    DuplicateField(&'static str),
    /// A JSON value of the wrong kind.
    #[error("{field} is {found}, expected {expected}")]
    WrongType {
        /// The field (`ranges[4]` for an element).
        field: String,
        /// What it is: `a string`, `null`, `an array of length other than 2`...
        found: &'static str,
        /// What it should be.
        expected: &'static str,
    },
    /// A number (or one of the numbers) of the field is not finite.
    #[error("{0} is not finite")]
    NotFinite(String),
    /// The JSON `id` is longer than 256 bytes (its length).
    #[error("id is {0} bytes long, more than {max}", max = jsonl::MAX_ID_BYTES)]
    IdTooLong(usize),
    /// The JSON `id` contains a control character.
    #[error("id contains a control character")]
    IdControlCharacter,
    /// `ranges` or `points` has more than [`ReadOptions::max_beams`] entries.
    #[error("{field} has {count} entries, more than max_beams = {max}")]
    TooManyEntries {
        /// `ranges` or `points`.
        field: &'static str,
        /// Its entries.
        count: usize,
        /// The limit.
        max: usize,
    },
    /// A required JSON field is missing.
    #[error("missing field {0}")]
    MissingField(&'static str),
    /// `ranges` or `points` is empty.
    #[error("{0} is empty")]
    Empty(&'static str),
    /// A JSON record has both `ranges` and `points`.
    #[error("both ranges and points given; expected one of them")]
    RangesAndPoints,
    /// A line of a CARMEN log that does not start with a keyword (its first
    /// field, escaped).
    #[error("not a CARMEN line: {0} is not an uppercase keyword such as FLASER")]
    NotCarmen(String),
    /// A value out of its range, a field missing from a CARMEN line, counts
    /// that disagree, an undecodable bag message: the message names the
    /// field and the value.
    #[error("{0}")]
    Invalid(String),
    /// A CARMEN log that ended with `RAWLASERk` lines (their count) and no
    /// line this reader takes as a scan. Raw laser lines are not read: a
    /// log that has them usually has each scan again as a `FLASER`,
    /// `RLASER` or `ROBOTLASERk` line, which carries the pose.
    #[error(
        "the log has {0} RAWLASERk lines and no FLASER, RLASER or ROBOTLASERk line: raw laser \
         lines are not read; give the scans as FLASER or ROBOTLASER1 lines, or as JSON Lines"
    )]
    RawLaserOnly(usize),
    /// A bag whose records end early or are damaged (the stream ends here).
    #[error(
        "bag ends early or is damaged after byte {byte} ({what}); {read} messages of {topic} read"
    )]
    BagDamaged {
        /// Bytes of the bag read.
        byte: u64,
        /// What went wrong.
        what: String,
        /// Messages of the topic read before.
        read: usize,
        /// The topic.
        topic: String,
    },
}

/// Input format of [`read_scans`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InputFormat {
    /// Decide from the first line that is neither blank nor a `#` comment:
    /// `{` means JSON Lines, an uppercase keyword (`FLASER`, `PARAM`, ...)
    /// means a CARMEN log. Lines before that decision that fit neither are
    /// errors.
    #[default]
    Auto,
    /// One JSON object per line (`sensor_msgs/LaserScan` field names).
    JsonLines,
    /// A CARMEN log.
    Carmen,
}

/// A name that [`InputFormat::from_str`] does not know.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown input format {0:?}: expected auto, jsonl or carmen")]
pub struct UnknownInputFormat(pub String);

impl FromStr for InputFormat {
    type Err = UnknownInputFormat;

    /// Parses `auto`, `jsonl` (or `json`, `jsonlines`) and `carmen`.
    fn from_str(s: &str) -> Result<Self, UnknownInputFormat> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(InputFormat::Auto),
            "jsonl" | "json" | "jsonlines" | "json-lines" => Ok(InputFormat::JsonLines),
            "carmen" | "log" => Ok(InputFormat::Carmen),
            _ => Err(UnknownInputFormat(s.to_owned())),
        }
    }
}

/// Options of [`read_scans`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReadOptions {
    /// Field of view (rad) of CARMEN `FLASER`/`RLASER` lines, overriding the
    /// default of pi (180 degrees). Must be in (0, 2 pi]. `ROBOTLASERk`
    /// lines carry their own angles and ignore it.
    pub fov: Option<f32>,
    /// Maximum range (m) used when the input gives none: JSON records
    /// without `range_max`, CARMEN `FLASER`/`RLASER` lines without an earlier
    /// `PARAM robot_front_laser_max`/`robot_rear_laser_max`, `ROBOTLASERk`
    /// lines whose `maximum_range` is not positive. Default 30.
    pub range_max: f32,
    /// Most beams (or points) one scan may have; a line with more is an
    /// error naming the count. Default 100 000.
    pub max_beams: usize,
    /// Longest line (bytes, without its newline); a longer line is an error,
    /// skipped without being buffered. Default 16 MiB.
    pub max_line_bytes: usize,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            fov: None,
            range_max: 30.0,
            max_beams: 100_000,
            max_line_bytes: 16 << 20,
        }
    }
}

/// Reads scans from `reader`, one item per scan line (streaming): a
/// malformed line yields an `Err` item and the iteration goes on with the
/// next line. Blank lines, `#` comments and non-laser CARMEN lines yield
/// nothing. An I/O error yields one final `Err` item.
pub fn read_scans(
    reader: impl BufRead,
    format: InputFormat,
    opts: &ReadOptions,
) -> impl Iterator<Item = Result<InputScan, ScanError>> {
    Scans {
        lines: LineReader::new(reader, opts.max_line_bytes),
        format,
        opts: *opts,
        carmen: CarmenState::default(),
    }
}

/// Opens `path` for reading: `-` is standard input; a path ending in `.gz`,
/// or whose first bytes are the gzip magic `1f 8b`, is decompressed
/// (concatenated gzip members included).
pub fn open_input(path: &str) -> io::Result<Box<dyn BufRead>> {
    if path == "-" {
        return wrap_input(io::stdin(), false);
    }
    let file = File::open(path)?;
    wrap_input(file, path.to_ascii_lowercase().ends_with(".gz"))
}

fn wrap_input<R: Read + 'static>(mut inner: R, gzip: bool) -> io::Result<Box<dyn BufRead>> {
    let mut magic = [0u8; 2];
    let mut got = 0;
    while got < magic.len() {
        match inner.read(&mut magic[got..]) {
            Ok(0) => break,
            Ok(k) => got += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    let joined = io::Cursor::new(magic[..got].to_vec()).chain(inner);
    if gzip || magic[..got] == [0x1f, 0x8b] {
        Ok(Box::new(BufReader::new(MultiGzDecoder::new(joined))))
    } else {
        Ok(Box::new(BufReader::new(joined)))
    }
}

/// Reads a shared `*-poses-in-map.txt` file (plain or gzip): lines
/// `scan_index ipc_timestamp logger_timestamp x y theta` (metres, radians,
/// map frame), `#` comments and blank lines skipped. Returns
/// `(scan_index, [x, y, theta])` in file order; a malformed line is an
/// [`io::ErrorKind::InvalidData`] error naming the line.
pub fn read_poses_in_map(path: impl AsRef<Path>) -> io::Result<Vec<(usize, [f64; 3])>> {
    read_poses_at_most(path.as_ref(), MAX_POSES)
}

fn read_poses_at_most(path: &Path, max: usize) -> io::Result<Vec<(usize, [f64; 3])>> {
    let gz = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let reader = wrap_input(File::open(path)?, gz)?;
    let bad = |line: usize, msg: String| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{}: line {line}: {msg}", path.display()),
        )
    };
    let mut lines = LineReader::new(reader, 1 << 20);
    let mut out = Vec::new();
    while let Some((line, raw)) = lines.next_line() {
        let text = match raw {
            RawLine::Text(t) => t,
            RawLine::TooLong { len, .. } => {
                return Err(bad(line, format!("line is {len} bytes long")))
            }
            RawLine::Failed(e) => return Err(e),
        };
        let text = text.trim_ascii();
        if text.is_empty() || text[0] == b'#' {
            continue;
        }
        let count = tokens(text).count();
        if count != 6 {
            return Err(bad(
                line,
                format!("{count} fields; expected 6 (scan_index ipc_timestamp logger_timestamp x y theta)"),
            ));
        }
        let mut it = tokens(text);
        let index = it
            .next()
            .and_then(|t| std::str::from_utf8(t).ok())
            .and_then(|s| s.parse::<usize>().ok())
            .ok_or_else(|| bad(line, "scan_index is not a non-negative integer".into()))?;
        let mut pose = [0.0; 3];
        for (k, name) in ["ipc_timestamp", "logger_timestamp", "x", "y", "theta"]
            .iter()
            .enumerate()
        {
            let v = parse_f64(it.next()).filter(|v| v.is_finite());
            let v = v.ok_or_else(|| bad(line, format!("{name} is not a finite number")))?;
            if k >= 2 {
                pose[k - 2] = v;
            }
        }
        if out.len() >= max {
            return Err(bad(
                line,
                format!("more than {max} poses: not a poses-in-map file of one log"),
            ));
        }
        out.push((index, pose));
    }
    Ok(out)
}

/// Most poses [`read_poses_in_map`] reads (32 bytes each: 128 MiB), so a
/// stream that never ends (a FIFO, a device) cannot exhaust memory.
pub const MAX_POSES: usize = 4 << 20;

// ---------------------------------------------------------------------------
// Bounded line reader.

/// Bytes of a too-long line kept to tell what it was (format sniffing,
/// CARMEN keyword).
const PREFIX_KEEP: usize = 64;

/// Reads lines of at most `max` bytes; a longer line is reported (with its
/// first [`PREFIX_KEEP`] bytes) and skipped up to its newline without
/// buffering it.
struct LineReader<R> {
    inner: R,
    max: usize,
    buf: Vec<u8>,
    line_no: usize,
    finished: bool,
}

enum RawLine<'a> {
    /// The line without its `\n` (and without a trailing `\r`).
    Text(&'a [u8]),
    /// The line was longer than the limit: its length (bytes) and first bytes.
    TooLong { len: u64, prefix: &'a [u8] },
    /// Reading failed; the reader is finished.
    Failed(io::Error),
}

impl<R: BufRead> LineReader<R> {
    fn new(inner: R, max: usize) -> Self {
        LineReader {
            inner,
            max,
            buf: Vec::new(),
            line_no: 0,
            finished: false,
        }
    }

    /// The next line and its 1-based number, or `None` at the end.
    fn next_line(&mut self) -> Option<(usize, RawLine<'_>)> {
        if self.finished {
            return None;
        }
        self.buf.clear();
        let mut len: u64 = 0;
        let mut overflow = false;
        let mut started = false;
        loop {
            let avail = match self.inner.fill_buf() {
                Ok(a) => a,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    self.finished = true;
                    self.line_no += 1;
                    return Some((self.line_no, RawLine::Failed(e)));
                }
            };
            if avail.is_empty() {
                if !started {
                    self.finished = true;
                    return None;
                }
                break;
            }
            started = true;
            let (take, newline) = match avail.iter().position(|&b| b == b'\n') {
                Some(i) => (i, true),
                None => (avail.len(), false),
            };
            if !overflow && take <= self.max - self.buf.len() {
                self.buf.extend_from_slice(&avail[..take]);
            } else {
                if !overflow {
                    overflow = true;
                    self.buf.truncate(PREFIX_KEEP);
                }
                let need = PREFIX_KEEP.saturating_sub(self.buf.len()).min(take);
                self.buf.extend_from_slice(&avail[..need]);
            }
            len = len.saturating_add(take as u64);
            self.inner.consume(take + usize::from(newline));
            if newline {
                break;
            }
        }
        self.line_no += 1;
        if overflow {
            return Some((
                self.line_no,
                RawLine::TooLong {
                    len,
                    prefix: &self.buf,
                },
            ));
        }
        let mut text = &self.buf[..];
        if let [rest @ .., b'\r'] = text {
            text = rest;
        }
        Some((self.line_no, RawLine::Text(text)))
    }
}

// ---------------------------------------------------------------------------
// The scan iterator.

struct Scans<R> {
    lines: LineReader<R>,
    format: InputFormat,
    opts: ReadOptions,
    carmen: CarmenState,
}

impl<R: BufRead> Iterator for Scans<R> {
    type Item = Result<InputScan, ScanError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let Some((line, raw)) = self.lines.next_line() else {
                return self.carmen.raw_only_notice();
            };
            let text = match raw {
                RawLine::Text(t) => t,
                RawLine::Failed(e) => {
                    return Some(Err(ScanError {
                        id: None,
                        line,
                        kind: ScanErrorKind::Read(e.to_string()),
                    }));
                }
                RawLine::TooLong { len, prefix } => {
                    let prefix = strip_bom(line, prefix).trim_ascii_start();
                    if prefix.first() == Some(&b'#') {
                        continue; // an over-long comment
                    }
                    if self.format == InputFormat::Auto {
                        if let Some(f) = sniff(prefix) {
                            self.format = f;
                        }
                    }
                    let id = match self.format {
                        InputFormat::Carmen => self.carmen.count_if_laser(prefix),
                        _ => None,
                    };
                    let kind = ScanErrorKind::LineTooLong {
                        len,
                        max: self.opts.max_line_bytes,
                    };
                    return Some(Err(ScanError { id, line, kind }));
                }
            };
            let text = strip_bom(line, text).trim_ascii();
            if text.is_empty() || text[0] == b'#' {
                continue;
            }
            let format = match self.format {
                InputFormat::Auto => match sniff(text) {
                    Some(f) => {
                        self.format = f;
                        f
                    }
                    None => {
                        return Some(Err(ScanError {
                            id: None,
                            line,
                            kind: ScanErrorKind::UnknownFormat(show(text)),
                        }));
                    }
                },
                f => f,
            };
            match format {
                InputFormat::Carmen => match self.carmen.line(text, line, &self.opts) {
                    Some(item) => return Some(item),
                    None => continue,
                },
                _ => return Some(jsonl::parse_json_line(text, line, &self.opts)),
            }
        }
    }
}

fn strip_bom(line: usize, text: &[u8]) -> &[u8] {
    match text {
        [0xEF, 0xBB, 0xBF, rest @ ..] if line == 1 => rest,
        _ => text,
    }
}

fn sniff(text: &[u8]) -> Option<InputFormat> {
    if text.first() == Some(&b'{') {
        return Some(InputFormat::JsonLines);
    }
    let first = tokens(text).next()?;
    is_keyword(first).then_some(InputFormat::Carmen)
}

/// A CARMEN message keyword: an uppercase letter, then uppercase letters,
/// digits or underscores.
fn is_keyword(t: &[u8]) -> bool {
    matches!(t.first(), Some(b'A'..=b'Z'))
        && t.iter()
            .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || *b == b'_')
}

/// Whitespace-separated fields of a line.
fn tokens(text: &[u8]) -> impl Iterator<Item = &[u8]> {
    text.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// A short, escaped rendering of input bytes for error messages.
fn show(t: &[u8]) -> String {
    const MAX: usize = 24;
    let cut = t.len() > MAX;
    let s = String::from_utf8_lossy(&t[..t.len().min(MAX)]);
    if cut {
        format!("{:?}...", s)
    } else {
        format!("{:?}", s)
    }
}

fn parse_f64(t: Option<&[u8]>) -> Option<f64> {
    std::str::from_utf8(t?).ok()?.parse::<f64>().ok()
}

fn range_max_from_opts(opts: &ReadOptions) -> Result<f32, ScanErrorKind> {
    let r = opts.range_max;
    if r.is_finite() && r > 0.0 {
        Ok(r)
    } else {
        Err(invalid(format!(
            "the default range_max ({r}) is not a positive number of metres"
        )))
    }
}

fn invalid(message: String) -> ScanErrorKind {
    ScanErrorKind::Invalid(message)
}

/// Largest |angle| (rad) accepted for a first bearing or a step.
const ANGLE_LIMIT: f64 = TAU + 1e-3;

/// The first bearing and step as the scan stores them (f32), checked: both
/// finite, the step non-zero, `|angle_min|` within [`ANGLE_LIMIT`], and `n`
/// beams spanning at most one turn. `names` are the two fields as the input
/// calls them.
///
/// The checks are made on the f32 values, not on the f64 ones read: near a
/// limit the two can fall on different sides of it (6.2841853 is inside
/// 2 pi + 1e-3, its f32 6.2841854 is not), and the record
/// [`scan_to_json`] writes from the f32 values must read back.
fn stored_angles(
    angle_min: f64,
    inc: f64,
    n: usize,
    names: [&str; 2],
) -> Result<(f32, f32), ScanErrorKind> {
    let [min_name, inc_name] = names;
    let (min32, inc32) = (angle_min as f32, inc as f32);
    if !inc.is_finite() {
        return Err(ScanErrorKind::NotFinite(inc_name.into()));
    }
    if inc == 0.0 {
        return Err(invalid(format!("{inc_name} is 0")));
    }
    if !inc32.is_finite() || inc32 == 0.0 {
        return Err(invalid(format!(
            "{inc_name} ({inc}) is out of the range of a 32-bit float (rounds to {inc32})"
        )));
    }
    let (angle_min, inc) = (min32 as f64, inc32 as f64);
    if !angle_min.is_finite() || angle_min.abs() > ANGLE_LIMIT {
        return Err(invalid(format!(
            "{min_name} ({min32}) is not a finite angle within [-2 pi, 2 pi] rad"
        )));
    }
    let span = n.saturating_sub(1) as f64 * inc.abs();
    if span > TAU * (1.0 + 1e-4) + 1e-6 {
        return Err(invalid(format!(
            "{n} beams at angle_increment {inc32} rad span {span:.4} rad, more than a full turn"
        )));
    }
    Ok((min32, inc32))
}

// ---------------------------------------------------------------------------
// CARMEN logs.

/// The bearing step (rad) of an `FLASER`/`RLASER` line of `n` beams over a
/// field of view of `fov` rad (pi unless [`ReadOptions::fov`] says
/// otherwise); the first beam is at `-fov / 2` (front laser).
///
/// These lines do not state their angles. The rule: the step is the
/// standard SICK resolution `r` of 1, 0.5 or 0.25 degrees (tried in that
/// order) for which `n` beams fill the field of view to within one step,
/// i.e. `(n - 1) r <= fov <= n r` (`n = fov / r` or `fov / r + 1`); if none
/// fits, `fov / (n - 1)` (`fov` for a single beam). With `fov = pi` this
/// gives 1 degree for n = 180 and 181 and 0.5 degree for n = 360 and 361,
/// as CARMEN's own `carmen_laser_guess_angle_increment` does (CARMEN also
/// uses 0.25 degree for 400 and 401 beams over 180 degrees, which this rule
/// gives only with `fov` = 100 degrees, the SICK mode those counts come
/// from).
pub fn carmen_angle_increment(n: usize, fov: f64) -> f64 {
    let nf = n as f64;
    for deg in [1.0f64, 0.5, 0.25] {
        let r = deg.to_radians();
        let tol = 1e-3 * r;
        if nf * r >= fov - tol && (nf - 1.0) * r <= fov + tol {
            return r;
        }
    }
    if n > 1 {
        fov / (nf - 1.0)
    } else {
        fov
    }
}

#[derive(Default)]
struct CarmenState {
    /// Laser lines seen so far (the next scan's index).
    scans: usize,
    /// `PARAM robot_front_laser_max` (m).
    front_max: Option<f32>,
    /// `PARAM robot_rear_laser_max` (m).
    rear_max: Option<f32>,
    /// `RAWLASERk` lines seen (not read), for the notice at the end of a
    /// log that has nothing else.
    raw_lines: usize,
    /// The line of the first of them.
    first_raw_line: usize,
}

#[derive(Clone, Copy)]
enum LaserKind {
    Front,
    Rear,
    Robot,
}

fn laser_kind(keyword: &[u8]) -> Option<LaserKind> {
    match keyword {
        b"FLASER" => Some(LaserKind::Front),
        b"RLASER" => Some(LaserKind::Rear),
        [b'R', b'O', b'B', b'O', b'T', b'L', b'A', b'S', b'E', b'R', rest @ ..]
            if !rest.is_empty() && rest.iter().all(u8::is_ascii_digit) =>
        {
            Some(LaserKind::Robot)
        }
        _ => None,
    }
}

/// True for `RAWLASERk` (k one or more digits).
fn is_raw_laser(keyword: &[u8]) -> bool {
    matches!(keyword, [b'R', b'A', b'W', b'L', b'A', b'S', b'E', b'R', rest @ ..]
        if !rest.is_empty() && rest.iter().all(u8::is_ascii_digit))
}

impl CarmenState {
    /// At the end of the input: once, an error item (at the first
    /// `RAWLASERk` line) when the log had such lines and no scan line, so
    /// that it does not look empty.
    fn raw_only_notice(&mut self) -> Option<Result<InputScan, ScanError>> {
        // Taking the count gives the notice once: a later call sees none.
        let raw_lines = core::mem::take(&mut self.raw_lines);
        if self.scans > 0 || raw_lines == 0 {
            return None;
        }
        Some(Err(ScanError {
            id: None,
            line: self.first_raw_line,
            kind: ScanErrorKind::RawLaserOnly(raw_lines),
        }))
    }

    /// Counts a (too long) line as a scan if it starts with a laser keyword,
    /// returning its id.
    fn count_if_laser(&mut self, prefix: &[u8]) -> Option<String> {
        let kw = tokens(prefix).next()?;
        laser_kind(kw)?;
        let k = self.scans;
        self.scans += 1;
        Some(format!("scan {k}"))
    }

    /// Handles one non-blank, non-comment line: `None` if it is not a scan.
    fn line(
        &mut self,
        text: &[u8],
        line: usize,
        opts: &ReadOptions,
    ) -> Option<Result<InputScan, ScanError>> {
        let kw = tokens(text).next()?;
        let Some(kind) = laser_kind(kw) else {
            if kw == b"PARAM" {
                self.param(text);
                return None;
            }
            if is_raw_laser(kw) {
                if self.raw_lines == 0 {
                    self.first_raw_line = line;
                }
                self.raw_lines = self.raw_lines.saturating_add(1);
                return None;
            }
            if is_keyword(kw) {
                return None;
            }
            return Some(Err(ScanError {
                id: None,
                line,
                kind: ScanErrorKind::NotCarmen(show(kw)),
            }));
        };
        let id = format!("scan {}", self.scans);
        self.scans += 1;
        let name = String::from_utf8_lossy(kw);
        let res = match kind {
            LaserKind::Front => parse_old_laser(text, &name, false, self.front_max, opts),
            LaserKind::Rear => parse_old_laser(text, &name, true, self.rear_max, opts),
            LaserKind::Robot => parse_robot_laser(text, &name, opts),
        };
        Some(match res {
            Ok((data, pose)) => Ok(InputScan {
                id,
                line,
                data,
                truth: Some(pose),
                stamp: None,
            }),
            Err(kind) => Err(ScanError {
                id: Some(id),
                line,
                kind,
            }),
        })
    }

    fn param(&mut self, text: &[u8]) {
        let mut it = tokens(text).skip(1);
        let slot = match it.next() {
            Some(b"robot_front_laser_max") => &mut self.front_max,
            Some(b"robot_rear_laser_max") => &mut self.rear_max,
            _ => return,
        };
        if let Some(v) = parse_f64(it.next()) {
            if v.is_finite() && v > 0.0 && (v as f32).is_finite() {
                *slot = Some(v as f32);
            }
        }
    }
}

/// Parses a count field: a non-negative decimal integer (saturating at
/// `usize::MAX`), checked against `max` when `max` is given.
fn parse_count(
    t: Option<&[u8]>,
    name: &str,
    what: &str,
    max: Option<usize>,
) -> Result<usize, ScanErrorKind> {
    let t = t.ok_or_else(|| invalid(format!("{name} line ends before its {what}")))?;
    let digits = match t {
        [b'-', rest @ ..] if !rest.is_empty() && rest.iter().all(u8::is_ascii_digit) => {
            return Err(invalid(format!("{name} {what} {} is negative", show(t))));
        }
        [b'+', rest @ ..] => rest,
        _ => t,
    };
    if digits.is_empty() || !digits.iter().all(u8::is_ascii_digit) {
        return Err(invalid(format!(
            "{name} {what} {} is not a non-negative integer",
            show(t)
        )));
    }
    let n = digits.iter().try_fold(0usize, |n, &d| {
        n.checked_mul(10)?.checked_add(usize::from(d - b'0'))
    });
    let n = n.unwrap_or(usize::MAX);
    if let Some(max) = max {
        if n > max {
            let shown = String::from_utf8_lossy(&digits[..digits.len().min(40)]).into_owned();
            return Err(invalid(format!(
                "{name} has {shown} beams, more than max_beams = {max}"
            )));
        }
        if n == 0 {
            return Err(invalid(format!("{name} has 0 beams")));
        }
    }
    Ok(n)
}

fn parse_number<'a>(
    it: &mut impl Iterator<Item = &'a [u8]>,
    name: &str,
    what: &str,
) -> Result<f64, ScanErrorKind> {
    let t = it
        .next()
        .ok_or_else(|| invalid(format!("{name} line ends before its {what}")))?;
    match parse_f64(Some(t)) {
        Some(v) if v.is_finite() => Ok(v),
        _ => Err(invalid(format!(
            "{name} {what} {} is not a finite number",
            show(t)
        ))),
    }
}

/// Reads `n` range fields: `NaN` for values that are not finite, not
/// positive, or at least `max` (no return).
fn parse_ranges<'a>(
    it: &mut impl Iterator<Item = &'a [u8]>,
    n: usize,
    max: f32,
    name: &str,
) -> Result<Vec<f32>, ScanErrorKind> {
    let mut ranges = Vec::with_capacity(n);
    for i in 0..n {
        let t = it
            .next()
            .ok_or_else(|| invalid(format!("{name} line ends before range {i}")))?;
        let r = parse_f64(Some(t))
            .ok_or_else(|| invalid(format!("{name} range {i} ({}) is not a number", show(t))))?;
        let r32 = r as f32;
        ranges.push(if r32.is_finite() && r32 > 0.0 && r32 < max {
            r32
        } else {
            f32::NAN
        });
    }
    Ok(ranges)
}

fn parse_pose<'a>(
    it: &mut impl Iterator<Item = &'a [u8]>,
    name: &str,
    what: &str,
) -> Result<[f64; 3], ScanErrorKind> {
    Ok([
        parse_number(it, name, &format!("{what} x"))?,
        parse_number(it, name, &format!("{what} y"))?,
        parse_number(it, name, &format!("{what} theta"))?,
    ])
}

/// `FLASER`/`RLASER n r1..rn x y theta odom_x odom_y odom_theta
/// ipc_timestamp hostname logger_timestamp` (the last three may be missing
/// in old logs). The rear laser looks backwards: its first beam is at
/// `pi - fov / 2` (pi/2 for the default fov) in the frame of the pose on its
/// line.
fn parse_old_laser(
    text: &[u8],
    name: &str,
    rear: bool,
    param_max: Option<f32>,
    opts: &ReadOptions,
) -> Result<(ScanData, [f64; 3]), ScanErrorKind> {
    let total = tokens(text).count();
    let mut it = tokens(text).skip(1);
    let n = parse_count(it.next(), name, "beam count", Some(opts.max_beams))?;
    let after = total - 2;
    let (lo, hi) = (n.saturating_add(6), n.saturating_add(9));
    if after < lo || after > hi {
        return Err(invalid(format!(
            "{name} says n = {n} beams but {after} fields follow the count; expected {lo} to {hi} \
             (n ranges, laser pose, odometry pose, timestamps and host)"
        )));
    }
    let fov = match opts.fov {
        None => PI,
        Some(f) if f.is_finite() && f > 0.0 && f as f64 <= ANGLE_LIMIT => f as f64,
        Some(f) => {
            return Err(invalid(format!(
                "the field of view override ({f} rad) is not in (0, 2 pi]"
            )))
        }
    };
    let inc = carmen_angle_increment(n, fov);
    let angle_min = if rear { PI - fov / 2.0 } else { -fov / 2.0 };
    // The same checks as for the other records (a field of view override
    // just over a turn spreads the beams over more than one).
    let (angle_min, inc) = stored_angles(angle_min, inc, n, ["first bearing", "beam spacing"])?;
    let max = match param_max {
        Some(m) => m,
        None => range_max_from_opts(opts)?,
    };
    let ranges = parse_ranges(&mut it, n, max, name)?;
    let pose = parse_pose(&mut it, name, "laser pose")?;
    let data = ScanData::Ranges {
        angle_min,
        angle_increment: inc,
        range_min: 0.0,
        range_max: max,
        ranges,
    };
    Ok((data, pose))
}

/// `ROBOTLASERk laser_type start_angle field_of_view angular_resolution
/// maximum_range accuracy remission_mode num_readings r1..rn num_remissions
/// rem1..remk laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
/// forward_safety side_safety turn_axis timestamp host logger_timestamp`
/// (the fields after the robot pose may be missing).
fn parse_robot_laser(
    text: &[u8],
    name: &str,
    opts: &ReadOptions,
) -> Result<(ScanData, [f64; 3]), ScanErrorKind> {
    let total = tokens(text).count();
    let mut it = tokens(text).skip(1);
    let _laser_type = it
        .next()
        .ok_or_else(|| invalid(format!("{name} line ends before its laser_type")))?;
    let start = parse_number(&mut it, name, "start_angle")?;
    let _fov = parse_number(&mut it, name, "field_of_view")?;
    let inc = parse_number(&mut it, name, "angular_resolution")?;
    let max_range = parse_number(&mut it, name, "maximum_range")?;
    let _accuracy = parse_number(&mut it, name, "accuracy")?;
    let _remission_mode = it
        .next()
        .ok_or_else(|| invalid(format!("{name} line ends before its remission_mode")))?;
    let n = parse_count(it.next(), name, "num_readings", Some(opts.max_beams))?;
    let after = total - 9;
    if after <= n {
        return Err(invalid(format!(
            "{name} says num_readings = {n} but only {after} fields follow; expected at least {}",
            n.saturating_add(7)
        )));
    }
    let (start, inc) = stored_angles(
        start,
        inc,
        n,
        [
            &format!("{name} start_angle"),
            &format!("{name} angular_resolution"),
        ],
    )?;
    let max = if max_range > 0.0 && (max_range as f32).is_finite() {
        max_range as f32
    } else {
        range_max_from_opts(opts)?
    };
    let ranges = parse_ranges(&mut it, n, max, name)?;
    let k = parse_count(it.next(), name, "num_remissions", None)?;
    let rest = after - n - 1;
    if k > rest || rest - k < 6 || rest - k > 14 {
        return Err(invalid(format!(
            "{name} says num_remissions = {k} but {rest} fields follow it; expected {} to {} \
             (remissions, laser pose, robot pose, velocities, timestamps and host)",
            k.saturating_add(6),
            k.saturating_add(14)
        )));
    }
    for _ in 0..k {
        it.next();
    }
    let pose = parse_pose(&mut it, name, "laser pose")?;
    let data = ScanData::Ranges {
        angle_min: start,
        angle_increment: inc,
        range_min: 0.0,
        range_max: max,
        ranges,
    };
    Ok((data, pose))
}
