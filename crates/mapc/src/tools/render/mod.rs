//! Map figures: an occupancy map drawn as a PNG with overlays placed in
//! map-frame coordinates (metres), with text in the bundled DejaVu Sans font
//! (drawn through `plotters`, see [`text`]).
//!
//! The module is self-contained (no other `mapc` module is needed): the map
//! comes in as a plain [`MapLayer`] and everything else as numbers. The
//! map image itself is a hand-written per-cell raster with anti-aliased
//! overlay primitives ([`Raster`], public as well); the charts of
//! [`crate::tools::plot`] draw into the same kind of image with `plotters`.
//!
//! ```no_run
//! use mapc::tools::render::{color, MapCanvas, MapLayer, Mark, Corner};
//! let gray = vec![255u8; 200 * 100];
//! let map = MapLayer { width: 200, height: 100, gray: &gray, resolution: 0.05, origin: [-5.0, -2.5, 0.0] };
//! let mut canvas = MapCanvas::new(&map);
//! canvas.pose(1.0, 0.5, 0.3, color::GREEN);
//! canvas.legend(&[("true pose", color::GREEN, Mark::Arrow)], Corner::TopRight);
//! canvas.scale_bar(Corner::BottomLeft);
//! canvas.save_png("/tmp/map.png").unwrap();
//! ```

pub mod color;
mod raster;
pub mod text;

#[cfg(test)]
mod tests;

use std::io;
use std::path::Path;

pub use raster::{Align, Raster, Rgb};
pub use text::text_size;

/// Default length in pixels of the longer side of a [`MapCanvas`].
pub const DEFAULT_LONG_SIDE: u32 = 1600;

/// Gray value used for cells missing from a too-short `gray` buffer.
const UNKNOWN_GRAY: u8 = 205;

/// An occupancy map as plain data (independent of the map loader's types).
#[derive(Debug, Clone, Copy)]
pub struct MapLayer<'a> {
    /// Width in cells.
    pub width: u32,
    /// Height in cells.
    pub height: u32,
    /// Row-major gray levels, row 0 = TOP row (image order), 0 black .. 255
    /// white. Missing entries (buffer too short) are drawn as unknown gray.
    pub gray: &'a [u8],
    /// Cell size in metres per cell (non-positive or non-finite: 1.0).
    pub resolution: f64,
    /// Map-frame pose `(x m, y m, yaw rad)` of the lower-left corner of the
    /// bottom-left cell (ROS map_server convention).
    pub origin: [f64; 3],
}

/// A corner of the image, for legends, scale bars and captions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Corner {
    /// Upper left.
    TopLeft,
    /// Upper right.
    TopRight,
    /// Lower left.
    BottomLeft,
    /// Lower right.
    BottomRight,
}

/// Symbol drawn next to a legend entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// Filled dot.
    Dot,
    /// Circle outline.
    Ring,
    /// Solid line.
    Line,
    /// Dashed line.
    Dashed,
    /// Filled square (cells, bars).
    Square,
    /// Arrow (poses).
    Arrow,
}

/// A map drawn into an RGB image, with drawing helpers in map-frame metres
/// (`x`, `y`, y up) and in cell coordinates (`cx`, `cy`, `cy = 0` the bottom
/// row). Pixel sizes (`radius_px`, `width_px`) are in output pixels.
#[derive(Debug, Clone)]
pub struct MapCanvas {
    raster: Raster,
    cells_h: f64,
    scale: f64,
    resolution: f64,
    origin: [f64; 2],
    cos_yaw: f64,
    sin_yaw: f64,
    yaw: f64,
    font_px: f64,
    unit: f64,
    /// Pixel box `(x0, x1, bottom)` of the title, which top-corner boxes avoid.
    title_box: Option<(f64, f64, f64)>,
}

impl MapCanvas {
    /// Canvas whose longer side is about [`DEFAULT_LONG_SIDE`] pixels.
    pub fn new(map: &MapLayer) -> Self {
        Self::with_long_side(map, DEFAULT_LONG_SIDE)
    }

