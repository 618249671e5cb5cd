//! Disturbances of simulated scans: what real data does to a scan that the
//! paper's "dynamic" case (range noise and random short returns) does not.
//! Each [`Class`] is its own `mapc eval` experiment (`docs/results.md`,
//! "Disturbance suite").
//!
//! Every random choice comes from the caller's [`Rng`] (one stream per
//! pose), so a run is reproducible. Distances are metres, angles radians,
//! poses in the map frame.

use refloc::raycast::BitGrid;
use refloc::{MapFrame, Pose2};

use crate::rng::Rng;
use crate::sim::{beam_range as beam, Lidar};

/// A class of disturbance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Class {
    /// 1-10 people (discs of radius 0.2-0.3 m) within 0.6-6 m of the sensor.
    People,
    /// 1-4 boxes (sides 0.4-1.2 m, any orientation) in the free space
    /// within 1-6 m: furniture the map lacks.
    FurnitureAdded,
    /// 1-3 blocks of 0.5-1.0 m of the map's obstacles within 8 m erased:
    /// furniture the map has and the world no longer does.
    FurnitureRemoved,
    /// The world shifted (up to 5 cm), turned (up to 0.5 degree) and scaled
    /// about the sensor (up to 0.3%) against the map: a map made by another
    /// run.
    Shifted,
    /// 1-4 runs of 5-30 beams with no return (glass, dark surfaces) and 5%
    /// of the other beams dropped.
    MissingReturns,
    /// Range noise growing with range: sigma = 1 cm + 1% of the range.
    RangeNoise,
    /// Each beam's true angle off its nominal one by N(0, 0.2 degree).
    AngularJitter,
    /// The scan taken while turning at up to 1 rad/s over a 0.1 s sweep,
    /// reported as if taken at the sweep's middle (the true pose).
    #[serde(rename = "motion")]
    MotionDistortion,
}

impl Class {
    /// Every class, in report order.
    pub const ALL: [Class; 8] = [
        Class::People,
        Class::FurnitureAdded,
        Class::FurnitureRemoved,
        Class::Shifted,
        Class::MissingReturns,
        Class::RangeNoise,
        Class::AngularJitter,
        Class::MotionDistortion,
    ];

    /// The experiment's name in `mapc eval --experiments`.
    pub fn name(self) -> &'static str {
        match self {
            Class::People => "people",
            Class::FurnitureAdded => "furniture-added",
            Class::FurnitureRemoved => "furniture-removed",
            Class::Shifted => "shifted",
            Class::MissingReturns => "missing-returns",
            Class::RangeNoise => "range-noise",
            Class::AngularJitter => "angular-jitter",
            Class::MotionDistortion => "motion",
        }
    }

    /// From [`Class::name`].
    pub fn parse(s: &str) -> Option<Class> {
        Class::ALL.into_iter().find(|c| c.name() == s)
    }
}

/// Sweep time of a scan for [`Class::MotionDistortion`] (s).
pub const SWEEP_S: f32 = 0.1;

