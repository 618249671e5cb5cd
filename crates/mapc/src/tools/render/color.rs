//! Colour constants, a categorical palette and a perceptual colour map.

use super::raster::Rgb;

/// Black.
pub const BLACK: Rgb = [0, 0, 0];
/// White.
pub const WHITE: Rgb = [255, 255, 255];
/// Dark gray (axes, text on light backgrounds).
pub const DARK_GRAY: Rgb = [64, 64, 64];
/// Mid gray.
pub const GRAY: Rgb = [128, 128, 128];
/// Light gray (grid lines).
pub const LIGHT_GRAY: Rgb = [225, 225, 225];
/// Blue (first palette colour).
pub const BLUE: Rgb = [31, 111, 180];
/// Orange.
pub const ORANGE: Rgb = [240, 128, 14];
/// Green.
pub const GREEN: Rgb = [40, 150, 44];
/// Red.
pub const RED: Rgb = [210, 35, 40];
/// Purple.
pub const PURPLE: Rgb = [140, 90, 190];
/// Brown.
pub const BROWN: Rgb = [140, 86, 75];
/// Pink / magenta.
pub const MAGENTA: Rgb = [220, 60, 180];
/// Olive.
pub const OLIVE: Rgb = [160, 160, 30];
/// Cyan / teal.
pub const CYAN: Rgb = [20, 175, 195];

/// Distinguishable categorical colours, in the order series should use them.
pub const PALETTE: [Rgb; 9] = [
    BLUE, ORANGE, GREEN, RED, PURPLE, BROWN, MAGENTA, OLIVE, CYAN,
];

/// The `i`-th palette colour (wrapping around).
pub fn palette(i: usize) -> Rgb {
    PALETTE[i % PALETTE.len()]
}

/// Anchor colours of the sequential map, dark blue-violet through teal to
/// yellow (monotonic in lightness, readable in grayscale).
const SEQ: [Rgb; 9] = [
    [68, 1, 84],
    [72, 38, 119],
    [62, 73, 137],
    [49, 104, 142],
    [38, 130, 142],
    [31, 158, 137],
    [53, 183, 121],
    [144, 215, 67],
    [253, 231, 37],
];

/// Sequential colour map: `t` in `[0, 1]` (clamped; NaN gives the low end)
/// from dark violet to yellow.
pub fn colormap(t: f64) -> Rgb {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (SEQ.len() - 1) as f64;
    let i = (x.floor() as usize).min(SEQ.len() - 2);
    let f = x - i as f64;
    let (a, b) = (SEQ[i], SEQ[i + 1]);
    let mut out = [0u8; 3];
    for k in 0..3 {
        out[k] = (a[k] as f64 + (b[k] as f64 - a[k] as f64) * f).round() as u8;
    }
    out
}

/// `c` mixed towards white by `amount` in `[0, 1]` (lighter tint).
pub fn tint(c: Rgb, amount: f64) -> Rgb {
    let a = amount.clamp(0.0, 1.0);
    let mut out = [0u8; 3];
    for k in 0..3 {
        out[k] = (c[k] as f64 + (255.0 - c[k] as f64) * a).round() as u8;
    }
    out
}
