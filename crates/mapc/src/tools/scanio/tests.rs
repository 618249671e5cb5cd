use super::*;

use std::f32::consts::PI as PI32;
use std::io::{Cursor, Write};

fn read_all(
    input: &[u8],
    format: InputFormat,
    opts: &ReadOptions,
) -> Vec<Result<InputScan, ScanError>> {
    read_scans(Cursor::new(input.to_vec()), format, opts).collect()
}

fn read(input: &str, format: InputFormat) -> Vec<Result<InputScan, ScanError>> {
    read_all(input.as_bytes(), format, &ReadOptions::default())
}

fn one(input: &str, format: InputFormat) -> Result<InputScan, ScanError> {
    let mut v = read(input, format);
    assert_eq!(v.len(), 1, "{v:?}");
    v.pop().unwrap()
}

fn err(input: &str, format: InputFormat) -> ScanError {
    match one(input, format) {
        Ok(s) => panic!("expected an error, got {s:?}"),
        Err(e) => e,
    }
}

fn ranges_of(s: &InputScan) -> (f32, f32, f32, f32, &[f32]) {
    match &s.data {
        ScanData::Ranges {
            angle_min,
            angle_increment,
            range_min,
            range_max,
            ranges,
        } => (*angle_min, *angle_increment, *range_min, *range_max, ranges),
        other => panic!("expected ranges, got {other:?}"),
    }
}

/// Same value, NaN equal to NaN.
fn same(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

/// A tiny deterministic generator for the robustness tests.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 17
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

// ---------------------------------------------------------------------------
// Line reader.

fn lines_of(input: &[u8], max: usize) -> Vec<(usize, Result<Vec<u8>, u64>)> {
    let mut r = LineReader::new(Cursor::new(input.to_vec()), max);
    let mut out = Vec::new();
    while let Some((n, raw)) = r.next_line() {
        out.push((
            n,
            match raw {
                RawLine::Text(t) => Ok(t.to_vec()),
                RawLine::TooLong { len, .. } => Err(len),
                RawLine::Failed(e) => panic!("{e}"),
            },
        ));
    }
    out
}

#[test]
fn line_reader_splits_and_bounds() {
    assert!(lines_of(b"", 10).is_empty());
    assert_eq!(lines_of(b"a", 10), vec![(1, Ok(b"a".to_vec()))]);
    assert_eq!(
        lines_of(b"a\r\n\nbc\n", 10),
        vec![
            (1, Ok(b"a".to_vec())),
            (2, Ok(vec![])),
            (3, Ok(b"bc".to_vec()))
        ]
    );
    let long = format!("short\n{}\nafter\n{}", "x".repeat(25), "y".repeat(11));
    assert_eq!(
        lines_of(long.as_bytes(), 10),
        vec![
            (1, Ok(b"short".to_vec())),
            (2, Err(25)),
            (3, Ok(b"after".to_vec())),
            (4, Err(11))
        ]
    );
    // Exactly at the limit is fine.
    assert_eq!(
        lines_of(b"0123456789\n", 10),
        vec![(1, Ok(b"0123456789".to_vec()))]
    );
}

#[test]
fn line_reader_with_tiny_buffer_reads() {
    // BufReader with a 3-byte buffer: lines arrive in many pieces.
    let text = b"first line\nsecond, longer line that overflows\nthird\n";
    let mut r = LineReader::new(BufReader::with_capacity(3, Cursor::new(text.to_vec())), 12);
    let mut got = Vec::new();
    while let Some((n, raw)) = r.next_line() {
        got.push(match raw {
            RawLine::Text(t) => format!("{n}:{}", String::from_utf8_lossy(t)),
            RawLine::TooLong { len, prefix } => {
                format!("{n}:long {len} {}", String::from_utf8_lossy(prefix))
            }
            RawLine::Failed(e) => format!("{n}:failed {e}"),
        });
    }
    assert_eq!(
        got,
        vec![
            "1:first line",
            "2:long 34 second, longer line that overflows",
            "3:third"
        ]
    );
}

struct FailAfter {
    data: Cursor<Vec<u8>>,
}

impl Read for FailAfter {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.data.read(buf)?;
        if n == 0 {
            Err(io::Error::other("disk on fire"))
        } else {
            Ok(n)
        }
    }
}

