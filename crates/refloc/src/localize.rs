//! The localizer: one scan in, a pose with its evidence out, using only the
//! caller's scratch memory.
//!
//! Stages, each in its own module and measurable on its own:
//! [`crate::prep`] → [`crate::pgr`] histogram → [`crate::coarse`] ranking →
//! per candidate: [`crate::ssm`] → [`crate::refine`] (optional) →
//! [`crate::verify`] → selection.

use core::fmt;

use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::coarse::{self, Ranked};
use crate::db::RefDb;
use crate::params::{Params, Selection};
use crate::prep;
use crate::refine::{self, DistMap};
use crate::ssm::{self, Affinity, SsmWork, DESC_LEN};
use crate::verify;
use crate::Pose2;

/// The default of `Params::affinity_cap`: most affinity entries stored per
/// SSM run (8 bytes each).
pub const AFFINITY_CAP: usize = 16 * 1024;

/// A laser scan as `sensor_msgs/LaserScan` ranges: beam `k` at angle
/// `angle_min + k * angle_increment` (radians, sensor frame); ranges in
/// metres; non-finite or out-of-limits ranges mean "no return".
#[derive(Clone, Copy, Debug)]
pub struct RangeScan<'a> {
    /// First beam angle (rad).
    pub angle_min: f32,
    /// Angle step (rad); negative for clockwise scans.
    pub angle_increment: f32,
    /// Minimum valid range (m).
    pub range_min: f32,
    /// Maximum valid range (m).
    pub range_max: f32,
    /// Ranges (m).
    pub ranges: &'a [f32],
}

/// An input scan.
#[derive(Clone, Copy, Debug)]
pub enum Scan<'a> {
    /// Ranges with beam geometry.
    Ranges(RangeScan<'a>),
    /// Points in the sensor frame (m), in scan order; `range_max` (m) bounds
    /// the verification's virtual beams. Non-finite points are "no return".
    Points {
        /// The points.
        points: &'a [[f32; 2]],
        /// Sensor maximum range (m).
        range_max: f32,
    },
}

impl Scan<'_> {
    /// Number of beams / points.
    pub fn len(&self) -> usize {
        match self {
            Scan::Ranges(r) => r.ranges.len(),
            Scan::Points { points, .. } => points.len(),
        }
    }
    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Why a scan could not be localized.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum LocalizeError {
    /// The scratch buffer is smaller than [`scratch_size`] says.
    ScratchTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        got: usize,
    },
    /// More beams than the scratch was sized for.
    TooManyBeams {
        /// Beams in the scan.
        beams: usize,
        /// Capacity.
        capacity: usize,
    },
    /// Scan geometry is unusable; the field is named.
    BadScan(&'static str),
    /// Too few valid returns.
    NotEnoughPoints {
        /// Valid points found.
        valid: usize,
        /// Needed.
        needed: usize,
    },
    /// No candidate site produced a pose.
    NoMatch {
        /// Candidates examined.
        candidates: usize,
    },
}

impl fmt::Display for LocalizeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            LocalizeError::ScratchTooSmall { needed, got } => {
                write!(f, "scratch buffer too small: {got} bytes, need {needed}")
            }
            LocalizeError::TooManyBeams { beams, capacity } => {
                write!(
                    f,
                    "scan has {beams} beams, the scratch was sized for {capacity}"
                )
            }
            LocalizeError::BadScan(what) => write!(f, "unusable scan: {what}"),
            LocalizeError::NotEnoughPoints { valid, needed } => {
                write!(f, "too few valid points: {valid}, need {needed}")
            }
            LocalizeError::NoMatch { candidates } => {
                write!(f, "no candidate site matched ({candidates} examined)")
            }
        }
    }
}

impl core::error::Error for LocalizeError {}

