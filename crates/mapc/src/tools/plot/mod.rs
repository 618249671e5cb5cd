//! Charts as PNG images without a plotting dependency: line, scatter and bar
//! (histogram) series with optional error bars, automatic "nice" ticks,
//! titles, axis labels, a legend that avoids the data, and heatmaps with a
//! colour bar. Text uses the built-in bitmap font of [`crate::tools::render`].
//!
//! ```no_run
//! use mapc::tools::plot::{color, histogram, Chart};
//! let (edges, counts) = histogram(&[0.1, 0.4, 0.45, 0.9], 10, Some((0.0, 1.0)));
//! let mut chart = Chart::new("Position error").x_label("error (m)").y_label("count");
//! chart.hist(&edges, &counts, color::BLUE, "errors");
//! chart.line(&[0.0, 1.0], &[0.0, 2.0], color::RED, "trend").with_yerr(&[0.1, 0.2]);
//! chart.save_png("/tmp/chart.png").unwrap();
//! ```

#[cfg(test)]
mod tests;

use std::io;
use std::path::Path;

pub use crate::tools::render::color;
use crate::tools::render::{draw_legend, legend_size, text_size, Align, Mark, Raster};
pub use crate::tools::render::{Corner, Rgb};

/// Default chart width in pixels.
pub const DEFAULT_WIDTH: u32 = 900;
/// Default chart height in pixels.
pub const DEFAULT_HEIGHT: u32 = 600;

/// The data of one chart series.
#[derive(Debug, Clone, PartialEq)]
pub enum SeriesData {
    /// Points joined by straight lines (a non-finite point breaks the line).
    Line {
        /// X values.
        xs: Vec<f64>,
        /// Y values (paired with `xs`; extra values of either are ignored).
        ys: Vec<f64>,
        /// Stroke width in pixels.
        width: f64,
    },
    /// Unconnected dots.
    Scatter {
        /// X values.
        xs: Vec<f64>,
        /// Y values.
        ys: Vec<f64>,
        /// Dot radius in pixels.
        radius: f64,
    },
    /// Bars spanning `[edges[i], edges[i+1]]` from zero to `heights[i]`.
    Bars {
        /// Bin edges (one more than the heights).
        edges: Vec<f64>,
        /// Bar heights.
        heights: Vec<f64>,
    },
}

/// One labelled series of a [`Chart`].
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend text; empty means "not in the legend".
    pub label: String,
    /// Colour.
    pub color: Rgb,
    /// Values and kind.
    pub data: SeriesData,
    /// Optional symmetric vertical error bars (per point; bar centres for
    /// [`SeriesData::Bars`]).
    pub yerr: Option<Vec<f64>>,
}

impl Series {
    /// Attach symmetric vertical error bars (`y +- err[i]`).
    pub fn with_yerr(&mut self, err: &[f64]) -> &mut Self {
        self.yerr = Some(err.to_vec());
        self
    }

    /// Set the line width (line series) or dot radius (scatter series), in
    /// pixels; no effect on bars.
    pub fn with_size(&mut self, px: f64) -> &mut Self {
        match &mut self.data {
            SeriesData::Line { width, .. } => *width = px,
            SeriesData::Scatter { radius, .. } => *radius = px,
            SeriesData::Bars { .. } => {}
        }
        self
    }

    /// Points `(x, y)` of the series (bar centres and heights for bars).
    fn points(&self) -> Vec<(f64, f64)> {
        match &self.data {
            SeriesData::Line { xs, ys, .. } | SeriesData::Scatter { xs, ys, .. } => {
                xs.iter().copied().zip(ys.iter().copied()).collect()
            }
            SeriesData::Bars { edges, heights } => edges
                .windows(2)
                .zip(heights)
                .map(|(e, &h)| ((e[0] + e[1]) / 2.0, h))
                .collect(),
        }
    }

    fn mark(&self) -> Mark {
        match self.data {
            SeriesData::Line { .. } => Mark::Line,
            SeriesData::Scatter { .. } => Mark::Dot,
            SeriesData::Bars { .. } => Mark::Square,
        }
    }
}

/// A colour-mapped 2D array shown as an image filling its extents.
#[derive(Debug, Clone, PartialEq)]
pub struct Heatmap {
    /// Row-major values, `rows * cols` of them (missing ones are blank,
    /// NaN cells are drawn light gray).
    pub data: Vec<f32>,
    /// Number of rows (along y; row 0 at the BOTTOM, i.e. at `y_extent.0`).
    pub rows: usize,
    /// Number of columns (along x; column 0 at `x_extent.0`).
    pub cols: usize,
    /// X values of the left edge of column 0 and the right edge of the last.
    pub x_extent: (f64, f64),
    /// Y values of the bottom edge of row 0 and the top edge of the last.
    pub y_extent: (f64, f64),
    /// Values mapped to the ends of the colour map (`None`: data min/max).
    pub value_range: Option<(f64, f64)>,
    /// Label of the colour bar.
    pub label: String,
}

