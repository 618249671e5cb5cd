//! A small, bounded CDR (OMG XCDR1, as ROS 2 serializes messages) decoder for
//! `sensor_msgs/msg/LaserScan`, and an encoder for the messages `mapc
//! localize --mcap` writes.
//!
//! The decoder reads untrusted bytes: it never panics, checks every length
//! against the bytes that are actually left before it allocates, bounds the
//! sequences by a caller's maximum, and says which field was cut or wrong and
//! at which byte.

use thiserror::Error;

/// A decoded `sensor_msgs/msg/LaserScan`.
#[derive(Clone, Debug, PartialEq)]
pub struct LaserScanMsg {
    /// `header.stamp.sec`.
    pub stamp_sec: i32,
    /// `header.stamp.nanosec`.
    pub stamp_nanosec: u32,
    /// `header.frame_id`.
    pub frame_id: String,
    /// Bearing of the first beam (rad).
    pub angle_min: f32,
    /// Bearing of the last beam (rad).
    pub angle_max: f32,
    /// Bearing step (rad).
    pub angle_increment: f32,
    /// Time between beams (s).
    pub time_increment: f32,
    /// Time between scans (s).
    pub scan_time: f32,
    /// Minimum valid range (m).
    pub range_min: f32,
    /// Maximum range (m).
    pub range_max: f32,
    /// One range per beam (m).
    pub ranges: Vec<f32>,
    /// One intensity per beam, or none.
    pub intensities: Vec<f32>,
}

impl LaserScanMsg {
    /// The header stamp in nanoseconds since the epoch (negative seconds
    /// give a negative value).
    pub fn stamp_ns(&self) -> i64 {
        self.stamp_sec as i64 * 1_000_000_000 + self.stamp_nanosec as i64
    }
}

/// Why a CDR message could not be decoded. Byte offsets count from the start
/// of the message, encapsulation header included.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum CdrError {
    /// Fewer than the 4 bytes of the encapsulation header.
    #[error("{len} bytes: too short for the 4-byte CDR encapsulation header")]
    NoHeader {
        /// Message length.
        len: usize,
    },
    /// The encapsulation is not plain CDR.
    #[error("encapsulation kind {kind:#06x} is not plain CDR (0x0000 big-endian or 0x0001 little-endian)")]
    Encapsulation {
        /// The kind found.
        kind: u16,
    },
    /// The message ends inside a field.
    #[error("truncated at byte {at} in {field}: needs {need} bytes, {have} left")]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Where it starts.
        at: usize,
        /// Bytes it needs.
        need: usize,
        /// Bytes left in the message.
        have: usize,
    },
    /// A sequence longer than allowed.
    #[error("{field} has {count} elements, more than the {max} allowed")]
    TooMany {
        /// The sequence.
        field: &'static str,
        /// The count written in the message.
        count: u32,
        /// The most allowed.
        max: usize,
    },
    /// A string that is not NUL-terminated UTF-8.
    #[error("{field} at byte {at} is not a NUL-terminated UTF-8 string")]
    BadString {
        /// The field.
        field: &'static str,
        /// Where its length starts.
        at: usize,
    },
}

/// Decodes a CDR-serialized `sensor_msgs/msg/LaserScan`; `ranges` and
/// `intensities` may have at most `max_beams` elements each. Bytes after the
/// message (padding) are ignored.
pub fn decode_laser_scan(data: &[u8], max_beams: usize) -> Result<LaserScanMsg, CdrError> {
    let mut r = Reader::new(data)?;
    let stamp_sec = r.u32("header.stamp.sec")? as i32;
    let stamp_nanosec = r.u32("header.stamp.nanosec")?;
    let frame_id = r.string("header.frame_id")?;
    let angle_min = r.f32("angle_min")?;
    let angle_max = r.f32("angle_max")?;
    let angle_increment = r.f32("angle_increment")?;
    let time_increment = r.f32("time_increment")?;
    let scan_time = r.f32("scan_time")?;
    let range_min = r.f32("range_min")?;
    let range_max = r.f32("range_max")?;
    let ranges = r.f32_seq("ranges", max_beams)?;
    let intensities = r.f32_seq("intensities", max_beams)?;
    Ok(LaserScanMsg {
        stamp_sec,
        stamp_nanosec,
        frame_id,
        angle_min,
        angle_max,
        angle_increment,
        time_increment,
        scan_time,
        range_min,
        range_max,
        ranges,
        intensities,
    })
}

