//! Pose refinement against the map (an addition to the paper): Gauss-Newton
//! on the squared distance from each scan point to the nearest obstacle
//! surface, read from the database's distance map with bilinear
//! interpolation. Points farther than `refine_max_dist` from any surface are
//! left out (clutter, people, unmapped objects).

use crate::format::DIST_STEPS_PER_CELL;
use crate::{MapFrame, Pose2};

/// The quantized distance map.
#[derive(Clone, Copy)]
pub struct DistMap<'a> {
    /// Cells per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// One byte per cell: distance in `resolution / DIST_STEPS_PER_CELL`.
    pub data: &'a [u8],
    /// Grid placement.
    pub frame: MapFrame,
}

impl DistMap<'_> {
    #[inline]
    fn at(&self, cx: i64, cy: i64) -> f32 {
        if cx < 0 || cy < 0 || cx >= self.width as i64 || cy >= self.height as i64 {
            return 255.0;
        }
        let i = cy as usize * self.width as usize + cx as usize;
        self.data.get(i).copied().unwrap_or(255) as f32
    }

    /// Distance (m) to the nearest surface at map point `p` and its gradient
    /// (dimensionless), by bilinear interpolation between cell centres.
    pub fn sample(&self, p: [f32; 2]) -> Option<(f32, [f32; 2])> {
        let uv = self.frame.to_cells(p);
        let (u, v) = (uv[0] - 0.5, uv[1] - 0.5);
        if !(u.is_finite() && v.is_finite())
            || u < -1.0
            || v < -1.0
            || u > self.width as f32
            || v > self.height as f32
        {
            return None;
        }
        let (x0, y0) = (libm::floorf(u), libm::floorf(v));
        let (fx, fy) = (u - x0, v - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let d00 = self.at(x0, y0);
        let d10 = self.at(x0 + 1, y0);
        let d01 = self.at(x0, y0 + 1);
        let d11 = self.at(x0 + 1, y0 + 1);
        let unit = self.frame.resolution / DIST_STEPS_PER_CELL;
        let d = (d00 * (1.0 - fx) * (1.0 - fy)
            + d10 * fx * (1.0 - fy)
            + d01 * (1.0 - fx) * fy
            + d11 * fx * fy)
            * unit;
        // Gradient in cell axes (per cell), then to the map frame (per metre).
        let gu = ((d10 - d00) * (1.0 - fy) + (d11 - d01) * fy) * unit / self.frame.resolution;
        let gv = ((d01 - d00) * (1.0 - fx) + (d11 - d10) * fx) * unit / self.frame.resolution;
        let (s, c) = (
            libm::sinf(self.frame.origin.theta),
            libm::cosf(self.frame.origin.theta),
        );
        Some((d, [c * gu - s * gv, s * gu + c * gv]))
    }
}

/// Refines the sensor pose `pose` (map frame) so the sensor-frame points
/// `pts` (non-finite entries skipped) fall on the map's surfaces.
/// Returns the refined pose and the number of points used in the last step.
pub fn refine(
    dm: &DistMap<'_>,
    pts: &[[f32; 2]],
    pose: Pose2,
    iters: u32,
    max_dist: f32,
) -> (Pose2, u32) {
    let mut pose = pose;
    let mut used = 0;
    for _ in 0..iters {
        let (s, c) = (libm::sinf(pose.theta), libm::cosf(pose.theta));
        let mut h = [[0.0f32; 3]; 3];
        let mut g = [0.0f32; 3];
        used = 0;
        for p in pts {
            if !p[0].is_finite() {
                continue;
            }
            let m = [pose.x + c * p[0] - s * p[1], pose.y + s * p[0] + c * p[1]];
            let Some((d, grad)) = dm.sample(m) else {
                continue;
            };
            if !(d < max_dist) {
                continue;
            }
            let dth = grad[0] * (-s * p[0] - c * p[1]) + grad[1] * (c * p[0] - s * p[1]);
            let j = [grad[0], grad[1], dth];
            for a in 0..3 {
                g[a] += j[a] * d;
                for b in 0..3 {
                    h[a][b] += j[a] * j[b];
                }
            }
            used += 1;
        }
        if used < 3 {
            break;
        }
        // Levenberg damping keeps the step sane on degenerate geometry (a corridor).
        for (a, row) in h.iter_mut().enumerate() {
            row[a] += 1e-3 * (1.0 + row[a]);
        }
        let Some(step) = solve3(&h, &g) else { break };
        let step = [-step[0], -step[1], -step[2]];
        // Bound each step: refinement corrects small errors, it does not search.
        let lim = 0.1;
        let sc = {
            let m = libm::fabsf(step[0])
                .max(libm::fabsf(step[1]))
                .max(libm::fabsf(step[2]) * 2.0);
            if m > lim {
                lim / m
            } else {
                1.0
            }
        };
        pose = Pose2::new(
            pose.x + sc * step[0],
            pose.y + sc * step[1],
            pose.theta + sc * step[2],
        );
        if libm::fabsf(step[0]) + libm::fabsf(step[1]) + libm::fabsf(step[2]) < 1e-5 {
            break;
        }
    }
    (pose, used)
}

/// Solves the 3x3 system `h x = g` (Cramer's rule); `None` when singular.
fn solve3(h: &[[f32; 3]; 3], g: &[f32; 3]) -> Option<[f32; 3]> {
    let det = |m: &[[f32; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(h);
    if !(libm::fabsf(d) > 1e-12) {
        return None;
    }
    let mut out = [0.0f32; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut m = *h;
        for r in 0..3 {
            m[r][k] = g[r];
        }
        *o = det(&m) / d;
    }
    if out.iter().all(|v| v.is_finite()) {
        Some(out)
    } else {
        None
    }
}