/// Where the legend goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LegendPos {
    /// An inside corner that covers no data, else outside on the right.
    Auto,
    /// This inside corner.
    Inside(Corner),
    /// To the right of the plot area.
    Outside,
    /// No legend.
    Hidden,
}

/// A 2D chart. Build with the consuming setters, add series with the
/// `&mut` methods, then [`Chart::save_png`] or [`Chart::render`].
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    title: String,
    x_label: String,
    y_label: String,
    width: u32,
    height: u32,
    x_range: Option<(f64, f64)>,
    y_range: Option<(f64, f64)>,
    series: Vec<Series>,
    heat: Option<Heatmap>,
    legend: LegendPos,
    grid: bool,
}

impl Chart {
    /// Empty chart with a title (may be empty), 900x600 pixels.
    pub fn new(title: &str) -> Self {
        Chart {
            title: title.to_string(),
            x_label: String::new(),
            y_label: String::new(),
            width: DEFAULT_WIDTH,
            height: DEFAULT_HEIGHT,
            x_range: None,
            y_range: None,
            series: Vec::new(),
            heat: None,
            legend: LegendPos::Auto,
            grid: true,
        }
    }

    /// Set the title.
    pub fn title(mut self, title: &str) -> Self {
        self.title = title.to_string();
        self
    }

    /// Set the x-axis label.
    pub fn x_label(mut self, label: &str) -> Self {
        self.x_label = label.to_string();
        self
    }

    /// Set the y-axis label.
    pub fn y_label(mut self, label: &str) -> Self {
        self.y_label = label.to_string();
        self
    }