    /// Canvas whose longer side is about `long_side` pixels: small maps are
    /// upscaled by the nearest integer factor (crisp, equal-sized cells), large
    /// maps are downscaled by an exact fractional factor.
    pub fn with_long_side(map: &MapLayer, long_side: u32) -> Self {
        let long = map.width.max(map.height).max(1) as f64;
        let s = long_side.max(1) as f64 / long;
        let s = if s >= 1.0 { s.round() } else { s };
        Self::with_scale(map, s)
    }

    /// Canvas with exactly `px_per_cell` output pixels per map cell
    /// (non-positive or non-finite values mean 1; clamped so that neither
    /// side exceeds 16384 pixels).
    ///
    /// Downscaled maps (factor < 1) average the covered cells but weight in
    /// the darkest one, so one-cell walls stay visible.
    pub fn with_scale(map: &MapLayer, px_per_cell: f64) -> Self {
        let (mw, mh) = (map.width.max(1), map.height.max(1));
        let mut s = if px_per_cell.is_finite() && px_per_cell > 0.0 {
            px_per_cell
        } else {
            1.0
        };
        s = s.min(16_384.0 / mw.max(mh) as f64);
        let w = ((mw as f64 * s).round() as u32).max(1);
        let h = ((mh as f64 * s).round() as u32).max(1);
        let mut raster = Raster::new(w, h, [UNKNOWN_GRAY; 3]);
        let cell = |x: u32, y: u32| -> u8 {
            if x >= map.width || y >= map.height {
                return UNKNOWN_GRAY;
            }
            let i = y as usize * map.width as usize + x as usize;
            map.gray.get(i).copied().unwrap_or(UNKNOWN_GRAY)
        };
        if s >= 1.0 {
            for oy in 0..h {
                let sy = (((oy as f64 + 0.5) / s) as u32).min(mh - 1);
                for ox in 0..w {
                    let sx = (((ox as f64 + 0.5) / s) as u32).min(mw - 1);
                    let g = cell(sx, sy);
                    raster.put(ox as i64, oy as i64, [g, g, g]);
                }
            }
        } else {
            let src = |o: u32, n: u32| -> (u32, u32) {
                let a = ((o as f64 / s).floor() as u32).min(n - 1);
                let b = (((o + 1) as f64 / s).ceil() as u32).clamp(a + 1, n);
                (a, b)
            };
            for oy in 0..h {
                let (ya, yb) = src(oy, mh);
                for ox in 0..w {
                    let (xa, xb) = src(ox, mw);
                    let (mut sum, mut n, mut min) = (0u64, 0u64, 255u8);
                    for y in ya..yb {
                        for x in xa..xb {
                            let g = cell(x, y);
                            sum += g as u64;
                            n += 1;
                            min = min.min(g);
                        }
                    }
                    let avg = sum as f64 / n.max(1) as f64;
                    let g = (0.5 * avg + 0.5 * min as f64).round() as u8;
                    raster.put(ox as i64, oy as i64, [g, g, g]);
                }
            }
        }
        let resolution = if map.resolution.is_finite() && map.resolution > 0.0 {
            map.resolution
        } else {
            1.0
        };
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        let yaw = finite(map.origin[2]);
        let long = w.max(h) as f64;
        MapCanvas {
            raster,
            cells_h: mh as f64,
            scale: s,
            resolution,
            origin: [finite(map.origin[0]), finite(map.origin[1])],
            cos_yaw: yaw.cos(),
            sin_yaw: yaw.sin(),
            yaw,
            font_px: (long / 60.0).clamp(10.0, 300.0),
            unit: (long / 900.0).max(1.0),
            title_box: None,
        }
    }