/// One candidate site examined by the fine stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, FromBytes, IntoBytes, KnownLayout, Immutable)]
#[repr(C)]
pub struct Candidate {
    /// Site index.
    pub site: u32,
    /// Coarse rank (0 = best correlation).
    pub rank: u32,
    /// Correlation coefficient gamma.
    pub gamma: f32,
    /// SSM matching score E (0 when SSM found no pose).
    pub match_score: f32,
    /// Correspondences accepted by binarization.
    pub matched: u32,
    /// RANSAC inliers.
    pub inliers: u32,
    /// Robot pose x in the map frame (m).
    pub x: f32,
    /// Robot pose y in the map frame (m).
    pub y: f32,
    /// Robot heading in the map frame (rad).
    pub theta: f32,
    /// Vicinity score M.
    pub vicinity: f32,
    /// Vicinity threshold.
    pub vicinity_threshold: f32,
    /// 1 when SSM produced a pose, 0 otherwise (no match, or skipped by the
    /// early stop's confirmation as near the best pose: see
    /// [`CONFIRM_SKIP_RADIUS`]).
    pub has_pose: u32,
    /// Input beams shorter than the map predicts at this pose (see [`crate::verify::Vicinity`]).
    pub short_beams: u32,
    /// Input beams longer than the map allows at this pose.
    pub long_beams: u32,
    /// N_P: input beams with a return.
    pub pairs: u32,
    /// Input beams through a wall at this pose (see [`crate::verify::Vicinity::through`]).
    pub through_beams: u32,
    /// 1 when the pose passes the free-space check (few beams through walls).
    pub free_space_ok: u32,
    /// The evidence for this pose: M less `short_weight * 4.5` per short
    /// beam (see [`crate::verify::Vicinity::evidence`]); selection,
    /// ambiguity and acceptance compare it with the threshold.
    pub evidence: f32,
}

/// The answer for one scan.
#[derive(Clone, Copy, Debug)]
pub struct Localization<'s> {
    /// Robot pose in the map frame (m, m, rad).
    pub pose: Pose2,
    /// Sensor pose in the map frame.
    pub sensor_pose: Pose2,
    /// The site the pose came through.
    pub site: u32,
    /// Coarse rank of that site (0 = best).
    pub coarse_rank: u32,
    /// Its correlation coefficient.
    pub gamma: f32,
    /// SSM matching score E.
    pub match_score: f32,
    /// RANSAC inliers.
    pub inliers: u32,
    /// Vicinity score M.
    pub vicinity: f32,
    /// Its acceptance threshold.
    pub vicinity_threshold: f32,
    /// The evidence for the pose: M less a share of the short beams' weight.
    pub evidence: f32,
    /// evidence > threshold, few beams through walls, and not ambiguous.
    pub accepted: bool,
    /// Another candidate with a clearly different pose scored within
    /// `ambiguity_ratio` of the best (the pose is then not accepted).
    pub ambiguous: bool,
    /// Valid input points.
    pub valid_points: u32,
    /// Input beams shorter than the map predicts at the pose.
    pub short_beams: u32,
    /// Input beams longer than the map allows at the pose.
    pub long_beams: u32,
    /// Input beams through a wall at the pose (the free-space check).
    pub through_beams: u32,
    /// The pose passes the free-space check.
    pub free_space_ok: bool,
    /// Every candidate examined, in coarse rank order.
    pub candidates: &'s [Candidate],
}

/// Sizes of the working arrays.
#[derive(Clone, Copy, Debug)]
struct Dims {
    beams: usize,
    ref_beams: usize,
    points: usize,
    hist: usize,
    cands: usize,
    tent: usize,
    aff: usize,
}

impl Dims {
    fn new(params: &Params, max_beams: usize) -> Dims {
        let points = params.max_points as usize;
        Dims {
            beams: max_beams,
            ref_beams: params.sensor.beams as usize,
            points,
            hist: params.hist_cells().max(params.win_cells()),
            cands: params.nc_max as usize,
            tent: points * params.tentative_k as usize,
            aff: params.affinity_cap as usize,
        }
    }

    /// (element count, element size, element alignment) of every array, in carve order.
    fn arrays(&self) -> [(usize, usize, usize); 20] {
        use core::mem::{align_of, size_of};
        let f = (size_of::<f32>(), align_of::<f32>());
        let p2 = (size_of::<[f32; 2]>(), align_of::<[f32; 2]>());
        let u = |n: usize, t: (usize, usize)| (n, t.0, t.1);
        [
            u(self.beams, p2),
            u(self.beams, f),
            u(self.beams, f),
            u(self.points, p2),
            u(self.points, p2),
            u(self.ref_beams, p2),
            u(self.points, p2),
            u(self.points, p2),
            u(self.hist, f),
            u(self.cands, (size_of::<Ranked>(), align_of::<Ranked>())),
            u(
                self.cands,
                (size_of::<Candidate>(), align_of::<Candidate>()),
            ),
            u(self.points * DESC_LEN, f),
            u(self.points * DESC_LEN, f),
            u(self.tent, (size_of::<[u16; 2]>(), align_of::<[u16; 2]>())),
            u(self.aff, (size_of::<Affinity>(), align_of::<Affinity>())),
            u(self.tent, f),
            u(self.tent, f),
            u(self.tent, (2, 2)),
            u(self.points, (size_of::<[u16; 2]>(), align_of::<[u16; 2]>())),
            u(3 * self.points + self.tent, (1, 1)),
        ]
    }