    /// Output size in pixels (each side clamped to `[64, 16384]`).
    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.width = width.clamp(64, 16_384);
        self.height = height.clamp(64, 16_384);
        self
    }

    /// Fix the x range instead of fitting the data (ignored if not finite).
    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }

    /// Fix the y range instead of fitting the data (ignored if not finite).
    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }

    /// Legend placement (default [`LegendPos::Auto`]).
    pub fn legend(mut self, pos: LegendPos) -> Self {
        self.legend = pos;
        self
    }

    /// Show grid lines at the ticks (default on).
    pub fn grid(mut self, on: bool) -> Self {
        self.grid = on;
        self
    }

    /// Palette colour for the next series added.
    pub fn next_color(&self) -> Rgb {
        color::palette(self.series.len())
    }

    /// The series added so far.
    pub fn series(&self) -> &[Series] {
        &self.series
    }

    /// Add a series and return it for further tweaks.
    pub fn add(&mut self, series: Series) -> &mut Series {
        self.series.push(series);
        self.series.last_mut().expect("just pushed")
    }

    fn push(&mut self, data: SeriesData, c: Rgb, label: &str) -> &mut Series {
        self.add(Series {
            label: label.to_string(),
            color: c,
            data,
            yerr: None,
        })
    }

    /// Add a line series (2 px wide).
    pub fn line(&mut self, xs: &[f64], ys: &[f64], c: Rgb, label: &str) -> &mut Series {
        let data = SeriesData::Line {
            xs: xs.to_vec(),
            ys: ys.to_vec(),
            width: 2.0,
        };
        self.push(data, c, label)
    }

    /// Add a scatter series (dots of radius 3 px).
    pub fn scatter(&mut self, xs: &[f64], ys: &[f64], c: Rgb, label: &str) -> &mut Series {
        let data = SeriesData::Scatter {
            xs: xs.to_vec(),
            ys: ys.to_vec(),
            radius: 3.0,
        };
        self.push(data, c, label)
    }

    /// Add bars between consecutive `edges` with the given heights.
    pub fn bars(&mut self, edges: &[f64], heights: &[f64], c: Rgb, label: &str) -> &mut Series {
        let data = SeriesData::Bars {
            edges: edges.to_vec(),
            heights: heights.to_vec(),
        };
        self.push(data, c, label)
    }

    /// Add a histogram as bars (e.g. the output of [`histogram`]).
    pub fn hist(&mut self, edges: &[f64], counts: &[u64], c: Rgb, label: &str) -> &mut Series {
        let heights: Vec<f64> = counts.iter().map(|&n| n as f64).collect();
        self.bars(edges, &heights, c, label)
    }

    /// Show a heatmap under the series (replaces any previous one) and a
    /// colour bar on the right.
    pub fn set_heatmap(&mut self, heat: Heatmap) -> &mut Self {
        self.heat = Some(heat);
        self
    }

    /// Write the chart as a PNG file.
    pub fn save_png(&self, path: impl AsRef<Path>) -> io::Result<()> {
        self.render().save_png(path)
    }

    /// Draw the chart into a new image.
    pub fn render(&self) -> Raster {
        let outside = self.legend == LegendPos::Outside;
        let (r, crowded) = self.render_pass(outside);
        if crowded && self.legend == LegendPos::Auto {
            self.render_pass(true).0
        } else {
            r
        }
    }

    fn legend_entries(&self) -> Vec<(&str, Rgb, Mark)> {
        if self.legend == LegendPos::Hidden {
            return Vec::new();
        }
        self.series
            .iter()
            .filter(|s| !s.label.is_empty())
            .map(|s| (s.label.as_str(), s.color, s.mark()))
            .collect()
    }

    /// Finite data bounds `(xmin, xmax, ymin, ymax)`, if any data.
    fn data_bounds(&self) -> (Span, Span) {
        let mut bx = Bounds::default();
        let mut by = Bounds::default();
        for s in &self.series {
            match &s.data {
                SeriesData::Line { xs, ys, .. } | SeriesData::Scatter { xs, ys, .. } => {
                    for (&x, &y) in xs.iter().zip(ys) {
                        if x.is_finite() && y.is_finite() {
                            bx.add(x);
                            by.add(y);
                        }
                    }
                }
                SeriesData::Bars { edges, heights } => {
                    for (e, &h) in edges.windows(2).zip(heights) {
                        if e[0].is_finite() && e[1].is_finite() && h.is_finite() {
                            bx.add(e[0]);
                            bx.add(e[1]);
                            by.add(h);
                            by.add(0.0);
                        }
                    }
                }
            }
            if let Some(err) = &s.yerr {
                for ((x, y), &e) in s.points().into_iter().zip(err) {
                    if x.is_finite() && y.is_finite() && e.is_finite() {
                        by.add(y - e.abs());
                        by.add(y + e.abs());
                    }
                }
            }
        }
        if let Some(h) = &self.heat {
            bx.add(h.x_extent.0);
            bx.add(h.x_extent.1);
            by.add(h.y_extent.0);
            by.add(h.y_extent.1);
        }
        (bx.get(), by.get())
    }

    /// Draw once; returns the image and whether an automatic inside legend
    /// would cover data.
    fn render_pass(&self, legend_outside: bool) -> (Raster, bool) {
        let (w, h) = (self.width.max(16), self.height.max(16));
        let mut r = Raster::new(w, h, color::WHITE);
        let ts: u32 = if w.min(h) >= 400 { 2 } else { 1 };
        let tick_len = 3 * ts as i64;
        let gap = 4.0 * ts as f64;
        let pad = 6.0 * ts as f64;
        let cap = text_size("0", ts).1 as f64;

        // Axis ranges and ticks. Heatmaps keep their exact extents.
        let (dbx, dby) = self.data_bounds();
        let exact = self.heat.is_some();
        let est_pw = w as f64 * 0.75;
        let est_ph = h as f64 * 0.7;
        let tx = ((est_pw / (60.0 * ts as f64)) as usize).clamp(2, 10);
        let ty = ((est_ph / (40.0 * ts as f64)) as usize).clamp(2, 10);
        let (xlo, xhi, mut xticks) = axis(self.x_range, dbx, tx, exact);
        let (ylo, yhi, yticks) = axis(self.y_range, dby, ty, exact);
        let ylabels = format_ticks(&yticks);

        // Colour bar data.
        let heat = self.heat.as_ref().map(|hm| {
            let (vlo, vhi) = heat_range(hm);
            let ticks = ticks_within(vlo, vhi, ty);
            let labels = format_ticks(&ticks);
            (hm, vlo, vhi, ticks, labels)
        });

        // Margins.
        let title_scale = {
            let mut s = ts + 1;
            while s > 1 && text_size(&self.title, s).0 as f64 + 2.0 * pad > w as f64 {
                s -= 1;
            }
            s
        };
        let top = pad
            + if self.title.is_empty() {
                cap / 2.0
            } else {
                text_size(&self.title, title_scale).1 as f64 + 2.0 * gap
            };
        let ytick_w = ylabels
            .iter()
            .map(|s| text_size(s, ts).0)
            .max()
            .unwrap_or(0) as f64;
        let left =
            pad + if self.y_label.is_empty() {
                0.0
            } else {
                cap + 2.0 * gap
            } + ytick_w
                + gap
                + tick_len as f64;
        let bottom = tick_len as f64
            + gap
            + cap
            + ts as f64
            + if self.x_label.is_empty() {
                0.0
            } else {
                2.0 * gap + cap
            }
            + pad;
        let xlabels_all = format_ticks(&xticks);
        let last_xw = xlabels_all.last().map_or(0, |s| text_size(s, ts).0) as f64;
        let mut right = pad + last_xw / 2.0;
        let cbar_w = 12.0 * ts as f64;
        if let Some((hm, _, _, _, labels)) = &heat {
            let lw = labels.iter().map(|s| text_size(s, ts).0).max().unwrap_or(0) as f64;
            right += 3.0 * gap
                + cbar_w
                + tick_len as f64
                + gap
                + lw
                + if hm.label.is_empty() {
                    0.0
                } else {
                    2.0 * gap + cap
                };
        }
        let entries = self.legend_entries();
        let (lw, lh) = legend_size(&entries, ts);
        if legend_outside && !entries.is_empty() {
            right += lw as f64 + 2.0 * gap;
        }
        let px0 = left.round() as i64;
        let py0 = top.round() as i64;
        let px1 = ((w as f64 - right).round() as i64).max(px0 + 2);
        let py1 = ((h as f64 - bottom).round() as i64).max(py0 + 2);
        let (pw, ph) = ((px1 - px0) as f64, (py1 - py0) as f64);
        let map_x = |x: f64| px0 as f64 + (x - xlo) / (xhi - xlo) * pw;
        let map_y = |y: f64| py1 as f64 - (y - ylo) / (yhi - ylo) * ph;

        // Thin x ticks until their labels do not collide.
        let xlabels = {
            let mut step = 1;
            loop {
                let kept: Vec<usize> = (0..xticks.len()).step_by(step).collect();
                let widths: Vec<f64> = kept
                    .iter()
                    .map(|&i| text_size(&xlabels_all[i], ts).0 as f64)
                    .collect();
                let ok = kept.windows(2).enumerate().all(|(k, p)| {
                    let d = (map_x(xticks[p[1]]) - map_x(xticks[p[0]])).abs();
                    d >= (widths[k] + widths[k + 1]) / 2.0 + 3.0 * gap
                });
                if ok || step >= xticks.len().max(1) {
                    let labels: Vec<String> =
                        kept.iter().map(|&i| xlabels_all[i].clone()).collect();
                    xticks = kept.iter().map(|&i| xticks[i]).collect();
                    break labels;
                }
                step += 1;
            }
        };

        // Grid.
        if self.grid && self.heat.is_none() {
            for &t in &xticks {
                let x = map_x(t).round() as i64;
                r.fill_rect(x, py0, x + 1, py1, GRID);
            }
            for &t in &yticks {
                let y = map_y(t).round() as i64;
                r.fill_rect(px0, y, px1, y + 1, GRID);
            }
        }

        // Heatmap image.
        if let Some((hm, vlo, vhi, _, _)) = &heat {
            draw_heat(&mut r, hm, *vlo, *vhi, (px0, py0, px1, py1), |px, py| {
                let x = xlo + (px - px0 as f64) / pw * (xhi - xlo);
                let y = ylo + (py1 as f64 - py) / ph * (yhi - ylo);
                (x, y)
            });
        }

        // Series, clipped to the plot area (a little slack for dots at the edge).
        r.set_clip(Some((px0 - 1, py0 - 1, px1 + 1, py1 + 1)));
        for s in &self.series {
            if let SeriesData::Bars { edges, heights } = &s.data {
                let fill = color::tint(s.color, 0.15);
                let base = map_y(0.0f64.clamp(ylo.min(yhi), ylo.max(yhi)));
                for (e, &hv) in edges.windows(2).zip(heights) {
                    let (xa, xb, yv) = (map_x(e[0]), map_x(e[1]), map_y(hv));
                    if ![xa, xb, yv, base].iter().all(|v| v.is_finite()) {
                        continue;
                    }
                    let (xa, xb) = (clamp_px(xa.min(xb)), clamp_px(xa.max(xb)));
                    let (ya, yb) = (clamp_px(yv.min(base)), clamp_px(yv.max(base)));
                    let (xa, xb) = (xa.round() as i64, xb.round() as i64);
                    let (ya, yb) = (ya.round() as i64, yb.round() as i64);
                    r.fill_rect(xa, ya, xb.max(xa + 1), yb, fill);
                    if xb - xa >= 4 && yb > ya {
                        r.stroke_rect(xa, ya, xb, yb, 1, s.color);
                    }
                }
            }
        }
        for s in &self.series {
            match &s.data {
                SeriesData::Line { width, .. } => {
                    let pts: Vec<(f64, f64)> = s
                        .points()
                        .into_iter()
                        .map(|(x, y)| (clamp_px(map_x(x)), clamp_px(map_y(y))))
                        .collect();
                    r.polyline(&pts, *width, s.color);
                }
                SeriesData::Scatter { radius, .. } => {
                    for (x, y) in s.points() {
                        r.disc(map_x(x), map_y(y), *radius, s.color);
                    }
                }
                SeriesData::Bars { .. } => {}
            }
            if let Some(err) = &s.yerr {
                let capw = 2.0 * ts as f64;
                let dark = darken(s.color);
                for ((x, y), &e) in s.points().into_iter().zip(err) {
                    let (xp, ya, yb) = (map_x(x), map_y(y - e.abs()), map_y(y + e.abs()));
                    let (ya, yb) = (clamp_px(ya), clamp_px(yb));
                    r.line(xp, ya, xp, yb, 1.5, dark);
                    r.line(xp - capw, ya, xp + capw, ya, 1.5, dark);
                    r.line(xp - capw, yb, xp + capw, yb, 1.5, dark);
                }
            }
        }
        r.set_clip(None);

        // Legend placement: choose an inside corner with the least ink.
        let mut crowded = false;
        let legend_at = if entries.is_empty() {
            None
        } else if legend_outside {
            Some((px1 as f64 + 2.0 * gap, py0 as f64))
        } else {
            let inset = 2.0 * gap;
            let spot = |c: Corner| -> (f64, f64) {
                let x = match c {
                    Corner::TopLeft | Corner::BottomLeft => px0 as f64 + inset,
                    _ => px1 as f64 - inset - lw as f64,
                };
                let y = match c {
                    Corner::TopLeft | Corner::TopRight => py0 as f64 + inset,
                    _ => py1 as f64 - inset - lh as f64,
                };
                (x, y)
            };
            match self.legend {
                LegendPos::Inside(c) => Some(spot(c)),
                _ => {
                    let best = [
                        Corner::TopRight,
                        Corner::TopLeft,
                        Corner::BottomRight,
                        Corner::BottomLeft,
                    ]
                    .into_iter()
                    .map(|c| {
                        let (x, y) = spot(c);
                        (ink(&r, x, y, lw, lh), (x, y))
                    })
                    .min_by_key(|(n, _)| *n)
                    .expect("four corners");
                    if best.0 > 0 {
                        crowded = true;
                    }
                    Some(best.1)
                }
            }
        };

        // Frame, ticks and tick labels.
        r.stroke_rect(px0 - 1, py0 - 1, px1 + 1, py1 + 1, 1, color::DARK_GRAY);
        for (t, lab) in xticks.iter().zip(&xlabels) {
            let x = map_x(*t).round();
            let xi = x as i64;
            r.fill_rect(xi, py1 + 1, xi + 1, py1 + 1 + tick_len, color::DARK_GRAY);
            r.text_aligned(
                x + 0.5,
                (py1 + 1 + tick_len) as f64 + gap,
                lab,
                ts,
                color::BLACK,
                Align::Center,
                Align::Start,
            );
        }
        for (t, lab) in yticks.iter().zip(&ylabels) {
            let y = map_y(*t).round();
            let yi = y as i64;
            r.fill_rect(px0 - 1 - tick_len, yi, px0 - 1, yi + 1, color::DARK_GRAY);
            r.text_aligned(
                (px0 - 1 - tick_len) as f64 - gap,
                y + 0.5,
                lab,
                ts,
                color::BLACK,
                Align::End,
                Align::Center,
            );
        }

        // Axis labels and title.
        if !self.x_label.is_empty() {
            r.text_aligned(
                (px0 + px1) as f64 / 2.0,
                h as f64 - pad,
                &self.x_label,
                ts,
                color::BLACK,
                Align::Center,
                Align::End,
            );
        }
        if !self.y_label.is_empty() {
            r.text_vertical(
                pad + cap / 2.0,
                (py0 + py1) as f64 / 2.0,
                &self.y_label,
                ts,
                color::BLACK,
            );
        }
        if !self.title.is_empty() {
            r.text_aligned(
                w as f64 / 2.0,
                pad + gap,
                &self.title,
                title_scale,
                color::BLACK,
                Align::Center,
                Align::Start,
            );
        }

        // Colour bar.
        if let Some((hm, vlo, vhi, ticks, labels)) = &heat {
            let bx0 = px1 as f64 + 3.0 * gap;
            let bx1 = bx0 + cbar_w;
            let (bx0i, bx1i) = (bx0.round() as i64, bx1.round() as i64);
            for y in py0..py1 {
                let t = (py1 - 1 - y) as f64 / (ph - 1.0).max(1.0);
                r.fill_rect(bx0i, y, bx1i, y + 1, color::colormap(t));
            }
            r.stroke_rect(bx0i - 1, py0 - 1, bx1i + 1, py1 + 1, 1, color::DARK_GRAY);
            let mut lab_right = bx1;
            for (t, lab) in ticks.iter().zip(labels) {
                let f = (t - vlo) / (vhi - vlo);
                let y = (py1 as f64 - f * ph).round();
                if !y.is_finite() {
                    continue;
                }
                let yi = y as i64;
                r.fill_rect(bx1i + 1, yi, bx1i + 1 + tick_len, yi + 1, color::DARK_GRAY);
                let tw = r.text_aligned(
                    (bx1i + 1 + tick_len) as f64 + gap,
                    y + 0.5,
                    lab,
                    ts,
                    color::BLACK,
                    Align::Start,
                    Align::Center,
                );
                lab_right = lab_right.max((bx1i + 1 + tick_len) as f64 + gap + tw as f64);
            }
            if !hm.label.is_empty() {
                r.text_vertical(
                    lab_right + 2.0 * gap + cap / 2.0,
                    (py0 + py1) as f64 / 2.0,
                    &hm.label,
                    ts,
                    color::BLACK,
                );
            }
        }

        if let Some((x, y)) = legend_at {
            draw_legend(&mut r, x, y, &entries, ts);
        }
        (r, crowded)
    }
}

