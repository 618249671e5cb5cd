//! Simulated laser scans: virtual scans ray-cast in the compiled grid at any
//! pose, with range noise and outliers (random short returns, and the
//! paper's x-y swap). Used by the logistic fit, `mapc eval` and the tests.

use refloc::raycast::{cast, BitGrid};
use refloc::{MapFrame, Pose2};

use crate::compiler::rng::Rng;

/// A 2D laser's geometry (radians, metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lidar {
    /// Number of beams.
    pub beams: usize,
    /// First beam angle (rad, sensor frame).
    pub angle_min: f32,
    /// Angle step (rad).
    pub angle_increment: f32,
    /// Minimum range (m).
    pub range_min: f32,
    /// Maximum range (m).
    pub range_max: f32,
}

impl Lidar {
    /// `beams` beams spread evenly over `fov` radians centred on the sensor's
    /// +x axis (a 360-degree scan starts at -pi and does not repeat its first
    /// beam).
    pub fn new(beams: usize, fov: f32, range_max: f32) -> Lidar {
        let full = fov >= 2.0 * std::f32::consts::PI - 1e-4;
        let beams = beams.max(2);
        let inc = if full {
            fov / beams as f32
        } else {
            fov / (beams - 1) as f32
        };
        Lidar {
            beams,
            angle_min: -fov / 2.0,
            angle_increment: inc,
            range_min: 0.0,
            range_max,
        }
    }

    /// Beam `k`'s angle (rad).
    pub fn angle(&self, k: usize) -> f32 {
        self.angle_min + k as f32 * self.angle_increment
    }
}

/// Noise model for simulated scans.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Noise {
    /// Range noise standard deviation (m).
    pub range_sigma: f32,
    /// Beams replaced by a random short return (a person, clutter).
    pub short_outliers: usize,
}

/// Exact virtual ranges (m; `INFINITY` for no return) of `lidar` at sensor
/// pose `sensor` (map frame).
pub fn virtual_scan(
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    sensor: &Pose2,
    lidar: &Lidar,
) -> Vec<f32> {
    (0..lidar.beams)
        .map(|k| {
            beam_range(
                grid,
                frame,
                [sensor.x, sensor.y],
                sensor.theta + lidar.angle(k),
                lidar.range_max,
            )
        })
        .collect()
}

/// The range (m; `INFINITY` for no return within `range_max`) of one beam
/// from `origin` (map frame, m) at map-frame angle `angle` (rad).
pub fn beam_range(
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    origin: [f32; 2],
    angle: f32,
    range_max: f32,
) -> f32 {
    let uv = frame.to_cells(origin);
    let a = frame.angle_to_cells(angle);
    match cast(grid, uv[0], uv[1], a, range_max / frame.resolution) {
        Some(t) => t * frame.resolution,
        None => f32::INFINITY,
    }
}

/// Adds noise to `ranges` in place.
pub fn add_noise(ranges: &mut [f32], lidar: &Lidar, noise: &Noise, rng: &mut Rng) {
    for r in ranges.iter_mut() {
        if r.is_finite() && noise.range_sigma > 0.0 {
            *r = (*r + noise.range_sigma * rng.normal() as f32)
                .clamp(lidar.range_min.max(1e-3), lidar.range_max);
        }
    }
    if ranges.is_empty() {
        return;
    }
    for _ in 0..noise.short_outliers {
        let k = rng.below(ranges.len() as u64) as usize;
        let cur = if ranges[k].is_finite() {
            ranges[k]
        } else {
            lidar.range_max
        };
        ranges[k] = rng.range(0.1, cur.max(0.2) as f64) as f32;
    }
}

/// Sensor-frame points of `ranges` (missing beams skipped).
pub fn to_points(ranges: &[f32], lidar: &Lidar) -> Vec<[f32; 2]> {
    ranges
        .iter()
        .enumerate()
        .filter(|(_, r)| r.is_finite())
        .map(|(k, &r)| {
            let a = lidar.angle(k);
            [r * a.cos(), r * a.sin()]
        })
        .collect()
}

/// The paper's outliers: swap x and y of `n` randomly chosen points.
pub fn swap_outliers(points: &mut [[f32; 2]], n: usize, rng: &mut Rng) {
    if points.is_empty() {
        return;
    }
    for _ in 0..n {
        let k = rng.below(points.len() as u64) as usize;
        points[k] = [points[k][1], points[k][0]];
    }
}