    fn bytes(&self) -> usize {
        self.arrays().iter().map(|&(n, s, a)| n * s + a - 1).sum()
    }
}

/// Bytes of scratch memory [`localize`] needs for scans of up to
/// `max_beams` beams against a database with `params`.
pub fn scratch_size(params: &Params, max_beams: usize) -> usize {
    Dims::new(params, max_beams).bytes()
}

/// The largest scan (beams) a scratch of `bytes` bytes can take, 0 if none.
pub fn max_beams_for(params: &Params, bytes: usize) -> usize {
    let base = scratch_size(params, 0);
    if bytes < base {
        return 0;
    }
    let per = scratch_size(params, 1) - base;
    (bytes - base) / per.max(1)
}

struct Arena<'a> {
    buf: &'a mut [u8],
}

impl<'a> Arena<'a> {
    fn take<T: FromBytes + IntoBytes + KnownLayout + Immutable>(
        &mut self,
        n: usize,
    ) -> Option<&'a mut [T]> {
        let buf = core::mem::take(&mut self.buf);
        let pad = buf.as_ptr().align_offset(core::mem::align_of::<T>());
        if pad > buf.len() {
            return None;
        }
        let (_, rest) = buf.split_at_mut(pad);
        let (slice, rest) = <[T]>::mut_from_prefix_with_elems(rest, n).ok()?;
        self.buf = rest;
        Some(slice)
    }
}