#[test]
fn io_error_ends_the_stream_with_one_error() {
    let good = r#"{"angle_min": 0, "angle_increment": 0.1, "ranges": [1, 2]}"#;
    let input = format!("{good}\n{good}");
    let reader = BufReader::new(FailAfter {
        data: Cursor::new(input.into_bytes()),
    });
    let items: Vec<_> = read_scans(reader, InputFormat::Auto, &ReadOptions::default()).collect();
    assert_eq!(items.len(), 2, "{items:?}");
    assert!(items[0].is_ok());
    let e = items[1].as_ref().unwrap_err();
    assert_eq!(e.line, 2);
    assert!(
        e.message().contains("read error") && e.message().contains("disk on fire"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------
// JSON Lines.

#[test]
fn json_ranges_basic() {
    let s = one(
        r#"{"id": "scan-1", "header": {"stamp": 3}, "angle_min": -1.5, "angle_max": 1.5,
            "angle_increment": 1.0, "range_min": 0.1, "range_max": 10, "ranges": [1, null, 2.5, 1e400],
            "intensities": [1, 2, 3, 4], "unknown": [[{"deep": true}]], "truth": [1.5, -2, 0.25]}"#
            .replace('\n', " ")
            .as_str(),
        InputFormat::JsonLines,
    )
    .unwrap();
    assert_eq!(s.id, "scan-1");
    assert_eq!(s.line, 1);
    assert_eq!(s.truth, Some([1.5, -2.0, 0.25]));
    let (amin, inc, rmin, rmax, r) = ranges_of(&s);
    assert_eq!((amin, inc, rmin, rmax), (-1.5, 1.0, 0.1, 10.0));
    assert!(same(r, &[1.0, f32::NAN, 2.5, f32::NAN]), "{r:?}");
}

#[test]
fn json_defaults_ids_and_skipped_lines() {
    let input = "# a comment\n\n   \n{\"angle_min\":0,\"angle_increment\":0.5,\"ranges\":[1]}\n\
                 {\"id\": 42, \"angle_min\":0,\"angle_increment\":0.5,\"ranges\":[40, 0, -1, 0.05]}\n\
                 {\"id\": 1.5, \"id2\": null, \"angle_min\":0,\"angle_increment\":0.5,\"range_min\":0.1,\"ranges\":[0.05, 0.1]}\r\n";
    let v = read(input, InputFormat::Auto);
    assert_eq!(v.len(), 3);
    let a = v[0].as_ref().unwrap();
    assert_eq!((a.id.as_str(), a.line, a.truth), ("line 4", 4, None));
    assert_eq!(ranges_of(a).3, 30.0, "range_max defaults to the options'");
    assert_eq!(ranges_of(a).2, 0.0);
    let b = v[1].as_ref().unwrap();
    assert_eq!(b.id, "42");
    // 40 > range_max 30, 0 and -1 are not positive: no return.
    assert!(same(ranges_of(b).4, &[f32::NAN, f32::NAN, f32::NAN, 0.05]));
    let c = v[2].as_ref().unwrap();
    assert_eq!(c.id, "1.5");
    assert!(same(ranges_of(c).4, &[f32::NAN, 0.1]));
}

#[test]
fn json_points() {
    let s = one(
        r#"{"id":"p","points":[[1,2],[-3.5,0]],"range_max":12}"#,
        InputFormat::Auto,
    )
    .unwrap();
    assert_eq!(
        s.data,
        ScanData::Points {
            points: vec![[1.0, 2.0], [-3.5, 0.0]],
            range_max: 12.0
        }
    );
    let s = one(r#"{"points":[[1,2]]}"#, InputFormat::Auto).unwrap();
    assert_eq!(
        s.data,
        ScanData::Points {
            points: vec![[1.0, 2.0]],
            range_max: 30.0
        }
    );
}

#[test]
fn json_error_message_format() {
    let e = err(
        r#"{"id":"scan-3","angle_min":0,"angle_increment":0.1,"ranges":[1,2,3,4,"5",6]}"#,
        InputFormat::JsonLines,
    );
    assert_eq!(
        e.to_string(),
        "line 1 (id scan-3): ranges[4] is a string, expected a number or null"
    );
    let e = err(
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[true]}"#,
        InputFormat::JsonLines,
    );
    assert_eq!(
        e.to_string(),
        "line 1: ranges[0] is a boolean, expected a number or null"
    );
    assert_eq!(e.id, None);
}

/// (record, expected words in the message)
const JSON_ERRORS: &[(&str, &[&str])] = &[
    (
        r#"{"angle_increment":0.1,"ranges":[1]}"#,
        &["missing field angle_min"],
    ),
    (
        r#"{"angle_min":0,"ranges":[1]}"#,
        &["missing field angle_increment"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1}"#,
        &["missing field ranges"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[]}"#,
        &["ranges is empty"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0,"ranges":[1]}"#,
        &["angle_increment is 0"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":1e400,"ranges":[1]}"#,
        &["angle_increment", "not finite"],
    ),
    (
        r#"{"angle_min":-1e999,"angle_increment":0.1,"ranges":[1]}"#,
        &["angle_min", "not a finite angle"],
    ),
    (
        r#"{"angle_min":100,"angle_increment":0.1,"ranges":[1]}"#,
        &["angle_min"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1,1]}"#,
        &["more than a full turn"],
    ),
    (
        r#"{"angle_min":"0","angle_increment":0.1,"ranges":[1]}"#,
        &["angle_min is a string, expected a number"],
    ),
    (
        r#"{"angle_min":null,"angle_increment":0.1,"ranges":[1]}"#,
        &["angle_min is null"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":[0.1],"ranges":[1]}"#,
        &["angle_increment is an array"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":{"a":1}}"#,
        &["ranges is an object"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":"1 2 3"}"#,
        &["ranges is a string"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[[1]]}"#,
        &["ranges[0] is an array"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1,2],"angle_max":0.3}"#,
        &["angle_max", "disagrees"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1],"range_max":-3}"#,
        &["range_max", "positive"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1],"range_max":false}"#,
        &["range_max is a boolean"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1],"range_min":50}"#,
        &["range_min"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1],"range_min":-1}"#,
        &["range_min"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1],"points":[[1,2]]}"#,
        &["both ranges and points"],
    ),
    (r#"{"points":[]}"#, &["points is empty"]),
    (
        r#"{"points":[[1,2],[3]]}"#,
        &["points[1]", "length other than 2"],
    ),
    (
        r#"{"points":[[1,2],[3,4,5]]}"#,
        &["points[1]", "length other than 2"],
    ),
    (r#"{"points":[[1,"2"]]}"#, &["points[0]", "non-number"]),
    (r#"{"points":[[1,null]]}"#, &["points[0]", "non-number"]),
    (r#"{"points":[[1,1e300]]}"#, &["points[0] is not finite"]),
    (r#"{"points":[3]}"#, &["points[0] is a number"]),
    (r#"{"points":7}"#, &["points is a number"]),
    (
        r#"{"points":[[1,2]],"truth":[1,2]}"#,
        &["truth", "length other than 3"],
    ),
    (
        r#"{"points":[[1,2]],"truth":[1,2,"x"]}"#,
        &["truth", "non-number"],
    ),
    (
        r#"{"points":[[1,2]],"truth":[1,2,1e999]}"#,
        &["truth is not finite"],
    ),
    (
        r#"{"points":[[1,2]],"truth":{"x":1}}"#,
        &["truth is an object"],
    ),
    (r#"{"points":[[1,2]],"id":true}"#, &["id is a boolean"]),
    (r#"{"points":[[1,2]],"id":{"a":1}}"#, &["id is an object"]),
    (
        r#"{"points":[[1,2]],"id":"a\u001bb"}"#,
        &["id contains a control character"],
    ),
    (
        r#"{"points":[[1,2]],"ranges":[1],"ranges":[2]}"#,
        &["field ranges appears more than once"],
    ),
    (r#"[1,2,3]"#, &["invalid JSON", "expected a JSON object"]),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1,2"#,
        &["invalid JSON", "EOF", "column"],
    ),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1]} trailing"#,
        &["invalid JSON", "trailing"],
    ),
    (r#"{"angle_min":0,,}"#, &["invalid JSON"]),
    (r#"{"angle_min":0x10}"#, &["invalid JSON"]),
    (r#"{"angle_min":NaN}"#, &["invalid JSON"]),
    (
        r#"{"angle_min":0,"angle_increment":0.1,"ranges":[1e400, 1e400e]}"#,
        &["invalid JSON"],
    ),
    ("{\"id\":\"\u{1}\"}", &["invalid JSON"]),
    ("{\"ranges\":[1,\u{1}]}", &["invalid JSON"]),
];

#[test]
fn json_errors_name_the_field() {
    for (k, (line, words)) in JSON_ERRORS.iter().enumerate() {
        // Each error is one item; the good record after it still reads.
        let input = format!("{line}\n{{\"angle_min\":0,\"angle_increment\":0.1,\"ranges\":[1]}}\n");
        let v = read(&input, InputFormat::JsonLines);
        assert_eq!(v.len(), 2, "case {k}: {line}: {v:?}");
        let e = v[0].as_ref().expect_err(line);
        assert_eq!(e.line, 1);
        for w in *words {
            assert!(
                e.message().contains(w),
                "case {k}: {line}: message {:?} lacks {w:?}",
                e.message()
            );
        }
        assert!(v[1].is_ok(), "case {k}");
    }
}

#[test]
fn json_error_keeps_the_id_seen_so_far() {
    let e = err(
        r#"{"id": 7, "angle_min":0,"angle_increment":0.1,"ranges":[1,"#,
        InputFormat::JsonLines,
    );
    assert_eq!(e.id.as_deref(), Some("7"));
    let e = err(
        r#"{"id": "x", "angle_min":0,"ranges":[1]}"#,
        InputFormat::JsonLines,
    );
    assert_eq!(
        e.to_string(),
        "line 1 (id x): missing field angle_increment"
    );
}

#[test]
fn json_invalid_utf8_and_long_id() {
    let mut line = br#"{"id":"a"#.to_vec();
    line.extend_from_slice(&[0xff, 0xfe]);
    line.extend_from_slice(br#"","points":[[1,2]]}"#);
    let v = read_all(&line, InputFormat::Auto, &ReadOptions::default());
    assert!(
        v[0].as_ref()
            .unwrap_err()
            .message()
            .contains("invalid JSON"),
        "{v:?}"
    );
    let v = read(
        &format!(r#"{{"id":"{}","points":[[1,2]]}}"#, "x".repeat(300)),
        InputFormat::Auto,
    );
    assert!(
        v[0].as_ref()
            .unwrap_err()
            .message()
            .contains("id is 300 bytes long"),
        "{v:?}"
    );
}

#[test]
fn json_angle_max_is_loose() {
    // angle_min + n * inc (one increment off) is accepted.
    let s = one(
        r#"{"angle_min":0,"angle_increment":0.1,"angle_max":0.3,"ranges":[1,2,3]}"#,
        InputFormat::Auto,
    );
    assert!(s.is_ok(), "{s:?}");
    let s = one(
        r#"{"angle_min":0,"angle_increment":-0.1,"angle_max":-0.2,"ranges":[1,2,3]}"#,
        InputFormat::Auto,
    );
    assert!(s.is_ok(), "{s:?}");
    let e = err(
        r#"{"angle_min":0,"angle_increment":0.1,"angle_max":0.31,"ranges":[1,2,3]}"#,
        InputFormat::Auto,
    );
    assert!(e.message().contains("angle_max"), "{e}");
}

#[test]
fn json_max_beams() {
    let opts = ReadOptions {
        max_beams: 3,
        ..ReadOptions::default()
    };
    let v = read_all(
        br#"{"angle_min":0,"angle_increment":0.1,"ranges":[1,2,3]}"#,
        InputFormat::Auto,
        &opts,
    );
    assert!(v[0].is_ok());
    let v = read_all(
        br#"{"angle_min":0,"angle_increment":0.1,"ranges":[1,2,3,4,5]}"#,
        InputFormat::Auto,
        &opts,
    );
    assert_eq!(
        v[0].as_ref().unwrap_err().message(),
        "ranges has 5 entries, more than max_beams = 3"
    );
    let v = read_all(
        br#"{"points":[[1,2],[1,2],[1,2],[1,2]]}"#,
        InputFormat::Auto,
        &opts,
    );
    assert_eq!(
        v[0].as_ref().unwrap_err().message(),
        "points has 4 entries, more than max_beams = 3"
    );
}

#[test]
fn json_deep_nesting_never_crashes() {
    let (open, close) = ("[".repeat(100_000), "]".repeat(100_000));
    let deep = format!(r#"{{"x":{open}{close}, "points":[[1,2]]}}"#);
    // Ignored fields may nest arbitrarily (serde_json skips them without recursion).
    assert!(one(&deep, InputFormat::Auto).is_ok());
    let deep_obj = format!(
        r#"{{"x":{}1{}, "points":[[1,2]]}}"#,
        "{\"a\":".repeat(50_000),
        "}".repeat(50_000)
    );
    assert!(one(&deep_obj, InputFormat::Auto).is_ok());
    for field in ["angle_min", "ranges", "points", "id", "truth"] {
        for value in [
            format!("{open}{close}"),
            format!("[{open}{close}]"),
            format!("[[{open}{close}]]"),
        ] {
            let v = read(
                &format!(r#"{{"angle_increment":0.1,"{field}":{value}}}"#),
                InputFormat::Auto,
            );
            assert!(v[0].is_err(), "{field}: {:?}", v[0]);
        }
    }
}

#[test]
fn numbers_beyond_f64_range_read_as_infinite() {
    // By the number type, not by serde_json's error: outside strings only.
    let s = one(
        r#"{"a\"1e999":"1e400","angle_min":0,"angle_increment":0.5,"ranges":[1e400,-2E+999,3.5,1.7e308,1e307]}"#,
        InputFormat::JsonLines,
    )
    .unwrap();
    assert!(same(
        ranges_of(&s).4,
        &[f32::NAN, f32::NAN, 3.5, f32::NAN, f32::NAN]
    ));
    let e = err(
        r#"{"angle_min":0,"angle_increment":0.5,"ranges":[1],"range_max":1e999}"#,
        InputFormat::JsonLines,
    );
    assert_eq!(
        e.message(),
        "range_max (inf) is not a positive finite number of metres"
    );
    let e = err(
        r#"{"angle_min":0,"angle_increment":1.5e308,"ranges":[1]}"#,
        InputFormat::JsonLines,
    );
    assert_eq!(e.kind, ScanErrorKind::NotFinite("angle_increment".into()));
    // A numeric id keeps the text it had: huge ones are clamped to 1e308.
    let e = err(r#"{"id":1e400,"points":[[1,2]]}"#, InputFormat::JsonLines);
    assert_eq!(e.kind, ScanErrorKind::IdTooLong(309));
    for (id, text) in [
        ("-0", "-0"),
        ("-5", "-5"),
        ("1e2", "100"),
        ("18446744073709551616", "18446744073709552000"),
    ] {
        let s = one(
            &format!(r#"{{"id":{id},"points":[[1,2]]}}"#),
            InputFormat::JsonLines,
        )
        .unwrap();
        assert_eq!(s.id, text);
    }
}

// ---------------------------------------------------------------------------
// Format sniffing.

#[test]
fn auto_sniffs_and_reports_undecidable_lines() {
    let input = "# header\nhello world\n{\"points\":[[1,2]]}\nFLASER 1 1 0 0 0 0 0 0\n";
    let v = read(input, InputFormat::Auto);
    assert_eq!(v.len(), 3, "{v:?}");
    let e = v[0].as_ref().unwrap_err();
    assert_eq!(e.line, 2);
    assert!(e.message().contains("cannot tell the input format"), "{e}");
    assert!(v[1].is_ok());
    // Once JSON, a CARMEN line is a JSON error.
    assert!(v[2]
        .as_ref()
        .unwrap_err()
        .message()
        .contains("invalid JSON"));

    let v = read(
        "\u{feff}PARAM x 1\nFLASER 1 1 0 0 0 0 0 0\n{\"points\":[[1,2]]}\n",
        InputFormat::Auto,
    );
    assert_eq!(v.len(), 2, "{v:?}");
    assert!(v[0].is_ok());
    assert!(v[1]
        .as_ref()
        .unwrap_err()
        .message()
        .contains("not a CARMEN line"));
}

#[test]
fn format_from_str() {
    assert_eq!("auto".parse(), Ok(InputFormat::Auto));
    assert_eq!("JSONL".parse(), Ok(InputFormat::JsonLines));
    assert_eq!("carmen".parse(), Ok(InputFormat::Carmen));
    assert!("xml".parse::<InputFormat>().is_err());
}

// ---------------------------------------------------------------------------
// CARMEN.

fn flaser(n: usize, r: f32, tail: &str) -> String {
    let ranges: Vec<String> = (0..n).map(|_| r.to_string()).collect();
    format!("FLASER {n} {} 1.5 -2.5 0.75 {tail}", ranges.join(" "))
}

#[test]
fn carmen_flaser_geometry() {
    let tail = "1 2 3 1134863807.7 b21 12.5";
    let deg = std::f32::consts::PI / 180.0;
    for (n, step) in [
        (180usize, 1.0f32),
        (181, 1.0),
        (360, 0.5),
        (361, 0.5),
        (720, 0.25),
        (721, 0.25),
    ] {
        let s = one(&flaser(n, 2.0, tail), InputFormat::Carmen).unwrap();
        let (amin, inc, rmin, _, r) = ranges_of(&s);
        assert_eq!(amin, -PI32 / 2.0, "n = {n}");
        assert!((inc - step * deg).abs() < 1e-7, "n = {n}: {inc}");
        assert_eq!((rmin, r.len()), (0.0, n));
        assert_eq!(s.truth, Some([1.5, -2.5, 0.75]));
        assert_eq!(s.id, "scan 0");
    }
    // Other counts: fov / (n - 1).
    let s = one(&flaser(100, 2.0, tail), InputFormat::Carmen).unwrap();
    assert!((ranges_of(&s).1 - PI32 / 99.0).abs() < 1e-7);
    let s = one(&flaser(1, 2.0, tail), InputFormat::Carmen).unwrap();
    assert_eq!(ranges_of(&s).4.len(), 1);
    assert_eq!(
        carmen_angle_increment(401, 100f64.to_radians()),
        0.25f64.to_radians()
    );
}

#[test]
fn carmen_fov_override_and_rear_laser() {
    let opts = ReadOptions {
        fov: Some(100f32.to_radians()),
        ..ReadOptions::default()
    };
    let line = flaser(401, 2.0, "0 0 0 1 h 2");
    let v = read_all(line.as_bytes(), InputFormat::Carmen, &opts);
    let s = v[0].as_ref().unwrap();
    let (amin, inc, ..) = ranges_of(s);
    assert!((amin + 50f32.to_radians()).abs() < 1e-6);
    assert!((inc - 0.25f32.to_radians()).abs() < 1e-7);

    let line = flaser(180, 2.0, "0 0 0 1 h 2").replacen("FLASER", "RLASER", 1);
    let s = one(&line, InputFormat::Carmen).unwrap();
    let (amin, inc, ..) = ranges_of(&s);
    assert_eq!(amin, PI32 / 2.0);
    assert!((inc - 1f32.to_radians()).abs() < 1e-7);

    for fov in [0.0, -1.0, 7.0, f32::NAN] {
        let opts = ReadOptions {
            fov: Some(fov),
            ..ReadOptions::default()
        };
        let v = read_all(
            flaser(180, 2.0, "0 0 0").as_bytes(),
            InputFormat::Carmen,
            &opts,
        );
        assert!(
            v[0].as_ref()
                .unwrap_err()
                .message()
                .contains("field of view"),
            "{v:?}"
        );
    }
}

#[test]
fn carmen_max_range_from_param_or_options() {
    let ranges = "1 29.99 30 50 80.9 81.91 0 -1 nan inf";
    let line = format!("FLASER 10 {ranges} 0 0 0 0 0 0 1 h 2");
    // No PARAM: the options' 30 m; values at or above it are no return.
    let s = one(&line, InputFormat::Carmen).unwrap();
    let nan = f32::NAN;
    assert!(same(
        ranges_of(&s).4,
        &[1.0, 29.99, nan, nan, nan, nan, nan, nan, nan, nan]
    ));
    assert_eq!(ranges_of(&s).3, 30.0);
    // PARAM robot_front_laser_max applies to later FLASER lines only.
    let input = format!(
        "{line}\nPARAM robot_front_laser_max 80.99 123 host 456\n{line}\n{}",
        line.replacen('F', "R", 1)
    );
    let v = read(&input, InputFormat::Carmen);
    assert_eq!(v.len(), 3);
    let s = v[1].as_ref().unwrap();
    assert_eq!(ranges_of(s).3, 80.99);
    assert!(same(
        ranges_of(s).4,
        &[1.0, 29.99, 30.0, 50.0, 80.9, nan, nan, nan, nan, nan]
    ));
    assert_eq!(
        ranges_of(v[2].as_ref().unwrap()).3,
        30.0,
        "RLASER uses robot_rear_laser_max"
    );
    assert_eq!(
        v.iter()
            .map(|r| r.as_ref().unwrap().id.clone())
            .collect::<Vec<_>>(),
        ["scan 0", "scan 1", "scan 2"]
    );
    // Garbage PARAM values are ignored.
    let input = format!("PARAM robot_front_laser_max -5\nPARAM robot_front_laser_max\n{line}");
    assert_eq!(
        ranges_of(&one(&input, InputFormat::Carmen).unwrap()).3,
        30.0
    );
}

#[test]
fn carmen_robotlaser() {
    let line = "ROBOTLASER1 0 -1.25 2.5 0.02 50.0 0.01 0 3 1.0 60 2.0 2 7 8 \
                0.1 0.2 0.3 0.0 0.0 0.25 0.5 0.1 0.5 0.3 0.2 1134.5 host 2.0";
    let s = one(line, InputFormat::Auto).unwrap();
    let (amin, inc, _, rmax, r) = ranges_of(&s);
    assert_eq!((amin, inc, rmax), (-1.25, 0.02, 50.0));
    assert!(same(r, &[1.0, f32::NAN, 2.0]));
    assert_eq!(s.truth, Some([0.1, 0.2, 0.3]));
    assert_eq!(s.id, "scan 0");
    // Without a usable maximum_range: the options'.
    let s = one(&line.replacen("50.0", "0", 1), InputFormat::Auto).unwrap();
    assert_eq!(ranges_of(&s).3, 30.0);
    // Robot pose only (no velocities, timestamps).
    let short = "ROBOTLASER2 0 -1.5 3.1 0.5 50 0.01 0 3 1 2 3 0 1 2 3 4 5 6";
    assert!(one(short, InputFormat::Carmen).is_ok());
}

/// (line, expected words in the message)
const CARMEN_ERRORS: &[(&str, &[&str])] = &[
    ("FLASER", &["ends before its beam count"]),
    ("FLASER -5 1 2 3", &["beam count", "is negative"]),
    ("FLASER 1.5 1 2 3", &["not a non-negative integer"]),
    ("FLASER abc 1 2 3", &["not a non-negative integer"]),
    ("FLASER 0 0 0 0 0 0 0", &["0 beams"]),
    (
        "FLASER 1000000000 1 2 3 4 5 6",
        &["1000000000 beams, more than max_beams = 100000"],
    ),
    (
        "FLASER 99999999999999999999999999 1 2",
        &["99999999999999999999999999 beams, more than max_beams"],
    ),
    (
        "FLASER 3 1 2 3 0 0",
        &["n = 3 beams but 5 fields follow", "expected 9 to 12"],
    ),
    (
        "FLASER 3 1 2 3 0 0 0 0 0 0 1 h 2 extra",
        &["n = 3 beams but 13 fields follow"],
    ),
    (
        "FLASER 3 1 2 x 0 0 0 0 0 0",
        &["range 2 (\"x\") is not a number"],
    ),
    (
        "FLASER 3 1 2 3 0 nan 0 0 0 0",
        &["laser pose y", "not a finite number"],
    ),
    (
        "RLASER 3 1 2 3 0 0 1e999 0 0 0",
        &["RLASER laser pose theta"],
    ),
    ("ROBOTLASER1 0 -1.5", &["ends before its field_of_view"]),
    (
        "ROBOTLASER1 0 -1.5 3.1 x 50 0.01 0 3 1 2 3 0 1 2 3 4 5 6",
        &["angular_resolution", "not a finite number"],
    ),
    (
        "ROBOTLASER1 0 -1.5 3.1 0 50 0.01 0 3 1 2 3 0 1 2 3 4 5 6",
        &["ROBOTLASER1 angular_resolution is 0"],
    ),
    (
        "ROBOTLASER1 0 -1.5 3.1 4 50 0.01 0 3 1 2 3 0 1 2 3 4 5 6",
        &["more than a full turn"],
    ),
    (
        "ROBOTLASER1 0 -1.5 3.1 0.5 50 0.01 0 3 1 2",
        &["num_readings = 3 but only 2 fields follow"],
    ),
    (
        "ROBOTLASER1 0 -1.5 3.1 0.5 50 0.01 0 3 1 2 3 5 1 2 3 4 5 6",
        &["num_remissions = 5 but 6 fields follow"],
    ),
    (
        "ROBOTLASER1 0 -1.5 3.1 0.5 50 0.01 0 3 1 2 3 -1 1 2 3 4 5 6",
        &["num_remissions", "negative"],
    ),
    (
        "ROBOTLASER1 0 -1.5 3.1 0.5 50 0.01 0 2000000 1 2 3",
        &["2000000 beams, more than max_beams"],
    ),
];

#[test]
fn carmen_errors() {
    for (k, (line, words)) in CARMEN_ERRORS.iter().enumerate() {
        let input = format!("ODOM 1 2 3\n{line}\nFLASER 1 1 0 0 0 0 0 0\n");
        let v = read(&input, InputFormat::Carmen);
        assert_eq!(v.len(), 2, "case {k}: {line}: {v:?}");
        let e = v[0].as_ref().expect_err(line);
        assert_eq!((e.line, e.id.as_deref()), (2, Some("scan 0")), "case {k}");
        for w in *words {
            assert!(
                e.message().contains(w),
                "case {k}: {line}: message {:?} lacks {w:?}",
                e.message()
            );
        }
        // The failed line still counts as a laser line.
        assert_eq!(v[1].as_ref().unwrap().id, "scan 1", "case {k}");
    }
}

#[test]
fn carmen_skips_other_lines_and_reports_garbage() {
    let input =
        "# comment\nODOM 1 2 3\nSYNC\nTRUEPOS 1 2\nNEFF 30\nRAWLASER1 0 0 0\nlowercase words\n\
                 FLASER 1 1 0 0 0 0 0 0\n";
    let v = read(input, InputFormat::Carmen);
    assert_eq!(v.len(), 2, "{v:?}");
    let e = v[0].as_ref().unwrap_err();
    assert_eq!((e.line, e.id.as_deref()), (7, None));
    assert!(e.message().contains("not a CARMEN line"), "{e}");
    assert_eq!(v[1].as_ref().unwrap().line, 8);
}

#[test]
fn too_long_lines_are_errors_and_counted() {
    let opts = ReadOptions {
        max_line_bytes: 200,
        ..ReadOptions::default()
    };
    let long = flaser(100, 2.0, "0 0 0");
    let input = format!(
        "{long}\n#{}\n{}\n",
        "c".repeat(500),
        flaser(3, 2.0, "0 0 0")
    );
    let v = read_all(input.as_bytes(), InputFormat::Auto, &opts);
    assert_eq!(v.len(), 2, "{v:?}");
    let e = v[0].as_ref().unwrap_err();
    assert_eq!(e.id.as_deref(), Some("scan 0"));
    assert!(e.message().contains(&format!(
        "line is {} bytes long, more than max_line_bytes = 200",
        long.len()
    )));
    assert_eq!(v[1].as_ref().unwrap().id, "scan 1");

    let json = format!(
        r#"{{"angle_min":0,"angle_increment":0.001,"ranges":[{}1]}}"#,
        "1,".repeat(200)
    );
    let v = read_all(
        format!("{json}\n{{\"points\":[[1,2]]}}").as_bytes(),
        InputFormat::Auto,
        &opts,
    );
    assert_eq!(v.len(), 2);
    assert_eq!(v[0].as_ref().unwrap_err().id, None);
    assert_eq!(v[1].as_ref().unwrap().line, 2);
}

// ---------------------------------------------------------------------------
// Robustness: no input makes the reader panic.

fn valid_lines() -> Vec<String> {
    vec![
        r#"{"id":"a","angle_min":-1.5,"angle_max":1.5,"angle_increment":1.0,"range_min":0.1,"range_max":10,"ranges":[1,null,2.5,1e400],"truth":[1,2,3]}"#.into(),
        r#"{"id":7,"points":[[1,2],[3,4]],"range_max":5,"header":{"a":[1,{"b":null}]}}"#.into(),
        flaser(10, 2.0, "1 2 3 4 host 5"),
        "ROBOTLASER1 0 -1.25 2.5 0.02 50.0 0.01 0 3 1.0 60 2.0 2 7 8 0.1 0.2 0.3 0 0 0.25 0.5 0.1 0.5 0.3 0.2 1134.5 host 2.0".into(),
        "PARAM robot_front_laser_max 50 1 h 2".into(),
    ]
}

#[test]
fn truncations_never_panic() {
    for line in valid_lines() {
        for cut in 0..=line.len() {
            for format in [
                InputFormat::Auto,
                InputFormat::JsonLines,
                InputFormat::Carmen,
            ] {
                let input = format!("{}\n{}\n", &line[..cut], line);
                let v = read_all(input.as_bytes(), format, &ReadOptions::default());
                assert!(v.len() <= 2);
            }
        }
    }
}

#[test]
fn random_garbage_never_panics() {
    let mut rng = Lcg(12345);
    let valid = valid_lines();
    let alphabet: &[u8] =
        b"{}[]\",:0123456789.-+eE nul trfasFLASERROBOTPARAM\t\r\n#\\\xff\xfe\x00\x80";
    let opts = ReadOptions {
        max_line_bytes: 400,
        max_beams: 50,
        ..ReadOptions::default()
    };
    for _ in 0..4000 {
        let mut input: Vec<u8> = valid[rng.below(valid.len())].clone().into_bytes();
        match rng.below(3) {
            0 => {
                // Flip some bytes.
                for _ in 0..1 + rng.below(5) {
                    let i = rng.below(input.len());
                    input[i] = alphabet[rng.below(alphabet.len())];
                }
            }
            1 => {
                // Pure random bytes.
                input = (0..rng.below(300)).map(|_| rng.next() as u8).collect();
            }
            _ => {
                // Random alphabet soup, sometimes glued after a valid line.
                let soup: Vec<u8> = (0..rng.below(500))
                    .map(|_| alphabet[rng.below(alphabet.len())])
                    .collect();
                input.push(b'\n');
                input.extend(soup);
            }
        }
        for format in [
            InputFormat::Auto,
            InputFormat::JsonLines,
            InputFormat::Carmen,
        ] {
            for item in read_scans(Cursor::new(&input), format, &opts) {
                match item {
                    Ok(s) => {
                        assert!(!s.data.is_empty() && s.data.len() <= 50);
                        if let ScanData::Ranges {
                            angle_increment, ..
                        } = s.data
                        {
                            assert!(angle_increment.is_finite() && angle_increment != 0.0);
                        }
                    }
                    Err(e) => assert!(!e.message().is_empty()),
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Writer round trips.

#[test]
fn scan_to_json_round_trips_ranges() {
    let mut rng = Lcg(7);
    let mut ranges: Vec<f32> = (0..1000)
        .map(|_| (rng.next() % 1_000_000) as f32 / 40_000.0 + 0.05)
        .collect();
    ranges[3] = f32::NAN;
    ranges[10] = f32::INFINITY;
    ranges[11] = 1e-7;
    ranges[12] = 29.999998;
    let data = ScanData::Ranges {
        angle_min: -2.356_194_5,
        angle_increment: 0.004_363_323,
        range_min: 0.0,
        range_max: 30.0,
        ranges: ranges.clone(),
    };
    let truth = Some([12.345678901234567, -0.1, std::f64::consts::PI]);
    let id = "sim \"7\" \\ é/\u{2028}";
    let json = scan_to_json(&data, id, truth);
    assert!(!json.contains('\n'));
    let s = one(&json, InputFormat::Auto).unwrap();
    assert_eq!(s.id, id);
    assert_eq!(s.truth, truth);
    let (amin, inc, rmin, rmax, r) = ranges_of(&s);
    assert_eq!(
        (amin, inc, rmin, rmax),
        (-2.356_194_5, 0.004_363_323, 0.0, 30.0)
    );
    ranges[10] = f32::NAN;
    assert!(same(r, &ranges));
    // And the record is plain JSON.
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert!(v["ranges"][3].is_null());
}

/// The exact text `scan_to_json` writes (as the hand-written writer before
/// serde_json did): floats as `{:?}` (`1e16`, `3e-6`, `-0.0`), `null` for
/// values that are not finite, control characters as `\u00XX` except
/// `\n`, `\r`, `\t`.
#[test]
fn scan_to_json_text_is_fixed() {
    let d = ScanData::Ranges {
        angle_min: -0.0,
        angle_increment: 1e-7,
        range_min: 1e16,
        range_max: f32::MAX,
        ranges: vec![f32::NAN, 1.0, 0.1, f32::INFINITY, 3e-6],
    };
    assert_eq!(
        scan_to_json(
            &d,
            "a\u{8}\u{c}\u{7f}\"\\\n\u{1}é",
            Some([1.0, -0.0, f64::NAN])
        ),
        r#"{"id":"a\u0008\u000c\u007f\"\\\n\u0001é","angle_min":-0.0,"angle_max":4e-7,"angle_increment":1e-7,"range_min":1e16,"range_max":3.4028235e38,"ranges":[null,1.0,0.1,null,3e-6],"truth":[1.0,-0.0,null]}"#
    );
    let d = ScanData::Points {
        points: vec![[1e-45, -1e38], [2.5, 0.0]],
        range_max: 30.0,
    };
    assert_eq!(
        scan_to_json(&d, "p", None),
        r#"{"id":"p","range_max":30.0,"points":[[1e-45,-1e38],[2.5,0.0]]}"#
    );
}

/// The angle limits hold for the f32 values a scan keeps, not only for the
/// f64 values read (fuzz findings `angle-min-f32-rounds-past-limit` and
/// `increment-f32-rounds-past-full-turn`): every record accepted near a
/// limit reads back from its `scan_to_json`, and values that only pass in
/// f64 are rejected naming the field.
#[test]
fn angles_are_checked_as_stored_f32() {
    let record = |amin: &str, inc: &str, n: usize| {
        let ranges = vec!["1"; n].join(",");
        format!(r#"{{"angle_min":{amin},"angle_increment":{inc},"ranges":[{ranges}]}}"#)
    };
    let round_trips = |s: &InputScan| {
        let back = one(
            &scan_to_json(&s.data, &s.id, s.truth),
            InputFormat::JsonLines,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back.data, s.data);
    };
    // angle_min: 6.2841853 is inside 2 pi + 1e-3 in f64, its f32 is not.
    let e = err(&record("6.2841853", "1", 1), InputFormat::JsonLines);
    assert!(e.message().starts_with("angle_min (6.2841854)"), "{e}");
    let e = err(&record("-6.2841853", "1", 1), InputFormat::JsonLines);
    assert!(e.message().starts_with("angle_min"), "{e}");
    // The largest f32 inside the limit is accepted and reads back.
    let limit = std::f64::consts::TAU + 1e-3;
    let mut inside = limit as f32;
    if inside as f64 > limit {
        inside = f32::from_bits(inside.to_bits() - 1);
    }
    for amin in [inside, -inside] {
        round_trips(
            &one(
                &record(&format!("{amin:?}"), "1", 1),
                InputFormat::JsonLines,
            )
            .unwrap(),
        );
    }
    // The span: 4 beams at increments around a third of the limit, in f64
    // steps finer than an f32 ulp. Accepted ones read back, and the
    // finding's value is rejected.
    let e = err(
        &record("0", "2.0946048752367683", 4),
        InputFormat::JsonLines,
    );
    assert!(e.message().contains("more than a full turn"), "{e}");
    let (mut accepted, mut rejected) = (0, 0);
    for k in -40..40 {
        let inc = 2.0946048752367683 + k as f64 * 3e-8;
        for sign in [1.0, -1.0] {
            match one(
                &record("0", &format!("{:?}", sign * inc), 4),
                InputFormat::JsonLines,
            ) {
                Ok(s) => {
                    round_trips(&s);
                    accepted += 1;
                }
                Err(e) => {
                    assert!(e.message().contains("more than a full turn"), "{e}");
                    rejected += 1;
                }
            }
        }
    }
    assert!(accepted > 0 && rejected > 0, "{accepted} / {rejected}");
    // An increment that is 0 or infinite as f32 is rejected, not stored.
    for inc in ["1e-50", "-1e-46"] {
        let e = err(&record("0", inc, 2), InputFormat::JsonLines);
        assert!(
            e.message().contains("32-bit float (rounds to"),
            "{inc}: {e}"
        );
    }
    let e = err(&record("0", "1e300", 1), InputFormat::JsonLines);
    assert!(e.message().contains("32-bit float (rounds to inf)"), "{e}");
    // ROBOTLASER1: the same checks on start_angle / angular_resolution.
    let robot = |start: &str, inc: &str| {
        format!("ROBOTLASER1 0 {start} 3.14 {inc} 30 0.01 0 2 1 1 0 0 0 0 0 0 0 0 0 0 0 0 1 h 2")
    };
    let e = err(&robot("6.2841853", "0.01"), InputFormat::Carmen);
    assert!(e.message().contains("start_angle (6.2841854)"), "{e}");
    let e = err(&robot("0", "1e-50"), InputFormat::Carmen);
    assert!(e.message().contains("angular_resolution"), "{e}");
    round_trips(&one(&robot("-1.57", "0.01"), InputFormat::Carmen).unwrap());
    // FLASER with a field of view override just over a turn (allowed up to
    // 2 pi + 1e-3): the beams would span more than the reader accepts back.
    let opts = ReadOptions {
        fov: Some((std::f64::consts::TAU + 9e-4) as f32),
        ..ReadOptions::default()
    };
    let v = read_all(
        flaser(1000, 2.0, "0 0 0").as_bytes(),
        InputFormat::Carmen,
        &opts,
    );
    let e = v[0].as_ref().unwrap_err();
    assert!(e.message().contains("more than a full turn"), "{e}");
    let opts = ReadOptions {
        fov: Some(std::f32::consts::TAU),
        ..ReadOptions::default()
    };
    let v = read_all(
        flaser(1000, 2.0, "0 0 0").as_bytes(),
        InputFormat::Carmen,
        &opts,
    );
    round_trips(v[0].as_ref().unwrap());
}

#[test]
fn scan_to_json_round_trips_points() {
    let data = ScanData::Points {
        points: vec![[1.0, -2.5], [1e-7, 123456.79], [-0.0, 3.0]],
        range_max: 8.0,
    };
    let json = scan_to_json(&data, "", None);
    let s = one(&json, InputFormat::JsonLines).unwrap();
    assert_eq!(s.data, data);
    assert_eq!((s.id.as_str(), s.truth), ("", None));
}

#[test]
fn scan_to_json_writes_null_for_non_finite() {
    let data = ScanData::Points {
        points: vec![[f32::NAN, 1.0]],
        range_max: 8.0,
    };
    let json = scan_to_json(&data, "x", Some([f64::NAN, 0.0, 0.0]));
    assert_eq!(
        json,
        r#"{"id":"x","range_max":8.0,"points":[[null,1.0]],"truth":[null,0.0,0.0]}"#
    );
}

// ---------------------------------------------------------------------------
// Files.

#[test]
fn open_input_plain_gzip_and_magic() {
    let dir = tempfile::tempdir().unwrap();
    let text = "FLASER 1 1 0 0 0 0 0 0\nFLASER 1 2 0 0 0 0 0 0\n";
    let plain = dir.path().join("a.log");
    std::fs::write(&plain, text).unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(text.as_bytes()).unwrap();
    let gz_bytes = gz.finish().unwrap();
    let named = dir.path().join("a.log.gz");
    std::fs::write(&named, &gz_bytes).unwrap();
    let unnamed = dir.path().join("b.log");
    std::fs::write(&unnamed, &gz_bytes).unwrap();
    // Two gzip members back to back read as one stream.
    let multi = dir.path().join("c.gz");
    std::fs::write(&multi, [gz_bytes.clone(), gz_bytes.clone()].concat()).unwrap();
    for (path, n) in [(&plain, 2), (&named, 2), (&unnamed, 2), (&multi, 4)] {
        let r = open_input(path.to_str().unwrap()).unwrap();
        let v: Vec<_> = read_scans(r, InputFormat::Auto, &ReadOptions::default()).collect();
        assert_eq!(v.len(), n, "{path:?}");
        assert!(v.iter().all(|s| s.is_ok()), "{v:?}");
    }
    // A .gz name with plain content, and a truncated gzip stream: a read error.
    let fake = dir.path().join("fake.gz");
    std::fs::write(&fake, text).unwrap();
    let truncated = dir.path().join("t.gz");
    std::fs::write(&truncated, &gz_bytes[..gz_bytes.len() / 2]).unwrap();
    for path in [&fake, &truncated] {
        let r = open_input(path.to_str().unwrap()).unwrap();
        let v: Vec<_> = read_scans(r, InputFormat::Auto, &ReadOptions::default()).collect();
        let last = v.last().unwrap().as_ref().unwrap_err();
        assert!(last.message().contains("read error"), "{last}");
    }
    assert!(open_input(dir.path().join("missing").to_str().unwrap()).is_err());
    // Empty and one-byte files.
    let empty = dir.path().join("e");
    std::fs::write(&empty, b"").unwrap();
    assert_eq!(
        read_scans(
            open_input(empty.to_str().unwrap()).unwrap(),
            InputFormat::Auto,
            &ReadOptions::default()
        )
        .count(),
        0
    );
    std::fs::write(&empty, [0x1f]).unwrap();
    assert_eq!(
        read_scans(
            open_input(empty.to_str().unwrap()).unwrap(),
            InputFormat::Auto,
            &ReadOptions::default()
        )
        .count(),
        1
    );
}

#[test]
fn poses_in_map_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("p.txt");
    std::fs::write(
        &p,
        "# header\n0 1.1e9 1.1e9 49.7 42.8 -1.7\n\n5 1 2 3 4 5\n",
    )
    .unwrap();
    assert_eq!(
        read_poses_in_map(&p).unwrap(),
        vec![(0, [49.7, 42.8, -1.7]), (5, [3.0, 4.0, 5.0])]
    );
    for bad in [
        "0 1 2 3 4\n",
        "x 1 2 3 4 5\n",
        "-1 1 2 3 4 5\n",
        "0 1 2 3 nan 5\n",
        "0 1 2 3 4 5 6\n",
    ] {
        std::fs::write(&p, bad).unwrap();
        let e = read_poses_in_map(&p).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData, "{bad}");
        assert!(e.to_string().contains("line 1"), "{e}");
    }
    // A file (or stream) with more poses than the bound is refused at the
    // first pose past it, naming the line.
    std::fs::write(&p, "0 0 0 1 2 3\n".repeat(5)).unwrap();
    let e = read_poses_at_most(&p, 3).unwrap_err();
    assert!(
        e.to_string().contains("line 4") && e.to_string().contains("more than 3"),
        "{e}"
    );
    assert_eq!(read_poses_at_most(&p, 5).unwrap().len(), 5);
}

// ---------------------------------------------------------------------------
// The shared real logs (skipped when /work/shared is absent).

fn shared_logs() -> Option<std::path::PathBuf> {
    let dir =
        std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/logs"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("skipping: shared logs not found at {}", dir.display());
        None
    }
}

#[test]
fn shared_carmen_logs() {
    let Some(dir) = shared_logs() else { return };
    // (name, scans, beams, step in degrees, max range from PARAM or the default 30 m)
    for (name, scans, beams, step, max) in [
        ("csail", 406, 361, 0.5f32, 50.0f32),
        ("aces", 440, 180, 1.0, 30.0),
        ("freiburg-campus", 2008, 360, 0.5, 80.99),
    ] {
        let path = dir.join(name).join(format!("{name}-corrected.log.gz"));
        if !path.exists() {
            eprintln!("skipping {}: not found", path.display());
            continue;
        }
        let r = open_input(path.to_str().unwrap()).unwrap();
        let mut n = 0;
        let mut returns = 0usize;
        for (k, item) in read_scans(r, InputFormat::Auto, &ReadOptions::default()).enumerate() {
            let s = item.unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(s.id, format!("scan {k}"));
            assert!(s.truth.is_some());
            let (amin, inc, _, rmax, r) = ranges_of(&s);
            assert_eq!(r.len(), beams, "{name} {}", s.id);
            assert_eq!(amin, -PI32 / 2.0);
            assert!((inc - step.to_radians()).abs() < 1e-7, "{name}: {inc}");
            assert_eq!(rmax, max, "{name}");
            returns += r.iter().filter(|r| r.is_finite()).count();
            n += 1;
        }
        assert_eq!(n, scans, "{name}");
        eprintln!("{name}: {n} scans of {beams} beams, {returns} returns");
        assert!(returns > n * beams / 2, "{name}: {returns}");

        let poses = dir.join(name).join(format!("{name}-poses-in-map.txt"));
        if poses.exists() {
            let p = read_poses_in_map(&poses).unwrap();
            assert_eq!(p.len(), scans, "{name} poses");
            assert!(p.iter().enumerate().all(|(k, (i, _))| *i == k));
        }
    }
}

#[test]
fn carmen_raw_laser_only_log_says_so_at_the_end() {
    let raw = "RAWLASER1 0 -1.5708 3.14159 0.0175 81.9 0.01 0 3 2.0 2.0 2.0 0 1.0 host 1.0";
    let log =
        format!("PARAM robot_front_laser_max 50\nODOM 1 2 3 0 0 0 1.0 host 1.0\n{raw}\n{raw}\n");
    let items = read(&log, InputFormat::Auto);
    assert_eq!(items.len(), 1, "{items:?}");
    let e = items[0].as_ref().unwrap_err();
    assert_eq!(e.kind, ScanErrorKind::RawLaserOnly(2));
    assert_eq!(e.line, 3, "points at the first raw laser line");
    assert!(e.to_string().contains("2 RAWLASERk lines"), "{e}");
    // With a scan line too, the raw ones are skipped silently, as before.
    let tail = "1 2 3 1134863807.7 b21 12.5";
    let mixed = format!("{raw}\n{}\n{raw}\n", flaser(180, 2.0, tail));
    let items = read(&mixed, InputFormat::Carmen);
    assert_eq!(items.len(), 1);
    assert_eq!(items[0].as_ref().unwrap().id, "scan 0");
    // RAWLASER alone is not a laser keyword of any other kind.
    assert!(!is_raw_laser(b"RAWLASER") && is_raw_laser(b"RAWLASER12"));
    assert!(read("ODOM 1 2 3 0 0 0 1.0 host 1.0\n", InputFormat::Carmen).is_empty());
}
