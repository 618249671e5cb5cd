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
    /// Input beams shorter than the virtual beam by 3 sigma_d or more (or
    /// with no virtual return): something not in the map is in front, as
    /// people and clutter are. Beams *longer* than the map allows count
    /// against the pose in M and are not counted here.
    pub short: u32,
    /// Input beams longer than the virtual beam by 3 sigma_d or more: the
    /// scan sees through where the map has a surface.
    pub long: u32,
}

impl Vicinity {
    /// M over its maximum for the beams that are not short:
    /// `M / (4.5 (N_P - short))`, 0 when every beam is short.
    pub fn explained_ratio(&self) -> f32 {
        let n = self.pairs.saturating_sub(self.short);
        if n == 0 {
            0.0
        } else {
            self.score / (4.5 * n as f32)
        }
    }
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
    let mut short = 0u32;
    let mut long = 0u32;
    for (a, r) in beams {
        if !r.is_finite() {
            continue;
        }
        n += 1;
        let ang = frame.angle_to_cells(sensor.theta + a);
        match cast(grid, uv[0], uv[1], ang, max_cells) {
            Some(t) => {
                let v = t * frame.resolution;
                let d = libm::fabsf(v - r);
                if d < lim {
                    m += 4.5 - d * d * inv;
                } else if r < v {
                    short += 1;
                } else {
                    long += 1;
                }
            }
            None => short += 1,
        }
    }
    Vicinity {
        score: m,
        threshold: 4.5 * n as f32 * accept_ratio,
        pairs: n,
        short,
        long,
    }
}