/// Reads CDR primitives; alignment is relative to the end of the 4-byte
/// encapsulation header.
struct Reader<'a> {
    data: &'a [u8],
    /// Position in `data` (header included).
    pos: usize,
    little: bool,
}

impl<'a> Reader<'a> {
    fn new(data: &'a [u8]) -> Result<Reader<'a>, CdrError> {
        if data.len() < 4 {
            return Err(CdrError::NoHeader { len: data.len() });
        }
        let kind = u16::from_be_bytes([data[0], data[1]]);
        let little = match kind {
            0x0000 => false,
            0x0001 => true,
            _ => return Err(CdrError::Encapsulation { kind }),
        };
        Ok(Reader {
            data,
            pos: 4,
            little,
        })
    }

    /// Takes `n` bytes after aligning to `align`.
    fn take(&mut self, field: &'static str, align: usize, n: usize) -> Result<&'a [u8], CdrError> {
        let body = self.pos - 4;
        let pad = (align - body % align) % align;
        let have = self.data.len() - self.pos;
        if pad.checked_add(n).is_none_or(|need| need > have) {
            return Err(CdrError::Truncated {
                field,
                at: self.pos,
                need: pad.saturating_add(n),
                have,
            });
        }
        let start = self.pos + pad;
        self.pos = start + n;
        Ok(&self.data[start..start + n])
    }

    fn u32(&mut self, field: &'static str) -> Result<u32, CdrError> {
        let b = self.take(field, 4, 4)?;
        let b = [b[0], b[1], b[2], b[3]];
        Ok(if self.little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }

    fn f32(&mut self, field: &'static str) -> Result<f32, CdrError> {
        self.u32(field).map(f32::from_bits)
    }

    fn string(&mut self, field: &'static str) -> Result<String, CdrError> {
        let at = self.pos;
        let len = self.u32(field)? as usize;
        // The length counts the terminating NUL; checked against the bytes
        // left before anything is copied.
        let b = self.take(field, 1, len)?;
        match b.split_last() {
            Some((0, text)) => std::str::from_utf8(text)
                .map(str::to_owned)
                .map_err(|_| CdrError::BadString { field, at }),
            _ => Err(CdrError::BadString { field, at }),
        }
    }

    fn f32_seq(&mut self, field: &'static str, max: usize) -> Result<Vec<f32>, CdrError> {
        let count = self.u32(field)?;
        if count as usize > max {
            return Err(CdrError::TooMany { field, count, max });
        }
        let b = self.take(field, 4, count as usize * 4)?;
        Ok(b.chunks_exact(4)
            .map(|c| {
                let c = [c[0], c[1], c[2], c[3]];
                f32::from_bits(if self.little {
                    u32::from_le_bytes(c)
                } else {
                    u32::from_be_bytes(c)
                })
            })
            .collect())
    }
}

/// Writes little-endian CDR (encapsulation `00 01 00 00`).
#[derive(Debug)]
pub struct Writer {
    buf: Vec<u8>,
}

impl Default for Writer {
    fn default() -> Self {
        Writer::new()
    }
}

impl Writer {
    /// An empty message (the encapsulation header only).
    pub fn new() -> Writer {
        Writer {
            buf: vec![0, 1, 0, 0],
        }
    }

    fn align(&mut self, n: usize) {
        while (self.buf.len() - 4) % n != 0 {
            self.buf.push(0);
        }
    }

    /// A `uint8` / `int8`.
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.u32(v as u32)
    }

    /// A `float32`.
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.u32(v.to_bits())
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `string` (length with the NUL, then the bytes and a NUL).
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        self
    }

    /// A `float32[]`.
    pub fn f32_seq(&mut self, v: &[f32]) -> &mut Self {
        self.u32(v.len() as u32);
        for &x in v {
            self.f32(x);
        }
        self
    }

    /// A `std_msgs/Header`: stamp (sec, nanosec) and frame id.
    pub fn header(&mut self, stamp_ns: i64, frame_id: &str) -> &mut Self {
        self.i32(stamp_ns.div_euclid(1_000_000_000) as i32)
            .u32(stamp_ns.rem_euclid(1_000_000_000) as u32)
            .string(frame_id)
    }

    /// A `geometry_msgs/Pose` in the plane: (x, y, 0) and a rotation of
    /// `theta` about z.
    pub fn pose2(&mut self, x: f64, y: f64, theta: f64) -> &mut Self {
        let (s, c) = (theta / 2.0).sin_cos();
        self.f64(x).f64(y).f64(0.0);
        self.f64(0.0).f64(0.0).f64(s).f64(c)
    }

    /// The message bytes.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan_bytes(ranges: &[f32]) -> Vec<u8> {
        let mut w = Writer::new();
        w.header(1_733_270_400_250_000_000, "laser")
            .f32(-1.5)
            .f32(1.5)
            .f32(0.01)
            .f32(0.0)
            .f32(0.1)
            .f32(0.05)
            .f32(30.0)
            .f32_seq(ranges)
            .f32_seq(&[7.0; 3]);
        w.into_bytes()
    }