/// Localizes `scan` against `db` with no initial pose, using only `scratch`
/// (at least [`scratch_size`]`(db.params(), scan.len())` bytes). Never
/// allocates and never panics.
///
/// A scratch too small for this scan gives [`LocalizeError::TooManyBeams`]
/// (with the beam count it can take) when it can take some scan, else
/// [`LocalizeError::ScratchTooSmall`].
pub fn localize<'s, D: AsRef<[u8]>>(
    db: &RefDb<D>,
    scan: &Scan<'_>,
    scratch: &'s mut [u8],
) -> Result<Localization<'s>, LocalizeError> {
    let params = db.params();
    let n_beams = scan.len();
    let dims = Dims::new(params, n_beams);
    let needed = dims.bytes();
    if scratch.len() < needed {
        let cap = max_beams_for(params, scratch.len());
        if cap < n_beams && scratch_size(params, 0) <= scratch.len() {
            return Err(LocalizeError::TooManyBeams {
                beams: n_beams,
                capacity: cap,
            });
        }
        return Err(LocalizeError::ScratchTooSmall {
            needed,
            got: scratch.len(),
        });
    }
    let mut ar = Arena { buf: scratch };
    let oom = LocalizeError::ScratchTooSmall {
        needed,
        got: needed,
    };
    macro_rules! take {
        ($t:ty, $n:expr) => {
            ar.take::<$t>($n).ok_or(oom)?
        };
    }
    let in_pts = take!([f32; 2], dims.beams);
    let in_ang = take!(f32, dims.beams);
    let in_rng = take!(f32, dims.beams);
    let q_pts = take!([f32; 2], dims.points);
    let q_tan = take!([f32; 2], dims.points);
    let r_dense = take!([f32; 2], dims.ref_beams);
    let r_pts = take!([f32; 2], dims.points);
    let r_tan = take!([f32; 2], dims.points);
    let hist = take!(f32, dims.hist);
    let top = take!(Ranked, dims.cands);
    let cands = take!(Candidate, dims.cands);
    let mut work = SsmWork {
        qdesc: take!(f32, dims.points * DESC_LEN),
        rdesc: take!(f32, dims.points * DESC_LEN),
        tent: take!([u16; 2], dims.tent),
        aff: take!(Affinity, dims.aff),
        x: take!(f32, dims.tent),
        y: take!(f32, dims.tent),
        order: take!(u16, dims.tent),
        acc: take!([u16; 2], dims.points),
        flags: take!(u8, 3 * dims.points + dims.tent),
    };

    // 1. Input scan to beam-ordered points, counter-clockwise.
    let (valid, fov, wrap, range_max) = load_scan(scan, in_pts, in_ang, in_rng)?;
    let needed_pts = params.min_valid_points as usize;
    if valid < needed_pts {
        return Err(LocalizeError::NotEnoughPoints {
            valid,
            needed: needed_pts,
        });
    }
    let in_pts = &in_pts[..n_beams];
    let nq = prep::prepare(in_pts, wrap, params, q_pts, q_tan);
    if nq < 8 {
        return Err(LocalizeError::NotEnoughPoints {
            valid: nq,
            needed: 8,
        });
    }
    let (q_pts, q_tan) = (&q_pts[..nq], &q_tan[..nq]);

    // 2. Coarse: histogram (of a window matching a partial field of view)
    //    and ranking. The reference buffers are free until the fine stage.
    let (window, cells) = coarse::query_histogram(in_pts, fov, wrap, params, r_pts, r_tan, hist);
    let hist = &hist[..cells];
    let ranked = coarse::rank_sites(db, hist, window, top);
    let nc = coarse::candidate_count(
        &top[..ranked],
        params.nc_min as usize,
        params.nc_max as usize,
        params.nc_margin,
    );

    // 3. Fine: SSM against each candidate, refine, verify.
    ssm::descriptors(q_pts, q_tan, params.desc_radius, work.qdesc);
    let s = &params.sensor;
    let ref_wrap = prep::covers_full_turn(s.angle_increment, s.beams as usize);
    let dm = DistMap::of(db);
    let grid = db.grid();
    let verifier = verify::Verifier::new(db, &grid, range_max);
    let offset_inv = s.offset.inverse();
    let mut best: Option<usize> = None;
    let mut examined = nc;
    // Set by the early stop: the coarse score below which the search ends.
    let mut confirm_floor: Option<f32> = None;
    let mut confirmed = 0usize;
    for (c, r) in top[..nc].iter().enumerate() {
        let site = r.site as usize;
        let mut cand = Candidate {
            site: r.site,
            rank: c as u32,
            gamma: r.gamma,
            ..Candidate::default()
        };
        if let (Some(floor), Some(b)) = (confirm_floor, best) {
            if r.gamma < floor || confirmed >= CONFIRM_MAX {
                examined = c;
                break;
            }
            // A site near the best pose would only find that pose again.
            let sxy = db.site_xy(site);
            let (dx, dy) = (sxy[0] - cands[b].x, sxy[1] - cands[b].y);
            if dx * dx + dy * dy < CONFIRM_SKIP_RADIUS * CONFIRM_SKIP_RADIUS {
                cands[c] = cand;
                continue;
            }
            confirmed += 1;
        }
        let n = prep::ranges_to_points(
            db.scan(site),
            s.angle_min,
            s.angle_increment,
            s.range_min,
            s.range_max,
            r_dense,
        );
        let nr = prep::prepare(&r_dense[..n], ref_wrap, params, r_pts, r_tan);
        ssm::descriptors(&r_pts[..nr], &r_tan[..nr], params.desc_radius, work.rdesc);
        if let Some(m) =
            ssm::match_scans(q_pts, q_tan, &r_pts[..nr], &r_tan[..nr], params, &mut work)
        {
            let sxy = db.site_xy(site);
            let mut sensor = Pose2::new(sxy[0], sxy[1], 0.0).compose(&m.pose);
            if params.refine_iters > 0 {
                sensor = refine::refine(
                    &dm,
                    in_pts,
                    sensor,
                    params.refine_iters,
                    params.refine_max_dist,
                )
                .0;
            }
            let v = verifier.score(
                &sensor,
                in_ang
                    .iter()
                    .copied()
                    .zip(in_rng.iter().copied())
                    .take(n_beams),
            );
            let free_ok = v.free_space_ok(params.through_max);
            let robot = sensor.compose(&offset_inv);
            cand.match_score = m.score;
            cand.matched = m.matched;
            cand.inliers = m.inliers;
            cand.x = robot.x;
            cand.y = robot.y;
            cand.theta = robot.theta;
            cand.vicinity = v.score;
            cand.vicinity_threshold = v.threshold;
            cand.has_pose = 1;
            cand.short_beams = v.short;
            cand.long_beams = v.long;
            cand.pairs = v.pairs;
            cand.through_beams = v.through;
            cand.free_space_ok = free_ok as u32;
            cand.evidence = v.evidence(params.short_weight, params.occlusion_fit);
            // A pose that passes the free-space check beats one that fails it.
            let better = match best {
                None => true,
                Some(b) if cands[b].free_space_ok != cand.free_space_ok => free_ok,
                Some(b) => match params.selection {
                    Selection::MatchScore => cand.match_score > cands[b].match_score,
                    Selection::Vicinity => cand.evidence > cands[b].evidence,
                },
            };
            if better {
                best = Some(c);
            }
            // Early stop (vicinity selection): a confident match (the beams
            // not blocked by something unmapped in front agree with the map
            // almost perfectly, at most a fifth are blocked, and M passes the
            // acceptance threshold), or enough candidates examined and an
            // acceptable best.
            let best_ok = best
                .map(|b| {
                    let bc = if b == c { &cand } else { &cands[b] };
                    bc.free_space_ok != 0 && bc.evidence > v.threshold
                })
                .unwrap_or(false);
            let done = params.selection == Selection::Vicinity
                && params.early_accept > 0.0
                && ((v.explained_ratio() >= params.early_accept
                    && v.short * 5 <= v.pairs
                    && cand.evidence > v.threshold
                    && free_ok)
                    || (params.early_min > 0 && c + 1 >= params.early_min as usize && best_ok));
            cands[c] = cand;
            // Before stopping, examine the sites the coarse stage rates
            // nearly as high as this one (within EARLY_CONFIRM_GAMMA): a
            // twin place (a symmetric or repeated part of the map) ranks
            // there, and the ambiguity test sees only what was examined.
            if done && confirm_floor.is_none() {
                confirm_floor = Some(r.gamma - EARLY_CONFIRM_GAMMA);
            }
        }
        cands[c] = cand;
    }
    let nc = examined.min(nc);
    let cands = &cands[..nc];
    let b = best.ok_or(LocalizeError::NoMatch { candidates: nc })?;
    let c = cands[b];
    let pose = Pose2::new(c.x, c.y, c.theta);
    // Ambiguity: another examined candidate far from this pose that explains
    // the scan almost as well (and passes the free-space check: a pose
    // that sees through walls is no alternative).
    let ambiguous = params.ambiguity_ratio > 0.0
        && cands.iter().any(|o| {
            let far = (o.x - c.x) * (o.x - c.x) + (o.y - c.y) * (o.y - c.y) > 1.0
                || libm::fabsf(crate::wrap_angle(o.theta - c.theta)) > 0.349_066; // 20 degrees
            o.has_pose != 0
                && o.free_space_ok != 0
                && far
                && o.evidence >= params.ambiguity_ratio * c.evidence
        });
    let free_ok = c.free_space_ok != 0;
    Ok(Localization {
        pose,
        sensor_pose: pose.compose(&s.offset),
        site: c.site,
        coarse_rank: c.rank,
        gamma: c.gamma,
        match_score: c.match_score,
        inliers: c.inliers,
        vicinity: c.vicinity,
        vicinity_threshold: c.vicinity_threshold,
        evidence: c.evidence,
        accepted: c.evidence > c.vicinity_threshold && free_ok && !ambiguous,
        ambiguous,
        valid_points: valid as u32,
        short_beams: c.short_beams,
        long_beams: c.long_beams,
        through_beams: c.through_beams,
        free_space_ok: free_ok,
        candidates: cands,
    })
}