/// Grid line colour (also treated as background by legend placement).
const GRID: Rgb = [232, 232, 232];

/// Keep pixel coordinates in a range where float geometry stays exact enough.
fn clamp_px(v: f64) -> f64 {
    if v.is_nan() {
        v
    } else {
        v.clamp(-1e6, 1e6)
    }
}

/// A darker shade of `c` (error bars).
fn darken(c: Rgb) -> Rgb {
    [
        (c[0] as f64 * 0.6) as u8,
        (c[1] as f64 * 0.6) as u8,
        (c[2] as f64 * 0.6) as u8,
    ]
}

/// Number of non-background pixels in the `w` x `h` box at `(x, y)`.
fn ink(r: &Raster, x: f64, y: f64, w: u32, h: u32) -> usize {
    let (x0, y0) = (x.round() as i64, y.round() as i64);
    let mut n = 0;
    for yy in y0..y0 + h as i64 {
        for xx in x0..x0 + w as i64 {
            if let Some(p) = r.pixel(xx, yy) {
                if p != color::WHITE && p != GRID {
                    n += 1;
                }
            }
        }
    }
    n
}

/// Draw the heatmap cells into the plot rectangle; `to_data` maps a pixel
/// centre to data coordinates.
fn draw_heat(
    r: &mut Raster,
    hm: &Heatmap,
    vlo: f64,
    vhi: f64,
    rect: (i64, i64, i64, i64),
    to_data: impl Fn(f64, f64) -> (f64, f64),
) {
    let (x0, y0, x1, y1) = rect;
    if hm.rows == 0 || hm.cols == 0 {
        return;
    }
    let (ex0, ex1) = hm.x_extent;
    let (ey0, ey1) = hm.y_extent;
    let (ew, eh) = (ex1 - ex0, ey1 - ey0);
    if !(ew.is_finite() && eh.is_finite()) || ew == 0.0 || eh == 0.0 {
        return;
    }
    let span = vhi - vlo;
    for py in y0..y1 {
        for px in x0..x1 {
            let (x, y) = to_data(px as f64 + 0.5, py as f64 + 0.5);
            let (fx, fy) = ((x - ex0) / ew, (y - ey0) / eh);
            if !(0.0..1.0).contains(&fx) || !(0.0..1.0).contains(&fy) {
                continue;
            }
            let col = ((fx * hm.cols as f64) as usize).min(hm.cols - 1);
            let row = ((fy * hm.rows as f64) as usize).min(hm.rows - 1);
            let Some(&v) = hm.data.get(row * hm.cols + col) else {
                continue;
            };
            let c = if v.is_finite() {
                color::colormap((v as f64 - vlo) / span)
            } else {
                [210, 210, 210]
            };
            r.put(px, py, c);
        }
    }
}

