//! An RGB pixel buffer with anti-aliased drawing primitives clipped to the
//! image;
//! text (see `text.rs`) and charts are drawn into it through `plotters`. Coordinates are pixels as `f64`, x right, y down;
//! pixel `(i, j)` covers `[i, i+1) x [j, j+1)`, so its centre is
//! `(i + 0.5, j + 0.5)`.

use std::io;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::{BitMapBackend, DrawingArea, IntoDrawingArea};

/// An 8-bit RGB colour.
pub type Rgb = [u8; 3];

/// Text alignment relative to the anchor point, per axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    /// Anchor at the left (horizontal) or top (vertical) edge of the text.
    Start,
    /// Anchor at the centre of the text.
    Center,
    /// Anchor at the right (horizontal) or bottom (vertical) edge of the text.
    End,
}

/// Half-open rectangle in integer pixels that drawing is clipped to (the image).
#[derive(Debug, Clone, Copy)]
struct Clip {
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
}

/// An RGB image with drawing operations. All operations clip to the image
/// and silently ignore non-finite input.
#[derive(Debug, Clone)]
pub struct Raster {
    width: u32,
    height: u32,
    buf: Vec<u8>,
    clip: Clip,
}

/// Largest dimension accepted; bigger requests are clamped (memory safety net).
const MAX_DIM: u32 = 16_384;

impl Raster {
    /// A `width` x `height` image filled with `bg` (each side clamped to
    /// `1..=16384`).
    pub fn new(width: u32, height: u32, bg: Rgb) -> Self {
        let width = width.clamp(1, MAX_DIM);
        let height = height.clamp(1, MAX_DIM);
        let n = width as usize * height as usize;
        let mut buf = Vec::with_capacity(n * 3);
        for _ in 0..n {
            buf.extend_from_slice(&bg);
        }
        Raster {
            width,
            height,
            buf,
            clip: Clip {
                x0: 0,
                y0: 0,
                x1: width as i64,
                y1: height as i64,
            },
        }
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Raw row-major RGB bytes (row 0 at the top).
    pub fn as_bytes(&self) -> &[u8] {
        &self.buf
    }

    /// A `plotters` drawing area over this image (for text and charts).
    pub fn drawing_area(&mut self) -> DrawingArea<BitMapBackend<'_>, Shift> {
        BitMapBackend::with_buffer(&mut self.buf, (self.width, self.height)).into_drawing_area()
    }

    /// Colour of pixel `(x, y)`, or `None` outside the image.
    pub fn pixel(&self, x: i64, y: i64) -> Option<Rgb> {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return None;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        Some([self.buf[i], self.buf[i + 1], self.buf[i + 2]])
    }

    /// Set pixel `(x, y)` to `c` (ignored outside the image).
    pub fn put(&mut self, x: i64, y: i64, c: Rgb) {
        self.blend(x, y, c, 1.0);
    }

    /// Mix `c` into pixel `(x, y)` with opacity `alpha` in `[0, 1]`.
    pub fn blend(&mut self, x: i64, y: i64, c: Rgb, alpha: f64) {
        let cl = self.clip;
        if x < cl.x0 || y < cl.y0 || x >= cl.x1 || y >= cl.y1 || alpha.is_nan() || alpha <= 0.0 {
            return;
        }
        let i = (y as usize * self.width as usize + x as usize) * 3;
        if alpha >= 1.0 {
            self.buf[i..i + 3].copy_from_slice(&c);
        } else {
            for (dst, &src) in self.buf[i..i + 3].iter_mut().zip(&c) {
                let old = *dst as f64;
                *dst = (old + (src as f64 - old) * alpha).round().clamp(0.0, 255.0) as u8;
            }
        }
    }

    /// Integer pixel range `[lo, hi)` of `[a, b]` clamped to `[min, max)`.
    fn span(a: f64, b: f64, min: i64, max: i64) -> (i64, i64) {
        let lo = a.floor().max(min as f64).min(max as f64) as i64;
        let hi = (b.ceil() + 1.0).max(min as f64).min(max as f64) as i64;
        (lo, hi)
    }