/// After the early stop's condition holds at a candidate of coarse score
/// gamma, the candidates still to come with a score of at least
/// `gamma - EARLY_CONFIRM_GAMMA` are examined too (ranked by gamma, they are
/// the next ones), except those whose site lies within
/// [`CONFIRM_SKIP_RADIUS`] of the best pose so far. Measured on a symmetric
/// map (tb3-world, 200 static 360-degree poses): the twin site ranks within
/// 0.02 of the one that stopped the search; without the confirmation 15.5%
/// of the poses were accepted at the twin, with it none (docs/ssm.md,
/// "Early stop and its confirmation").
pub const EARLY_CONFIRM_GAMMA: f32 = 0.05;

/// Confirmation after the early stop skips candidate sites closer than this
/// (m) to the best pose so far: their match would find the same pose, and
/// the ambiguity test looks for poses over 1 m away.
pub const CONFIRM_SKIP_RADIUS: f32 = 2.0;

/// Most candidates the confirmation after the early stop examines.
pub const CONFIRM_MAX: usize = 6;

/// Fills dense points, beam angles and ranges in counter-clockwise order.
/// Returns (valid count, angular coverage in rad, closes a full turn, range_max).
fn load_scan(
    scan: &Scan<'_>,
    pts: &mut [[f32; 2]],
    ang: &mut [f32],
    rng: &mut [f32],
) -> Result<(usize, f32, bool, f32), LocalizeError> {
    use core::f32::consts::PI;
    let n = scan.len();
    if n > pts.len() || n > ang.len() || n > rng.len() {
        return Err(LocalizeError::TooManyBeams {
            beams: n,
            capacity: pts.len(),
        });
    }
    let mut valid = 0;
    match scan {
        Scan::Ranges(r) => {
            let inc = r.angle_increment;
            if !(r.angle_min.is_finite() && inc.is_finite() && inc != 0.0) {
                return Err(LocalizeError::BadScan(
                    "angle_min/angle_increment must be finite and non-zero",
                ));
            }
            if !(libm::fabsf(inc) * n as f32 <= 2.0 * PI * 1.01 + libm::fabsf(inc)) {
                return Err(LocalizeError::BadScan(
                    "angle_increment * beams exceeds a full turn",
                ));
            }
            if !(r.range_max.is_finite()
                && r.range_max > 0.0
                && r.range_min.is_finite()
                && r.range_min >= 0.0
                && r.range_min < r.range_max)
            {
                return Err(LocalizeError::BadScan(
                    "range_min/range_max must be finite, 0 <= range_min < range_max",
                ));
            }
            for k in 0..n {
                // Store counter-clockwise: reverse a clockwise scan.
                let src = if inc > 0.0 { k } else { n - 1 - k };
                let a = r.angle_min + src as f32 * inc;
                let d = r.ranges[src];
                let ok = d.is_finite() && d >= r.range_min && d <= r.range_max && d > 0.0;
                ang[k] = a;
                if ok {
                    rng[k] = d;
                    pts[k] = [d * libm::cosf(a), d * libm::sinf(a)];
                    valid += 1;
                } else {
                    rng[k] = f32::INFINITY;
                    pts[k] = [f32::NAN, f32::NAN];
                }
            }
            let fov = (libm::fabsf(inc) * n as f32).min(2.0 * PI);
            let wrap = prep::covers_full_turn(inc, n);
            Ok((valid, fov, wrap, r.range_max))
        }
        Scan::Points { points, range_max } => {
            if !(range_max.is_finite() && *range_max > 0.0) {
                return Err(LocalizeError::BadScan(
                    "range_max must be finite and positive",
                ));
            }
            // Orientation: majority vote of the turn direction between
            // consecutive valid points (robust to outliers, which make large
            // jumps of either sign); coverage: the sum of the small steps.
            let (mut ccw, mut cw) = (0usize, 0usize);
            let mut turn = 0.0f32;
            let mut last: Option<[f32; 2]> = None;
            // Only points that will be kept (finite, within range) vote, so
            // points discarded as "no return" cannot fake a direction or a
            // coverage.
            let keep = |p: &[f32; 2]| {
                let r = crate::math::norm(*p);
                p[0].is_finite() && p[1].is_finite() && r > 0.0 && r <= *range_max
            };
            for p in points.iter() {
                if keep(p) {
                    if let Some(l) = last {
                        let step = crate::math::signed_angle(l, *p);
                        if libm::fabsf(step) < core::f32::consts::FRAC_PI_4 {
                            if step > 0.0 {
                                ccw += 1;
                            } else if step < 0.0 {
                                cw += 1;
                            }
                            turn += libm::fabsf(step);
                        }
                    }
                    last = Some(*p);
                }
            }
            let rev = cw > ccw;
            for k in 0..n {
                let p = points[if rev { n - 1 - k } else { k }];
                let r = crate::math::norm(p);
                if keep(&p) {
                    pts[k] = p;
                    ang[k] = crate::math::atan2(p[1], p[0]);
                    rng[k] = r;
                    valid += 1;
                } else {
                    pts[k] = [f32::NAN, f32::NAN];
                    ang[k] = 0.0;
                    rng[k] = f32::INFINITY;
                }
            }
            Ok((valid, turn.min(2.0 * PI), turn > 2.0 * PI * 0.9, *range_max))
        }
    }
}
