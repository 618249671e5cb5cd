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

use crate::compiler::rng::Rng;
use crate::compiler::sim::{beam_range as beam, Lidar};

/// A class of disturbance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Class {
    /// 1-10 people (discs of radius 0.2-0.3 m) standing in the free space
    /// within 0.6-6 m of the sensor (a disc that would overlap an obstacle
    /// is drawn again, up to [`PLACE_TRIES`] times, else left out).
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
    /// 1-3 doors toggled within 1-8 m: a doorway-wide gap (0.6-1.2 m
    /// between walls) closed by a wall the map lacks, or a stretch of
    /// 0.8-1.0 m of a thin wall (at most 0.25 m thick, free on both sides)
    /// opened where the map has it closed.
    DoorsToggled,
    /// The scan taken while turning at up to 1 rad/s over a 0.1 s sweep,
    /// reported as if taken at the sweep's middle (the true pose).
    #[serde(rename = "motion")]
    MotionDistortion,
    /// The sensor mounted up to 5 cm and 2 degrees off where the database
    /// says it is (a mount measured wrongly, or knocked): the scan is taken
    /// from the true sensor pose composed with that error. The robot pose
    /// the localizer reports is then off by about the error, well within
    /// the tolerance; what is measured is whether it is still found and
    /// accepted.
    MountError,
}

impl Class {
    /// Every class, in report order.
    pub const ALL: [Class; 10] = [
        Class::People,
        Class::FurnitureAdded,
        Class::FurnitureRemoved,
        Class::DoorsToggled,
        Class::Shifted,
        Class::MissingReturns,
        Class::RangeNoise,
        Class::AngularJitter,
        Class::MotionDistortion,
        Class::MountError,
    ];

    /// The experiment's name in `mapc eval --experiments`.
    pub fn name(self) -> &'static str {
        match self {
            Class::People => "people",
            Class::FurnitureAdded => "furniture-added",
            Class::FurnitureRemoved => "furniture-removed",
            Class::DoorsToggled => "doors",
            Class::Shifted => "shifted",
            Class::MissingReturns => "missing-returns",
            Class::RangeNoise => "range-noise",
            Class::AngularJitter => "angular-jitter",
            Class::MotionDistortion => "motion",
            Class::MountError => "mount-error",
        }
    }

    /// From [`Class::name`].
    pub fn parse(s: &str) -> Option<Class> {
        Class::ALL.into_iter().find(|c| c.name() == s)
    }
}

/// Largest position (m) and heading (rad, 2 degrees) error of the sensor
/// mount for [`Class::MountError`], each uniform in +- this.
pub const MOUNT_ERROR: [f32; 2] = [0.05, 2.0 * std::f32::consts::PI / 180.0];

/// Draws of a person's position before it is left out ([`Class::People`]).
pub const PLACE_TRIES: usize = 20;

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
    let scene = Scene {
        grid,
        frame,
        sensor,
        lidar,
    };
    match class {
        Class::People => scene.people(rng),
        Class::FurnitureAdded => scene.furniture_added(rng),
        Class::FurnitureRemoved => scene.furniture_removed(rng),
        Class::DoorsToggled => scene.doors_toggled(rng),
        Class::Shifted => scene.shifted(rng),
        Class::MissingReturns => scene.missing_returns(rng),
        Class::RangeNoise => scene.range_noise(rng),
        Class::AngularJitter => scene.angular_jitter(rng),
        Class::MountError => scene.mount_error(rng),
        Class::MotionDistortion => scene.motion_distortion(rng),
    }
}

/// What a disturbed scan is taken in and with: the map's grid and frame,
/// the true sensor pose and the lidar. One method per [`Class`], each
/// drawing from the caller's [`Rng`] in a fixed order.
struct Scene<'a, 'g> {
    grid: &'a BitGrid<'g>,
    frame: &'a MapFrame,
    sensor: &'a Pose2,
    lidar: &'a Lidar,
}

impl Scene<'_, '_> {
    /// The sensor's position.
    fn xy(&self) -> [f32; 2] {
        [self.sensor.x, self.sensor.y]
    }

    /// The nominal world direction (rad) of beam `k`.
    fn nominal(&self, k: usize) -> f32 {
        self.sensor.theta + self.lidar.angle(k)
    }

    /// The undisturbed scan of the sensor in grid `g`.
    fn exact(&self, g: &BitGrid<'_>) -> Vec<f32> {
        crate::compiler::sim::virtual_scan(g, self.frame, self.sensor, self.lidar)
    }

