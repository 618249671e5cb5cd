//! Verification by the vicinity score (paper eq. 23).
//!
//! A virtual scan is ray-cast in the database's grid from the estimated
//! sensor pose along the input's own beam directions, and paired with the
//! input beam by beam. For a pair at distance d (the two endpoints lie on the
//! same ray, so d = |range difference|):
//! `m = 4.5 - d^2 / (2 sigma_d^2)` when `d < 3 sigma_d`, else 0.
//! `M = sum m` over the `N_P` input beams with a return; the pose is accepted
//! when `M > 4.5 * N_P * accept_ratio` (the paper's `accept_ratio` is 1/2).
//!
//! Beyond the paper, a free-space check: a beam that returns well beyond a
//! surface of the map (by `through_excess` or more) *and* ends away from any
//! surface (3 sigma_d or more from it, by the database's distance map) has
//! passed through a wall. A static world with a correct pose allows few of
//! them (glass, an open door, map errors); a pose on the wrong map or in the
//! wrong place makes many. Unlike the range difference alone, the endpoint
//! test forgives beams at grazing incidence, whose range error under a small
//! pose error is large but whose endpoint still lies on the surface.
//!
//! On a map of cells coarser than [`REFERENCE_CELL`] a beam may also fit by
//! its end point: a cell is occupied wherever a surface runs through it, so
//! the cast stops at the cell's face while the surface may lie up to the
//! extra cell size deeper, and a beam meeting the wall at a grazing angle
//! runs far past the cast. A beam longer than the cast by less than
//! [`coarse_reach`] whose end point lies within `3 sigma_d` of a surface
//! (the distance map) scores as a hit by that end point's distance. On
//! maps of [`REFERENCE_CELL`] or finer cells the reach is 0 and nothing
//! changes (docs/results.md, "Coarse maps: beams past the cell's face").

use crate::raycast::{cast_dir, cast_dir_clear, BitGrid, Occupancy};

/// The most a beam adds to the vicinity score M: `m = HIT_SCORE - d^2 /
/// (2 sigma_d^2)` for a beam whose range is off by `d` (paper eq. 23, where
/// the constant is 4.5 = (3 sigma_d)^2 / (2 sigma_d^2), so that m falls to
/// 0 at the cut-off d = 3 sigma_d).
pub const HIT_SCORE: f32 = 4.5;

/// Beams count as fitting the map within this many sigma_d (paper eq. 23).
pub const FIT_SIGMAS: f32 = 3.0;

/// The cell size (m) of the maps the verification's tolerance (`sigma_d`)
/// and the confidence model were chosen and fitted on (every shared map
/// has 0.05 m cells). A surface lies somewhere inside the occupied cell the
/// cast stops at: within one such cell, `sigma_d` absorbs it.
pub const REFERENCE_CELL: f32 = 0.05;

/// How far past the cast, per metre of cell size beyond
/// [`REFERENCE_CELL`], a beam may run and still fit by its end point
/// ([`coarse_reach`]). A surface up to `res - REFERENCE_CELL` deeper than
/// the cell's face, met at a grazing angle `g`, lets the beam run `(res -
/// REFERENCE_CELL) / sin g` past the face: 8 covers angles down to 7
/// degrees. Chosen on maps of 0.1 m cells of the Intel and ACES logs
/// (4, 8, 12 and 16 within a point of each other), reported on CSAIL's
/// (docs/results.md, "Coarse maps: beams past the cell's face").
pub const COARSE_REACH_PER_CELL: f32 = 8.0;

/// The reach (m) of the end-point fit on a map of `res` m cells:
/// [`COARSE_REACH_PER_CELL`] times the cell's excess over
/// [`REFERENCE_CELL`], 0 on maps of that cell size or finer.
pub fn coarse_reach(res: f32) -> f32 {
    (COARSE_REACH_PER_CELL * (res - REFERENCE_CELL)).max(0.0)
}

/// The verification's casts cross open space in steps of the distance
/// map's clearance while it is at least this many cells
/// ([`crate::raycast::cast_dir_clear`]); nearer surfaces they go cell by
/// cell. A jump's next position waits on the clearance it reads (a byte
/// per cell, often not in cache), where the exact traversal's next cell
/// does not wait on its bit, so a jump pays only when it skips several
/// cells (docs/performance.md, "Verification casts across open space").
pub const OPEN_JUMP_CELLS: f32 = 6.0;
use crate::refine::DistMap;
use crate::{MapFrame, Pose2, RefDb};

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
    /// scan sees through where the map has a surface. (On a map of cells
    /// coarser than [`REFERENCE_CELL`], not those that fit by their end
    /// point: see the module documentation.)
    pub long: u32,
    /// Of the long beams, those longer by `through_excess` or more whose end
    /// point lies 3 sigma_d or more from every surface of the map, in runs
    /// of at least `through_run` consecutive beams: beams through a wall (0
    /// when no distance map is given). An isolated such beam (a spurious
    /// return, a reflection) does not count; a wall seen through over an
    /// angular extent does.
    pub through: u32,
    /// Of the short beams, those on a foreground surface of the scan
    /// (something person-sized in front of farther returns,
    /// [`crate::prep::foreground_mask`]) whose nearest beams with a return
    /// on both sides outside it fit the map: a person or a chair in front
    /// of a wall the pose explains. [`Vicinity::evidence`] does not charge
    /// them. At a wrong pose the beams beside such a surface rarely fit.
    pub occluded: u32,
}