    #[test]
    fn decodes_what_the_writer_wrote() {
        let m = decode_laser_scan(&scan_bytes(&[1.0, 2.5, f32::INFINITY]), 10).unwrap();
        assert_eq!((m.stamp_sec, m.stamp_nanosec), (1_733_270_400, 250_000_000));
        assert_eq!(m.stamp_ns(), 1_733_270_400_250_000_000);
        assert_eq!(m.frame_id, "laser");
        assert_eq!(
            (m.angle_min, m.angle_max, m.angle_increment),
            (-1.5, 1.5, 0.01)
        );
        assert_eq!((m.scan_time, m.range_min, m.range_max), (0.1, 0.05, 30.0));
        assert_eq!(m.ranges, vec![1.0, 2.5, f32::INFINITY]);
        assert_eq!(m.intensities, vec![7.0; 3]);
    }

    #[test]
    fn every_cut_is_a_typed_error() {
        let b = scan_bytes(&[1.0; 5]);
        for len in 0..b.len() {
            let e = decode_laser_scan(&b[..len], 10).unwrap_err();
            if len < 4 {
                assert_eq!(e, CdrError::NoHeader { len });
            } else {
                assert!(matches!(e, CdrError::Truncated { .. }), "cut at {len}: {e}");
            }
        }
    }

    #[test]
    fn a_huge_count_is_refused_before_allocation() {
        let mut b = scan_bytes(&[]);
        // The ranges count sits after header (8 + 4 + 6 -> padded to 20) and
        // seven floats (28): body offset 48, i.e. byte 52.
        b[52..56].copy_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(
            decode_laser_scan(&b, 100_000).unwrap_err(),
            CdrError::TooMany {
                field: "ranges",
                count: u32::MAX,
                max: 100_000
            }
        );
        b[52..56].copy_from_slice(&1000u32.to_le_bytes());
        assert!(matches!(
            decode_laser_scan(&b, 100_000).unwrap_err(),
            CdrError::Truncated {
                field: "ranges",
                need: 4000,
                ..
            }
        ));
    }

    #[test]
    fn bad_encapsulation_and_strings() {
        assert_eq!(
            decode_laser_scan(&[0, 3, 0, 0, 0, 0, 0, 0], 10).unwrap_err(),
            CdrError::Encapsulation { kind: 3 }
        );
        let mut b = scan_bytes(&[1.0]);
        // frame_id "laser\0" at body offset 12: drop its NUL.
        b[16 + 5] = b'x';
        assert!(matches!(
            decode_laser_scan(&b, 10).unwrap_err(),
            CdrError::BadString {
                field: "header.frame_id",
                ..
            }
        ));
    }

    #[test]
    fn big_endian_is_read_too() {
        let mut b = vec![0, 0, 0, 0];
        for v in [5u32, 6, 1] {
            b.extend_from_slice(&v.to_be_bytes());
        }
        b.extend_from_slice(&[0, 0, 0, 0]);
        for f in [0.0f32, 1.0, 0.5, 0.0, 0.0, 0.0, 10.0] {
            b.extend_from_slice(&f.to_be_bytes());
        }
        b.extend_from_slice(&1u32.to_be_bytes());
        b.extend_from_slice(&2.0f32.to_be_bytes());
        b.extend_from_slice(&0u32.to_be_bytes());
        let m = decode_laser_scan(&b, 10).unwrap();
        assert_eq!(
            (m.stamp_sec, m.stamp_nanosec, m.frame_id.as_str()),
            (5, 6, "")
        );
        assert_eq!((m.ranges, m.range_max), (vec![2.0], 10.0));
    }
}
