use super::*;

fn approx(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
}

fn temp_png(name: &str) -> std::path::PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    std::env::temp_dir().join(format!(
        "mapc_plot_{name}_{}_{nanos}.png",
        std::process::id()
    ))
}

fn labels(t: &[f64]) -> Vec<String> {
    let f = tick_format(t);
    t.iter().map(f).collect()
}

#[test]
fn ticks_are_round_and_whole_on_integer_axes() {
    assert!(approx(
        &ticks(0.0, 0.97, 5, false),
        &[0.0, 0.2, 0.4, 0.6, 0.8]
    ));
    assert!(approx(
        &ticks(0.0, 10.0, 5, false),
        &[0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
    ));
    assert!(approx(
        &ticks(-3.2, 7.9, 5, false),
        &[-2.0, 0.0, 2.0, 4.0, 6.0]
    ));
    // Counts up to 3: fractional ticks on a plain axis, whole ones on an
    // integer axis.
    assert!(approx(
        &ticks(0.0, 3.15, 6, false),
        &[0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]
    ));
    assert!(approx(&ticks(0.0, 3.15, 6, true), &[0.0, 1.0, 2.0, 3.0]));
    assert!(approx(
        &ticks(0.5, 10.5, 5, true),
        &[2.0, 4.0, 6.0, 8.0, 10.0]
    ));
    let t = ticks(1234.0, 98765.0, 5, false);
    assert!(t[0] >= 1234.0 && *t.last().unwrap() <= 98765.0 && t.len() <= 8);
    // Degenerate and invalid input.
    assert!(!ticks(5.0, 5.0, 5, false).is_empty());
    assert!(ticks(f64::NAN, 1.0, 5, false).is_empty());
    assert!(ticks(0.0, f64::INFINITY, 5, true).is_empty());
    assert!(ticks(-f64::MAX, f64::MAX, 5, false).is_empty());
    assert!(approx(
        &ticks(0.97, 0.0, 5, false),
        &ticks(0.0, 0.97, 5, false)
    ));
    assert!(!ticks(0.0, 1.0, 0, false).is_empty());
}

#[test]
fn tick_labels_share_decimals() {
    assert_eq!(labels(&[0.0, 0.2, 0.4]), ["0.0", "0.2", "0.4"]);
    assert_eq!(labels(&[0.0, 0.05, 0.1]), ["0.00", "0.05", "0.10"]);
    assert_eq!(labels(&[-10.0, 0.0, 10.0]), ["-10", "0", "10"]);
    assert_eq!(labels(&[1.0, 2.0, 3.0]), ["1", "2", "3"]);
    assert_eq!(labels(&[0.0, 1e6, 2e6]), ["0.0e0", "1.0e6", "2.0e6"]);
    assert_eq!(labels(&[-1e-17, 0.1]), ["0.0", "0.1"]);
    assert!(labels(&[]).is_empty());
}

#[test]
fn histogram_counts_and_edges() {
    let v = [0.0, 0.1, 0.5, 0.99, 1.0, f64::NAN, 2.0, -1.0];
    let (e, c) = histogram(&v, 4, Some((0.0, 1.0)));
    assert!(approx(&e, &[0.0, 0.25, 0.5, 0.75, 1.0]));
    assert_eq!(c, [2, 0, 1, 2]);
    let (e, c) = histogram(&v, 2, None);
    assert!(approx(&e, &[-1.0, 0.5, 2.0]));
    assert_eq!(c.iter().sum::<u64>(), 7);
    let (e, c) = histogram(&[], 0, None);
    assert_eq!((e.len(), c.as_slice()), (2, &[0u64][..]));
    let (e, c) = histogram(&[3.0, 3.0], 3, None);
    assert_eq!(e.len(), 4);
    assert_eq!(c.iter().sum::<u64>(), 2);
    let (_, c) = histogram(&[1.0], 3, Some((f64::NAN, 2.0)));
    assert_eq!(c.iter().sum::<u64>(), 1);
}

#[test]
fn odd_charts_render_without_panic() {
    let mut c = Chart::new("");
    assert_eq!(c.render().unwrap().width(), DEFAULT_WIDTH);
    c.line(&[], &[], color::RED, "empty");
    c.line(
        &[f64::NAN, 1.0, 2.0],
        &[1.0, f64::INFINITY, 3.0],
        color::BLUE,
        "nan",
    );
    c.line(&[1.0, 2.0, 3.0], &[5.0], color::GREEN, "short");
    c.bars(&[0.0], &[1.0, 2.0], color::ORANGE, "bad bars");
    c.render().unwrap();
    let c2 = c
        .clone()
        .x_range(3.0, 3.0)
        .y_range(f64::NAN, 1.0)
        .size(10, 10);
    assert_eq!(c2.render().unwrap().width(), 64);
    let c3 = c.clone().x_range(-1e300, 1e300).y_range(1e-300, 2e-300);
    c3.render().unwrap();
    let mut c4 = Chart::new("huge values");
    c4.line(&[0.0, 1.0], &[-f64::MAX, f64::MAX], color::RED, "x");
    c4.render().unwrap();
    let mut c5 = Chart::new("all nan").integer_x().integer_y();
    c5.line(&[f64::NAN], &[f64::NAN], color::RED, "");
    c5.hist(&[], &[], color::BLUE, "");
    c5.render().unwrap();
    heatmap(&[], 0, 0, (0.0, 0.0), (f64::NAN, 1.0))
        .render()
        .unwrap();
    heatmap(&[f32::NAN; 4], 2, 2, (0.0, 1.0), (0.0, 1.0))
        .render()
        .unwrap();
    heatmap(&[1.0; 3], 2, 2, (1.0, 0.0), (0.0, 1.0))
        .render()
        .unwrap();
}

#[test]
fn line_chart_draws_its_series_and_the_same_chart_gives_the_same_bytes() {
    let xs: Vec<f64> = (0..50).map(|i| i as f64 / 49.0).collect();
    let ys: Vec<f64> = xs.iter().map(|x| x * x).collect();
    let mut c = Chart::new("t").x_label("x").y_label("y");
    c.line(&xs, &ys, color::RED, "square");
    let r = c.render().unwrap();
    let red = r
        .as_bytes()
        .chunks_exact(3)
        .filter(|p| *p == color::RED)
        .count();
    assert!(red > 500, "{red}");
    assert_eq!(r.as_bytes(), c.render().unwrap().as_bytes());
    let mut h = Chart::new("ranks").integer_x().integer_y();
    let (e, n) = histogram(&[1.0, 1.0, 2.0, 5.0], 5, Some((0.5, 5.5)));
    h.hist(&e, &n, color::BLUE, "");
    assert_eq!(
        h.render().unwrap().as_bytes(),
        h.render().unwrap().as_bytes()
    );
}

#[test]
fn heatmap_rows_go_up_and_columns_right() {
    let data = [0.0f32, 1.0, 2.0, 3.0]; // rows x cols = 2 x 2, row 0 at the bottom
    let c = heatmap(&data, 2, 2, (0.0, 1.0), (0.0, 1.0)).size(400, 300);
    let r = c.render().unwrap();
    let (lo, hi) = (color::colormap(0.0), color::colormap(1.0));
    let (w, h) = (r.width() as i64, r.height() as i64);
    // In the left half of the image (the colour bar is on the right), the low
    // colour is at the bottom-left and the high one at the top-right of the
    // plot.
    let mut lo_px = Vec::new();
    let mut hi_px = Vec::new();
    for y in 0..h {
        for x in 0..w * 2 / 3 {
            let p = r.pixel(x, y).unwrap();
            if p == lo {
                lo_px.push((x, y));
            }
            if p == hi {
                hi_px.push((x, y));
            }
        }
    }
    assert!(!lo_px.is_empty() && !hi_px.is_empty());
    let mean = |v: &[(i64, i64)]| {
        let n = v.len() as f64;
        (
            v.iter().map(|p| p.0 as f64).sum::<f64>() / n,
            v.iter().map(|p| p.1 as f64).sum::<f64>() / n,
        )
    };
    let (lm, hm) = (mean(&lo_px), mean(&hi_px));
    assert!(lm.0 < hm.0 && lm.1 > hm.1, "{lm:?} {hm:?}");
}

#[test]
fn save_png_writes_a_decodable_file() {
    let mut c = Chart::new("save").size(300, 200);
    c.line(&[1.0, 2.0], &[3.0, 4.0], color::BLUE, "pts");
    let path = temp_png("save");
    c.save_png(&path).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    std::fs::remove_file(&path).ok();
    assert_eq!(img.dimensions(), (300, 200));
}
