//! Pairwise geometric relationships (paper section 2) and the 2D geometric
//! histogram used by the coarse stage (section 4).
//!
//! For an ordered pair (i, j) of prepared points: `rho_ij = |p_j - p_i|` and
//! `theta_ij`, the *signed* angle from the tangent `u_i` to `p_j - p_i`, in
//! (-pi, pi]. The paper's arccos gives an unsigned angle that cannot tell a
//! place from its mirror image; the signed angle is just as invariant to rigid
//! motion and keeps that information.
//!
//! Binning: `hist_rho_bins` equal bins over [0, `hist_rho_max`) (longer pairs
//! go in the last bin) times `hist_theta_bins` equal bins around the circle,
//! centred on -pi (= pi) and 0 (see [`cell`]);
//! cell index `rho_bin * theta_bins + theta_bin`. Every ordered pair votes 1;
//! the histogram is then normalized to sum 1, so scans with different point
//! counts compare directly.

use crate::math::{norm, signed_angle};
use crate::params::Params;

/// `(rho, theta)` of the ordered pair (i, j): metres, radians.
#[inline]
pub fn pgr(pi: [f32; 2], ui: [f32; 2], pj: [f32; 2]) -> (f32, f32) {
    let d = [pj[0] - pi[0], pj[1] - pi[1]];
    (norm(d), signed_angle(ui, d))
}

/// Histogram cell of `(rho, theta)`. Theta bins are centred on 0 and pi
/// (bin `b` covers `[-pi + (b - 1/2) w, -pi + (b + 1/2) w)` modulo 2 pi,
/// `w = 2 pi / theta_bins`): pairs along one straight surface have theta
/// exactly 0 or pi and must not sit on a bin edge, where rounding would
/// scatter them between two bins.
#[inline]
pub fn cell(rho: f32, theta: f32, rho_bins: usize, theta_bins: usize, rho_max: f32) -> usize {
    use core::f32::consts::PI;
    let rb = ((rho / rho_max) * rho_bins as f32) as usize;
    let rb = rb.min(rho_bins - 1);
    let half = PI / theta_bins as f32;
    let mut t = theta + PI + half;
    if t >= 2.0 * PI {
        t -= 2.0 * PI;
    }
    let tb = ((t / (2.0 * PI)) * theta_bins as f32) as usize;
    let tb = tb.min(theta_bins - 1);
    rb * theta_bins + tb
}

/// Fills `out` (length `params.hist_cells()`) with the normalized 2D
/// geometric histogram of prepared points `pts` with tangents `tan`.
/// Returns the number of ordered pairs that voted.
pub fn histogram(pts: &[[f32; 2]], tan: &[[f32; 2]], params: &Params, out: &mut [f32]) -> usize {
    histogram_binned(
        pts,
        tan,
        params.coarse.hist_rho_bins as usize,
        params.coarse.hist_theta_bins as usize,
        params.coarse.hist_rho_max,
        out,
    )
}

/// As [`histogram`] with explicit binning: `rho_bins` over [0, `rho_max`)
/// (m) times `theta_bins` over [-pi, pi). Fills `out[..rho_bins * theta_bins]`.
pub fn histogram_binned(
    pts: &[[f32; 2]],
    tan: &[[f32; 2]],
    rho_bins: usize,
    theta_bins: usize,
    rho_max: f32,
    out: &mut [f32],
) -> usize {
    let (rb, tb) = (rho_bins, theta_bins);
    let k = rb * tb;
    for v in out.iter_mut() {
        *v = 0.0;
    }
    if out.len() < k || k == 0 {
        return 0;
    }
    let n = pts.len().min(tan.len());
    let mut votes = 0usize;
    for i in 0..n {
        for j in (i + 1)..n {
            let d = [pts[j][0] - pts[i][0], pts[j][1] - pts[i][1]];
            let rho = norm(d);
            if !rho.is_finite() {
                continue;
            }
            let t_ij = signed_angle(tan[i], d);
            let t_ji = signed_angle(tan[j], [-d[0], -d[1]]);
            out[cell(rho, t_ij, rb, tb, rho_max)] += 1.0;
            out[cell(rho, t_ji, rb, tb, rho_max)] += 1.0;
            votes += 2;
        }
    }
    if votes > 0 {
        let s = 1.0 / votes as f32;
        for v in out[..k].iter_mut() {
            *v *= s;
        }
    }
    votes
}