/// Colour-map value range of a heatmap: the fixed range or finite min/max,
/// widened when degenerate.
fn heat_range(hm: &Heatmap) -> (f64, f64) {
    let fixed = hm
        .value_range
        .filter(|(a, b)| a.is_finite() && b.is_finite() && a != b);
    if let Some((a, b)) = fixed {
        return (a.min(b), a.max(b));
    }
    let mut b = Bounds::default();
    for &v in &hm.data {
        if v.is_finite() {
            b.add(v as f64);
        }
    }
    let (lo, hi) = b.get().unwrap_or((0.0, 1.0));
    sanitize_range(lo, hi).unwrap_or((0.0, 1.0))
}

/// An optional `(min, max)` range.
type Span = Option<(f64, f64)>;

/// Running min/max of finite values.
#[derive(Default)]
struct Bounds(Span);

impl Bounds {
    fn add(&mut self, v: f64) {
        if !v.is_finite() {
            return;
        }
        self.0 = Some(match self.0 {
            None => (v, v),
            Some((a, b)) => (a.min(v), b.max(v)),
        });
    }
    fn get(&self) -> Span {
        self.0
    }
}

/// Resolve one axis: returns `(lo, hi, ticks)`. A fixed range is used as is
/// (ticks inside it); data bounds are widened to nice tick values unless
/// `exact`.
fn axis(
    fixed: Option<(f64, f64)>,
    data: Option<(f64, f64)>,
    target: usize,
    exact: bool,
) -> (f64, f64, Vec<f64>) {
    if let Some((lo, hi)) = fixed.and_then(|(a, b)| sanitize_range(a, b)) {
        return (lo, hi, ticks_within(lo, hi, target));
    }
    let (lo, hi) = data
        .and_then(|(a, b)| sanitize_range(a, b))
        .unwrap_or((0.0, 1.0));
    if exact {
        return (lo, hi, ticks_within(lo, hi, target));
    }
    // Snap the axis to covering round ticks unless that wastes too much of
    // the plot; then pad the data range a little and put ticks inside.
    let t = nice_ticks_n(lo, hi, target);
    if let (Some(&a), Some(&b)) = (t.first(), t.last()) {
        if b > a && (b - a).is_finite() && (b - a) <= 1.25 * (hi - lo) {
            return (a, b, t);
        }
    }
    let pad = 0.03 * (hi - lo);
    let lo = if lo == 0.0 { lo } else { lo - pad };
    let hi = if hi == 0.0 { hi } else { hi + pad };
    (lo, hi, ticks_within(lo, hi, target))
}

