//! ROS 2 bags (rosbag2's MCAP storage) in: the `sensor_msgs/msg/LaserScan`
//! messages of one topic, as [`InputScan`]s with their header stamps.
//!
//! [`open_bag`] reads the file once to list its channels (and finds a cut-off
//! end there), picks the LaserScan topic, then [`Bag::scans`] reads it again,
//! streaming, and decodes each message with the bounded CDR decoder of
//! [`super::cdr`]. [`open_bag_bytes`] does the same for a bag in memory. Memory is bounded by [`MAX_RECORD_BYTES`] per record (a
//! chunk's declared sizes included), never by a count written in the file.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, Cursor, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use thiserror::Error;

use super::cdr::{decode_laser_scan, CdrError};
use super::{InputScan, ReadOptions, ScanData, ScanError, ScanErrorKind};

/// The MCAP magic: the first 8 bytes of every MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Longest record (or chunk, compressed or not) read from a bag: 64 MiB.
pub const MAX_RECORD_BYTES: usize = 64 << 20;

/// Most bytes handed to the MCAP reader at once.
const READ_STEP: usize = 1 << 20;

/// Schema names of `sensor_msgs/msg/LaserScan` (ROS 2, and the ROS 1 name
/// some converters write).
fn is_laser_scan(schema: &str) -> bool {
    schema == "sensor_msgs/msg/LaserScan" || schema == "sensor_msgs/LaserScan"
}

/// One channel of a bag.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BagTopic {
    /// Topic name.
    pub topic: String,
    /// Schema (message type) name, `""` if the channel has none.
    pub schema: String,
    /// Message encoding (`cdr` for rosbag2).
    pub encoding: String,
    /// Messages seen on it.
    pub messages: u64,
}

/// Why a bag cannot be read (as a whole; a bad message is a [`ScanError`]).
#[derive(Debug, Error)]
pub enum BagError {
    /// The file cannot be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The bag.
        path: PathBuf,
        /// The error.
        source: io::Error,
    },
    /// The file does not start with the MCAP magic.
    #[error("{path}: not an MCAP file (no MCAP magic at byte 0); ROS 2 bags must use rosbag2's mcap storage")]
    NotMcap {
        /// The bag.
        path: PathBuf,
    },
    /// The MCAP structure is broken before any LaserScan topic was found.
    #[error("{path}: {what} after byte {at}")]
    Mcap {
        /// The bag.
        path: PathBuf,
        /// Bytes read before the error.
        at: u64,
        /// The MCAP reader's message.
        what: String,
    },
    /// No channel carries LaserScan messages.
    #[error("{path}: no sensor_msgs/msg/LaserScan topic; topics present: {}", list(.topics))]
    NoScanTopic {
        /// The bag.
        path: PathBuf,
        /// What it has.
        topics: Vec<BagTopic>,
    },
    /// Several LaserScan topics and no `--topic`.
    #[error("{path}: several sensor_msgs/msg/LaserScan topics ({}); choose one with --topic", list(.topics))]
    SeveralScanTopics {
        /// The bag.
        path: PathBuf,
        /// The LaserScan topics.
        topics: Vec<BagTopic>,
    },
    /// `--topic` names no channel of the bag.
    #[error("{path}: no topic {topic}; topics present: {}", list(.topics))]
    NoSuchTopic {
        /// The bag.
        path: PathBuf,
        /// The topic asked for.
        topic: String,
        /// What it has.
        topics: Vec<BagTopic>,
    },
    /// `--topic` names a channel of another type or encoding.
    #[error("{path}: topic {} is {} ({}), not sensor_msgs/msg/LaserScan (cdr)", .found.topic, .found.schema, .found.encoding)]
    NotLaserScan {
        /// The bag.
        path: PathBuf,
        /// The channel.
        found: BagTopic,
    },
}

