//! Text in the bundled DejaVu Sans font (`crates/mapc/assets/fonts`), drawn
//! through `plotters` (its `ab_glyph` rasterizer). The font is compiled in, so
//! figures never depend on the fonts installed on the machine and the same
//! inputs always give the same pixels.

use std::sync::Once;

use plotters::prelude::*;
use plotters::style::{register_font, FontDesc, FontStyle};

use super::raster::{Align, Raster, Rgb};

/// Family name under which the bundled font is registered with `plotters`.
const FAMILY: &str = "mapc-dejavu-sans";

/// DejaVu Sans (Bitstream Vera license, see `assets/fonts/LICENSE-DejaVu.txt`).
static FONT_TTF: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

/// Share of the font size between the top of the text box and where
/// `plotters`' `ab_glyph` layout puts the text anchor, so that capitals and
/// descenders sit inside the box reported by [`text_size`].
const TOP_SHIFT: f64 = 0.16;

/// The bundled font at `px` pixels (registered with `plotters` on first use).
pub fn font(px: f64) -> FontDesc<'static> {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        let ok = register_font(FAMILY, FontStyle::Normal, FONT_TTF).is_ok();
        assert!(ok, "the bundled DejaVu Sans font does not parse");
    });
    (FAMILY, px.clamp(1.0, 2000.0)).into_font()
}

/// Pixel size `(w, h)` of one line of `text` at font size `px` (the height
/// is the font size: room for capitals and descenders).
pub fn text_size(text: &str, px: f64) -> (u32, u32) {
    let w = font(px).box_size(text).map_or(0, |(w, _)| w);
    (w, px.clamp(1.0, 2000.0).round() as u32)
}

/// Color in `plotters`' type.
pub fn rgb(c: Rgb) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

impl Raster {
    /// Draw one line of `text` at font size `px`, placed relative to `(x, y)`
    /// by the `h`/`v` alignment of its [`text_size`] box. Returns its width.
    #[allow(clippy::too_many_arguments)]
    pub fn text(&mut self, x: f64, y: f64, text: &str, px: f64, c: Rgb, h: Align, v: Align) -> u32 {
        let (w, ht) = text_size(text, px);
        if !(x.is_finite() && y.is_finite()) || text.is_empty() {
            return w;
        }
        let (x0, y0) = aligned_origin(x, y, w, ht, h, v);
        let style = font(px).color(&rgb(c));
        let pos = (x0.round() as i32, (y0 + TOP_SHIFT * px).round() as i32);
        let area = self.drawing_area();
        // Drawing into a memory buffer cannot fail; glyphs off the image are clipped.
        let _ = area.draw_text(text, &style, pos);
        w
    }

    /// Like [`Raster::text`] after drawing the text in `halo` one pixel
    /// around, so that it stays legible over a busy image.
    #[allow(clippy::too_many_arguments)]
    pub fn text_halo(
        &mut self,
        x: f64,
        y: f64,
        text: &str,
        px: f64,
        c: Rgb,
        halo: Rgb,
        h: Align,
        v: Align,
    ) -> u32 {
        let d = (px / 16.0).max(1.0);
        for (dx, dy) in [(-1.0, 0.0), (1.0, 0.0), (0.0, -1.0), (0.0, 1.0)] {
            self.text(x + dx * d, y + dy * d, text, px, halo, h, v);
        }
        for (dx, dy) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            self.text(x + dx * d * 0.7, y + dy * d * 0.7, text, px, halo, h, v);
        }
        self.text(x, y, text, px, c, h, v)
    }
}

/// Top-left corner of a `w` x `h` box anchored at `(x, y)` with alignment.
fn aligned_origin(x: f64, y: f64, w: u32, h: u32, ha: Align, va: Align) -> (f64, f64) {
    let shift = |a: Align, len: u32| match a {
        Align::Start => 0.0,
        Align::Center => len as f64 / 2.0,
        Align::End => len as f64,
    };
    (x - shift(ha, w), y - shift(va, h))
}