impl Vicinity {
    /// M over its maximum for the beams that are not short:
    /// `M / (HIT_SCORE (N_P - short))`, 0 when every beam is short.
    pub fn explained_ratio(&self) -> f32 {
        ratio(self.score, self.pairs.saturating_sub(self.short))
    }

    /// The vicinity ratio: M over its maximum, `M / (HIT_SCORE N_P)`, 0
    /// with no beams.
    pub fn vicinity_ratio(&self) -> f32 {
        ratio(self.score, self.pairs)
    }
}

/// `m / (HIT_SCORE n)`: a vicinity score as a share of its maximum over
/// `n` beams, 0 when `n` is 0.
pub fn ratio(m: f32, n: u32) -> f32 {
    if n == 0 {
        0.0
    } else {
        m / (HIT_SCORE * n as f32)
    }
}

/// The verification's map and settings.
#[derive(Clone, Copy)]
pub struct Verifier<'a, G: Occupancy + ?Sized> {
    /// Occupancy for the virtual beams.
    pub grid: &'a G,
    /// Grid placement.
    pub frame: MapFrame,
    /// Distance to the nearest surface, for the through-wall test (`None`
    /// skips it: [`Vicinity::through`] stays 0).
    pub dist: Option<DistMap<'a>>,
    /// The distance map the casts cross open space with
    /// ([`crate::raycast::cast_dir_clear`], jumps of at least
    /// [`OPEN_JUMP_CELLS`]); `None` traverses every cell (the same answers,
    /// more work).
    pub open: Option<DistMap<'a>>,
    /// Bound of the virtual beams (m).
    pub range_max: f32,
    /// sigma_d (m).
    pub sigma_d: f32,
    /// Accept when `M > HIT_SCORE N_P accept_ratio`.
    pub accept_ratio: f32,
    /// Least excess range (m) of a beam through a wall.
    pub through_excess: f32,
    /// Beams through a wall count only in runs of at least this many
    /// consecutive beams (beams with no return do not break a run).
    pub through_run: u32,
}

impl<'a> Verifier<'a, BitGrid<'a>> {
    /// The verifier of `db` (its grid `grid = db.grid()`, distance map and
    /// parameters) for a sensor of maximum range `range_max` (m).
    pub fn new<D: AsRef<[u8]>>(db: &'a RefDb<D>, grid: &'a BitGrid<'a>, range_max: f32) -> Self {
        Self::with_dist(db, grid, range_max, DistMap::of(db))
    }

    /// [`Verifier::new`] with `db`'s distance map `dm` ([`DistMap::of`])
    /// already made: the localizer keeps one for all its verifications.
    pub fn with_dist<D: AsRef<[u8]>>(
        db: &'a RefDb<D>,
        grid: &'a BitGrid<'a>,
        range_max: f32,
        dm: DistMap<'a>,
    ) -> Self {
        let p = db.params();
        Verifier {
            grid,
            frame: db.frame(),
            dist: (p.verify.through_max > 0.0).then_some(dm),
            open: Some(dm),
            range_max,
            sigma_d: p.verify.sigma_d,
            accept_ratio: p.verify.accept_ratio,
            through_excess: p.verify.through_excess,
            through_run: p.verify.through_run,
        }
    }
}