fn list(topics: &[BagTopic]) -> String {
    if topics.is_empty() {
        return "none".into();
    }
    topics
        .iter()
        .map(|t| {
            format!(
                "{} [{}, {} messages]",
                t.topic,
                if t.schema.is_empty() { "?" } else { &t.schema },
                t.messages
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Where a bag's bytes are: a file, read again for each pass, or memory.
enum BagData {
    File(PathBuf),
    Bytes(Arc<[u8]>),
}

impl std::fmt::Debug for BagData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BagData::File(p) => write!(f, "File({})", p.display()),
            BagData::Bytes(b) => write!(f, "Bytes({} bytes)", b.len()),
        }
    }
}

impl BagData {
    fn stream(&self) -> io::Result<RecordStream> {
        Ok(RecordStream::new(match self {
            BagData::File(path) => Box::new(File::open(path)?),
            BagData::Bytes(b) => Box::new(Cursor::new(Arc::clone(b))),
        }))
    }
}

/// An opened bag and its chosen LaserScan topic.
#[derive(Debug)]
pub struct Bag {
    data: BagData,
    /// Every channel, by topic name.
    pub topics: Vec<BagTopic>,
    /// The topic whose scans [`Bag::scans`] yields.
    pub topic: String,
    /// Set when the first pass met a broken or cut-off file: the scans
    /// before it are read, then this error ends the stream.
    pub damage: Option<String>,
}

/// True if the file at `path` starts with the MCAP magic.
pub fn is_mcap(path: &Path) -> bool {
    starts_with(path, MAGIC)
}

/// The magic of an SQLite database file: rosbag2's sqlite3 storage (`.db3`).
pub const SQLITE_MAGIC: &[u8; 16] = b"SQLite format 3\0";

/// True if the file at `path` is an SQLite database (a rosbag2 sqlite3
/// bag, which this reader does not read: see docs/robot.md).
pub fn is_sqlite(path: &Path) -> bool {
    starts_with(path, SQLITE_MAGIC)
}

fn starts_with<const N: usize>(path: &Path, magic: &[u8; N]) -> bool {
    let mut head = [0u8; N];
    File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && &head == magic
}

/// Opens a bag, lists its channels and picks the LaserScan topic: `topic`
/// if given, else the only LaserScan channel.
pub fn open_bag(path: &Path, topic: Option<&str>) -> Result<Bag, BagError> {
    if !is_mcap(path) {
        // Say why: a missing or unreadable file, or another format.
        File::open(path).map_err(|source| BagError::Io {
            path: path.to_owned(),
            source,
        })?;
        return Err(BagError::NotMcap {
            path: path.to_owned(),
        });
    }
    choose_topic(BagData::File(path.to_owned()), path, topic)
}

/// As [`open_bag`], for a bag held in memory; `name` stands for its path
/// in errors. [`Bag::scans`] then reads the same bytes.
pub fn open_bag_bytes(
    bytes: impl Into<Arc<[u8]>>,
    name: &Path,
    topic: Option<&str>,
) -> Result<Bag, BagError> {
    let bytes = bytes.into();
    if !bytes.starts_with(MAGIC) {
        return Err(BagError::NotMcap {
            path: name.to_owned(),
        });
    }
    choose_topic(BagData::Bytes(bytes), name, topic)
}

/// The first pass of [`open_bag`] and [`open_bag_bytes`]: lists the
/// channels of the bag in `data` and picks the topic.
fn choose_topic(data: BagData, path: &Path, topic: Option<&str>) -> Result<Bag, BagError> {
    let io_err = |source| BagError::Io {
        path: path.to_owned(),
        source,
    };
    let mut channels: BTreeMap<u16, (String, u16, String)> = BTreeMap::new();
    let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
    let mut counts: BTreeMap<u16, u64> = BTreeMap::new();
    let mut stream = data.stream().map_err(io_err)?;
    let mut damage = None;
    loop {
        let step = stream.next(|rec| match rec {
            Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                channels.insert(c.id, (c.topic, c.schema_id, c.message_encoding));
            }
            Record::Message { header, .. } => {
                *counts.entry(header.channel_id).or_default() += 1;
            }
            _ => {}
        });
        match step {
            Ok(true) => {}
            Ok(false) => break,
            Err(StreamError::Io(e)) => return Err(io_err(e)),
            Err(StreamError::Mcap(what)) => {
                damage = Some(format!("{what} after byte {}", stream.bytes));
                break;
            }
        }
    }
    // Nothing readable before the damage (a chunk compression this reader
    // does not know, say): the damage is the answer, with or without --topic.
    if let (Some(what), true) = (&damage, channels.is_empty()) {
        return Err(BagError::Mcap {
            path: path.to_owned(),
            at: stream.bytes,
            what: what.clone(),
        });
    }
    let mut topics: Vec<BagTopic> = channels
        .iter()
        .map(|(id, (t, schema_id, enc))| BagTopic {
            topic: t.clone(),
            schema: schemas.get(schema_id).cloned().unwrap_or_default(),
            encoding: enc.clone(),
            messages: counts.get(id).copied().unwrap_or(0),
        })
        .collect();
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    topics.dedup_by(|a, b| a.topic == b.topic && a.schema == b.schema);
    let scan_topics: Vec<BagTopic> = topics
        .iter()
        .filter(|t| is_laser_scan(&t.schema) && t.encoding == "cdr")
        .cloned()
        .collect();
    let chosen = match topic {
        Some(want) => match topics.iter().find(|t| t.topic == want) {
            None => {
                return Err(BagError::NoSuchTopic {
                    path: path.to_owned(),
                    topic: want.to_owned(),
                    topics,
                })
            }
            Some(t) if !(is_laser_scan(&t.schema) && t.encoding == "cdr") => {
                return Err(BagError::NotLaserScan {
                    path: path.to_owned(),
                    found: t.clone(),
                })
            }
            Some(t) => t.topic.clone(),
        },
        None => match scan_topics.as_slice() {
            [] => {
                return Err(BagError::NoScanTopic {
                    path: path.to_owned(),
                    topics,
                });
            }
            [one] => one.topic.clone(),
            _ => {
                return Err(BagError::SeveralScanTopics {
                    path: path.to_owned(),
                    topics: scan_topics,
                })
            }
        },
    };
    Ok(Bag {
        data,
        topics,
        topic: chosen,
        damage,
    })
}

