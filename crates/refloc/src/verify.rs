//! Verification by the vicinity score (paper eq. 23).
//!
//! A virtual scan is ray-cast in the database's grid from the estimated
//! sensor pose along the input's own beam directions, and paired with the
//! input beam by beam. For a pair at distance d (the two endpoints lie on the
//! same ray, so d = |range difference|):
//! `m = 4.5 - d^2 / (2 sigma_d^2)` when `d < 3 sigma_d`, else 0.
//! `M = sum m` over the `N_P` input beams with a return; the pose is accepted
//! when `M > 4.5 * N_P * accept_ratio` (the paper's `accept_ratio` is 1/2).

use crate::raycast::{cast, Occupancy};
use crate::{MapFrame, Pose2};

/// The vicinity score of a pose.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vicinity {
    /// M.
    pub score: f32,
    /// The acceptance threshold for this scan.
    pub threshold: f32,
    /// N_P: input beams with a return.
    pub pairs: u32,
}

/// Scores `sensor` (map frame) for input beams given as (angle in the sensor
/// frame, range) pairs; non-finite ranges are skipped. `range_max` bounds the
/// virtual beams (m).
#[allow(clippy::too_many_arguments)]
pub fn vicinity<G: Occupancy + ?Sized>(
    grid: &G,
    frame: &MapFrame,
    sensor: &Pose2,
    beams: impl Iterator<Item = (f32, f32)>,
    range_max: f32,
    sigma_d: f32,
    accept_ratio: f32,
) -> Vicinity {
    let uv = frame.to_cells([sensor.x, sensor.y]);
    let max_cells = range_max / frame.resolution;
    let lim = 3.0 * sigma_d;
    let inv = 1.0 / (2.0 * sigma_d * sigma_d);
    let mut m = 0.0f32;
    let mut n = 0u32;
    for (a, r) in beams {
        if !r.is_finite() {
            continue;
        }
        n += 1;
        let ang = frame.angle_to_cells(sensor.theta + a);
        if let Some(t) = cast(grid, uv[0], uv[1], ang, max_cells) {
            let d = libm::fabsf(t * frame.resolution - r);
            if d < lim {
                m += 4.5 - d * d * inv;
            }
        }
    }
    Vicinity {
        score: m,
        threshold: 4.5 * n as f32 * accept_ratio,
        pairs: n,
    }
}