    /// A world point `d` m from the sensor in direction `a` (rad).
    fn around(&self, d: f32, a: f32) -> [f32; 2] {
        let xy = self.xy();
        [xy[0] + d * a.cos(), xy[1] + d * a.sin()]
    }

    /// The exact scan with each beam cut short by the added obstacles:
    /// `hits(origin, dir)` gives the distances along the beam from the
    /// sensor in direction `dir` at which it meets one.
    fn exact_cut<I: Iterator<Item = f32>>(
        &self,
        hits: impl Fn([f32; 2], [f32; 2]) -> I,
    ) -> Vec<f32> {
        let xy = self.xy();
        let mut ranges = self.exact(self.grid);
        for (k, r) in ranges.iter_mut().enumerate() {
            let dir = [self.nominal(k).cos(), self.nominal(k).sin()];
            for t in hits(xy, dir) {
                *r = r.min(t);
            }
        }
        ranges
    }

    /// True when a disc of radius `r` (m) centred at `c` (map frame) lies
    /// in free cells of the map: its centre and 8 points of its rim.
    fn disc_is_free(&self, c: [f32; 2], r: f32) -> bool {
        use refloc::raycast::Occupancy;
        let (w, h) = (self.grid.width(), self.grid.height());
        (0..9).all(|k| {
            let (dx, dy) = if k == 8 {
                (0.0, 0.0)
            } else {
                let a = k as f32 * std::f32::consts::FRAC_PI_4;
                (r * a.cos(), r * a.sin())
            };
            cell_at(w, h, self.frame, [c[0] + dx, c[1] + dy])
                .is_some_and(|(x, y)| !self.grid.blocked(x, y))
        })
    }

    /// [`Class::People`].
    fn people(&self, rng: &mut Rng) -> Vec<f32> {
        let n = 1 + rng.below(10) as usize;
        let discs: Vec<([f32; 2], f32)> = (0..n)
            .filter_map(|_| {
                let r = rng.range(0.2, 0.3) as f32;
                (0..PLACE_TRIES).find_map(|_| {
                    let (d, a) = (rng.range(0.6, 6.0) as f32, rng.range(-3.15, 3.15) as f32);
                    let c = self.around(d, a);
                    self.disc_is_free(c, r).then_some((c, r))
                })
            })
            .collect();
        let discs = &discs;
        self.exact_cut(move |xy, dir| {
            discs
                .iter()
                .filter_map(move |(c, rad)| ray_disc(xy, dir, *c, *rad))
        })
    }

