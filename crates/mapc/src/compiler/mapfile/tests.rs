use super::*;
use std::fs;

/// The largest map-size limit: the file-size bounds behind the cell limit
/// are tested with it.
const WIDEST: MapLimits = MapLimits {
    max_cells: MAX_CELLS,
};

/// Writes an 8-bit binary PGM, rows top first.
fn write_pgm(path: &Path, w: usize, h: usize, px: &[u8]) {
    assert_eq!(px.len(), w * h);
    let mut b = format!("P5\n# test\n{w} {h}\n255\n").into_bytes();
    b.extend_from_slice(px);
    fs::write(path, b).unwrap();
}

fn write_yaml(path: &Path, text: &str) {
    fs::write(path, text).unwrap();
}

const STD: &str = "resolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n";

/// 3x2 image: top row 0 (black), 254 (white), 205 (grey); bottom row 254 x3.
const PX: [u8; 6] = [0, 254, 205, 254, 254, 254];

fn setup(yaml_extra: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    write_pgm(&dir.path().join("m.pgm"), 3, 2, &PX);
    let y = dir.path().join("m.yaml");
    write_yaml(&y, &format!("image: m.pgm\n{yaml_extra}"));
    (dir, y)
}

#[test]
fn loads_standard_yaml_and_flips_rows() {
    let (_d, y) = setup(STD);
    let m = load_yaml(&y).unwrap();
    let g = &m.grid;
    assert_eq!((g.width, g.height), (3, 2));
    assert_eq!(g.resolution, 0.05);
    assert_eq!(g.origin, [0.0, 0.0, 0.0]);
    // Image top row is grid row cy = 1.
    assert_eq!(g.get(0, 1), Cell::Occupied);
    assert_eq!(g.get(1, 1), Cell::Free);
    assert_eq!(g.get(2, 1), Cell::Unknown);
    for cx in 0..3 {
        assert_eq!(g.get(cx, 0), Cell::Free);
    }
    assert_eq!(g.get(3, 0), Cell::Unknown, "outside the grid");
    assert_eq!(g.free_count(), 4);
    assert_eq!(m.mode, Mode::Trinary);
    assert!(!m.negate);
    assert_eq!(m.occupied_thresh, 0.65);
    assert_eq!(m.free_thresh, 0.196);
    assert_eq!(m.yaml_path.as_deref(), Some(y.as_path()));
    assert!(m.image_path.ends_with("m.pgm"));
    let yaml_bytes = fs::read(&y).unwrap();
    assert_eq!(m.yaml_sha256, Some(sha256(&yaml_bytes)));
    assert_eq!(m.image_sha256, sha256(&fs::read(&m.image_path).unwrap()));
}

#[test]
fn accepts_ints_comments_bools_and_tags() {
    let (_d, y) = setup(
        "# a comment\nresolution: 1 # metres\norigin: [-15, 2.5, !!float 0]\nnegate: false\noccupied_thresh: 1\nfree_thresh: 0.3\nmode: Trinary\nextra_key: [1, 2]\n",
    );
    let m = load_yaml(&y).unwrap();
    assert_eq!(m.grid.resolution, 1.0);
    assert_eq!(m.grid.origin, [-15.0, 2.5, 0.0]);
    assert_eq!(m.occupied_thresh, 1.0);
    assert_eq!(m.free_thresh, 0.3);
    assert!(!m.negate);
    // Grey 205 (p = 0.196) is free with free_thresh 0.3.
    assert_eq!(m.grid.get(2, 1), Cell::Free);
}

#[test]
fn negate_missing_defaults_to_false_and_mode_optional() {
    let (_d, y) =
        setup("resolution: 0.1\norigin: [1, 2, 0.5]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n");
    let m = load_yaml(&y).unwrap();
    assert!(!m.negate);
    assert_eq!(m.grid.origin, [1.0, 2.0, 0.5]);
    assert_eq!(m.grid.resolution, 0.1);
}

#[test]
fn negate_inverts() {
    for negate in ["1", "true"] {
        let (_d, y) = setup(&STD.replace("negate: 0", &format!("negate: {negate}")));
        let m = load_yaml(&y).unwrap();
        assert!(m.negate);
        let g = &m.grid;
        // Black (0) is free now, white (254) occupied, grey 205 -> p=0.80 occupied.
        assert_eq!(g.get(0, 1), Cell::Free);
        assert_eq!(g.get(1, 1), Cell::Occupied);
        assert_eq!(g.get(2, 1), Cell::Occupied);
        assert_eq!(g.free_count(), 1);
    }
}