impl Bag {
    /// The scans of the chosen topic in file order, each named `"msg K"`
    /// (0-based index on the topic) with its header stamp; `line` is `K + 1`.
    /// A message that does not decode is an `Err` item and reading goes on; a
    /// broken or cut-off file ends the stream with one `Err` item.
    pub fn scans(
        &self,
        opts: &ReadOptions,
    ) -> io::Result<impl Iterator<Item = Result<InputScan, ScanError>>> {
        Ok(BagScans {
            stream: self.data.stream()?,
            topic: self.topic.clone(),
            ids: Vec::new(),
            schemas: BTreeMap::new(),
            opts: *opts,
            k: 0,
            done: false,
        })
    }
}

struct BagScans {
    stream: RecordStream,
    topic: String,
    /// Channel ids of the chosen topic that carry LaserScans (CDR).
    ids: Vec<u16>,
    /// Schema ids seen so far, and whether each is a LaserScan.
    schemas: BTreeMap<u16, bool>,
    opts: ReadOptions,
    /// Messages of the topic seen so far.
    k: usize,
    done: bool,
}

impl Iterator for BagScans {
    type Item = Result<InputScan, ScanError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let mut out = None;
            let (ids, schemas, topic, k, opts) = (
                &mut self.ids,
                &mut self.schemas,
                &self.topic,
                &mut self.k,
                &self.opts,
            );
            let step = self.stream.next(|rec| match rec {
                Record::Schema { header, .. } => {
                    schemas.insert(header.id, is_laser_scan(&header.name));
                }
                // Only the topic's LaserScan channels: a bag may hold another
                // channel of the same name with another type (found by the
                // `bag` fuzz target), whose messages are not LaserScans.
                Record::Channel(c)
                    if &c.topic == topic
                        && c.message_encoding == "cdr"
                        && schemas.get(&c.schema_id) == Some(&true) =>
                {
                    ids.push(c.id)
                }
                Record::Message { header, data } if ids.contains(&header.channel_id) => {
                    out = Some(to_scan(&data, *k, header.log_time, opts));
                    *k += 1;
                }
                _ => {}
            });
            match step {
                Ok(true) => {}
                Ok(false) => self.done = true,
                Err(e) => {
                    self.done = true;
                    let what = match e {
                        StreamError::Io(e) => e.to_string(),
                        StreamError::Mcap(m) => m,
                    };
                    return Some(Err(ScanError {
                        id: None,
                        line: self.k + 1,
                        kind: ScanErrorKind::BagDamaged {
                            byte: self.stream.bytes,
                            what,
                            read: self.k,
                            topic: self.topic.clone(),
                        },
                    }));
                }
            }
            if out.is_some() {
                return out;
            }
        }
        None
    }
}