    /// Output pixels per map cell.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Output pixels per metre.
    pub fn px_per_meter(&self) -> f64 {
        self.scale / self.resolution
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.raster.width()
    }

    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.raster.height()
    }

    /// Font size in pixels of legends and the scale bar (labels are a
    /// little smaller, the title larger): about 1/60 of the longer side.
    pub fn font_px(&self) -> f64 {
        self.font_px
    }

    /// Change the font size (pixels, at least 4).
    pub fn set_font_px(&mut self, px: f64) {
        if px.is_finite() {
            self.font_px = px.max(4.0);
        }
    }

    /// Default stroke unit in pixels (about 1 px per 900 px of image side),
    /// used for the default sizes of poses, legends and the scale bar.
    pub fn unit(&self) -> f64 {
        self.unit
    }

    /// The underlying image.
    pub fn raster(&self) -> &Raster {
        &self.raster
    }

    /// Mutable access to the underlying image, for custom pixel drawing
    /// (combine with [`MapCanvas::world_to_px`]).
    pub fn raster_mut(&mut self) -> &mut Raster {
        &mut self.raster
    }

    /// Consume the canvas, returning its image.
    pub fn into_raster(self) -> Raster {
        self.raster
    }

    /// Map-frame point (metres) to continuous pixel coordinates (x right,
    /// y down; pixel `(i, j)` spans `[i, i+1) x [j, j+1)`).
    pub fn world_to_px(&self, x: f64, y: f64) -> (f64, f64) {
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        let lx = self.cos_yaw * dx + self.sin_yaw * dy;
        let ly = -self.sin_yaw * dx + self.cos_yaw * dy;
        let (u, v) = (lx / self.resolution, ly / self.resolution);
        (u * self.scale, (self.cells_h - v) * self.scale)
    }

    /// Inverse of [`MapCanvas::world_to_px`].
    pub fn px_to_world(&self, px: f64, py: f64) -> (f64, f64) {
        let u = px / self.scale;
        let v = self.cells_h - py / self.scale;
        let (lx, ly) = (u * self.resolution, v * self.resolution);
        (
            self.origin[0] + self.cos_yaw * lx - self.sin_yaw * ly,
            self.origin[1] + self.sin_yaw * lx + self.cos_yaw * ly,
        )
    }

    /// Pixel coordinates of the centre of cell `(cx, cy)` (`cy = 0` is the
    /// bottom row; fractional cells allowed).
    pub fn cell_to_px(&self, cx: f64, cy: f64) -> (f64, f64) {
        (
            (cx + 0.5) * self.scale,
            (self.cells_h - cy - 0.5) * self.scale,
        )
    }

    /// Map-frame coordinates (metres) of the centre of cell `(cx, cy)`.
    pub fn cell_to_world(&self, cx: f64, cy: f64) -> (f64, f64) {
        let (px, py) = self.cell_to_px(cx, cy);
        self.px_to_world(px, py)
    }

    /// Pixel-space direction angle (radians, y down) of map-frame heading `theta`.
    fn px_angle(&self, theta: f64) -> f64 {
        -(theta - self.yaw)
    }

    /// Blend the whole image towards white by `amount` in `[0, 1]` so that
    /// overlays stand out; call before drawing overlays.
    pub fn fade(&mut self, amount: f64) {
        self.raster.wash(color::WHITE, amount);
    }

    /// Paint cell `(cx, cy)` (`cy = 0` bottom row) with `c`; at least one
    /// pixel is painted even when the map is downscaled.
    pub fn fill_cell(&mut self, cx: i64, cy: i64, c: Rgb) {
        let s = self.scale;
        let top = self.cells_h as i64 - 1 - cy;
        let x0 = (cx as f64 * s).round() as i64;
        let y0 = (top as f64 * s).round() as i64;
        let x1 = (((cx + 1) as f64 * s).round() as i64).max(x0 + 1);
        let y1 = (((top + 1) as f64 * s).round() as i64).max(y0 + 1);
        self.raster.fill_rect(x0, y0, x1, y1, c);
    }

    /// Paint every cell of `cells` (`(cx, cy)`, `cy = 0` bottom row).
    pub fn fill_cells<I: IntoIterator<Item = (i64, i64)>>(&mut self, cells: I, c: Rgb) {
        for (cx, cy) in cells {
            self.fill_cell(cx, cy, c);
        }
    }

    /// Filled dot of `radius_px` at the centre of cell `(cx, cy)`.
    pub fn dot_cell(&mut self, cx: f64, cy: f64, radius_px: f64, c: Rgb) {
        let (px, py) = self.cell_to_px(cx, cy);
        self.raster.disc(px, py, radius_px, c);
    }

    /// Polyline through the centres of cells `(cx, cy)`.
    pub fn cell_polyline<I: IntoIterator<Item = (f64, f64)>>(
        &mut self,
        cells: I,
        width_px: f64,
        c: Rgb,
    ) {
        let pts: Vec<_> = cells
            .into_iter()
            .map(|(cx, cy)| self.cell_to_px(cx, cy))
            .collect();
        self.raster.polyline(&pts, width_px, c);
    }

    /// Filled dot of `radius_px` pixels at map-frame `(x, y)`.
    pub fn dot(&mut self, x: f64, y: f64, radius_px: f64, c: Rgb) {
        let (px, py) = self.world_to_px(x, y);
        self.raster.disc(px, py, radius_px, c);
    }

    /// Dot with a contrasting outline ring (more visible on busy maps).
    pub fn marker(&mut self, x: f64, y: f64, radius_px: f64, fill: Rgb, outline: Rgb) {
        let (px, py) = self.world_to_px(x, y);
        self.raster.disc(px, py, radius_px + 1.0, outline);
        self.raster.disc(px, py, radius_px - 0.5, fill);
    }

    /// Line segment between two map-frame points.
    pub fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, width_px: f64, c: Rgb) {
        let (a, b) = (self.world_to_px(x0, y0), self.world_to_px(x1, y1));
        self.raster.line(a.0, a.1, b.0, b.1, width_px, c);
    }

    /// Dashed line segment between two map-frame points.
    pub fn dashed_line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, width_px: f64, c: Rgb) {
        let (a, b) = (self.world_to_px(x0, y0), self.world_to_px(x1, y1));
        let dash = 4.0 * width_px.max(1.0);
        self.raster
            .dashed_line(a.0, a.1, b.0, b.1, width_px, dash, dash * 0.6, c);
    }

    /// Polyline through map-frame points.
    pub fn polyline<I: IntoIterator<Item = (f64, f64)>>(&mut self, pts: I, width_px: f64, c: Rgb) {
        let pts: Vec<_> = pts
            .into_iter()
            .map(|(x, y)| self.world_to_px(x, y))
            .collect();
        self.raster.polyline(&pts, width_px, c);
    }

    /// Circle outline of `radius_m` metres around map-frame `(x, y)`.
    pub fn circle(&mut self, x: f64, y: f64, radius_m: f64, width_px: f64, c: Rgb) {
        let (px, py) = self.world_to_px(x, y);
        self.raster
            .ring(px, py, radius_m * self.px_per_meter(), width_px, c);
    }

    /// Pose arrow of default size: a dot at `(x, y)` and an arrow pointing
    /// along heading `theta` (radians, map frame, CCW from +x).
    pub fn pose(&mut self, x: f64, y: f64, theta: f64, c: Rgb) {
        let u = self.unit;
        self.arrow(x, y, theta, 26.0 * u, 2.2 * u, c);
    }

    /// Pose arrow `length_px` long with a `width_px` shaft, starting at a dot
    /// on `(x, y)` and pointing along heading `theta` (map frame).
    pub fn arrow(&mut self, x: f64, y: f64, theta: f64, length_px: f64, width_px: f64, c: Rgb) {
        let (px, py) = self.world_to_px(x, y);
        let a = self.px_angle(theta);
        let (tx, ty) = (px + length_px * a.cos(), py + length_px * a.sin());
        self.raster.disc(px, py, width_px * 1.4, c);
        self.raster
            .arrow(px, py, tx, ty, width_px, length_px * 0.45, c);
    }

    /// Text label next to map-frame point `(x, y)` (to its upper right), at
    /// 0.8 times the canvas font size, with a white halo.
    pub fn label(&mut self, x: f64, y: f64, text: &str, c: Rgb) {
        let (px, py) = self.world_to_px(x, y);
        let fs = 0.8 * self.font_px;
        let off = 0.15 * fs;
        self.raster.text_halo(
            px + off,
            py - off,
            text,
            fs,
            c,
            color::WHITE,
            Align::Start,
            Align::End,
        );
    }

    /// Top-left pixel of a `w` x `h` box inset from `corner` (boxes in a top
    /// corner move below the title if they would overlap it).
    fn corner_origin(&self, corner: Corner, w: f64, h: f64) -> (f64, f64) {
        let m = (8.0 * self.unit).round();
        let (cw, ch) = (self.width() as f64, self.height() as f64);
        let (x, y) = match corner {
            Corner::TopLeft => (m, m),
            Corner::TopRight => (cw - m - w, m),
            Corner::BottomLeft => (m, ch - m - h),
            Corner::BottomRight => (cw - m - w, ch - m - h),
        };
        match (corner, self.title_box) {
            (Corner::TopLeft | Corner::TopRight, Some((t0, t1, bottom)))
                if x < t1 && x + w > t0 =>
            {
                (x, bottom + m / 2.0)
            }
            _ => (x, y),
        }
    }

    /// Legend box in `corner` listing `(label, colour, mark)` entries.
    pub fn legend(&mut self, entries: &[(&str, Rgb, Mark)], corner: Corner) {
        if entries.is_empty() {
            return;
        }
        let fs = self.font_px;
        let (w, h) = legend_size(entries, fs);
        let (x, y) = self.corner_origin(corner, w as f64, h as f64);
        draw_legend(&mut self.raster, x, y, entries, fs);
    }

    /// Title text centred at the top of the image in a white box, 1.3 times
    /// the canvas font size (smaller if it would not fit). Legends and scale
    /// bars drawn afterwards in a top corner avoid it.
    pub fn title(&mut self, text: &str) {
        let mut fs = 1.3 * self.font_px;
        let fit = 0.95 * self.width() as f64;
        let w0 = text_size(text, fs).0 as f64;
        if w0 > fit {
            fs = (fs * fit / w0).max(4.0);
        }
        let (w, h) = text_size(text, fs);
        let pad = (0.3 * fs).round() as i64;
        let cx = self.width() as i64 / 2;
        let y0 = (6.0 * self.unit) as i64;
        let x0 = cx - w as i64 / 2;
        self.title_box = Some((
            (x0 - pad) as f64,
            (x0 + w as i64 + pad) as f64,
            (y0 + h as i64 + pad) as f64,
        ));
        self.raster.fill_rect_alpha(
            x0 - pad,
            y0 - pad,
            x0 + w as i64 + pad,
            y0 + h as i64 + pad,
            color::WHITE,
            0.85,
        );
        self.raster.text(
            x0 as f64,
            y0 as f64,
            text,
            fs,
            color::BLACK,
            Align::Start,
            Align::Start,
        );
    }

    /// Scale bar with an automatically chosen round length (about a sixth of
    /// the image width).
    pub fn scale_bar(&mut self, corner: Corner) {
        let target_m = self.width() as f64 / 6.0 / self.px_per_meter();
        let len = nice_floor(target_m);
        self.scale_bar_len(len, corner);
    }

    /// Scale bar of `length_m` metres (alternating black and white quarters)
    /// with its length printed above, in a white box.
    pub fn scale_bar_len(&mut self, length_m: f64, corner: Corner) {
        if !(length_m.is_finite() && length_m > 0.0) {
            return;
        }
        let bar_px = length_m * self.px_per_meter();
        if !(bar_px.is_finite() && bar_px >= 1.0) || bar_px > 4.0 * self.width() as f64 {
            return;
        }
        let fs = self.font_px;
        let label = format!("{} m", format_number(length_m));
        let (tw, th) = text_size(&label, fs);
        let pad = 0.3 * fs;
        let bar_h = (3.0 * self.unit).round().max(3.0);
        let w = bar_px.max(tw as f64) + 2.0 * pad;
        let h = pad + th as f64 + pad + bar_h + pad;
        let (x, y) = self.corner_origin(corner, w, h);
        let r = &mut self.raster;
        let (xi, yi) = (x.round() as i64, y.round() as i64);
        r.fill_rect_alpha(
            xi,
            yi,
            xi + w.round() as i64,
            yi + h.round() as i64,
            color::WHITE,
            0.85,
        );
        let bx = x + (w - bar_px) / 2.0;
        let by = y + pad + th as f64 + pad;
        for q in 0..4 {
            let qa = (bx + bar_px * q as f64 / 4.0).round() as i64;
            let qb = (bx + bar_px * (q + 1) as f64 / 4.0).round() as i64;
            let c = if q % 2 == 0 {
                color::BLACK
            } else {
                color::WHITE
            };
            r.fill_rect(qa, by as i64, qb, (by + bar_h) as i64, c);
        }
        r.stroke_rect(
            bx.round() as i64,
            by as i64,
            (bx + bar_px).round() as i64,
            (by + bar_h) as i64,
            1,
            color::BLACK,
        );
        r.text(
            x + w / 2.0,
            y + pad,
            &label,
            fs,
            color::BLACK,
            Align::Center,
            Align::Start,
        );
    }

    /// Write the image as a PNG file.
    pub fn save_png(&self, path: impl AsRef<Path>) -> io::Result<()> {
        self.raster.save_png(path)
    }
}