/// Order a range and widen it if empty; `None` if not finite.
fn sanitize_range(lo: f64, hi: f64) -> Option<(f64, f64)> {
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    let mag = lo.abs().max(hi.abs());
    if hi - lo <= mag * 1e-12 {
        let d = if mag > 0.0 { mag * 0.05 } else { 0.5 };
        return Some((lo - d, hi + d));
    }
    Some((lo, hi))
}

/// The smallest of {1, 2, 2.5, 5, 10} x 10^k that is at least `raw`.
fn nice_step(raw: f64) -> f64 {
    let k = raw.log10().floor();
    let base = 10f64.powf(k);
    let m = raw / base;
    let mant = [1.0, 2.0, 2.5, 5.0, 10.0]
        .into_iter()
        .find(|&c| c >= m * (1.0 - 1e-9))
        .unwrap_or(10.0);
    mant * base
}

/// Evenly spaced round tick values covering `[lo, hi]` with about 5
/// intervals: the first tick is `<= lo`, the last `>= hi`. For example
/// `nice_ticks(0.0, 0.97)` gives `0, 0.2, 0.4, 0.6, 0.8, 1.0`. Empty if either
/// bound is not finite.
pub fn nice_ticks(lo: f64, hi: f64) -> Vec<f64> {
    nice_ticks_n(lo, hi, 5)
}