/// The ranges (m, `INFINITY`: no return) of `lidar` at sensor pose `sensor`
/// in the map's world disturbed by `class`.
pub fn scan(
    class: Class,
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    sensor: &Pose2,
    lidar: &Lidar,
    rng: &mut Rng,
) -> Vec<f32> {
    let xy = [sensor.x, sensor.y];
    let nominal = |k: usize| sensor.theta + lidar.angle(k);
    let exact = |g: &BitGrid<'_>| -> Vec<f32> {
        (0..lidar.beams)
            .map(|k| beam(g, frame, xy, nominal(k), lidar.range_max))
            .collect()
    };
    match class {
        Class::People => {
            let n = 1 + rng.below(10) as usize;
            let discs: Vec<([f32; 2], f32)> = (0..n)
                .map(|_| {
                    let (d, a) = (rng.range(0.6, 6.0) as f32, rng.range(-3.15, 3.15) as f32);
                    let r = rng.range(0.2, 0.3) as f32;
                    ([xy[0] + d * a.cos(), xy[1] + d * a.sin()], r)
                })
                .collect();
            let mut ranges = exact(grid);
            for (k, r) in ranges.iter_mut().enumerate() {
                let dir = [nominal(k).cos(), nominal(k).sin()];
                for (c, rad) in &discs {
                    if let Some(t) = ray_disc(xy, dir, *c, *rad) {
                        *r = r.min(t);
                    }
                }
            }
            ranges
        }
        Class::FurnitureAdded => {
            let n = 1 + rng.below(4) as usize;
            let boxes: Vec<Box2> = (0..n)
                .map(|_| {
                    let half = [rng.range(0.2, 0.6) as f32, rng.range(0.2, 0.6) as f32];
                    let reach = (half[0] * half[0] + half[1] * half[1]).sqrt() + 0.3;
                    let (d, a) = (
                        rng.range(reach.max(1.0) as f64, 6.0_f64.max(reach as f64 + 0.5)) as f32,
                        rng.range(-3.15, 3.15) as f32,
                    );
                    Box2 {
                        centre: [xy[0] + d * a.cos(), xy[1] + d * a.sin()],
                        half,
                        theta: rng.range(0.0, 3.15) as f32,
                    }
                })
                .collect();
            let mut ranges = exact(grid);
            for (k, r) in ranges.iter_mut().enumerate() {
                let dir = [nominal(k).cos(), nominal(k).sin()];
                for b in &boxes {
                    if let Some(t) = b.ray(xy, dir) {
                        *r = r.min(t);
                    }
                }
            }
            ranges
        }
        Class::FurnitureRemoved => {
            let mut words = grid.words().to_vec();
            let (w, h) = (
                refloc::raycast::Occupancy::width(grid),
                refloc::raycast::Occupancy::height(grid),
            );
            let blocks = 1 + rng.below(3) as usize;
            let mut erased = 0;
            // Look for obstacle cells near the sensor to erase around.
            for _ in 0..400 {
                if erased == blocks {
                    break;
                }
                let (d, a) = (rng.range(0.5, 8.0) as f32, rng.range(-3.15, 3.15) as f32);
                let p = frame.to_cells([xy[0] + d * a.cos(), xy[1] + d * a.sin()]);
                let (cx, cy) = (p[0].floor() as i64, p[1].floor() as i64);
                if cx < 0 || cy < 0 || cx >= w as i64 || cy >= h as i64 {
                    continue;
                }
                if !refloc::raycast::Occupancy::blocked(grid, cx as u32, cy as u32) {
                    continue;
                }
                let half = (rng.range(0.25, 0.5) as f32 / frame.resolution).ceil() as i64;
                for y in (cy - half).max(0)..(cy + half + 1).min(h as i64) {
                    for x in (cx - half).max(0)..(cx + half + 1).min(w as i64) {
                        let bit = y as usize * w as usize + x as usize;
                        if let Some(word) = words.get_mut(bit / 32) {
                            *word &= !(1u32 << (bit % 32));
                        }
                    }
                }
                erased += 1;
            }
            match BitGrid::new(w, h, &words) {
                Some(g) => exact(&g),
                None => exact(grid),
            }
        }
        Class::Shifted => {
            let shift = Pose2::new(
                rng.range(-0.05, 0.05) as f32,
                rng.range(-0.05, 0.05) as f32,
                rng.range(-0.5, 0.5).to_radians() as f32,
            );
            let scale = 1.0 + rng.range(-0.003, 0.003) as f32;
            // The sensor stands in the world at `sensor`; around it the world
            // is the map moved by `shift` (about the sensor, so the local
            // disagreement is at most the shift) and scaled: cast in the map
            // from where the sensor is in map coordinates, ranges scaled.
            let in_map = Pose2::new(
                sensor.x - shift.x,
                sensor.y - shift.y,
                sensor.theta - shift.theta,
            );
            (0..lidar.beams)
                .map(|k| {
                    let a = in_map.theta + lidar.angle(k);
                    let origin = [in_map.x, in_map.y];
                    beam(grid, frame, origin, a, lidar.range_max / scale) * scale
                })
                .map(|r| {
                    if r > lidar.range_max {
                        f32::INFINITY
                    } else {
                        r
                    }
                })
                .collect()
        }
        Class::MissingReturns => {
            let mut ranges = exact(grid);
            let n = ranges.len();
            if n == 0 {
                return ranges;
            }
            for _ in 0..1 + rng.below(4) {
                let len = (5 + rng.below(26)) as usize;
                let start = rng.below(n as u64) as usize;
                for r in &mut ranges[start..(start + len).min(n)] {
                    *r = f32::INFINITY;
                }
            }
            for r in ranges.iter_mut() {
                if rng.uniform() < 0.05 {
                    *r = f32::INFINITY;
                }
            }
            ranges
        }
        Class::RangeNoise => {
            let mut ranges = exact(grid);
            for r in ranges.iter_mut().filter(|r| r.is_finite()) {
                let sigma = 0.01 + 0.01 * *r;
                *r = (*r + sigma * rng.normal() as f32).clamp(1e-3, lidar.range_max);
            }
            ranges
        }
        Class::AngularJitter => (0..lidar.beams)
            .map(|k| {
                let jitter = (0.2f64.to_radians() * rng.normal()) as f32;
                beam(grid, frame, xy, nominal(k) + jitter, lidar.range_max)
            })
            .collect(),
        Class::MotionDistortion => {
            let omega = rng.range(-1.0, 1.0) as f32;
            let n = lidar.beams.max(1) as f32;
            (0..lidar.beams)
                .map(|k| {
                    let t = (k as f32 / n - 0.5) * SWEEP_S;
                    beam(grid, frame, xy, nominal(k) + omega * t, lidar.range_max)
                })
                .collect()
        }
    }
}