/// Largest number of the form {1, 2, 5} x 10^k not above `v` (v > 0).
fn nice_floor(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return 1.0;
    }
    let k = v.log10().floor();
    let base = 10f64.powf(k);
    let m = v / base;
    let mant = if m >= 5.0 {
        5.0
    } else if m >= 2.0 {
        2.0
    } else {
        1.0
    };
    mant * base
}

/// Short decimal rendering of a round number (no trailing zeros).
fn format_number(v: f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" || s.is_empty() {
        "0".to_string()
    } else {
        s.to_string()
    }
}

/// Geometry of a legend at font size `fs`: (padding, swatch width, row
/// height), in pixels.
fn legend_metrics(fs: f64) -> (f64, f64, f64) {
    (0.4 * fs, 1.6 * fs, 1.25 * fs)
}

/// Pixel size `(w, h)` of the legend box for `entries` at font size `fs`.
fn legend_size(entries: &[(&str, Rgb, Mark)], fs: f64) -> (u32, u32) {
    let (pad, sw, row) = legend_metrics(fs);
    let tw = entries
        .iter()
        .map(|e| text_size(e.0, fs).0)
        .max()
        .unwrap_or(0) as f64;
    let n = entries.len() as f64;
    (
        (pad + sw + pad + tw + pad).ceil() as u32,
        (2.0 * pad + n * row).ceil() as u32,
    )
}

