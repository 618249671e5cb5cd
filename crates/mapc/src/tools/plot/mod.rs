//! Charts as PNG images, drawn with `plotters` into an in-memory bitmap:
//! line and bar (histogram) series with a legend, and heatmaps with a colour
//! bar. Text is the bundled DejaVu Sans font of [`crate::tools::render`], so
//! the same chart always gives the same bytes. Ticks are round numbers, and
//! whole numbers on an axis marked as integer ([`Chart::integer_x`],
//! [`Chart::integer_y`]: ranks, counts).
//!
//! ```no_run
//! use mapc::tools::plot::{color, histogram, Chart};
//! let (edges, counts) = histogram(&[0.1, 0.4, 0.45, 0.9], 10, Some((0.0, 1.0)));
//! let mut chart = Chart::new("Position error").x_label("error (m)").y_label("count").integer_y();
//! chart.hist(&edges, &counts, color::BLUE, "errors");
//! chart.line(&[0.0, 1.0], &[0.0, 2.0], color::RED, "trend");
//! chart.save_png("/tmp/chart.png").unwrap();
//! ```

#[cfg(test)]
mod tests;

use std::error::Error;
use std::io;
use std::ops::Range;
use std::path::Path;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::coord::Shift;
use plotters::prelude::*;

pub use crate::tools::render::color;
use crate::tools::render::text::{font, rgb, text_size};
pub use crate::tools::render::{Raster, Rgb};

/// Default chart width in pixels.
pub const DEFAULT_WIDTH: u32 = 900;
/// Default chart height in pixels.
pub const DEFAULT_HEIGHT: u32 = 600;

/// Grid line colour.
const GRID: Rgb = [228, 228, 228];

/// Share of the font size by which y tick labels move down to centre on
/// their ticks (`plotters`' `ab_glyph` text sits a little high).
const LABEL_DROP: f64 = 0.15;

/// A drawing area of the in-memory bitmap.
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// The data of one series.
#[derive(Debug, Clone, PartialEq)]
enum Data {
    /// Points joined by straight lines (non-finite points are skipped).
    Line(Vec<(f64, f64)>),
    /// Bars spanning `[edges[i], edges[i+1]]` from zero to `heights[i]`.
    Bars { edges: Vec<f64>, heights: Vec<f64> },
}

/// One labelled series (an empty label keeps it out of the legend).
#[derive(Debug, Clone, PartialEq)]
struct Series {
    label: String,
    color: Rgb,
    data: Data,
}

/// A colour-mapped 2D array shown as an image filling its extents.
#[derive(Debug, Clone, PartialEq)]
struct Heatmap {
    /// Row-major values (row 0 at the bottom); NaN cells are light gray.
    data: Vec<f32>,
    rows: usize,
    cols: usize,
    x_extent: (f64, f64),
    y_extent: (f64, f64),
    /// Values at the ends of the colour map (`None`: data min/max).
    value_range: Option<(f64, f64)>,
    /// Label of the colour bar.
    label: String,
}