/// Distance along the unit ray `origin + t dir` to a disc, if it hits.
fn ray_disc(origin: [f32; 2], dir: [f32; 2], centre: [f32; 2], radius: f32) -> Option<f32> {
    let o = [origin[0] - centre[0], origin[1] - centre[1]];
    let b = o[0] * dir[0] + o[1] * dir[1];
    let c = o[0] * o[0] + o[1] * o[1] - radius * radius;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 0.0).then_some(t)
}

/// An oriented box (m, rad).
struct Box2 {
    centre: [f32; 2],
    half: [f32; 2],
    theta: f32,
}

impl Box2 {
    /// Distance along the unit ray to the box, if it hits (slab method in
    /// the box's frame).
    fn ray(&self, origin: [f32; 2], dir: [f32; 2]) -> Option<f32> {
        let (s, c) = self.theta.sin_cos();
        let o = [origin[0] - self.centre[0], origin[1] - self.centre[1]];
        let lo = [c * o[0] + s * o[1], -s * o[0] + c * o[1]];
        let ld = [c * dir[0] + s * dir[1], -s * dir[0] + c * dir[1]];
        let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
        for i in 0..2 {
            if ld[i].abs() < 1e-9 {
                if lo[i].abs() > self.half[i] {
                    return None;
                }
                continue;
            }
            let a = (-self.half[i] - lo[i]) / ld[i];
            let b = (self.half[i] - lo[i]) / ld[i];
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 <= t1 && t0 > 0.0).then_some(t0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rays_hit_discs_and_boxes_where_geometry_says() {
        let t = ray_disc([0.0, 0.0], [1.0, 0.0], [3.0, 0.0], 0.25).unwrap();
        assert!((t - 2.75).abs() < 1e-5);
        assert!(ray_disc([0.0, 0.0], [0.0, 1.0], [3.0, 0.0], 0.25).is_none());
        assert!(ray_disc([0.0, 0.0], [-1.0, 0.0], [3.0, 0.0], 0.25).is_none());
        let b = Box2 {
            centre: [2.0, 0.0],
            half: [0.5, 0.5],
            theta: std::f32::consts::FRAC_PI_4,
        };
        let t = b.ray([0.0, 0.0], [1.0, 0.0]).unwrap();
        assert!((t - (2.0 - 0.5 * 2f32.sqrt())).abs() < 1e-5, "{t}");
        assert!(b.ray([0.0, 0.0], [0.0, 1.0]).is_none());
    }

    #[test]
    fn every_class_has_a_name_that_parses_back() {
        for c in Class::ALL {
            assert_eq!(Class::parse(c.name()), Some(c));
        }
        assert_eq!(Class::parse("doors"), None);
    }

    #[test]
    fn disturbances_change_the_scan_and_are_reproducible() {
        // A 10 m x 10 m room (0.1 m cells, walls one cell thick).
        let (w, h) = (100u32, 100u32);
        let mut words = vec![0u32; BitGrid::words_for(w, h)];
        for y in 0..h {
            for x in 0..w {
                if x == 0 || y == 0 || x == w - 1 || y == h - 1 {
                    let bit = (y * w + x) as usize;
                    words[bit / 32] |= 1 << (bit % 32);
                }
            }
        }
        let grid = BitGrid::new(w, h, &words).unwrap();
        let frame = MapFrame {
            resolution: 0.1,
            origin: Pose2::new(0.0, 0.0, 0.0),
        };
        let lidar = Lidar::new(360, std::f32::consts::TAU, 30.0);
        let sensor = Pose2::new(5.0, 5.0, 0.3);
        let clean = crate::sim::virtual_scan(&grid, &frame, &sensor, &lidar);
        for c in Class::ALL {
            let a = scan(c, &grid, &frame, &sensor, &lidar, &mut Rng::new(3));
            let b = scan(c, &grid, &frame, &sensor, &lidar, &mut Rng::new(3));
            assert_eq!(a.len(), 360);
            assert!(
                a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{c:?}"
            );
            let changed = a
                .iter()
                .zip(&clean)
                .filter(|(x, y)| !(x.is_infinite() && y.is_infinite()) && (*x - *y).abs() > 1e-4)
                .count();
            // Erasing a piece of wall may remove the only obstacle in reach
            // of some beams; every class changes some beams.
            assert!(changed > 0, "{c:?} changed nothing");
        }
    }
}