/// Like [`nice_ticks`] with about `target` intervals (minimum 1).
pub fn nice_ticks_n(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    ticks_impl(lo, hi, target, true)
}

/// Round tick values lying inside `[lo, hi]` with about `target` intervals.
pub fn ticks_within(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    ticks_impl(lo, hi, target, false)
}

fn ticks_impl(lo: f64, hi: f64, target: usize, cover: bool) -> Vec<f64> {
    let Some((lo, hi)) = sanitize_range(lo, hi) else {
        return Vec::new();
    };
    let span = hi - lo;
    if !span.is_finite() {
        return if cover { vec![lo, hi] } else { Vec::new() };
    }
    let target = target.max(1);
    let raw = span / target as f64;
    let step = if cover {
        cover_step(lo, hi, raw, target)
    } else {
        nice_step(raw)
    };
    if !(step.is_finite() && step > 0.0) {
        return if cover { vec![lo, hi] } else { Vec::new() };
    }
    let Some((i0, i1)) = tick_indices(lo, hi, step, cover) else {
        return if cover { vec![lo, hi] } else { Vec::new() };
    };
    (0..=(i1 - i0) as i64)
        .map(|k| {
            let v = (i0 + k as f64) * step;
            if v.abs() < step * 1e-9 {
                0.0
            } else {
                v
            }
        })
        .collect()
}

/// First and last tick index (multiples of `step`), either covering
/// `[lo, hi]` or inside it; `None` if absurd (more than 1000 ticks).
fn tick_indices(lo: f64, hi: f64, step: f64, cover: bool) -> Option<(f64, f64)> {
    let (a, b) = (lo / step, hi / step);
    let (i0, i1) = if cover {
        ((a + 1e-9).floor(), (b - 1e-9).ceil())
    } else {
        ((a - 1e-9).ceil(), (b + 1e-9).floor())
    };
    (i0.is_finite() && i1.is_finite() && i1 >= i0 && i1 - i0 <= 1000.0).then_some((i0, i1))
}

