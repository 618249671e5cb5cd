//! The figures of `mapc eval`, `mapc demo` and `mapc render`: the paper's
//! Fig. 7b (map, GVD, sites), Fig. 10/15 (true and estimated poses),
//! Fig. 12 (error distributions), Fig. 16 (coarse ranks), Fig. 6 (matching
//! rate curves), Fig. 4/9 (a virtual scan and its PGR histogram).

use std::io;
use std::path::Path;

use refloc::raycast::Occupancy;
use refloc::RefDb;

use crate::tools::eval::Trial;
use crate::tools::plot::{self, color, Chart};
use crate::tools::render::{Corner, MapCanvas, MapLayer, Mark};

/// Gray levels (image order: top row first) of a database's grid:
/// beam-stopping cells dark, free cells white.
pub fn db_gray<D: AsRef<[u8]>>(db: &RefDb<D>) -> Vec<u8> {
    let (w, h) = db.grid_size();
    let grid = db.grid();
    let mut g = vec![255u8; w as usize * h as usize];
    for row in 0..h {
        let cy = h - 1 - row;
        for cx in 0..w {
            if grid.blocked(cx, cy) {
                g[(row * w + cx) as usize] = 60;
            }
        }
    }
    g
}

/// A canvas with the database's map drawn on it.
pub fn db_canvas<D: AsRef<[u8]>>(db: &RefDb<D>, gray: &[u8]) -> MapCanvas {
    let (w, h) = db.grid_size();
    let f = db.frame();
    MapCanvas::new(&MapLayer {
        width: w,
        height: h,
        gray,
        resolution: f.resolution as f64,
        origin: [f.origin.x as f64, f.origin.y as f64, f.origin.theta as f64],
    })
}

/// Fig. 10/15: the map with true (green) and estimated (red: accepted and
/// wrong, blue: correct) poses; at most `max` trials drawn.
pub fn poses_figure<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    trials: &[Trial],
    title: &str,
    max: usize,
    path: &Path,
) -> io::Result<()> {
    let gray = db_gray(db);
    let mut c = db_canvas(db, &gray);
    for s in 0..db.site_count() {
        let p = db.site_xy(s);
        c.dot(p[0] as f64, p[1] as f64, 2.0, color::LIGHT_GRAY);
    }
    for t in trials.iter().take(max) {
        c.pose(t.truth[0], t.truth[1], t.truth[2], color::GREEN);
        if let Some(e) = t.est {
            if t.accepted {
                let col = if t.correct() { color::BLUE } else { color::RED };
                if !t.correct() {
                    c.dashed_line(t.truth[0], t.truth[1], e[0], e[1], 1.5, color::RED);
                }
                c.pose(e[0], e[1], e[2], col);
            }
        }
    }
    c.title(title);
    c.legend(
        &[
            ("true pose", color::GREEN, Mark::Line),
            ("estimate (correct)", color::BLUE, Mark::Line),
            ("estimate (wrong, accepted)", color::RED, Mark::Line),
            ("reference site", color::LIGHT_GRAY, Mark::Dot),
        ],
        Corner::TopRight,
    );
    c.scale_bar(Corner::BottomLeft);
    c.save_png(path)
}

/// Fig. 12: distributions of |x|, |y| (mm) and |theta| (deg) errors of the
/// accepted, correct trials.
pub fn error_figure(trials: &[Trial], title: &str, path: &Path) -> io::Result<()> {
    let mut ex = Vec::new();
    let mut ey = Vec::new();
    let mut et = Vec::new();
    for t in trials.iter().filter(|t| t.correct()) {
        if let (Some(e), Some(th)) = (t.est, t.err_theta) {
            ex.push((e[0] - t.truth[0]).abs() * 1000.0);
            ey.push((e[1] - t.truth[1]).abs() * 1000.0);
            et.push(th.to_degrees());
        }
    }
    let hi = ex
        .iter()
        .chain(&ey)
        .copied()
        .fold(1.0f64, f64::max)
        .min(300.0);
    let mut c = Chart::new(title)
        .x_label("|error| (mm; heading: deg x 10)")
        .y_label("trials")
        .integer_y();
    let (e1, c1) = plot::histogram(&ex, 30, Some((0.0, hi)));
    let (_, c2) = plot::histogram(&ey, 30, Some((0.0, hi)));
    let (_, c3) = plot::histogram(
        &et.iter().map(|v| v * 10.0).collect::<Vec<_>>(),
        30,
        Some((0.0, hi)),
    );
    let xs: Vec<f64> = e1.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
    c.line(
        &xs,
        &c1.iter().map(|&v| v as f64).collect::<Vec<_>>(),
        color::BLUE,
        "|x| (mm)",
    );
    c.line(
        &xs,
        &c2.iter().map(|&v| v as f64).collect::<Vec<_>>(),
        color::ORANGE,
        "|y| (mm)",
    );
    c.line(
        &xs,
        &c3.iter().map(|&v| v as f64).collect::<Vec<_>>(),
        color::GREEN,
        "|theta| (deg x 10)",
    );
    c.save_png(path)
}

/// Fig. 16: histogram of the coarse rank of the correct site.
pub fn rank_figure(trials: &[Trial], title: &str, path: &Path) -> io::Result<()> {
    let ranks: Vec<f64> = trials
        .iter()
        .filter_map(|t| t.correct_rank.map(|r| r as f64 + 1.0))
        .collect();
    let top = ranks.iter().copied().fold(10.0f64, f64::max).min(60.0);
    let (edges, counts) = plot::histogram(&ranks, top as usize, Some((0.5, top + 0.5)));
    let mut c = Chart::new(title)
        .x_label("coarse rank of the correct site (1 = best)")
        .y_label("queries")
        .integer_x()
        .integer_y();
    c.hist(&edges, &counts, color::BLUE, "");
    c.save_png(path)
}

/// Fig. 6: matching rate curves.
pub fn curve_figure(
    xs: &[f64],
    ys: &[f64],
    title: &str,
    xlabel: &str,
    path: &Path,
) -> io::Result<()> {
    let mut c = Chart::new(title)
        .x_label(xlabel)
        .y_label("matching rate")
        .y_range(0.0, 1.05);
    c.line(xs, ys, color::BLUE, "SSM");
    c.save_png(path)
}