#[test]
fn thresholds_are_strict_like_map_server() {
    // Pixel 205: p = 50/255 = 0.19608 -> not < 0.196: unknown; with
    // free_thresh 0.25 it is free.
    let (_d, y) = setup(&STD.replace("free_thresh: 0.196", "free_thresh: 0.25"));
    let g = load_yaml(&y).unwrap().grid;
    assert_eq!(g.get(2, 1), Cell::Free);
}

#[test]
fn scale_mode() {
    let dir = tempfile::tempdir().unwrap();
    // Grey-alpha PNG: (value, alpha).
    let px: Vec<u8> = vec![
        254, 255, // free
        0, 255, // occupied
        128, 255, // p = 0.498: between thresholds -> unknown
        254, 128, // half transparent: unknown in scale mode
        254, 0, // fully transparent: unknown
        0, 254, // nearly opaque black: unknown in scale mode
    ];
    image::save_buffer(
        dir.path().join("s.png"),
        &px,
        6,
        1,
        image::ExtendedColorType::La8,
    )
    .unwrap();
    write_yaml(
        &dir.path().join("s.yaml"),
        &format!("image: s.png\nmode: scale\n{STD}"),
    );
    let m = load_yaml(&dir.path().join("s.yaml")).unwrap();
    assert_eq!(m.mode, Mode::Scale);
    let row: Vec<Cell> = (0..6).map(|x| m.grid.get(x, 0)).collect();
    use Cell::*;
    assert_eq!(row, [Free, Occupied, Unknown, Unknown, Unknown, Unknown]);
}

#[test]
fn trinary_mode_averages_alpha_like_map_server() {
    let dir = tempfile::tempdir().unwrap();
    let px: Vec<u8> = vec![
        254, 255, // free
        254, 200, // avg (3 * 254 + 200) / 4 = 240.5: p = 0.06 -> free
        254, 20, // avg 195.5: p = 0.233 -> unknown
        0, 0, // fully transparent black: unknown (not occupied)
        0, 255, // avg 63.75: p = 0.75 -> occupied
    ];
    image::save_buffer(
        dir.path().join("t.png"),
        &px,
        5,
        1,
        image::ExtendedColorType::La8,
    )
    .unwrap();
    write_yaml(
        &dir.path().join("t.yaml"),
        &format!("image: t.png\nmode: trinary\n{STD}"),
    );
    let g = load_yaml(&dir.path().join("t.yaml")).unwrap().grid;
    use Cell::*;
    let row: Vec<Cell> = (0..5).map(|x| g.get(x, 0)).collect();
    assert_eq!(row, [Free, Free, Unknown, Unknown, Occupied]);
}

#[test]
fn raw_mode() {
    let dir = tempfile::tempdir().unwrap();
    // 0 free, 100 occupied, 255 unknown, 10 (p=0.1 < 0.196) free,
    // 50 unknown, 70 occupied, 101 unknown.
    write_pgm(
        &dir.path().join("r.pgm"),
        7,
        1,
        &[0, 100, 255, 10, 50, 70, 101],
    );
    // negate is ignored in raw mode (Nav2).
    write_yaml(
        &dir.path().join("r.yaml"),
        &format!(
            "image: r.pgm\nmode: raw\n{}",
            STD.replace("negate: 0", "negate: 1")
        ),
    );
    let m = load_yaml(&dir.path().join("r.yaml")).unwrap();
    assert_eq!(m.mode, Mode::Raw);
    use Cell::*;
    let row: Vec<Cell> = (0..7).map(|x| m.grid.get(x, 0)).collect();
    assert_eq!(
        row,
        [Free, Occupied, Unknown, Free, Unknown, Occupied, Unknown]
    );
}

#[test]
fn rgb_png_channels_are_averaged() {
    let dir = tempfile::tempdir().unwrap();
    let px: Vec<u8> = vec![
        254, 254, 254, // free
        0, 0, 0, // occupied
        255, 0, 0, // avg 85: p = 0.667 -> occupied
        255, 255, 0, // avg 170: p = 0.333 -> unknown
    ];
    image::save_buffer(
        dir.path().join("c.png"),
        &px,
        4,
        1,
        image::ExtendedColorType::Rgb8,
    )
    .unwrap();
    let m = load_image(&dir.path().join("c.png"), Some(0.1), None).unwrap();
    use Cell::*;
    let row: Vec<Cell> = (0..4).map(|x| m.grid.get(x, 0)).collect();
    assert_eq!(row, [Free, Occupied, Occupied, Unknown]);
    assert_eq!(m.grid.origin, [0.0; 3]);
    assert!(m.yaml_path.is_none() && m.yaml_sha256.is_none());
}