    /// [`Class::FurnitureAdded`].
    fn furniture_added(&self, rng: &mut Rng) -> Vec<f32> {
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
                    centre: self.around(d, a),
                    half,
                    theta: rng.range(0.0, 3.15) as f32,
                }
            })
            .collect();
        let boxes = &boxes;
        self.exact_cut(move |xy, dir| boxes.iter().filter_map(move |b| b.ray(xy, dir)))
    }

    /// The scan in an edited copy of the map's world: `edit` is tried up
    /// to 400 times, until `wanted` tries have changed it (returned true).
    fn edited(&self, wanted: usize, mut edit: impl FnMut(&mut Cells) -> bool) -> Vec<f32> {
        let mut world = Cells::of(self.grid);
        let mut done = 0;
        for _ in 0..400 {
            if done == wanted {
                break;
            }
            done += edit(&mut world) as usize;
        }
        world.cast(self.grid, |g| self.exact(g))
    }

    /// [`Class::FurnitureRemoved`].
    fn furniture_removed(&self, rng: &mut Rng) -> Vec<f32> {
        let (grid, frame) = (self.grid, self.frame);
        let blocks = 1 + rng.below(3) as usize;
        // Look for obstacle cells near the sensor to erase around.
        self.edited(blocks, |world| {
            let (w, h) = (world.w as i64, world.h as i64);
            let (d, a) = (rng.range(0.5, 8.0) as f32, rng.range(-3.15, 3.15) as f32);
            let Some((cx, cy)) = world.cell(frame, self.around(d, a)) else {
                return false;
            };
            if !refloc::raycast::Occupancy::blocked(grid, cx, cy) {
                return false;
            }
            let (cx, cy) = (cx as i64, cy as i64);
            let half = (rng.range(0.25, 0.5) as f32 / frame.resolution).ceil() as i64;
            for y in (cy - half).max(0)..(cy + half + 1).min(h) {
                for x in (cx - half).max(0)..(cx + half + 1).min(w) {
                    world.set(x as u32, y as u32, false);
                }
            }
            true
        })
    }

    /// [`Class::DoorsToggled`].
    fn doors_toggled(&self, rng: &mut Rng) -> Vec<f32> {
        let (grid, frame) = (self.grid, self.frame);
        let toggles = 1 + rng.below(3) as usize;
        self.edited(toggles, |world| {
            let (d, a) = (rng.range(1.0, 8.0) as f32, rng.range(-3.15, 3.15) as f32);
            let p = self.around(d, a);
            let across = rng.range(0.0, std::f64::consts::PI) as f32;
            if world.blocked_at(frame, p) {
                open_door(world, grid, frame, p, across, rng)
            } else {
                close_door(world, grid, frame, self.xy(), p, across)
            }
        })
    }

    /// [`Class::Shifted`].
    fn shifted(&self, rng: &mut Rng) -> Vec<f32> {
        let (sensor, lidar) = (self.sensor, self.lidar);
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
                beam(self.grid, self.frame, origin, a, lidar.range_max / scale) * scale
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

    /// [`Class::MissingReturns`].
    fn missing_returns(&self, rng: &mut Rng) -> Vec<f32> {
        let mut ranges = self.exact(self.grid);
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

    /// [`Class::RangeNoise`].
    fn range_noise(&self, rng: &mut Rng) -> Vec<f32> {
        let mut ranges = self.exact(self.grid);
        for r in ranges.iter_mut().filter(|r| r.is_finite()) {
            let sigma = 0.01 + 0.01 * *r;
            *r = (*r + sigma * rng.normal() as f32).clamp(1e-3, self.lidar.range_max);
        }
        ranges
    }

    /// [`Class::AngularJitter`].
    fn angular_jitter(&self, rng: &mut Rng) -> Vec<f32> {
        let lidar = self.lidar;
        (0..lidar.beams)
            .map(|k| {
                let jitter = (0.2f64.to_radians() * rng.normal()) as f32;
                let a = self.nominal(k) + jitter;
                beam(self.grid, self.frame, self.xy(), a, lidar.range_max)
            })
            .collect()
    }

    /// [`Class::MountError`].
    fn mount_error(&self, rng: &mut Rng) -> Vec<f32> {
        let [dp, dth] = MOUNT_ERROR.map(f64::from);
        let err = Pose2::new(
            rng.range(-dp, dp) as f32,
            rng.range(-dp, dp) as f32,
            rng.range(-dth, dth) as f32,
        );
        crate::compiler::sim::virtual_scan(
            self.grid,
            self.frame,
            &self.sensor.compose(&err),
            self.lidar,
        )
    }

    /// [`Class::MotionDistortion`].
    fn motion_distortion(&self, rng: &mut Rng) -> Vec<f32> {
        let lidar = self.lidar;
        let omega = rng.range(-1.0, 1.0) as f32;
        let n = lidar.beams.max(1) as f32;
        (0..lidar.beams)
            .map(|k| {
                let t = (k as f32 / n - 0.5) * SWEEP_S;
                beam(
                    self.grid,
                    self.frame,
                    self.xy(),
                    self.nominal(k) + omega * t,
                    lidar.range_max,
                )
            })
            .collect()
    }
}

/// Widest gap (m) a closed door fills, and the narrowest.
const DOOR_GAP: [f32; 2] = [0.6, 1.2];
/// Thickest wall (m) an opened door goes through.
const DOOR_WALL: f32 = 0.25;
/// Nearest a closed door comes to the sensor (m).
const DOOR_CLEARANCE: f32 = 0.4;

/// The cell under world point `p` of a `w` x `h` grid placed by `frame`,
/// if inside it.
fn cell_at(w: u32, h: u32, frame: &MapFrame, p: [f32; 2]) -> Option<(u32, u32)> {
    let c = frame.to_cells(p);
    let (x, y) = (c[0].floor(), c[1].floor());
    (x >= 0.0 && y >= 0.0 && x < w as f32 && y < h as f32).then_some((x as u32, y as u32))
}

/// An editable copy of an occupancy bit grid (row-major bits, 32 a word).
struct Cells {
    w: u32,
    h: u32,
    words: Vec<u32>,
}

impl Cells {
    fn of(grid: &BitGrid<'_>) -> Cells {
        Cells {
            w: refloc::raycast::Occupancy::width(grid),
            h: refloc::raycast::Occupancy::height(grid),
            words: grid.words().to_vec(),
        }
    }

    /// The cell under world point `p`, if inside the grid.
    fn cell(&self, frame: &MapFrame, p: [f32; 2]) -> Option<(u32, u32)> {
        cell_at(self.w, self.h, frame, p)
    }

    fn blocked(&self, x: u32, y: u32) -> bool {
        let bit = y as usize * self.w as usize + x as usize;
        self.words
            .get(bit / 32)
            .is_some_and(|word| word & (1 << (bit % 32)) != 0)
    }

    /// Whether world point `p` is an obstacle (outside the grid: yes).
    fn blocked_at(&self, frame: &MapFrame, p: [f32; 2]) -> bool {
        self.cell(frame, p).is_none_or(|(x, y)| self.blocked(x, y))
    }

    /// Sets (`on`) or clears cell (x, y) (outside the grid: nothing).
    fn set(&mut self, x: u32, y: u32, on: bool) {
        if x >= self.w || y >= self.h {
            return;
        }
        let bit = y as usize * self.w as usize + x as usize;
        if let Some(word) = self.words.get_mut(bit / 32) {
            if on {
                *word |= 1 << (bit % 32);
            } else {
                *word &= !(1 << (bit % 32));
            }
        }
    }

    /// Sets (`on`) or clears the cell under world point `p`.
    fn set_at(&mut self, frame: &MapFrame, p: [f32; 2], on: bool) {
        if let Some((x, y)) = self.cell(frame, p) {
            self.set(x, y, on);
        }
    }

    /// `scan` of this world (of `grid` itself if the copy is unusable).
    fn cast(&self, grid: &BitGrid<'_>, scan: impl Fn(&BitGrid<'_>) -> Vec<f32>) -> Vec<f32> {
        match BitGrid::new(self.w, self.h, &self.words) {
            Some(g) => scan(&g),
            None => scan(grid),
        }
    }
}