/// A 2D chart. Build with the consuming setters, add series with the `&mut`
/// methods, then [`Chart::save_png`] or [`Chart::render`].
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    title: String,
    x_label: String,
    y_label: String,
    width: u32,
    height: u32,
    x_range: Option<(f64, f64)>,
    y_range: Option<(f64, f64)>,
    x_integer: bool,
    y_integer: bool,
    series: Vec<Series>,
    heat: Option<Heatmap>,
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
            x_integer: false,
            y_integer: false,
            series: Vec::new(),
            heat: None,
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

    /// The x values are whole numbers (ranks, counts): ticks only at them.
    pub fn integer_x(mut self) -> Self {
        self.x_integer = true;
        self
    }

    /// The y values are whole numbers (ranks, counts): ticks only at them.
    pub fn integer_y(mut self) -> Self {
        self.y_integer = true;
        self
    }

    /// Add a line series (points paired from `xs` and `ys`).
    pub fn line(&mut self, xs: &[f64], ys: &[f64], c: Rgb, label: &str) {
        let pts = xs.iter().copied().zip(ys.iter().copied()).collect();
        self.push(Data::Line(pts), c, label);
    }

    /// Add bars between consecutive `edges` with the given heights.
    pub fn bars(&mut self, edges: &[f64], heights: &[f64], c: Rgb, label: &str) {
        let data = Data::Bars {
            edges: edges.to_vec(),
            heights: heights.to_vec(),
        };
        self.push(data, c, label);
    }

    /// Add a histogram as bars (e.g. the output of [`histogram`]).
    pub fn hist(&mut self, edges: &[f64], counts: &[u64], c: Rgb, label: &str) {
        let heights: Vec<f64> = counts.iter().map(|&n| n as f64).collect();
        self.bars(edges, &heights, c, label);
    }

    fn push(&mut self, data: Data, c: Rgb, label: &str) {
        self.series.push(Series {
            label: label.to_string(),
            color: c,
            data,
        });
    }

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

    /// Write the chart as a PNG file.
    pub fn save_png(&self, path: impl AsRef<Path>) -> io::Result<()> {
        self.render()?.save_png(path)
    }

    /// Draw the chart into a new image.
    pub fn render(&self) -> io::Result<Raster> {
        let mut r = Raster::new(self.width, self.height, color::WHITE);
        self.draw(&r.drawing_area())
            .map_err(|e| io::Error::other(format!("drawing the chart: {e}")))?;
        Ok(r)
    }

    /// Font size in pixels of the tick labels (titles and axis labels are
    /// larger): 20 px on the default 900x600 chart.
    fn font_px(&self) -> f64 {
        (self.width.min(self.height) as f64 / 30.0).clamp(9.0, 80.0)
    }

    /// Title, then the plot (and the colour bar of a heatmap).
    fn draw(&self, root: &Area) -> Result<(), Box<dyn Error>> {
        let fs = self.font_px();
        let body = if self.title.is_empty() {
            root.clone()
        } else {
            let style = font(fs * 1.3).color(&BLACK);
            root.titled(&self.title, style)?
        };
        let frame = Frame {
            fs,
            margin: (fs * 0.8).round() as u32,
            x_area: (fs * 3.0).round() as u32,
        };
        match &self.heat {
            None => self.draw_plot(&body, &frame),
            Some(hm) => {
                let (vlo, vhi) = heat_range(hm);
                let bar_w = colorbar_width(hm, vlo, vhi, fs);
                let w = body.dim_in_pixel().0;
                let (plot, bar) = body.split_horizontally(w.saturating_sub(bar_w).max(1));
                self.draw_plot(&plot, &frame)?;
                draw_colorbar(&bar, hm, (vlo, vhi), &frame)
            }
        }
    }

    /// Axes, grid, heatmap cells, series and legend.
    fn draw_plot(&self, area: &Area, f: &Frame) -> Result<(), Box<dyn Error>> {
        let (dx, dy) = self.data_bounds();
        let exact = self.heat.is_some();
        let (xlo, xhi) = axis_range(self.x_range, dx, 0.0);
        let (ylo, yhi) = axis_range(self.y_range, dy, if exact { 0.0 } else { 0.05 });
        let (nx, ny) = (
            (area.dim_in_pixel().0 as f64 / (6.0 * f.fs)) as usize,
            (area.dim_in_pixel().1 as f64 / (3.0 * f.fs)) as usize,
        );
        let xt = ticks(xlo, xhi, nx.clamp(2, 10), self.x_integer);
        let yt = ticks(ylo, yhi, ny.clamp(2, 10), self.y_integer);
        let (xfmt, yfmt) = (tick_format(&xt), tick_format(&yt));
        let y_area = yt.iter().map(|&v| text_size(&yfmt(&v), 0.9 * f.fs).0).max();
        let mut chart = ChartBuilder::on(area)
            .margin(f.margin)
            .x_label_area_size(f.x_area)
            .y_label_area_size(y_area.unwrap_or(0) + (2.2 * f.fs) as u32)
            .build_cartesian_2d(Axis::new(xlo, xhi, xt), Axis::new(ylo, yhi, yt))?;
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .label_style(font(0.9 * f.fs))
            .axis_desc_style(font(f.fs))
            .bold_line_style(rgb(GRID))
            .axis_style(rgb(color::DARK_GRAY))
            .y_label_offset(LABEL_DROP * f.fs)
            .x_label_formatter(&xfmt)
            .y_label_formatter(&yfmt);
        if exact {
            mesh.disable_mesh();
        }
        mesh.draw()?;
        if let Some(hm) = &self.heat {
            let (vlo, vhi) = heat_range(hm);
            chart.draw_series(heat_cells(hm, vlo, vhi))?;
        }
        let mut legend = false;
        for s in &self.series {
            let c = rgb(s.color);
            let anno = match &s.data {
                Data::Line(pts) => {
                    let finite = pts.iter().filter(|p| p.0.is_finite() && p.1.is_finite());
                    let style = c.stroke_width(2);
                    chart.draw_series(LineSeries::new(finite.copied(), style))?
                }
                Data::Bars { edges, heights } => {
                    let fill = rgb(color::tint(s.color, 0.25)).filled();
                    let bars = edges.windows(2).zip(heights).filter_map(|(e, &h)| {
                        let ok = e[0].is_finite() && e[1].is_finite() && h.is_finite() && h != 0.0;
                        ok.then(|| [(e[0], 0.0), (e[1], h)])
                    });
                    let rects: Vec<[(f64, f64); 2]> = bars.collect();
                    chart.draw_series(rects.iter().map(|&r| Rectangle::new(r, fill)))?;
                    chart.draw_series(rects.iter().map(|&r| Rectangle::new(r, c)))?
                }
            };
            if !s.label.is_empty() {
                legend = true;
                let w = (1.6 * f.fs) as i32;
                anno.label(s.label.as_str()).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + w, y)], c.stroke_width(3))
                });
            }
        }
        if legend {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font(font(0.9 * f.fs))
                .background_style(WHITE.mix(0.9))
                .border_style(rgb(color::GRAY))
                .legend_area_size((2.0 * f.fs) as i32)
                .draw()?;
        }
        Ok(())
    }

    /// Finite data bounds of the series and heatmap, `(x, y)`.
    fn data_bounds(&self) -> (Span, Span) {
        let mut bx = Bounds::default();
        let mut by = Bounds::default();
        for s in &self.series {
            match &s.data {
                Data::Line(pts) => {
                    for &(x, y) in pts.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
                        bx.add(x);
                        by.add(y);
                    }
                }
                Data::Bars { edges, heights } => {
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
        }
        if let Some(h) = &self.heat {
            bx.add(h.x_extent.0);
            bx.add(h.x_extent.1);
            by.add(h.y_extent.0);
            by.add(h.y_extent.1);
        }
        (bx.0, by.0)
    }
}