    /// Fill the half-open integer rectangle `[x0, x1) x [y0, y1)` with `c`.
    pub fn fill_rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb) {
        let cl = self.clip;
        let (xa, xb) = (x0.max(cl.x0), x1.min(cl.x1));
        let (ya, yb) = (y0.max(cl.y0), y1.min(cl.y1));
        if xa >= xb || ya >= yb {
            return;
        }
        let w = self.width as usize;
        for y in ya..yb {
            let row = y as usize * w;
            for x in xa..xb {
                let i = (row + x as usize) * 3;
                self.buf[i..i + 3].copy_from_slice(&c);
            }
        }
    }

    /// Fill an integer rectangle blending `c` with opacity `alpha`.
    pub fn fill_rect_alpha(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb, alpha: f64) {
        let cl = self.clip;
        for y in y0.max(cl.y0)..y1.min(cl.y1) {
            for x in x0.max(cl.x0)..x1.min(cl.x1) {
                self.blend(x, y, c, alpha);
            }
        }
    }

    /// One-pixel-per-`width` outline of the half-open rectangle
    /// `[x0, x1) x [y0, y1)`, drawn inside it.
    pub fn stroke_rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, width: i64, c: Rgb) {
        let w = width.max(1);
        self.fill_rect(x0, y0, x1, (y0 + w).min(y1), c);
        self.fill_rect(x0, (y1 - w).max(y0), x1, y1, c);
        self.fill_rect(x0, y0, (x0 + w).min(x1), y1, c);
        self.fill_rect((x1 - w).max(x0), y0, x1, y1, c);
    }

    /// Clip segment `a`-`b` to the rectangle grown by `pad` (Liang-Barsky).
    fn clip_segment(&self, a: (f64, f64), b: (f64, f64), pad: f64) -> Option<[f64; 4]> {
        let cl = self.clip;
        let (xmin, xmax) = (cl.x0 as f64 - pad, cl.x1 as f64 + pad);
        let (ymin, ymax) = (cl.y0 as f64 - pad, cl.y1 as f64 + pad);
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (p, q) in [
            (-dx, a.0 - xmin),
            (dx, xmax - a.0),
            (-dy, a.1 - ymin),
            (dy, ymax - a.1),
        ] {
            if p == 0.0 {
                if q < 0.0 {
                    return None;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
                if t0 > t1 {
                    return None;
                }
            }
        }
        Some([a.0 + dx * t0, a.1 + dy * t0, a.0 + dx * t1, a.1 + dy * t1])
    }

    /// Anti-aliased line segment with round caps, `width` pixels thick.
    /// Widths below one pixel give proportionally fainter lines.
    pub fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, width: f64, c: Rgb) {
        if ![x0, y0, x1, y1, width].iter().all(|v| v.is_finite()) {
            return;
        }
        let r = width.max(0.05) / 2.0;
        let pad = r + 1.0;
        let Some([ax, ay, bx, by]) = self.clip_segment((x0, y0), (x1, y1), pad) else {
            return;
        };
        let (dx, dy) = (bx - ax, by - ay);
        let len2 = dx * dx + dy * dy;
        let cl = self.clip;
        let (ya, yb) = Self::span(ay.min(by) - pad, ay.max(by) + pad, cl.y0, cl.y1);
        for py in ya..yb {
            let yc = py as f64 + 0.5;
            let (xlo, xhi) = if dy.abs() < 1e-9 {
                (ax.min(bx) - pad, ax.max(bx) + pad)
            } else {
                let ta = ((yc - pad - ay) / dy).clamp(0.0, 1.0);
                let tb = ((yc + pad - ay) / dy).clamp(0.0, 1.0);
                let (xa, xb) = (ax + dx * ta, ax + dx * tb);
                (xa.min(xb) - pad, xa.max(xb) + pad)
            };
            let (xs, xe) = Self::span(xlo, xhi, cl.x0, cl.x1);
            for px in xs..xe {
                let xc = px as f64 + 0.5;
                let t = if len2 > 0.0 {
                    (((xc - ax) * dx + (yc - ay) * dy) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let (qx, qy) = (ax + dx * t - xc, ay + dy * t - yc);
                let d = (qx * qx + qy * qy).sqrt();
                let cov = (r + 0.5 - d).clamp(0.0, 1.0);
                self.blend(px, py, c, cov);
            }
        }
    }

    /// Connected line segments through `pts`; a non-finite point breaks the line.
    pub fn polyline(&mut self, pts: &[(f64, f64)], width: f64, c: Rgb) {
        for w in pts.windows(2) {
            self.line(w[0].0, w[0].1, w[1].0, w[1].1, width, c);
        }
    }

    /// Dashed straight line: `dash` pixels on, `gap` pixels off.
    #[allow(clippy::too_many_arguments)]
    pub fn dashed_line(
        &mut self,
        x0: f64,
        y0: f64,
        x1: f64,
        y1: f64,
        width: f64,
        dash: f64,
        gap: f64,
        c: Rgb,
    ) {
        let len = ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
        if !len.is_finite() || dash.is_nan() || dash <= 0.0 || gap < 0.0 || !gap.is_finite() {
            return;
        }
        let period = dash + gap;
        if len / period > 100_000.0 {
            self.line(x0, y0, x1, y1, width, c);
            return;
        }
        let (ux, uy) = if len > 0.0 {
            ((x1 - x0) / len, (y1 - y0) / len)
        } else {
            (0.0, 0.0)
        };
        let mut s = 0.0;
        while s < len {
            let e = (s + dash).min(len);
            self.line(x0 + ux * s, y0 + uy * s, x0 + ux * e, y0 + uy * e, width, c);
            s += period;
        }
    }

    /// Filled anti-aliased disc of radius `r` pixels centred at `(cx, cy)`.
    pub fn disc(&mut self, cx: f64, cy: f64, r: f64, c: Rgb) {
        if ![cx, cy, r].iter().all(|v| v.is_finite()) || r < 0.0 {
            return;
        }
        let cl = self.clip;
        let pad = r + 1.0;
        let (xa, xb) = Self::span(cx - pad, cx + pad, cl.x0, cl.x1);
        let (ya, yb) = Self::span(cy - pad, cy + pad, cl.y0, cl.y1);
        for py in ya..yb {
            for px in xa..xb {
                let d = ((px as f64 + 0.5 - cx).powi(2) + (py as f64 + 0.5 - cy).powi(2)).sqrt();
                self.blend(px, py, c, (r + 0.5 - d).clamp(0.0, 1.0));
            }
        }
    }

    /// Anti-aliased circle outline of radius `r`, stroke `width` pixels.
    pub fn ring(&mut self, cx: f64, cy: f64, r: f64, width: f64, c: Rgb) {
        if ![cx, cy, r, width].iter().all(|v| v.is_finite()) || r < 0.0 {
            return;
        }
        let hw = width.max(0.05) / 2.0;
        let pad = r + hw + 1.0;
        let cl = self.clip;
        let (xa, xb) = Self::span(cx - pad, cx + pad, cl.x0, cl.x1);
        let (ya, yb) = Self::span(cy - pad, cy + pad, cl.y0, cl.y1);
        for py in ya..yb {
            let ddy = py as f64 + 0.5 - cy;
            for px in xa..xb {
                let ddx = px as f64 + 0.5 - cx;
                let d = (ddx * ddx + ddy * ddy).sqrt();
                self.blend(px, py, c, (hw + 0.5 - (d - r).abs()).clamp(0.0, 1.0));
            }
        }
    }

    /// Filled anti-aliased triangle.
    pub fn triangle(&mut self, p: [(f64, f64); 3], c: Rgb) {
        if !p.iter().all(|q| q.0.is_finite() && q.1.is_finite()) {
            return;
        }
        let area2 = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[1].1 - p[0].1) * (p[2].0 - p[0].0);
        if area2 == 0.0 {
            self.polyline(&[p[0], p[1], p[2]], 0.5, c);
            return;
        }
        let sign = area2.signum();
        // Inward-facing unit normals and offsets of the three edges.
        let mut edges = [(0.0, 0.0, 0.0); 3];
        for (k, e) in edges.iter_mut().enumerate() {
            let (a, b) = (p[k], p[(k + 1) % 3]);
            let (ex, ey) = (b.0 - a.0, b.1 - a.1);
            let len = (ex * ex + ey * ey).sqrt().max(1e-12);
            let (nx, ny) = (-ey * sign / len, ex * sign / len);
            *e = (nx, ny, -(nx * a.0 + ny * a.1));
        }
        let cl = self.clip;
        let xs = p.iter().map(|q| q.0);
        let ys = p.iter().map(|q| q.1);
        let (xmin, xmax) = xs.fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
        let (ymin, ymax) = ys.fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
        let (xa, xb) = Self::span(xmin - 1.0, xmax + 1.0, cl.x0, cl.x1);
        let (ya, yb) = Self::span(ymin - 1.0, ymax + 1.0, cl.y0, cl.y1);
        for py in ya..yb {
            let yc = py as f64 + 0.5;
            for px in xa..xb {
                let xc = px as f64 + 0.5;
                let d = edges
                    .iter()
                    .map(|&(nx, ny, o)| nx * xc + ny * yc + o)
                    .fold(f64::MAX, f64::min);
                self.blend(px, py, c, (d + 0.5).clamp(0.0, 1.0));
            }
        }
    }

    /// Arrow from `(x0, y0)` to the tip `(x1, y1)`: a shaft `width` thick and
    /// a filled head `head` pixels long.
    #[allow(clippy::too_many_arguments)]
    pub fn arrow(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, width: f64, head: f64, c: Rgb) {
        let (dx, dy) = (x1 - x0, y1 - y0);
        let len = (dx * dx + dy * dy).sqrt();
        if !len.is_finite() || !head.is_finite() {
            return;
        }
        if len < 1e-9 {
            self.disc(x0, y0, width.max(1.0), c);
            return;
        }
        let (ux, uy) = (dx / len, dy / len);
        let h = head.min(len).max(0.0);
        let hw = (h * 0.5).max(width);
        let (bx, by) = (x1 - ux * h, y1 - uy * h);
        self.line(x0, y0, x1 - ux * h * 0.5, y1 - uy * h * 0.5, width, c);
        self.triangle(
            [
                (x1, y1),
                (bx - uy * hw, by + ux * hw),
                (bx + uy * hw, by - ux * hw),
            ],
            c,
        );
    }

    /// Blend the whole image towards `c` by `amount` in `[0, 1]` (e.g. to
    /// fade a background before drawing overlays). Ignores the clip.
    pub fn wash(&mut self, c: Rgb, amount: f64) {
        let a = if amount.is_finite() {
            amount.clamp(0.0, 1.0)
        } else {
            0.0
        };
        for px in self.buf.chunks_exact_mut(3) {
            for k in 0..3 {
                let old = px[k] as f64;
                px[k] = (old + (c[k] as f64 - old) * a).round() as u8;
            }
        }
    }

    /// Copy into an `image` crate buffer.
    pub fn to_image(&self) -> image::RgbImage {
        image::RgbImage::from_raw(self.width, self.height, self.buf.clone())
            .unwrap_or_else(|| image::RgbImage::new(self.width, self.height))
    }

    /// Write the image as a PNG file.
    pub fn save_png(&self, path: impl AsRef<Path>) -> io::Result<()> {
        self.to_image()
            .save_with_format(path, image::ImageFormat::Png)
            .map_err(image_err)
    }
}

/// Convert an `image` error into an `io::Error`, keeping real I/O errors.
pub(crate) fn image_err(e: image::ImageError) -> io::Error {
    match e {
        image::ImageError::IoError(e) => e,
        other => io::Error::other(other),
    }
}