/// Draw a legend box with its top-left corner at `(x, y)`.
fn draw_legend(r: &mut Raster, x: f64, y: f64, entries: &[(&str, Rgb, Mark)], fs: f64) {
    let (w, h) = legend_size(entries, fs);
    let (pad, sw, row) = legend_metrics(fs);
    let s = fs / 10.0;
    let (xi, yi) = (x.round() as i64, y.round() as i64);
    r.fill_rect_alpha(xi, yi, xi + w as i64, yi + h as i64, color::WHITE, 0.9);
    r.stroke_rect(xi, yi, xi + w as i64, yi + h as i64, 1, color::GRAY);
    for (i, &(label, c, mark)) in entries.iter().enumerate() {
        let cy = yi as f64 + pad + (i as f64 + 0.5) * row;
        let (sx0, sx1) = (xi as f64 + pad, xi as f64 + pad + sw);
        let mid = (sx0 + sx1) / 2.0;
        match mark {
            Mark::Dot => r.disc(mid, cy, 3.0 * s, c),
            Mark::Ring => r.ring(mid, cy, 3.0 * s, 0.7 * s, c),
            Mark::Line => r.line(sx0, cy, sx1, cy, 1.5 * s, c),
            Mark::Dashed => r.dashed_line(sx0, cy, sx1, cy, 1.5 * s, 4.0 * s, 2.5 * s, c),
            Mark::Square => {
                let hs = (0.35 * fs).round() as i64;
                let (m, yc) = (mid.round() as i64, cy.round() as i64);
                r.fill_rect(m - hs, yc - hs, m + hs, yc + hs, c);
            }
            Mark::Arrow => r.arrow(sx0, cy, sx1, cy, 1.2 * s, 6.0 * s, c),
        }
        r.text(
            sx1 + pad,
            cy,
            label,
            fs,
            color::BLACK,
            Align::Start,
            Align::Center,
        );
    }
}