#[test]
fn sixteen_bit_pgm() {
    let dir = tempfile::tempdir().unwrap();
    let mut b = b"P5\n3 1\n65535\n".to_vec();
    for v in [65535u16, 0, 52685] {
        b.extend_from_slice(&v.to_be_bytes());
    }
    fs::write(dir.path().join("w.pgm"), b).unwrap();
    write_yaml(&dir.path().join("w.yaml"), &format!("image: w.pgm\n{STD}"));
    let g = load_yaml(&dir.path().join("w.yaml")).unwrap().grid;
    use Cell::*;
    // 52685 -> 205 (8 bits): unknown.
    assert_eq!(
        [g.get(0, 0), g.get(1, 0), g.get(2, 0)],
        [Free, Occupied, Unknown]
    );
}

#[test]
fn absolute_image_path() {
    let dir = tempfile::tempdir().unwrap();
    let other = tempfile::tempdir().unwrap();
    let img = dir.path().join("a.pgm");
    write_pgm(&img, 3, 2, &PX);
    let y = other.path().join("a.yaml");
    write_yaml(&y, &format!("image: {}\n{STD}", img.display()));
    let m = load_yaml(&y).unwrap();
    assert_eq!(m.image_path, img);
}

fn err_of(yaml_extra: &str) -> MapError {
    let (_d, y) = setup(yaml_extra);
    load_yaml(&y).unwrap_err()
}

