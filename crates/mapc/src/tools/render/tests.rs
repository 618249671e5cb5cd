use super::*;

const BG: Rgb = [255, 255, 255];

fn white_map(w: u32, h: u32) -> Vec<u8> {
    vec![255u8; (w * h) as usize]
}

fn temp_png(name: &str) -> std::path::PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    std::env::temp_dir().join(format!(
        "mapc_render_{name}_{}_{nanos}.png",
        std::process::id()
    ))
}

/// A `w` x `h` map of 5 cm cells at the origin.
fn blank_layer(gray: &[u8], w: u32, h: u32) -> MapLayer<'_> {
    MapLayer {
        width: w,
        height: h,
        gray,
        resolution: 0.05,
        origin: [0.0; 3],
    }
}

fn count_color(r: &Raster, c: Rgb) -> usize {
    r.as_bytes().chunks_exact(3).filter(|p| *p == c).count()
}

fn close(a: (f64, f64), b: (f64, f64)) -> bool {
    (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9
}

#[test]
fn world_to_px_honours_resolution_and_origin() {
    let gray = white_map(10, 5);
    let map = MapLayer {
        width: 10,
        height: 5,
        gray: &gray,
        resolution: 0.5,
        origin: [-1.0, -2.0, 0.0],
    };
    let mut c = MapCanvas::with_scale(&map, 4.0);
    assert_eq!((c.width(), c.height()), (40, 20));
    assert_eq!(c.px_per_meter(), 8.0);
    // Centre of cell (2, 1): x = -1 + 2.5 * 0.5, y = -2 + 1.5 * 0.5.
    let (x, y) = (-1.0 + 1.25, -2.0 + 0.75);
    assert!(close(c.world_to_px(x, y), (10.0, 14.0)));
    assert!(close(c.cell_to_px(2.0, 1.0), (10.0, 14.0)));
    assert!(close(c.cell_to_world(2.0, 1.0), (x, y)));
    // The origin is the lower-left image corner.
    assert!(close(c.world_to_px(-1.0, -2.0), (0.0, 20.0)));

    c.dot(x, y, 1.5, color::RED);
    assert_eq!(c.raster().pixel(9, 13), Some(color::RED));
    assert_eq!(c.raster().pixel(10, 14), Some(color::RED));
    assert_eq!(c.raster().pixel(4, 4), Some(BG));

    // Cell (2, 1) covers image columns 8..12 and rows 12..16.
    c.fill_cell(2, 1, color::BLUE);
    assert_eq!(c.raster().pixel(8, 12), Some(color::BLUE));
    assert_eq!(c.raster().pixel(11, 15), Some(color::BLUE));
    assert_eq!(c.raster().pixel(12, 15), Some(BG));
    assert_eq!(c.raster().pixel(11, 16), Some(BG));
    assert_eq!(count_color(c.raster(), color::BLUE), 16);
}

#[test]
fn world_to_px_honours_origin_yaw() {
    let gray = white_map(20, 20);
    let map = MapLayer {
        width: 20,
        height: 20,
        gray: &gray,
        resolution: 0.1,
        origin: [1.0, 2.0, std::f64::consts::FRAC_PI_2],
    };
    let c = MapCanvas::with_scale(&map, 1.0);
    // With yaw = 90 degrees the map's x axis (image right) is world +y ...
    let p = c.world_to_px(1.0, 2.55);
    assert!(
        (p.0 - 5.5).abs() < 1e-9 && (p.1 - 20.0).abs() < 1e-9,
        "{p:?}"
    );
    // ... and the map's y axis (image up) is world -x.
    let p = c.world_to_px(0.65, 2.0);
    assert!(
        (p.0 - 0.0).abs() < 1e-9 && (p.1 - 16.5).abs() < 1e-9,
        "{p:?}"
    );
    for &(x, y) in &[(0.3, 2.7), (1.0, 3.9), (-0.5, 2.2)] {
        let (px, py) = c.world_to_px(x, y);
        let (bx, by) = c.px_to_world(px, py);
        assert!((bx - x).abs() < 1e-9 && (by - y).abs() < 1e-9);
    }
}

#[test]
fn pose_arrow_follows_heading_in_rotated_map() {
    let gray = white_map(40, 40);
    let yaw = 0.7;
    let map = MapLayer {
        width: 40,
        height: 40,
        gray: &gray,
        resolution: 0.05,
        origin: [3.0, -1.0, yaw],
    };
    let mut c = MapCanvas::with_scale(&map, 2.0);
    let (x, y) = c.cell_to_world(20.0, 20.0);
    // Heading equal to the map yaw points to image +x.
    c.arrow(x, y, yaw, 25.0, 2.0, color::RED);
    let (px, py) = c.cell_to_px(20.0, 20.0);
    let (px, py) = (px as i64, py as i64);
    assert_eq!(c.raster().pixel(px + 20, py), Some(color::RED));
    assert_eq!(c.raster().pixel(px - 15, py), Some(BG));
    assert_eq!(c.raster().pixel(px, py - 15), Some(BG));
    // A quarter turn more points up in the image.
    c.arrow(
        x,
        y,
        yaw + std::f64::consts::FRAC_PI_2,
        25.0,
        2.0,
        color::BLUE,
    );
    assert_eq!(c.raster().pixel(px, py - 20), Some(color::BLUE));
}

#[test]
fn text_renders_glyph_pixels_inside_its_box() {
    let mut r = Raster::new(120, 50, BG);
    let (tw, th) = text_size("Abg1", 20.0);
    assert_eq!(th, 20);
    assert!((35..60).contains(&tw), "width {tw}");
    let w = r.text(
        3.0,
        4.0,
        "Abg1",
        20.0,
        color::BLACK,
        Align::Start,
        Align::Start,
    );
    assert_eq!(w, tw);
    let ink: Vec<(i64, i64)> = (0..50)
        .flat_map(|y| (0..120).map(move |x| (x, y)))
        .filter(|&(x, y)| r.pixel(x, y) != Some(BG))
        .collect();
    assert!(ink.len() > 80, "only {} ink pixels", ink.len());
    // Capitals and descenders stay inside the box (anti-aliasing may
    // spill over by a pixel).
    for &(x, y) in &ink {
        assert!(
            (2..=4 + tw as i64).contains(&x) && (3..=4 + th as i64).contains(&y),
            "({x},{y})"
        );
    }
    let (ymin, ymax) = (ink.iter().map(|p| p.1).min(), ink.iter().map(|p| p.1).max());
    assert!(ymin < Some(9) && ymax > Some(18), "{ymin:?}..{ymax:?}");
    assert_eq!(text_size("", 12.0), (0, 12));
    // Off-image and non-finite anchors draw nothing and do not panic.
    let mut r = Raster::new(20, 20, BG);
    r.text(
        f64::NAN,
        0.0,
        "x",
        10.0,
        color::BLACK,
        Align::Center,
        Align::Center,
    );
    r.text(-1e9, 1e9, "x", 10.0, color::BLACK, Align::End, Align::End);
    assert_eq!(count_color(&r, BG), 400);
}

#[test]
fn text_and_canvas_drawing_is_deterministic() {
    let gray = white_map(120, 80);
    let map = blank_layer(&gray, 120, 80);
    let draw = || {
        let mut c = MapCanvas::with_long_side(&map, 600);
        c.title("a title: θ and 12 sites");
        c.label(2.0, 2.0, "17", color::DARK_GRAY);
        c.legend(&[("pose", color::GREEN, Mark::Arrow)], Corner::TopRight);
        c.scale_bar(Corner::BottomLeft);
        c.into_raster()
    };
    assert_eq!(draw().as_bytes(), draw().as_bytes());
}

#[test]
fn odd_input_is_clipped_or_ignored() {
    let gray = white_map(10, 10);
    let map = MapLayer {
        width: 10,
        height: 10,
        gray: &gray,
        resolution: 0.1,
        origin: [0.0, 0.0, 0.0],
    };
    let mut c = MapCanvas::with_scale(&map, 3.0);
    let before = c.raster().as_bytes().to_vec();
    c.dot(100.0, -50.0, 4.0, color::RED);
    c.dot(f64::NAN, 0.5, 4.0, color::RED);
    c.line(0.0, f64::INFINITY, 1.0, 1.0, 2.0, color::RED);
    c.line(-1e12, -3e11, -1e12, 5e11, 2.0, color::RED);
    c.circle(0.5, 0.5, f64::NAN, 1.0, color::RED);
    c.arrow(f64::NAN, 0.0, 0.0, 10.0, 1.0, color::RED);
    c.label(f64::NAN, 0.0, "x", color::RED);
    c.polyline(Vec::<(f64, f64)>::new(), 1.0, color::RED);
    c.fill_cell(-5, 3, color::RED);
    c.fill_cell(3, 50, color::RED);
    c.scale_bar_len(f64::NAN, Corner::TopLeft);
    c.scale_bar_len(1e9, Corner::TopLeft);
    c.legend(&[], Corner::TopLeft);
    assert_eq!(c.raster().as_bytes(), &before[..]);

    // A long line crossing the canvas is drawn only where visible.
    c.line(-1e9, 0.5, 1e9, 0.5, 2.0, color::RED);
    assert!(count_color(c.raster(), color::RED) >= 30);

    // Degenerate maps and short buffers do not panic.
    let empty = MapLayer {
        width: 0,
        height: 0,
        gray: &[],
        resolution: 0.0,
        origin: [f64::NAN, 0.0, 0.0],
    };
    let mut c = MapCanvas::new(&empty);
    c.dot(0.0, 0.0, 3.0, color::RED);
    c.legend(&[("a", color::RED, Mark::Dot)], Corner::BottomRight);
    c.scale_bar(Corner::BottomLeft);
    c.title("tiny");
    let short = MapLayer {
        width: 7,
        height: 3,
        gray: &[0u8; 5],
        resolution: 1.0,
        origin: [0.0; 3],
    };
    let c = MapCanvas::with_long_side(&short, 70);
    assert_eq!((c.width(), c.height()), (70, 30));
    assert_eq!(c.raster().pixel(0, 0), Some([0; 3]));
    assert_eq!(c.raster().pixel(69, 29), Some([UNKNOWN_GRAY; 3]));
}

#[test]
fn scaling_choice_and_thin_walls_survive_downscaling() {
    let (w, h) = (400u32, 100u32);
    let mut gray = white_map(w, h);
    for y in 0..h {
        gray[(y * w + 201) as usize] = 0; // a one-cell vertical wall
    }
    let map = MapLayer {
        width: w,
        height: h,
        gray: &gray,
        resolution: 0.05,
        origin: [0.0; 3],
    };
    let c = MapCanvas::with_long_side(&map, 100);
    assert_eq!((c.width(), c.height()), (100, 25));
    let darkest = (0..100)
        .map(|x| c.raster().pixel(x, 10).unwrap()[0])
        .min()
        .unwrap();
    assert!(darkest < 128, "wall faded to {darkest}");
    // Small maps are upscaled by the nearest integer factor.
    let c = MapCanvas::with_long_side(&map, 1700);
    assert_eq!(c.scale(), 4.0);
    assert_eq!(c.width(), 1600);
    let c = MapCanvas::with_long_side(&map, 1850);
    assert_eq!(c.scale(), 5.0);
    let c = MapCanvas::with_long_side(&map, 1600);
    assert_eq!(c.scale(), 4.0);
}

#[test]
fn legend_scale_bar_and_overlays_draw() {
    let gray = white_map(200, 120);
    let map = MapLayer {
        width: 200,
        height: 120,
        gray: &gray,
        resolution: 0.05,
        origin: [-2.0, -1.0, 0.0],
    };
    let mut c = MapCanvas::with_long_side(&map, 800);
    c.legend(
        &[
            ("site", color::RED, Mark::Dot),
            ("edge", color::BLUE, Mark::Line),
            ("pose", color::GREEN, Mark::Arrow),
        ],
        Corner::TopRight,
    );
    assert!(count_color(c.raster(), color::RED) > 0);
    assert!(count_color(c.raster(), color::BLUE) > 0);
    // Top-left stays empty, top-right has the legend.
    let ink = |c: &MapCanvas, x0: i64, x1: i64, y0: i64, y1: i64| {
        (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| c.raster().pixel(x, y) != Some(BG))
            .count()
    };
    assert_eq!(ink(&c, 0, 200, 0, 100), 0);
    assert!(ink(&c, 600, 800, 0, 100) > 100);
    c.scale_bar(Corner::BottomLeft);
    assert!(ink(&c, 0, 300, 380, 480) > 100);
    assert_eq!(nice_floor(3.7), 2.0);
    assert_eq!(nice_floor(0.06), 0.05);
    assert_eq!(format_number(0.5), "0.5");
    assert_eq!(format_number(20.0), "20");
}

#[test]
fn save_png_writes_a_decodable_file() {
    let gray: Vec<u8> = (0..30 * 20).map(|i| (i % 256) as u8).collect();
    let map = MapLayer {
        width: 30,
        height: 20,
        gray: &gray,
        resolution: 0.1,
        origin: [0.0; 3],
    };
    let mut c = MapCanvas::with_scale(&map, 2.0);
    c.pose(1.0, 1.0, 0.5, color::RED);
    let path = temp_png("save");
    c.save_png(&path).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    std::fs::remove_file(&path).ok();
    assert_eq!(img.dimensions(), (60, 40));
    assert_eq!(img.as_raw(), c.raster().as_bytes());
    // Errors come back as io::Error rather than panics.
    let bad = std::env::temp_dir().join("mapc_no_such_dir_xyz/a.png");
    assert!(c.save_png(&bad).is_err());
}