/// A linear axis whose ticks are the given values (no minor grid lines).
struct Axis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
}

impl Axis {
    fn new(lo: f64, hi: f64, ticks: Vec<f64>) -> Self {
        Axis { lo, hi, ticks }
    }
}

impl Ranged for Axis {
    type ValueType = f64;
    type FormatOption = DefaultFormatting;

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }

    /// Linear map to pixels, kept far from `i32` overflow for values far
    /// outside the range.
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let t = (value - self.lo) / (self.hi - self.lo);
        let px = limit.0 as f64 + t * (limit.1 - limit.0) as f64;
        if px.is_nan() {
            return limit.0;
        }
        px.clamp(-1e6, 1e6).round() as i32
    }

    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.clone()
        }
    }
}

/// Sizes shared by a chart and its colour bar, so their plot areas line up.
struct Frame {
    /// Tick label font size in pixels.
    fs: f64,
    /// Margin around the plot areas.
    margin: u32,
    /// Height of the x tick label and axis label area.
    x_area: u32,
}

/// Width of the colour bar area: the bar, its tick labels and its label.
fn colorbar_width(hm: &Heatmap, vlo: f64, vhi: f64, fs: f64) -> u32 {
    let t = ticks(vlo, vhi, 6, false);
    let fmt = tick_format(&t);
    let lw = t.iter().map(|v| text_size(&fmt(v), 0.9 * fs).0).max();
    let desc = if hm.label.is_empty() { 0.0 } else { 1.6 * fs };
    (1.5 * fs) as u32 + lw.unwrap_or(0) + (1.2 * fs + desc) as u32
}

/// The colour bar of a heatmap: the colour map from `vlo` (bottom) to `vhi`.
fn draw_colorbar(
    area: &Area,
    hm: &Heatmap,
    (vlo, vhi): (f64, f64),
    f: &Frame,
) -> Result<(), Box<dyn Error>> {
    let t = ticks(vlo, vhi, 6, false);
    let fmt = tick_format(&t);
    let lw = t.iter().map(|v| text_size(&fmt(v), 0.9 * f.fs).0).max();
    let desc = if hm.label.is_empty() { 0.0 } else { 1.6 * f.fs };
    let mut chart = ChartBuilder::on(area)
        .margin(f.margin)
        .margin_left(0)
        .x_label_area_size(f.x_area)
        .right_y_label_area_size(lw.unwrap_or(0) + (0.8 * f.fs + desc) as u32)
        .build_cartesian_2d(0.0..1.0, Axis::new(vlo, vhi, t))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(hm.label.as_str())
        .label_style(font(0.9 * f.fs))
        .axis_desc_style(font(f.fs))
        .axis_style(rgb(color::DARK_GRAY))
        .y_label_offset(LABEL_DROP * f.fs)
        .set_tick_mark_size(LabelAreaPosition::Right, (0.4 * f.fs) as i32)
        .y_label_formatter(&fmt)
        .draw()?;
    let n = 256;
    let step = (vhi - vlo) / n as f64;
    chart.draw_series((0..n).map(|i| {
        let v = vlo + i as f64 * step;
        let c = rgb(color::colormap((i as f64 + 0.5) / n as f64));
        Rectangle::new([(0.0, v), (1.0, v + step)], c.filled())
    }))?;
    Ok(())
}

