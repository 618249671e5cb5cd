//! Coarse stage (paper section 4): correlation coefficient between the input
//! histogram and every site's (eq. 21-22), and the adaptive candidate count.
//!
//! N_C rule (see `docs/ssm.md` for the measurements behind it): the sites are
//! ranked by gamma; every site whose gamma is within `nc_margin` of the best
//! is a candidate, with at least `nc_min` and at most `nc_max` candidates.

use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

/// Correlation coefficient of two histograms with the joint mean of eq. 22:
/// `h_bar = (sum h + sum g) / 2K`. Returns a value in [-1, 1]; 0 when either
/// histogram is flat or non-finite.
pub fn correlation(h: &[f32], g: &[f32]) -> f32 {
    let k = h.len().min(g.len());
    if k == 0 {
        return 0.0;
    }
    let (mut sh, mut sg) = (0.0f32, 0.0f32);
    for i in 0..k {
        sh += h[i];
        sg += g[i];
    }
    let mean = (sh + sg) / (2 * k) as f32;
    let (mut num, mut dh, mut dg) = (0.0f32, 0.0f32, 0.0f32);
    for i in 0..k {
        let a = h[i] - mean;
        let b = g[i] - mean;
        num += a * b;
        dh += a * a;
        dg += b * b;
    }
    let den = libm::sqrtf(dh * dg);
    let r = num / den;
    if r.is_finite() {
        r.clamp(-1.0, 1.0)
    } else {
        0.0
    }
}

/// A ranked site: index and correlation.
#[derive(Clone, Copy, Debug, Default, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable)]
#[repr(C)]
pub struct Ranked {
    /// Site index.
    pub site: u32,
    /// Correlation coefficient gamma.
    pub gamma: f32,
}

/// Keeps the `top.len()` best sites in `top`, best first (ties: lower site
/// index first). Returns how many entries are filled.
pub fn rank_top<'h>(
    input: &[f32],
    sites: impl Iterator<Item = &'h [f32]>,
    top: &mut [Ranked],
) -> usize {
    let cap = top.len();
    let mut n = 0;
    for (s, h) in sites.enumerate() {
        let g = correlation(input, h);
        let better = |a: f32, ai: u32, b: &Ranked| a > b.gamma || (a == b.gamma && ai < b.site);
        if n < cap || (cap > 0 && better(g, s as u32, &top[cap - 1])) {
            let mut pos = n.min(cap.saturating_sub(1));
            if n < cap {
                n += 1;
            }
            while pos > 0 && better(g, s as u32, &top[pos - 1]) {
                top[pos] = top[pos - 1];
                pos -= 1;
            }
            top[pos] = Ranked {
                site: s as u32,
                gamma: g,
            };
        }
    }
    n
}

/// Applies the N_C rule to a ranked list (best first); returns N_C.
pub fn candidate_count(ranked: &[Ranked], nc_min: usize, nc_max: usize, margin: f32) -> usize {
    let Some(best) = ranked.first() else {
        return 0;
    };
    let within = ranked
        .iter()
        .take_while(|r| r.gamma >= best.gamma - margin)
        .count();
    within.clamp(nc_min, nc_max).min(ranked.len())
}