fn to_scan(
    data: &[u8],
    k: usize,
    log_time: u64,
    opts: &ReadOptions,
) -> Result<InputScan, ScanError> {
    let id = format!("msg {k}");
    let err = |message: String| ScanError {
        id: Some(id.clone()),
        line: k + 1,
        kind: ScanErrorKind::Invalid(message),
    };
    let m = decode_laser_scan(data, opts.max_beams)
        .map_err(|e: CdrError| err(format!("LaserScan CDR: {e}")))?;
    if m.ranges.is_empty() {
        return Err(err("ranges is empty".into()));
    }
    if !(m.angle_increment.is_finite() && m.angle_increment != 0.0 && m.angle_min.is_finite()) {
        return Err(err(format!(
            "angle_min {} and angle_increment {} must be finite, angle_increment non-zero",
            m.angle_min, m.angle_increment
        )));
    }
    let range_max = if m.range_max.is_finite() && m.range_max > 0.0 {
        m.range_max
    } else {
        opts.range_max
    };
    let range_min = if m.range_min.is_finite() && m.range_min >= 0.0 {
        m.range_min
    } else {
        0.0
    };
    let stamp = Stamp {
        ns: m.stamp_ns(),
        log_time_ns: log_time,
        frame_id: m.frame_id,
    };
    Ok(InputScan {
        id: id.clone(),
        line: k + 1,
        data: ScanData::Ranges {
            angle_min: m.angle_min,
            angle_increment: m.angle_increment,
            range_min,
            range_max,
            ranges: m.ranges,
        },
        truth: None,
        stamp: Some(stamp),
    })
}

/// Where and when a scan was taken, for scans read from a bag.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stamp {
    /// `header.stamp` in nanoseconds since the epoch.
    pub ns: i64,
    /// The bag's log time of the message (ns).
    pub log_time_ns: u64,
    /// `header.frame_id`.
    pub frame_id: String,
}

enum StreamError {
    Io(io::Error),
    Mcap(String),
}

/// MCAP records from a file (or bytes), streaming, bounded by
/// [`MAX_RECORD_BYTES`].
struct RecordStream {
    file: Box<dyn Read + Send>,
    reader: LinearReader,
    /// Bytes read from the file so far.
    bytes: u64,
    /// The MCAP reader failed inside (see [`RecordStream::next`]).
    broken: bool,
}

const BROKEN: &str = "malformed MCAP records (the mcap reader gave up on them)";

impl RecordStream {
    fn new(file: Box<dyn Read + Send>) -> RecordStream {
        RecordStream {
            file,
            reader: LinearReader::new_with_options(
                LinearReaderOptions::default()
                    .with_record_length_limit(MAX_RECORD_BYTES)
                    .with_validate_chunk_crcs(true),
            ),
            bytes: 0,
            broken: false,
        }
    }

    /// Hands the next record to `f`: `Ok(true)` after a record, `Ok(false)`
    /// at the end of the file.
    ///
    /// The mcap crate's reader can panic on crafted records (an arithmetic
    /// overflow on a chunk's sizes in debug builds, found by
    /// `flipped_bytes_never_panic`): that is caught here and becomes an
    /// error, and the reader is not used again.
    fn next(&mut self, f: impl FnOnce(Record<'_>)) -> Result<bool, StreamError> {
        if self.broken {
            return Err(StreamError::Mcap(BROKEN.into()));
        }
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.step(f))) {
            Ok(r) => r,
            Err(_) => {
                self.broken = true;
                Err(StreamError::Mcap(BROKEN.into()))
            }
        }
    }

    fn step(&mut self, f: impl FnOnce(Record<'_>)) -> Result<bool, StreamError> {
        loop {
            match self.reader.next_event() {
                None => return Ok(false),
                Some(Err(e)) => return Err(StreamError::Mcap(mcap_message(&e))),
                Some(Ok(LinearReadEvent::ReadRequest(need))) => {
                    let buf = self.reader.insert(need.clamp(1, READ_STEP));
                    let n = loop {
                        match self.file.read(buf) {
                            Ok(n) => break n,
                            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                            Err(e) => return Err(StreamError::Io(e)),
                        }
                    };
                    self.bytes += n as u64;
                    self.reader.notify_read(n);
                }
                Some(Ok(LinearReadEvent::Record { opcode, data })) => {
                    check_string_lengths(opcode, data).map_err(StreamError::Mcap)?;
                    let rec = mcap::parse_record(opcode, data)
                        .map_err(|e| StreamError::Mcap(mcap_message(&e)))?;
                    f(rec);
                    return Ok(true);
                }
            }
        }
    }
}