/// Closes the doorway through free point `p` along direction `across`
/// (rad) when the free gap there is doorway-wide and clear of the sensor
/// at `sensor`: a wall from one side to the other. True when it did.
fn close_door(
    world: &mut Cells,
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    sensor: [f32; 2],
    p: [f32; 2],
    across: f32,
) -> bool {
    let reach = DOOR_GAP[1] + 0.1;
    let t1 = beam(grid, frame, p, across, reach);
    let t2 = beam(grid, frame, p, across + std::f32::consts::PI, reach);
    let gap = t1 + t2;
    if !(DOOR_GAP[0]..=DOOR_GAP[1]).contains(&gap) {
        return false;
    }
    let u = [across.cos(), across.sin()];
    let a = [p[0] - t2 * u[0], p[1] - t2 * u[1]];
    // Keep the sensor off the new wall: its distance to the segment a..a+gap u.
    let s = ((sensor[0] - a[0]) * u[0] + (sensor[1] - a[1]) * u[1]).clamp(0.0, gap);
    let q = [a[0] + s * u[0], a[1] + s * u[1]];
    if ((sensor[0] - q[0]).powi(2) + (sensor[1] - q[1]).powi(2)).sqrt() < DOOR_CLEARANCE {
        return false;
    }
    let step = 0.5 * frame.resolution;
    let n = (gap / step).ceil() as usize;
    for i in 0..=n {
        let t = (i as f32 * step).min(gap);
        world.set_at(frame, [a[0] + t * u[0], a[1] + t * u[1]], true);
    }
    true
}