impl<G: Occupancy + ?Sized> Verifier<'_, G> {
    /// Scores `sensor` (map frame) for input beams given as (angle in the
    /// sensor frame (rad), range (m)) pairs; non-finite ranges are skipped.
    pub fn score(&self, sensor: &Pose2, beams: impl Iterator<Item = (f32, f32)>) -> Vicinity {
        self.score_dirs(
            sensor,
            beams.map(|(a, r)| ([libm::cosf(a), libm::sinf(a)], r)),
        )
    }

    /// [`Verifier::score`] for beams given as (unit direction in the sensor
    /// frame, range (m)) pairs: no trigonometry per beam.
    pub fn score_dirs(
        &self,
        sensor: &Pose2,
        beams: impl Iterator<Item = ([f32; 2], f32)>,
    ) -> Vicinity {
        self.score_marked(sensor, beams.map(|(u, r)| (u, r, false)))
    }

    /// [`Verifier::score_dirs`] for beams that also say whether they lie on
    /// a foreground surface of the scan ([`crate::prep::foreground_mask`]),
    /// for [`Vicinity::occluded`]; the beams come in scan order.
    pub fn score_marked(
        &self,
        sensor: &Pose2,
        beams: impl Iterator<Item = ([f32; 2], f32, bool)>,
    ) -> Vicinity {
        let frame = &self.frame;
        // Sensor frame to grid axes, and to the map frame (for end points).
        let to_cells = frame.angle_to_cells(sensor.theta);
        let (cs, cc) = (libm::sinf(to_cells), libm::cosf(to_cells));
        let (ms, mc) = (libm::sinf(sensor.theta), libm::cosf(sensor.theta));
        let uv = frame.to_cells([sensor.x, sensor.y]);
        let max_cells = self.range_max / frame.resolution;
        let inv_res = 1.0 / frame.resolution;
        let lim = FIT_SIGMAS * self.sigma_d;
        let inv = 1.0 / (2.0 * self.sigma_d * self.sigma_d);
        let reach_past = coarse_reach(frame.resolution);
        // The map point `r` metres along direction `u` (sensor frame).
        let end_of = |u: [f32; 2], r: f32| {
            [
                sensor.x + r * (mc * u[0] - ms * u[1]),
                sensor.y + r * (ms * u[0] + mc * u[1]),
            ]
        };
        let surfaces = self.dist.as_ref().or(self.open.as_ref());
        let mut m = 0.0f32;
        let mut n = 0u32;
        let mut short = 0u32;
        let mut long = 0u32;
        let mut through = 0u32;
        let mut occluded = 0u32;
        // The short beams so far of the foreground surface being read (0
        // between surfaces), and whether the last beam with a return off
        // the foreground fitted the map: the one before that surface.
        let mut pending = 0u32;
        let mut last_fit = false;
        let min_run = self.through_run.max(1);
        let mut run = 0u32;
        for (u, r, fg) in beams {
            if !r.is_finite() {
                continue;
            }
            n += 1;
            let mut through_here = false;
            let mut fits = false;
            let mut is_short = false;
            // A surface farther than r + lim only makes the beam short, as
            // no surface at all does: the cast stops a cell beyond that.
            let reach = ((r + lim) * inv_res + 1.0).min(max_cells);
            let (dx, dy) = (cc * u[0] - cs * u[1], cs * u[0] + cc * u[1]);
            let hit = match &self.open {
                Some(dm) => cast_dir_clear(
                    self.grid,
                    uv[0],
                    uv[1],
                    dx,
                    dy,
                    reach,
                    OPEN_JUMP_CELLS,
                    |cx, cy| dm.clearance(cx, cy),
                ),
                None => cast_dir(self.grid, uv[0], uv[1], dx, dy, reach),
            };
            match hit {
                Some(t) => {
                    let v = t * frame.resolution;
                    let d = libm::fabsf(v - r);
                    if d < lim {
                        m += HIT_SCORE - d * d * inv;
                        fits = true;
                    } else if r < v {
                        is_short = true;
                    } else if let Some(e) = (r - v < reach_past)
                        .then(|| surfaces.and_then(|dm| dm.sample(end_of(u, r))))
                        .flatten()
                        .map(|(e, _)| libm::fabsf(e))
                        .filter(|e| *e < lim)
                    {
                        // A coarse cell's surface behind its face.
                        m += HIT_SCORE - e * e * inv;
                        fits = true;
                    } else {
                        long += 1;
                        if r - v >= self.through_excess {
                            if let Some(dm) = &self.dist {
                                // Outside the grid counts as away from surfaces.
                                let off = dm
                                    .sample(end_of(u, r))
                                    .is_none_or(|(e, _)| libm::fabsf(e) >= lim);
                                through_here = off;
                            }
                        }
                    }
                }
                None => is_short = true, // no surface within reach
            }
            short += u32::from(is_short);
            if fg {
                pending += u32::from(is_short);
            } else {
                if last_fit && fits {
                    occluded += pending;
                }
                pending = 0;
                last_fit = fits;
            }
            if through_here {
                run += 1;
                if run == min_run {
                    through += min_run;
                } else if run > min_run {
                    through += 1;
                }
            } else {
                run = 0;
            }
        }
        Vicinity {
            score: m,
            threshold: HIT_SCORE * n as f32 * self.accept_ratio,
            pairs: n,
            short,
            long,
            through,
            occluded,
        }
    }
}

impl Vicinity {
    /// The evidence for the pose: M itself when the beams that are not
    /// short fit the map at least `occlusion_fit` well
    /// ([`Vicinity::explained_ratio`]; the short beams are then taken for
    /// unmapped things in front, people and clutter), else
    /// `M - HIT_SCORE short_weight (short - occluded)`: each beam that ends
    /// in front of where the map has a surface costs a share of a hit's
    /// weight, as it does on a wrong map, where the rest of the scan fits
    /// only loosely, unless it is on a person-sized surface standing in
    /// front of a surface the pose explains ([`Vicinity::occluded`]).
    /// `short_weight` 0 gives the paper's M.
    pub fn evidence(&self, short_weight: f32, occlusion_fit: f32) -> f32 {
        if occlusion_fit > 0.0 && self.explained_ratio() >= occlusion_fit {
            self.score
        } else {
            let charged = self.short.saturating_sub(self.occluded);
            self.score - HIT_SCORE * short_weight * charged as f32
        }
    }

    /// True when at most `through_max` of the beams with a return went
    /// through a wall (`through_max` 0 disables the test).
    pub fn free_space_ok(&self, through_max: f32) -> bool {
        through_max <= 0.0 || self.through as f32 <= through_max * self.pairs as f32
    }
}