/// Step for covering ticks: among round steps near `raw` giving 2 to
/// `target + 2` intervals, the one wasting the least range beyond
/// `[lo, hi]`, then the one closest to `target` intervals.
fn cover_step(lo: f64, hi: f64, raw: f64, target: usize) -> f64 {
    let k = raw.log10().floor();
    let mut best: Option<(f64, usize, f64)> = None;
    for e in [k - 1.0, k, k + 1.0] {
        for m in [1.0, 2.0, 2.5, 5.0] {
            let s = m * 10f64.powf(e);
            if !(s >= raw / 2.5 && s <= raw * 2.5) {
                continue;
            }
            let Some((i0, i1)) = tick_indices(lo, hi, s, true) else {
                continue;
            };
            let n = (i1 - i0) as usize;
            if n < 2 || n > target + 2 {
                continue;
            }
            let waste = ((i1 - i0) * s - (hi - lo)) / (hi - lo);
            let dev = n.abs_diff(target);
            let better = match best {
                None => true,
                Some((bw, bd, _)) => waste < bw - 1e-9 || (waste <= bw + 1e-9 && dev < bd),
            };
            if better {
                best = Some((waste, dev, s));
            }
        }
    }
    best.map_or_else(|| nice_step(raw), |b| b.2)
}

/// Tick labels with a shared number of decimals derived from the spacing;
/// very large or small magnitudes use exponent notation (`1.5e6`).
pub fn format_ticks(ticks: &[f64]) -> Vec<String> {
    let step = ticks
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .find(|d| *d > 0.0 && d.is_finite())
        .unwrap_or_else(|| ticks.first().map_or(1.0, |v| v.abs().max(1e-300)));
    let mag = ticks
        .iter()
        .filter(|v| v.is_finite())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let sci = mag >= 1e6 || (step < 1e-4 && mag > 0.0);
    ticks
        .iter()
        .map(|&v| {
            if !v.is_finite() {
                return format!("{v}");
            }
            let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
            let s = if sci {
                let d = (mag.log10().floor() - step.log10().floor()).clamp(0.0, 6.0) as usize;
                let d = if v == 0.0 { 0 } else { d };
                format!("{v:.d$e}")
            } else {
                let k = step.log10().floor();
                let m = step / 10f64.powf(k);
                let mut d = (-k).max(0.0) as usize;
                if (m - 2.5).abs() < 1e-6 && k <= 0.0 {
                    d += 1;
                }
                format!("{v:.d$}", d = d.min(12))
            };
            if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
                s[1..].to_string()
            } else {
                s
            }
        })
        .collect()
}

/// Histogram of the finite `values` in `bins` equal bins over `range`
/// (default: the finite min/max; empty or degenerate ranges are widened).
/// Returns `bins + 1` edges and `bins` counts; values outside the range are
/// ignored, the upper edge belongs to the last bin; `bins = 0` means 1.
pub fn histogram(values: &[f64], bins: usize, range: Option<(f64, f64)>) -> (Vec<f64>, Vec<u64>) {
    let bins = bins.clamp(1, 1 << 24);
    let (lo, hi) = range
        .and_then(|(a, b)| sanitize_range(a, b))
        .or_else(|| {
            let mut b = Bounds::default();
            values.iter().for_each(|&v| b.add(v));
            b.get().and_then(|(a, c)| sanitize_range(a, c))
        })
        .unwrap_or((0.0, 1.0));
    let width = (hi - lo) / bins as f64;
    let edges: Vec<f64> = (0..=bins)
        .map(|i| if i == bins { hi } else { lo + width * i as f64 })
        .collect();
    let mut counts = vec![0u64; bins];
    for &v in values {
        if !(v >= lo && v <= hi) {
            continue;
        }
        let i = (((v - lo) / (hi - lo)) * bins as f64) as usize;
        counts[i.min(bins - 1)] += 1;
    }
    (edges, counts)
}

/// A chart showing `data` (`rows` x `cols`, row-major, row 0 at the bottom)
/// as a colour-mapped image over `x_extent` x `y_extent`, with a colour bar.
/// Add a title and labels with the [`Chart`] setters, e.g.
/// `heatmap(&h, nr, nc, (0.0, 8.0), (-PI, PI)).title("PGR").x_label("ρ (m)")`.
pub fn heatmap(
    data: &[f32],
    rows: usize,
    cols: usize,
    x_extent: (f64, f64),
    y_extent: (f64, f64),
) -> Chart {
    let mut c = Chart::new("");
    c.set_heatmap(Heatmap {
        data: data.to_vec(),
        rows,
        cols,
        x_extent,
        y_extent,
        value_range: None,
        label: String::new(),
    });
    c
}

impl Chart {
    /// Fix the colour-map value range of the heatmap (no effect without one).
    pub fn color_range(mut self, lo: f64, hi: f64) -> Self {
        if let Some(h) = &mut self.heat {
            h.value_range = Some((lo, hi));
        }
        self
    }

    /// Label the heatmap colour bar (no effect without a heatmap).
    pub fn colorbar_label(mut self, label: &str) -> Self {
        if let Some(h) = &mut self.heat {
            h.label = label.to_string();
        }
        self
    }
}