#[test]
fn missing_image_file() {
    let dir = tempfile::tempdir().unwrap();
    let y = dir.path().join("x.yaml");
    write_yaml(&y, &format!("image: nothere.pgm\n{STD}"));
    let e = load_yaml(&y).unwrap_err();
    assert!(matches!(e, MapError::ImageMissing { .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains("nothere.pgm") && msg.contains("x.yaml"),
        "{msg}"
    );
}

#[test]
fn missing_yaml_file() {
    let e = load_yaml(Path::new("/nonexistent/dir/m.yaml")).unwrap_err();
    assert!(matches!(e, MapError::Io { .. }), "{e}");
    assert!(e.to_string().contains("/nonexistent/dir/m.yaml"));
}

#[test]
fn malformed_yaml_reports_line() {
    let e = err_of("resolution: 0.05\norigin: [0, 0, 0\nnegate: 0\n");
    match &e {
        MapError::YamlSyntax { line, .. } => assert!(line.is_some()),
        other => panic!("{other}"),
    }
    assert!(e.to_string().contains("m.yaml"), "{e}");
    let e = err_of("resolution: 0.05\nresolution: 0.1\n");
    assert!(
        matches!(e, MapError::YamlSyntax { .. }),
        "duplicate key: {e}"
    );
    let e = err_of("");
    // Only "image: m.pgm": the other required fields are missing.
    assert!(
        matches!(
            e,
            MapError::MissingField {
                field: "resolution",
                ..
            }
        ),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let y = dir.path().join("list.yaml");
    write_yaml(&y, "- 1\n- 2\n");
    assert!(matches!(
        load_yaml(&y).unwrap_err(),
        MapError::YamlSyntax { .. }
    ));
    write_yaml(&y, "");
    assert!(matches!(
        load_yaml(&y).unwrap_err(),
        MapError::YamlSyntax { .. }
    ));
    fs::write(&y, b"image: \xff\xfe\n").unwrap();
    assert!(matches!(
        load_yaml(&y).unwrap_err(),
        MapError::YamlSyntax { .. }
    ));
    write_yaml(&y, &"[".repeat(100_000));
    assert!(matches!(
        load_yaml(&y).unwrap_err(),
        MapError::YamlSyntax { .. }
    ));
}

#[test]
fn missing_and_ill_typed_fields() {
    let e = err_of(&STD.replace("origin: [0.0, 0.0, 0.0]\n", ""));
    assert!(
        matches!(
            e,
            MapError::MissingField {
                field: "origin",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("origin"));
    let e = err_of(&STD.replace("free_thresh: 0.196\n", ""));
    assert!(
        matches!(
            e,
            MapError::MissingField {
                field: "free_thresh",
                ..
            }
        ),
        "{e}"
    );
    let e = err_of(&STD.replace("[0.0, 0.0, 0.0]", "[0.0, 0.0]"));
    assert!(
        matches!(
            e,
            MapError::BadField {
                field: "origin",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("2 items"), "{e}");
    let e = err_of(&STD.replace("[0.0, 0.0, 0.0]", "[0.0, abc, 0.0]"));
    assert!(
        matches!(
            e,
            MapError::BadField {
                field: "origin",
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("abc"), "{e}");
    let e = err_of(&STD.replace("negate: 0", "negate: maybe"));
    assert!(
        matches!(
            e,
            MapError::BadField {
                field: "negate",
                ..
            }
        ),
        "{e}"
    );
    let e = err_of(&format!("{STD}mode: fancy\n"));
    assert!(matches!(e, MapError::BadField { field: "mode", .. }), "{e}");
    assert!(e.to_string().contains("fancy"));
    let e = err_of(&STD.replace("occupied_thresh: 0.65", "occupied_thresh: [1]"));
    assert!(
        matches!(
            e,
            MapError::BadField {
                field: "occupied_thresh",
                ..
            }
        ),
        "{e}"
    );
    let (_d, y) = setup("");
    write_yaml(&y, &format!("image: [a]\n{STD}"));
    let e = load_yaml(&y).unwrap_err();
    assert!(
        matches!(e, MapError::BadField { field: "image", .. }),
        "{e}"
    );
}

#[test]
fn bad_resolution() {
    for r in ["0", "-0.05", ".nan", ".inf"] {
        let e = err_of(&STD.replace("0.05", r));
        assert!(matches!(e, MapError::BadResolution { .. }), "{r}: {e}");
    }
    let e = err_of(&STD.replace("0.05", "fine"));
    assert!(
        matches!(
            e,
            MapError::BadField {
                field: "resolution",
                ..
            }
        ),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let img = dir.path().join("q.pgm");
    write_pgm(&img, 3, 2, &PX);
    let e = load_image(&img, Some(0.0), None).unwrap_err();
    assert!(matches!(e, MapError::BadResolution { .. }), "{e}");
}

#[test]
fn bad_thresholds() {
    for (o, f) in [
        ("0.65", "0.7"),
        ("1.5", "0.2"),
        ("0.65", "-0.1"),
        ("0.5", "0.5"),
    ] {
        let e = err_of(
            &STD.replace("occupied_thresh: 0.65", &format!("occupied_thresh: {o}"))
                .replace("free_thresh: 0.196", &format!("free_thresh: {f}")),
        );
        assert!(matches!(e, MapError::BadThresholds { .. }), "{o} {f}: {e}");
    }
}

#[test]
fn no_free_cell() {
    let dir = tempfile::tempdir().unwrap();
    write_pgm(&dir.path().join("b.pgm"), 2, 2, &[0, 0, 205, 0]);
    write_yaml(&dir.path().join("b.yaml"), &format!("image: b.pgm\n{STD}"));
    let e = load_yaml(&dir.path().join("b.yaml")).unwrap_err();
    assert!(matches!(e, MapError::NoFreeCell { .. }), "{e}");
}

#[test]
fn undecodable_images() {
    let dir = tempfile::tempdir().unwrap();
    let y = dir.path().join("u.yaml");
    write_yaml(&y, &format!("image: u.pgm\n{STD}"));
    for bytes in [
        &b"hello world"[..],
        &b"P5\n3 2\n255\n\x00\x01"[..], // truncated data
        &b"P5\n0 2\n255\n"[..],
        &b"P5\n3 2\n0\n\x00\x00\x00\x00\x00\x00"[..], // maxval 0
        &b"\x89PNG\r\n\x1a\nnonsense"[..],
        &b""[..],
    ] {
        fs::write(dir.path().join("u.pgm"), bytes).unwrap();
        let e = load_yaml(&y).unwrap_err();
        assert!(matches!(e, MapError::ImageDecode { .. }), "{bytes:?}: {e}");
        assert!(e.to_string().contains("u.pgm"), "{e}");
    }
}

#[test]
fn huge_header_with_tiny_file() {
    let dir = tempfile::tempdir().unwrap();
    let y = dir.path().join("h.yaml");
    write_yaml(&y, &format!("image: h.pgm\n{STD}"));
    // Beyond the cell limit: refused from the header.
    fs::write(
        dir.path().join("h.pgm"),
        b"P5\n100000 100000\n255\n\x00\x00",
    )
    .unwrap();
    let e = load_yaml(&y).unwrap_err();
    assert!(
        matches!(e, MapError::ImageTooLarge { width: 100000, .. }),
        "{e}"
    );
    fs::write(dir.path().join("h.pgm"), b"P5\n300000 2\n255\n\x00\x00").unwrap();
    let e = load_yaml(&y).unwrap_err();
    assert!(matches!(e, MapError::ImageTooLarge { .. }), "{e}");
    // Beyond the default --max-cells: refused from the header, naming the
    // option and the true sizes.
    fs::write(dir.path().join("h.pgm"), b"P5\n40000 40000\n255\n\x00\x00").unwrap();
    let e = load_yaml(&y).unwrap_err();
    assert!(
        matches!(e, MapError::ImageTooLarge { decoded: None, .. }),
        "{e}"
    );
    assert!(
        e.to_string().contains(
            "40000 x 40000 pixels (1600000000 cells); the limit is 268435456 cells, \
             1073741824 decoded bytes"
        ) && e.to_string().contains("--max-cells"),
        "{e}"
    );
    // Within the largest limit but the file cannot hold that many pixels:
    // refused before the decoder allocates 1.6 GB.
    let e = load_yaml_within(&y, &WIDEST).unwrap_err();
    assert!(matches!(e, MapError::ImageDecode { .. }), "{e}");
    assert!(e.to_string().contains("truncated"), "{e}");
    // A PNG header claiming 40000 x 40000 in a few dozen bytes.
    let mut png = b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR".to_vec();
    png.extend_from_slice(&40000u32.to_be_bytes());
    png.extend_from_slice(&40000u32.to_be_bytes());
    png.extend_from_slice(&[8, 0, 0, 0, 0]);
    let mut crc_in = b"IHDR".to_vec();
    crc_in.extend_from_slice(&png[16..29]);
    png.extend_from_slice(&crc32(&crc_in).to_be_bytes());
    fs::write(dir.path().join("h.png"), &png).unwrap();
    write_yaml(&y, &format!("image: h.png\n{STD}"));
    let e = load_yaml(&y).unwrap_err();
    assert!(matches!(e, MapError::ImageDecode { .. }), "{e}");
}

use crate::testdata::png::{chunk, crc32};

#[test]
fn load_image_forms() {
    let dir = tempfile::tempdir().unwrap();
    let img = dir.path().join("lab.pgm");
    write_pgm(&img, 3, 2, &PX);
    // No YAML, no resolution: a helpful error.
    let e = load_image(&img, None, None).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, MapError::NoYamlBeside { .. }));
    assert!(
        msg.contains("no lab.yaml beside lab.pgm; pass --resolution (m/cell) and optionally --origin x,y,yaw"),
        "{msg}"
    );
    // Resolution given: origin defaults to zero.
    let m = load_image(&img, Some(0.1), None).unwrap();
    assert_eq!(m.grid.resolution, 0.1);
    assert_eq!(m.grid.origin, [0.0; 3]);
    let m = load_image(&img, Some(0.1), Some([1.0, 2.0, 0.0])).unwrap();
    assert_eq!(m.grid.origin, [1.0, 2.0, 0.0]);
    // A YAML beside it is used.
    write_yaml(
        &dir.path().join("lab.yaml"),
        &format!("image: lab.pgm\n{STD}"),
    );
    let m = load_image(&img, None, None).unwrap();
    assert_eq!(m.grid.resolution, 0.05);
    assert!(m.yaml_path.is_some());
    assert!(load_image(&img, Some(0.05), Some([0.0; 3])).is_ok());
    let e = load_image(&img, Some(0.1), None).unwrap_err();
    assert!(
        matches!(
            e,
            MapError::Conflict {
                field: "resolution",
                ..
            }
        ),
        "{e}"
    );
    // ... and must describe this image.
    write_pgm(&dir.path().join("other.pgm"), 3, 2, &PX);
    write_yaml(
        &dir.path().join("lab.yaml"),
        &format!("image: other.pgm\n{STD}"),
    );
    let e = load_image(&img, None, None).unwrap_err();
    assert!(matches!(e, MapError::ImageMismatch { .. }), "{e}");
    // Missing image without YAML.
    let e = load_image(&dir.path().join("none.pgm"), Some(0.1), None).unwrap_err();
    assert!(matches!(e, MapError::ImageMissing { .. }), "{e}");
}

#[test]
fn blocked_bits_layout() {
    let g = OccupancyGrid::from_ascii(
        &[
            "#..?.", //
            ".....", "?#...", "....#", ".....", ".....", "....#",
        ],
        0.1,
        [0.0; 3],
    );
    assert_eq!((g.width, g.height), (5, 7));
    for unknown_blocks in [false, true] {
        let words = g.blocked_bits(unknown_blocks);
        assert_eq!(words.len(), BitGrid::words_for(5, 7));
        let bg = BitGrid::new(5, 7, &words).unwrap();
        use refloc::raycast::Occupancy;
        for cy in 0..7 {
            for cx in 0..5 {
                let want = match g.get(cx, cy) {
                    Cell::Free => false,
                    Cell::Occupied => true,
                    Cell::Unknown => unknown_blocks,
                };
                assert_eq!(bg.blocked(cx, cy), want, "{cx},{cy}");
            }
        }
    }
    assert_eq!(g.get(4, 0), Cell::Occupied);
    assert_eq!(g.get(0, 6), Cell::Occupied);
    assert_eq!(g.get(3, 6), Cell::Unknown);
}

#[test]
fn cell_center_and_frame_agree() {
    let g = OccupancyGrid::from_cells(4, 3, 0.05, [1.0, -2.0, 0.5], vec![Cell::Free; 12]);
    let f = g.frame();
    for (cx, cy) in [(0, 0), (3, 2), (1, 2)] {
        let c = g.cell_center(cx, cy);
        let m = f.to_map([cx as f32 + 0.5, cy as f32 + 0.5]);
        assert!((c[0] - m[0] as f64).abs() < 1e-5 && (c[1] - m[1] as f64).abs() < 1e-5);
        let uv = f.to_cells([c[0] as f32, c[1] as f32]);
        assert!((uv[0] - (cx as f32 + 0.5)).abs() < 1e-3);
        assert!((uv[1] - (cy as f32 + 0.5)).abs() < 1e-3);
    }
    let c =
        OccupancyGrid::from_cells(1, 1, 2.0, [0.0, 0.0, 0.0], vec![Cell::Free]).cell_center(0, 0);
    assert_eq!(c, [1.0, 1.0]);
}

/// The shared maps directory (`/work/shared/maps`), when present.
pub(crate) fn shared_maps() -> Option<Vec<PathBuf>> {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/maps"));
    let Ok(rd) = fs::read_dir(dir) else {
        eprintln!("skipping: shared maps not found at {}", dir.display());
        return None;
    };
    let mut yamls = Vec::new();
    for e in rd.flatten() {
        if let Ok(inner) = fs::read_dir(e.path()) {
            for f in inner.flatten() {
                if f.path().extension().is_some_and(|x| x == "yaml") {
                    yamls.push(f.path());
                }
            }
        }
    }
    yamls.sort();
    Some(yamls)
}

#[test]
fn every_shared_map_loads() {
    let Some(yamls) = shared_maps() else { return };
    assert_eq!(yamls.len(), 9, "{yamls:?}");
    for y in &yamls {
        let m = load_yaml(y).unwrap_or_else(|e| panic!("{e}"));
        let g = &m.grid;
        let occ = g.cells.iter().filter(|&&c| c == Cell::Occupied).count();
        eprintln!(
            "{:<28} {:>5} x {:<5} res {:.3} origin {:?} free {:>8} occupied {:>7}",
            y.file_name().unwrap().to_string_lossy(),
            g.width,
            g.height,
            g.resolution,
            g.origin,
            g.free_count(),
            occ
        );
        assert!(g.free_count() > 1000);
        assert!(occ > 100);
    }
}

// ---------------------------------------------------------------------------
// PNG colour types and bit depths, and the memory bound from the header.

/// A PNG (no interlace) of `w x h` pixels: `colour` and `depth` as in IHDR,
/// `samples` one value per channel (palette index for colour type 3), each
/// below `2^depth`, rows top first; `plte` / `trns` written when non-empty.
fn png(
    w: u32,
    h: u32,
    depth: u8,
    colour: u8,
    samples: &[u16],
    plte: &[u8],
    trns: &[u8],
) -> Vec<u8> {
    use std::io::Write as _;
    let channels = match colour {
        0 | 3 => 1,
        4 => 2,
        2 => 3,
        _ => 4,
    };
    let per_row = w as usize * channels;
    assert_eq!(samples.len(), per_row * h as usize);
    let mut raw = Vec::new();
    for row in samples.chunks(per_row) {
        raw.push(0); // filter: none
        if depth >= 8 {
            for &v in row {
                if depth == 16 {
                    raw.extend_from_slice(&v.to_be_bytes());
                } else {
                    raw.push(v as u8);
                }
            }
        } else {
            let mut bits = 0u32;
            let mut n = 0;
            for &v in row {
                bits = (bits << depth) | v as u32;
                n += depth as u32;
                if n == 8 {
                    raw.push(bits as u8);
                    (bits, n) = (0, 0);
                }
            }
            if n > 0 {
                raw.push((bits << (8 - n)) as u8);
            }
        }
    }
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    z.write_all(&raw).unwrap();
    let idat = z.finish().unwrap();
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[depth, colour, 0, 0, 0]);
    chunk(&mut out, b"IHDR", &ihdr);
    if !plte.is_empty() {
        chunk(&mut out, b"PLTE", plte);
    }
    if !trns.is_empty() {
        chunk(&mut out, b"tRNS", trns);
    }
    chunk(&mut out, b"IDAT", &idat);
    chunk(&mut out, b"IEND", &[]);
    out
}

/// Every PNG colour type and bit depth decodes to the cells its 8-bit
/// equivalent gives: low depths are scaled up (1-bit 1 is 255), 16-bit
/// samples are narrowed as `round(v * 255 / 65535)` whatever the byte
/// order, palettes are expanded (with tRNS alpha when present).
#[test]
fn png_every_colour_type_and_depth() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.png");
    let params = Params {
        negate: false,
        occupied_thresh: DEFAULT_OCCUPIED_THRESH,
        free_thresh: DEFAULT_FREE_THRESH,
        mode: Mode::Trinary,
    };
    let (w, h) = (4u32, 2u32);
    // Grey levels (8-bit) in image order, all multiples of 85 so that 2- and
    // 4-bit images hold them exactly; 1-bit images use only 0 and 255.
    let grey = [0u16, 255, 170, 85, 255, 255, 0, 170];
    let grey1 = [0u16, 255, 255, 0, 255, 255, 0, 255];
    let alpha = [255u16, 255, 0, 255, 128, 255, 255, 255];
    let load = |bytes: &[u8]| {
        fs::write(&path, bytes).unwrap();
        load_image(&path, Some(0.1), None)
            .unwrap_or_else(|e| panic!("{e}"))
            .grid
    };
    // The cells of an image whose 8-bit pixels (rows top first) are `px`.
    let expect = |px: &[Vec<u8>], has_alpha: bool| -> Vec<Cell> {
        let mut cells = Vec::new();
        for row in px.chunks(w as usize).rev() {
            cells.extend(row.iter().map(|p| classify_pixel(p, has_alpha, &params)));
        }
        cells
    };
    let mut checked = 0;
    for depth in [1u8, 2, 4, 8, 16] {
        let max = (1u32 << depth) - 1;
        let levels: &[u16] = if depth == 1 { &grey1 } else { &grey };
        let to = |v8: u16| (v8 as u32 * max / 255) as u16;
        // Grey.
        let s: Vec<u16> = levels.iter().map(|&v| to(v)).collect();
        let g = load(&png(w, h, depth, 0, &s, &[], &[]));
        let px: Vec<Vec<u8>> = levels.iter().map(|&v| vec![v as u8]).collect();
        assert_eq!(g.cells, expect(&px, false), "grey {depth}");
        checked += 1;
        // Palette (depths up to 8): index k has grey level levels[k], with
        // and without per-entry alpha.
        if depth <= 8 {
            let n = levels.len().min(1 << depth);
            let plte: Vec<u8> = levels[..n].iter().flat_map(|&v| [v as u8; 3]).collect();
            let idx: Vec<u16> = (0..levels.len()).map(|k| (k % n) as u16).collect();
            let g = load(&png(w, h, depth, 3, &idx, &plte, &[]));
            let px: Vec<Vec<u8>> = idx
                .iter()
                .map(|&k| vec![levels[k as usize] as u8; 3])
                .collect();
            assert_eq!(g.cells, expect(&px, false), "palette {depth}");
            let trns: Vec<u8> = alpha[..n].iter().map(|&a| a as u8).collect();
            let g = load(&png(w, h, depth, 3, &idx, &plte, &trns));
            let px: Vec<Vec<u8>> = idx
                .iter()
                .map(|&k| {
                    let v = levels[k as usize] as u8;
                    vec![v, v, v, alpha[k as usize] as u8]
                })
                .collect();
            assert_eq!(g.cells, expect(&px, true), "palette {depth} with tRNS");
            checked += 2;
        }
        // Grey + alpha, RGB, RGBA: depths 8 and 16.
        if depth >= 8 {
            let wide = |v: u16| if depth == 16 { v * 257 } else { v };
            let s: Vec<u16> = (0..8)
                .flat_map(|i| [wide(grey[i]), wide(alpha[i])])
                .collect();
            let g = load(&png(w, h, depth, 4, &s, &[], &[]));
            let px: Vec<Vec<u8>> = (0..8)
                .map(|i| vec![grey[i] as u8, alpha[i] as u8])
                .collect();
            assert_eq!(g.cells, expect(&px, true), "grey+alpha {depth}");
            // RGB with unequal channels: (v, v / 2 + 127, v).
            let rgb = |i: usize| [grey[i], grey[i] / 2 + 127, grey[i]];
            let s: Vec<u16> = (0..8).flat_map(|i| rgb(i).map(wide)).collect();
            let g = load(&png(w, h, depth, 2, &s, &[], &[]));
            let px: Vec<Vec<u8>> = (0..8).map(|i| rgb(i).map(|v| v as u8).to_vec()).collect();
            assert_eq!(g.cells, expect(&px, false), "rgb {depth}");
            let s: Vec<u16> = (0..8)
                .flat_map(|i| {
                    let [r, g, b] = rgb(i);
                    [r, g, b, alpha[i]].map(wide)
                })
                .collect();
            let g = load(&png(w, h, depth, 6, &s, &[], &[]));
            let px: Vec<Vec<u8>> = (0..8)
                .map(|i| {
                    let [r, g, b] = rgb(i);
                    vec![r as u8, g as u8, b as u8, alpha[i] as u8]
                })
                .collect();
            assert_eq!(g.cells, expect(&px, true), "rgba {depth}");
            checked += 3;
        }
    }
    assert_eq!(checked, 5 + 2 * 4 + 3 * 2);
    // 16-bit rounding: 52685 -> 205 (unknown), 65535 -> 255, 128 -> 0 (not 1).
    let g = load(&png(3, 1, 16, 0, &[52685, 65535, 128], &[], &[]));
    assert_eq!(g.cells, [Cell::Unknown, Cell::Free, Cell::Occupied]);
}

/// A PNG's header declares the raw bits per pixel (colour type x bit
/// depth); the file must be at least `width * height * bits / 8 / 1032`
/// bytes (deflate's best ratio) or it is refused as truncated before the
/// pixel buffer is allocated (fuzz finding `png-rgba16-header-4gib-alloc`:
/// a 64 KB file claiming 23000 x 23000 RGBA16, 4.2 GB decoded). Files
/// just large enough are decoded (and fail on the cut-off data).
#[test]
fn png_header_size_needs_a_file_to_match() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.png");
    // (colour type, bit depth, bits per pixel)
    let kinds = [
        (0u8, 1u8, 1u64),
        (3, 1, 1),
        (0, 8, 8),
        (3, 8, 8),
        (0, 16, 16),
        (4, 8, 16),
        (2, 8, 24),
        (6, 8, 32),
        (4, 16, 32),
        (2, 16, 48),
        (6, 16, 64),
    ];
    for (colour, depth, bits) in kinds {
        // A valid 1 x 1 image of this kind, then IHDR patched to `side` x
        // `side` (CRC fixed): its IDAT is far too short for that.
        let channels = match colour {
            4 => 2,
            2 => 3,
            6 => 4,
            _ => 1,
        };
        let plte: &[u8] = if colour == 3 {
            &[0, 0, 0, 255, 255, 255]
        } else {
            &[]
        };
        let one_pixel = png(1, 1, depth, colour, &vec![0; channels], plte, &[]);
        for side in [1000u32, 23000, 46000] {
            let mut file = one_pixel.clone();
            file[16..20].copy_from_slice(&side.to_be_bytes());
            file[20..24].copy_from_slice(&side.to_be_bytes());
            let crc = crc32(&file[12..29]);
            file[29..33].copy_from_slice(&crc.to_be_bytes());
            let need = (side as u64 * side as u64 * bits).div_ceil(8) / 1032;
            // Just too short: refused from the header. Just long enough
            // (padding after IEND): decoded, and then the data is cut off;
            // tried only where the pixel buffer is small (this allocates it).
            let decoded =
                side as u64 * side as u64 * bits.max(8) / 8 * if colour == 3 { 3 } else { 1 };
            let mut lens = vec![need - 1];
            if decoded <= 64 << 20 {
                lens.push(need + 1);
            }
            for len in lens {
                let mut f = file.clone();
                assert!(f.len() as u64 <= len, "{} > {len}", f.len());
                f.resize(len as usize, 0);
                fs::write(&path, &f).unwrap();
                let e = load_image_within(&path, Some(0.1), None, &WIDEST).unwrap_err();
                // 16-bit RGB(A) at 46000 x 46000: over the largest decoded
                // size, refused from the header whatever the file length.
                if let MapError::ImageTooLarge {
                    decoded: Some(d), ..
                } = e
                {
                    assert!(d > WIDEST.decoded_bytes(), "{e}");
                    continue;
                }
                assert!(matches!(e, MapError::ImageDecode { .. }), "{e}");
                let truncated = e.to_string().contains("truncated: the header claims");
                assert_eq!(
                    truncated,
                    len < need,
                    "colour {colour} depth {depth} side {side}, {len} bytes (need {need}): {e}"
                );
            }
        }
    }
}