/// A field of an MCAP record, for [`check_string_lengths`].
#[derive(Clone, Copy)]
enum Field {
    /// `n` bytes of fixed-size fields.
    Fixed(usize),
    /// A `string`: u32 length, then that many bytes.
    Str,
    /// A `map<string, string>`: u32 length in bytes, then key and value
    /// strings.
    StrMap,
    /// A u32 length in bytes, then entries of fixed size (an array or a
    /// map of integers).
    Sized,
}

/// The fields of each record kind (MCAP spec) up to its last string; a
/// record without strings (message, footer, ...) has none.
fn string_fields(opcode: u8) -> (&'static str, &'static [Field]) {
    use Field::*;
    match opcode {
        0x01 => ("header", &[Str, Str]),
        0x03 => ("schema", &[Fixed(2), Str, Str]),
        0x04 => ("channel", &[Fixed(4), Str, Str, StrMap]),
        0x06 => ("chunk", &[Fixed(28), Str]),
        0x08 => ("chunk index", &[Fixed(32), Sized, Fixed(8), Str]),
        0x09 => ("attachment", &[Fixed(16), Str, Str]),
        0x0a => ("attachment index", &[Fixed(40), Str, Str]),
        0x0c => ("metadata", &[Str, StrMap]),
        0x0d => ("metadata index", &[Fixed(16), Str]),
        _ => ("", &[]),
    }
}