/// Opens a door in the wall at obstacle point `p` when, along direction
/// `across` (rad), the wall is at most [`DOOR_WALL`] thick with free space
/// on both sides: clears a 0.8-1.0 m stretch of it. True when it did.
fn open_door(
    world: &mut Cells,
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    p: [f32; 2],
    across: f32,
    rng: &mut Rng,
) -> bool {
    let u = [across.cos(), across.sin()];
    let step = 0.5 * frame.resolution;
    // Obstacle extent along +u and -u from p in the map, stepping until
    // free (None: thicker than a wall a door goes through, or the edge).
    let extent = |sign: f32| -> Option<f32> {
        let mut t = 0.0;
        while t <= DOOR_WALL {
            t += step;
            let (x, y) = world.cell(frame, [p[0] + sign * t * u[0], p[1] + sign * t * u[1]])?;
            if !refloc::raycast::Occupancy::blocked(grid, x, y) {
                return Some(t);
            }
        }
        None
    };
    let (Some(fwd), Some(back)) = (extent(1.0), extent(-1.0)) else {
        return false;
    };
    if fwd + back > DOOR_WALL {
        return false;
    }
    let v = [-u[1], u[0]];
    let half = 0.5 * rng.range(0.8, 1.0) as f32;
    let n_along = (2.0 * half / step).ceil() as i32;
    let n_across = ((fwd + back) / step).ceil() as i32 + 2;
    for i in 0..=n_along {
        let s = -half + i as f32 * step;
        for j in 0..=n_across {
            let t = -back - step + j as f32 * step;
            let q = [p[0] + s * v[0] + t * u[0], p[1] + s * v[1] + t * u[1]];
            world.set_at(frame, q, false);
        }
    }
    true
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
        assert_eq!(Class::parse("windows"), None);
    }

    /// A 10 m x 10 m room (0.1 m cells, walls one cell thick) split at
    /// x = 7 m by a wall with a 1 m doorway at y = 4-5 m.
    fn two_rooms() -> (u32, u32, Vec<u32>) {
        let (w, h) = (100u32, 100u32);
        let mut words = vec![0u32; BitGrid::words_for(w, h)];
        for y in 0..h {
            for x in 0..w {
                let outer = x == 0 || y == 0 || x == w - 1 || y == h - 1;
                let inner = x == 70 && !(40..50).contains(&y);
                if outer || inner {
                    let bit = (y * w + x) as usize;
                    words[bit / 32] |= 1 << (bit % 32);
                }
            }
        }
        (w, h, words)
    }

    const FRAME: MapFrame = MapFrame {
        resolution: 0.1,
        origin: Pose2 {
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        },
    };

    #[test]
    fn doors_open_walls_and_close_doorways() {
        let (w, h, words) = two_rooms();
        let grid = BitGrid::new(w, h, &words).unwrap();
        let lidar = Lidar::new(720, std::f32::consts::TAU, 30.0);
        let sensor = Pose2::new(5.0, 4.5, 0.0);
        let clean = crate::compiler::sim::virtual_scan(&grid, &FRAME, &sensor, &lidar);
        let (mut longer, mut shorter) = (0, 0);
        for seed in 0..40 {
            let a = scan(
                Class::DoorsToggled,
                &grid,
                &FRAME,
                &sensor,
                &lidar,
                &mut Rng::new(seed),
            );
            // A closed door never comes nearer the sensor than
            // DOOR_CLEARANCE (less a cell of rasterization).
            assert!(a.iter().all(|r| *r >= DOOR_CLEARANCE - 0.1), "seed {seed}");
            // Beams towards the inner wall (|angle| < 60 degrees from +x).
            for (k, (x, y)) in a.iter().zip(&clean).enumerate() {
                let ang = lidar.angle(k);
                if ang.cos() < 0.5 {
                    continue;
                }
                if *x > *y + 0.5 {
                    longer += 1; // through an opened door
                } else if *x < *y - 0.5 {
                    shorter += 1; // stopped by a closed door
                }
            }
        }
        assert!(
            longer > 0 && shorter > 0,
            "longer {longer} shorter {shorter}"
        );
    }

    /// People stand in the free space: a disc across or inside a wall is
    /// not free; people only ever shorten beams, and over many seeds they
    /// shorten many.
    #[test]
    fn people_stand_in_free_space() {
        let (w, h, words) = two_rooms();
        let grid = BitGrid::new(w, h, &words).unwrap();
        let lidar = Lidar::new(720, std::f32::consts::TAU, 30.0);
        let sensor = Pose2::new(6.3, 2.0, 0.0);
        let scene = Scene {
            grid: &grid,
            frame: &FRAME,
            sensor: &sensor,
            lidar: &lidar,
        };
        let clean = crate::compiler::sim::virtual_scan(&grid, &FRAME, &sensor, &lidar);
        let mut shortened = 0;
        for seed in 0..40 {
            let a = scene.people(&mut Rng::new(seed));
            assert!(a.iter().zip(&clean).all(|(x, c)| x <= c), "seed {seed}");
            shortened += a.iter().zip(&clean).filter(|(x, c)| x < c).count();
        }
        assert!(shortened > 40 * 20, "{shortened}");
        // A disc across the wall, or centred in it, is not free.
        assert!(!scene.disc_is_free([7.0, 2.0], 0.25));
        assert!(!scene.disc_is_free([6.8, 2.0], 0.25));
        assert!(scene.disc_is_free([6.5, 2.0], 0.25));
    }

    #[test]
    fn disturbances_change_the_scan_and_are_reproducible() {
        let (w, h, words) = two_rooms();
        let grid = BitGrid::new(w, h, &words).unwrap();
        let frame = FRAME;
        let lidar = Lidar::new(360, std::f32::consts::TAU, 30.0);
        let sensor = Pose2::new(5.0, 5.0, 0.3);
        let clean = crate::compiler::sim::virtual_scan(&grid, &frame, &sensor, &lidar);
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