/// The cells of a heatmap as filled rectangles in data coordinates.
fn heat_cells(hm: &Heatmap, vlo: f64, vhi: f64) -> Vec<Rectangle<(f64, f64)>> {
    let (ex0, ex1) = hm.x_extent;
    let (ey0, ey1) = hm.y_extent;
    let (cw, ch) = (
        (ex1 - ex0) / hm.cols.max(1) as f64,
        (ey1 - ey0) / hm.rows.max(1) as f64,
    );
    if !(cw.is_finite() && ch.is_finite()) {
        return Vec::new();
    }
    let mut cells = Vec::with_capacity(hm.data.len());
    for (i, &v) in hm.data.iter().take(hm.rows * hm.cols).enumerate() {
        let (row, col) = (i / hm.cols, i % hm.cols);
        let c = if v.is_finite() {
            color::colormap((v as f64 - vlo) / (vhi - vlo))
        } else {
            [210, 210, 210]
        };
        let (x0, y0) = (ex0 + col as f64 * cw, ey0 + row as f64 * ch);
        cells.push(Rectangle::new(
            [(x0, y0), (x0 + cw, y0 + ch)],
            rgb(c).filled(),
        ));
    }
    cells
}

/// Colour-map value range of a heatmap: the fixed range or finite min/max,
/// widened when degenerate.
fn heat_range(hm: &Heatmap) -> (f64, f64) {
    let fixed = hm
        .value_range
        .and_then(|(a, b)| (a != b).then_some(()).and(sanitize_range(a, b)));
    if let Some(r) = fixed {
        return r;
    }
    let mut b = Bounds::default();
    for &v in &hm.data {
        b.add(v as f64);
    }
    b.0.and_then(|(lo, hi)| sanitize_range(lo, hi))
        .unwrap_or((0.0, 1.0))
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
}

/// The range of one axis: the fixed one, else the data's (default `0..1`)
/// with `headroom` (a share of the span) above.
fn axis_range(fixed: Span, data: Span, headroom: f64) -> (f64, f64) {
    if let Some(r) = fixed.and_then(|(a, b)| sanitize_range(a, b)) {
        return r;
    }
    let (lo, hi) = data
        .and_then(|(a, b)| sanitize_range(a, b))
        .unwrap_or((0.0, 1.0));
    (lo, hi + headroom * (hi - lo))
}

/// Order a range and widen it if empty; `None` if not finite or so wide
/// that its span overflows.
fn sanitize_range(lo: f64, hi: f64) -> Option<(f64, f64)> {
    if !(lo.is_finite() && hi.is_finite() && (hi - lo).is_finite()) {
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

/// Round tick values inside `[lo, hi]`, about `target` intervals: the
/// smallest step of {1, 2, 5} x 10^k at least 0.7 times the span over
/// `target`, and at least 1 when `integer`. Empty if the
/// range is not finite or would need more than 1000 ticks.
pub fn ticks(lo: f64, hi: f64, target: usize, integer: bool) -> Vec<f64> {
    let Some((lo, hi)) = sanitize_range(lo, hi) else {
        return Vec::new();
    };
    let raw = (hi - lo) / target.max(1) as f64;
    let base = 10f64.powf(raw.log10().floor());
    let mut step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * base)
        .find(|&s| s >= raw * 0.7)
        .unwrap_or(10.0 * base);
    if integer {
        step = step.max(1.0).round();
    }
    let (i0, i1) = ((lo / step - 1e-9).ceil(), (hi / step + 1e-9).floor());
    if !(step > 0.0 && i0.is_finite() && i1.is_finite() && i1 >= i0 && i1 - i0 <= 1000.0) {
        return Vec::new();
    }
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

/// Tick label formatter for `ticks`: as many decimals as their spacing
/// needs (none for whole-number steps), exponent notation for huge or tiny
/// magnitudes.
pub fn tick_format(ticks: &[f64]) -> impl Fn(&f64) -> String {
    let step = ticks
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .find(|d| *d > 0.0 && d.is_finite())
        .unwrap_or(1.0);
    let mag = ticks.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let sci = mag >= 1e6 || (step < 1e-4 && mag > 0.0);
    let decimals = (-step.log10().floor()).clamp(0.0, 12.0) as usize;
    move |&v: &f64| {
        let s = if sci {
            format!("{v:.1e}")
        } else {
            format!("{v:.decimals$}")
        };
        match s.strip_prefix('-') {
            Some(t) if t.chars().all(|c| c == '0' || c == '.') => t.to_string(),
            _ => s,
        }
    }
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
            b.0.and_then(|(a, c)| sanitize_range(a, c))
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
    c.heat = Some(Heatmap {
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