/// Refuses a record with a string longer than the bytes left in it. The
/// mcap crate reserves a string's declared length before it reads the
/// string (up to 4 GiB for a record of a few bytes: found by the `bag`
/// fuzz target); other length errors it reports itself, without allocating.
fn check_string_lengths(opcode: u8, data: &[u8]) -> Result<(), String> {
    let (name, fields) = string_fields(opcode);
    let len_at = |at: usize| -> Option<usize> {
        let b = data.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    // A string at `at`: the offset after it; `None` when its length does
    // not fit (the mcap crate reports that).
    let string = |at: usize| -> Result<Option<usize>, String> {
        let Some(len) = len_at(at) else {
            return Ok(None);
        };
        let left = data.len() - (at + 4);
        if len > left {
            return Err(format!(
                "{name} record: a string at byte {at} claims {len} bytes, {left} are left in the record"
            ));
        }
        Ok(Some(at + 4 + len))
    };
    let mut at = 0usize;
    for &f in fields {
        let next = match f {
            Field::Fixed(n) => Some(at + n).filter(|&e| e <= data.len()),
            Field::Str => string(at)?,
            Field::Sized => len_at(at)
                .map(|len| at + 4 + len)
                .filter(|&e| e <= data.len()),
            Field::StrMap => {
                let Some(bytes) = len_at(at) else {
                    return Ok(());
                };
                // As the mcap crate reads it: entries until the map's
                // length is used up, each string within the record.
                let start = at + 4;
                let mut p = Some(start);
                while let Some(q) = p.filter(|&q| q - start < bytes) {
                    p = match string(q)? {
                        Some(r) => string(r)?,
                        None => None,
                    };
                }
                p
            }
        };
        match next {
            Some(n) => at = n,
            None => return Ok(()),
        }
    }
    Ok(())
}

fn mcap_message(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::UnexpectedEof => {
            "the file ends inside a record (a cut-off bag: recording interrupted or copy incomplete)"
                .into()
        }
        mcap::McapError::UnsupportedCompression(c) => format!(
            "chunk compression {c:?} is not supported (only zstd, lz4 and none); re-compress with `mcap compress --compression zstd`"
        ),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::borrow::Cow;

    /// A bag written with the mcap crate's writer: `n` LaserScans on /scan.
    fn bag_bytes(n: usize, compression: Option<mcap::Compression>) -> Vec<u8> {
        let mut out = io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new()
            .compression(compression)
            .chunk_size(Some(512))
            .create(&mut out)
            .unwrap();
        let s = w
            .add_schema("sensor_msgs/msg/LaserScan", "ros2msg", b"")
            .unwrap();
        let c = w.add_channel(s, "/scan", "cdr", &BTreeMap::new()).unwrap();
        for k in 0..n {
            let mut m = super::super::cdr::Writer::new();
            m.header(k as i64 * 1000, "laser");
            for v in [-1.0, 1.0, 0.5, 0.0, 0.1, 0.0, 10.0] {
                m.f32(v);
            }
            m.f32_seq(&[1.0, 2.0, 3.0, 4.0, 5.0]).f32_seq(&[]);
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: c,
                    sequence: k as u32,
                    log_time: k as u64,
                    publish_time: k as u64,
                },
                &Cow::<[u8]>::Owned(m.into_bytes()),
            )
            .unwrap();
        }
        w.finish().unwrap();
        drop(w);
        out.into_inner()
    }

    /// Every item of the bag `bytes` read from a file; reading the same
    /// bytes from memory must give the same items and errors.
    fn read_all(bytes: &[u8]) -> Result<Vec<Result<InputScan, ScanError>>, BagError> {
        let f = tempfile::NamedTempFile::new().unwrap();
        std::fs::write(f.path(), bytes).unwrap();
        let read = |bag: Result<Bag, BagError>| -> Result<Vec<_>, BagError> {
            Ok(bag?.scans(&ReadOptions::default()).unwrap().collect())
        };
        let from_file = read(open_bag(f.path(), None));
        let from_bytes = read(open_bag_bytes(bytes, f.path(), None));
        assert_eq!(format!("{from_file:?}"), format!("{from_bytes:?}"));
        from_file
    }

    #[test]
    fn reads_plain_zstd_and_lz4_bags() {
        for c in [
            None,
            Some(mcap::Compression::Zstd),
            Some(mcap::Compression::Lz4),
        ] {
            let got = read_all(&bag_bytes(20, c)).unwrap();
            assert_eq!(got.len(), 20);
            let s = got[7].as_ref().unwrap();
            assert_eq!(s.id, "msg 7");
            assert_eq!(s.stamp.as_ref().unwrap().ns, 7000);
            assert_eq!(s.data.len(), 5);
        }
    }

    /// Another channel named /scan with another type (found by the `bag`
    /// fuzz target): its messages are not read as LaserScans.
    #[test]
    fn only_the_laser_scan_channels_of_the_topic_are_read() {
        let mut out = io::Cursor::new(Vec::new());
        let mut w = mcap::WriteOptions::new()
            .compression(None)
            .create(&mut out)
            .unwrap();
        let laser = w
            .add_schema("sensor_msgs/msg/LaserScan", "ros2msg", b"")
            .unwrap();
        let text = w.add_schema("std_msgs/msg/String", "ros2msg", b"").unwrap();
        let scan = w
            .add_channel(laser, "/scan", "cdr", &BTreeMap::new())
            .unwrap();
        let other = w
            .add_channel(text, "/scan", "cdr", &BTreeMap::new())
            .unwrap();
        let mut m = super::super::cdr::Writer::new();
        m.header(5, "laser");
        for v in [-1.0, 1.0, 0.5, 0.0, 0.1, 0.0, 10.0] {
            m.f32(v);
        }
        m.f32_seq(&[1.0, 2.0, 3.0]).f32_seq(&[]);
        let scan_msg = m.into_bytes();
        let text_msg = b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00".to_vec();
        for (k, (channel_id, data)) in [(other, &text_msg), (scan, &scan_msg), (other, &text_msg)]
            .into_iter()
            .enumerate()
        {
            let header = mcap::records::MessageHeader {
                channel_id,
                sequence: k as u32,
                log_time: k as u64,
                publish_time: k as u64,
            };
            w.write_to_known_channel(&header, data).unwrap();
        }
        w.finish().unwrap();
        drop(w);
        let got = read_all(&out.into_inner()).unwrap();
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(got[0].as_ref().unwrap().data.len(), 3);
    }

    #[test]
    fn an_unknown_chunk_compression_is_named_in_the_error() {
        // The chunk records' compression string, renamed (same length).
        let name = b"\x04\x00\x00\x00zstd";
        let mut b = bag_bytes(5, Some(mcap::Compression::Zstd));
        let at: Vec<usize> = (0..b.len() - name.len())
            .filter(|&i| b[i..].starts_with(name))
            .collect();
        assert!(!at.is_empty());
        for i in at {
            b[i + 4..i + 8].copy_from_slice(b"brot");
        }
        let msg = match read_all(&b) {
            Err(e) => e.to_string(),
            Ok(items) => match items.into_iter().find_map(Result::err) {
                Some(e) => e.message(),
                None => panic!("an unknown compression read without error"),
            },
        };
        assert!(
            msg.contains("\"brot\"") && msg.contains("not supported"),
            "{msg}"
        );
        // Asked for a topic, the answer is the same (not "no topic /scan").
        let f = tempfile::NamedTempFile::new().unwrap();
        std::fs::write(f.path(), &b).unwrap();
        let e = open_bag(f.path(), Some("/scan")).err().unwrap().to_string();
        assert!(e.contains("\"brot\"") && e.contains("not supported"), "{e}");
    }

    #[test]
    fn every_cut_is_an_error_not_a_panic() {
        let full = bag_bytes(20, Some(mcap::Compression::Zstd));
        for len in (0..full.len()).step_by(7) {
            match read_all(&full[..len]) {
                Err(_) => {}
                Ok(items) => {
                    // The scans before the cut, then one error.
                    let last = items.last().expect("a cut bag ends with an error");
                    assert!(last.is_err(), "cut at {len}");
                    assert!(items[..items.len() - 1].iter().all(|i| i.is_ok()));
                }
            }
        }
    }

    /// The `bag` fuzz target's first finding (`tests/fuzz/bag/`): a header
    /// record whose profile string claims 4,294,639,620 bytes made the mcap
    /// crate reserve 4 GiB for a 256-byte file.
    #[test]
    fn a_string_longer_than_its_record_is_an_error_not_an_allocation() {
        let mut b = MAGIC.to_vec();
        b.push(0x01);
        b.extend_from_slice(&12u64.to_le_bytes());
        b.extend_from_slice(&0xfffb_0004u32.to_le_bytes());
        b.extend_from_slice(b"ros2\0\0\0\0");
        b.extend_from_slice(MAGIC);
        match read_all(&b) {
            Err(BagError::Mcap { what, .. }) => assert!(
                what.starts_with(
                    "header record: a string at byte 0 claims 4294639620 bytes, 8 are left in the record"
                ),
                "{what}"
            ),
            other => panic!("{other:?}"),
        }
        // Every string field of every record kind is checked, in maps too.
        assert!(check_string_lengths(0x04, &[0, 0, 0, 0, 2, 0, 0, 0, b'/', b's']).is_ok());
        // A channel whose metadata key overruns the record, a chunk index
        // whose compression name does.
        let cases: [(u8, Vec<u8>, &str); 2] = [
            (
                0x04,
                [&[0u8; 12][..], &[8, 0, 0, 0, 9, 0, 0, 0], b"abcd"].concat(),
                "channel record: a string at byte 16 claims 9 bytes, 4",
            ),
            (
                0x08,
                [
                    &[0u8; 32][..],
                    &[2, 0, 0, 0],
                    &[0; 10],
                    &[5, 0, 0, 0],
                    b"zstd",
                ]
                .concat(),
                "chunk index record: a string at byte 46",
            ),
        ];
        for (opcode, record, says) in cases {
            let e = check_string_lengths(opcode, &record).unwrap_err();
            assert!(e.starts_with(says), "{e}");
        }
        // A valid bag passes unchanged (reads_plain_and_zstd_bags), and a
        // record too short for its fixed fields is left to the mcap crate.
        assert!(check_string_lengths(0x08, &[0; 10]).is_ok());
    }

    #[test]
    fn flipped_bytes_never_panic() {
        let full = bag_bytes(10, None);
        for i in (8..full.len()).step_by(3) {
            let mut b = full.clone();
            b[i] ^= 0xff;
            let _ = read_all(&b);
        }
    }
}
