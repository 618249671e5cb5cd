//! The localizer: one scan in, a pose with its evidence out, using only the
//! caller's scratch memory.
//!
//! Stages, each in its own module and callable on its own through
//! [`Localizer`]: [`crate::prep`] → [`crate::pgr`] histogram →
//! [`crate::coarse`] ranking → per candidate: [`crate::ssm`] →
//! [`crate::refine`] (optional) → [`crate::verify`] → [`crate::select`].

use core::fmt;

use zerocopy::{FromBytes, Immutable, IntoBytes, KnownLayout};

use crate::coarse::{self, Ranked};
use crate::confidence::{self, Decision};
use crate::db::RefDb;
use crate::params::Params;
use crate::prep;
use crate::prior::Prior;
use crate::rank;
use crate::raycast::BitGrid;
use crate::refine::{self, DistMap};
use crate::select::{self, Next, Placement, Search};
use crate::ssm::{self, DescBin, SsmWork, DESC_LEN};
use crate::verify;
use crate::Pose2;

pub use crate::select::{CONFIRM_MAX, CONFIRM_SKIP_RADIUS, EARLY_CONFIRM_GAMMA};

/// The default of `Params::affinity_cap`: most affinity entries stored per
/// SSM run (8 bytes each).
pub const AFFINITY_CAP: usize = 16 * 1024;

/// A laser scan as `sensor_msgs/LaserScan` ranges: beam `k` at angle
/// `angle_min + k * angle_increment` (radians, sensor frame); ranges in
/// metres. "No return" is a non-finite range, one below `range_min`, or one
/// of `range_max` or more: many drivers and simulators (Stage, CARMEN logs)
/// report a beam that hit nothing as exactly `range_max`, which taken as a
/// return would draw an arc of false surface at the sensor's reach.
#[derive(Clone, Copy, Debug)]
pub struct RangeScan<'a> {
    /// First beam angle (rad).
    pub angle_min: f32,
    /// Angle step (rad); negative for clockwise scans.
    pub angle_increment: f32,
    /// Minimum valid range (m).
    pub range_min: f32,
    /// Maximum range (m): returns are shorter than this; a range of
    /// `range_max` or more is "no return".
    pub range_max: f32,
    /// Ranges (m).
    pub ranges: &'a [f32],
}

/// True when range `d` (m) is a return under [`RangeScan`]'s rule: finite,
/// at least `range_min` and under `range_max` (m).
#[inline]
pub fn is_return(d: f32, range_min: f32, range_max: f32) -> bool {
    d.is_finite() && d >= range_min && d < range_max
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
    /// No candidate site produced a pose (with a prior: none inside it).
    NoMatch {
        /// Candidates examined.
        candidates: usize,
    },
    /// A prior whose numbers make no sense ([`Prior::is_valid`]).
    BadPrior,
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
            LocalizeError::BadPrior => write!(
                f,
                "unusable prior: the centre and heading must be finite, the radius > 0 m (infinite with a polygon), the heading tolerance >= 0 rad"
            ),
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
    /// How loosely the scan pins the position: `ln(spread / unit)`
    /// ([`crate::confidence::spread_feature`], 0.05 m on a 0.05 m map) of
    /// [`crate::refine::position_spread`] (m) at this pose, clamped to
    /// +-[`crate::confidence::SPREAD_MAX`]; the maximum with no pose or a
    /// degenerate fit. A feature of the confidence ([`crate::confidence`]).
    pub spread: f32,
}

/// Most hypotheses a [`Localization`] reports.
pub const MAX_HYPOTHESES: usize = 5;

/// One distinct pose hypothesis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Hypothesis {
    /// Robot pose in the map frame (m, m, rad).
    pub pose: Pose2,
    /// Probability (0..=1) that this pose is right.
    pub confidence: f32,
    /// Its index in [`Localization::candidates`].
    pub candidate: u32,
}

/// The answer for one scan.
#[derive(Clone, Copy, Debug)]
pub struct Localization<'s> {
    /// Robot pose in the map frame (m, m, rad): the chosen candidate's,
    /// or that pose slid along its corridor when it fits better there
    /// ([`refine::slide`]; the candidate's record keeps the matched pose,
    /// and the first hypothesis carries this one).
    pub pose: Pose2,
    /// Sensor pose in the map frame.
    pub sensor_pose: Pose2,
    /// The heading change (rad) over the scanner's sweep that the answer
    /// was fitted with, when a scan taken while turning fitted much better
    /// so ([`Localizer::select`], [`refine::skew_fit`]); the poses are
    /// those at the middle of the sweep. 0 for a rigid fit.
    pub skew: f32,
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
    /// The pose is accepted: with a database's decision model
    /// ([`RefDb::decision`]), `confidence >= threshold`; in a database built
    /// without one, evidence > threshold, few beams through walls, and not
    /// ambiguous.
    pub accepted: bool,
    /// Probability (0..=1) that the pose is right ([`crate::confidence`]):
    /// the database's model, or [`crate::confidence::Decision::DEFAULT`] in
    /// a database without one; after a deeper pass with its odds divided
    /// by [`DEEPER_ODDS`]; at most 0.5 when ambiguous.
    pub confidence: f32,
    /// Covariance of `pose` (row-major 3x3 over x, y, theta; m^2, m rad,
    /// rad^2) from the fit of the scan to the map
    /// ([`crate::refine::covariance`]) plus a floor of one map cell in x
    /// and y and 0.01 rad in heading: how well the geometry pins the pose
    /// locally (large along a corridor), as ROS's `/initialpose` carries
    /// it. `None` when the fit has too few points or is degenerate.
    pub covariance: Option<[f32; 9]>,
    /// The top distinct hypotheses (poses at least
    /// [`crate::select::DISTINCT_DISTANCE`] or
    /// [`crate::select::DISTINCT_HEADING`] apart), the first
    /// `hypothesis_count` entries: the first is `pose`, the alternatives
    /// follow by probability, highest first.
    pub hypotheses: [Hypothesis; MAX_HYPOTHESES],
    /// Entries of `hypotheses` in use (1..=[`MAX_HYPOTHESES`]).
    pub hypothesis_count: usize,
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

impl Localization<'_> {
    /// The distinct hypotheses: the answer, then the alternatives by
    /// probability, highest first.
    pub fn hypotheses(&self) -> &[Hypothesis] {
        &self.hypotheses[..self.hypothesis_count.min(MAX_HYPOTHESES)]
    }
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
        let points = params.prep.max_points as usize;
        Dims {
            beams: max_beams,
            ref_beams: params.sensor.beams as usize,
            points,
            hist: params.coarse.hist_cells().max(params.coarse.win_cells()),
            // The first ranking's candidates and the background pass's,
            // then room for the deeper pass's ranking of N_C max +
            // DEEPER_MAX sites after them.
            cands: 2 * params.coarse.nc_max as usize + BACKGROUND_MAX + DEEPER_MAX,
            tent: points * params.ssm.tentative_k as usize,
            aff: params.ssm.affinity_cap as usize,
        }
    }

    /// Scratch bytes of these arrays: [`carve`] run against a counting arena.
    fn bytes(&self) -> usize {
        let mut counter = Arena::counting();
        // A counting arena hands out empty slices and never fails.
        let _ = carve(self, &mut counter);
        counter.counted
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

/// Hands out typed, aligned slices of a byte buffer, or (counting) only
/// adds up the bytes that would take, with the worst-case alignment padding.
struct Arena<'a> {
    buf: &'a mut [u8],
    counting: bool,
    counted: usize,
}

impl<'a> Arena<'a> {
    fn over(buf: &'a mut [u8]) -> Arena<'a> {
        Arena {
            buf,
            counting: false,
            counted: 0,
        }
    }

    fn counting() -> Arena<'a> {
        Arena {
            buf: &mut [],
            counting: true,
            counted: 0,
        }
    }

    fn take<T: FromBytes + IntoBytes + KnownLayout + Immutable>(
        &mut self,
        n: usize,
    ) -> Option<&'a mut [T]> {
        let (size, align) = (core::mem::size_of::<T>(), core::mem::align_of::<T>());
        if self.counting {
            let bytes = n.saturating_mul(size).saturating_add(align - 1);
            self.counted = self.counted.saturating_add(bytes);
            return Some(Default::default());
        }
        let buf = core::mem::take(&mut self.buf);
        let pad = buf.as_ptr().align_offset(align);
        if pad > buf.len() {
            return None;
        }
        let (_, rest) = buf.split_at_mut(pad);
        let (slice, rest) = <[T]>::mut_from_prefix_with_elems(rest, n).ok()?;
        self.buf = rest;
        Some(slice)
    }
}

/// The localizer's working arrays, carved from the scratch.
struct Bufs<'a> {
    /// The input scan: beam-ordered points (sensor frame, m) and ranges
    /// (m, infinite = no return), counter-clockwise. A beam's direction is
    /// its point over its range ([`Localizer::verify_pose_skewed`]).
    in_pts: &'a mut [[f32; 2]],
    in_rng: &'a mut [f32],
    in_fg: &'a mut [u8],
    /// The prepared query: resampled points and tangents.
    q_pts: &'a mut [[f32; 2]],
    q_tan: &'a mut [[f32; 2]],
    /// A candidate's reference scan: dense points, then prepared points,
    /// tangents (these two also serve the query histogram) and descriptors
    /// (unused when the database stores them: [`RefDb::features`]).
    r_dense: &'a mut [[f32; 2]],
    r_pts: &'a mut [[f32; 2]],
    r_tan: &'a mut [[f32; 2]],
    r_desc: &'a mut [DescBin],
    hist: &'a mut [f32],
    top: &'a mut [Ranked],
    cands: &'a mut [Candidate],
    work: SsmWork<'a>,
}

/// The one description of the scratch layout: [`Dims::bytes`] runs it
/// against a counting arena, [`Localizer::new`] against the buffer.
fn carve<'a>(d: &Dims, ar: &mut Arena<'a>) -> Option<Bufs<'a>> {
    Some(Bufs {
        in_pts: ar.take(d.beams)?,
        in_rng: ar.take(d.beams)?,
        in_fg: ar.take(d.beams)?,
        q_pts: ar.take(d.points)?,
        q_tan: ar.take(d.points)?,
        r_dense: ar.take(d.ref_beams)?,
        r_pts: ar.take(d.points)?,
        r_tan: ar.take(d.points)?,
        r_desc: ar.take(d.points * DESC_LEN)?,
        hist: ar.take(d.hist)?,
        top: ar.take(d.cands)?,
        cands: ar.take(d.cands)?,
        work: SsmWork {
            qdesc: ar.take(d.points * DESC_LEN)?,
            tent: ar.take(d.tent)?,
            ends: ar.take(4 * d.tent)?,
            aff: ar.take(d.aff)?,
            x: ar.take(d.tent)?,
            y: ar.take(d.tent)?,
            order: ar.take(d.tent)?,
            acc: ar.take(d.points)?,
            flags: ar.take(3 * d.points + d.tent)?,
            bins: ssm::BinWork {
                cols: ar.take(d.points * DESC_LEN)?,
                sums: ar.take(d.points)?,
                shared: ar.take(d.points)?,
                dist: ar.take(d.points)?,
            },
        },
    })
}

/// An SSM pose whose evidence is below this share of its maximum
/// (`HIT_SCORE N_P`) is not refined: refinement corrects centimetres and a
/// few degrees, it does not turn a pose that explains almost nothing of the
/// scan into a right one. Chosen on the real Intel and ACES logs (the
/// right candidates' SSM poses fall below 0.1 in 6% of cases, all of them
/// scans whose right pose other sites also found; 53-68% of all candidates
/// do), checked on the CSAIL log held out (docs/performance.md). A crowded
/// scan also refines by [`CROWDED_REFINE_GATE`].
pub const REFINE_GATE: f32 = 0.1;

/// The candidates with the most evidence (at least [`REFINE_GATE`] of
/// its maximum) that the corridor pass ([`Localizer::corridor_pass`])
/// searches around. Chosen on `mapc eval`'s ACES people class (seed 1;
/// 6 candidates: 95.7%, 24: 95.8% before a better fit of a known place
/// was allowed) and reported on the independent simulator's sets and the
/// real logs (docs/results.md, "A corridor search in a crowd").
pub const CORRIDOR_CANDIDATES: usize = 24;

/// An entry of the corridor pass's best-first lists ([`rank::insert`]):
/// a score (a candidate's evidence, or a found pose's gain), the key that
/// breaks ties (lower first: the candidate's index, or the order found),
/// the candidate searched from, and a found pose's robot pose and
/// vicinity.
#[derive(Clone, Copy, Default)]
struct Scoring {
    score: f32,
    key: u32,
    from: usize,
    robot: Pose2,
    v: verify::Vicinity,
}

impl Scoring {
    fn new(score: f32, key: usize, from: usize, robot: Pose2, v: verify::Vicinity) -> Scoring {
        Scoring {
            score,
            key: key as u32,
            from,
            robot,
            v,
        }
    }
}

impl rank::Scored for Scoring {
    fn score(&self) -> f32 {
        self.score
    }
    fn key(&self) -> u32 {
        self.key
    }
}

/// In a crowded scan ([`Localizer::crowded`]) an SSM pose is also refined
/// when its vicinity score M (which does not charge the beams that end short
/// of the map) is at least this share of its maximum. The evidence charges
/// those beams, and in a crowd they are the people: a nearly right SSM pose
/// of a crowded scan fell under [`REFINE_GATE`] and kept its rough pose.
/// Chosen among 0.1, 0.2 and 0.3 on `mapc eval`'s people scans, the
/// independent simulator's seed-5 people and clutter scans and the real
/// logs (0.1 gains as much and costs CSAIL's real queries 11% more
/// instructions on average, 0.3 gains less), reported on other sets
/// (docs/results.md, "Refining crowded scans").
pub const CROWDED_REFINE_GATE: f32 = 0.2;

/// The answer is refitted with the scan's skew (a scanner that turned
/// while it scanned, [`refine::skew_fit`]) only when the skewed fit's
/// robust cost is at most this share of the rigid fit's: the turn must
/// explain at least a fifth of what the rigid fit leaves. First set to a
/// half on noise-free simulated turning scans (cost ratio median
/// 0.13-0.17); with range noise (1 cm + 1% of the range, as real
/// sensors have) the noise stays in both costs and a turn at up to 1
/// rad/s explains less of the total, so a half left right answers of
/// turning scans rejected. 0.8 was chosen among 0.5, 0.7, 0.8 and 1.0 on
/// the independent simulator's turning scans (seed 5) and the real logs
/// (1.0 adds false accepts on ACES), and checked on seed 6, the
/// disturbance suite and the paper's experiments (docs/results.md, "A
/// scan skew for the answer" and "Turning scans with range noise").
pub const SKEW_COST_RATIO: f32 = 0.8;

/// The least number of resampled query points the fine stage works with.
pub const MIN_PREPARED_POINTS: usize = 8;

/// A scan whose sensor reaches less than this share of the database's
/// reference sensor range (`mapc build --range-max`, 30 m by default) gets
/// an exhaustive search ([`Localizer::short_reach`]). Not fitted: half is
/// a round line between the real logs' sensors (30-80 m against 30 m
/// references, never affected) and short-range sensors (4-12 m), for which
/// a database built at their own range is better still (docs/robot.md,
/// "Sensor reach"; docs/results.md, "A sensor of short reach").
pub const SHORT_REACH: f32 = 0.5;

/// True when a sensor reaching `reach` m is short-range for a database
/// whose reference scans reach `reference` m: under [`SHORT_REACH`] of
/// it. The one test behind [`Localizer::short_reach`] (every early stop
/// off) and `mapc localize`'s reference scans made for the scan's reach.
pub fn is_short_reach(reach: f32, reference: f32) -> bool {
    reach < SHORT_REACH * reference
}

/// Most candidates the background pass ([`Localizer::rank_background`])
/// adds to a rejected scan's search. It runs only for scans whose first
/// answer is rejected, which have usually examined every one of the first
/// N_C candidates; this bounds what they cost on top (docs/performance.md).
pub const BACKGROUND_MAX: usize = 16;

/// A scan is *crowded* when at least this share of its returns lie on
/// foreground surfaces ([`crate::prep::foreground_mask`]: people, boxes,
/// chairs in front of farther returns). Its walls are partly hidden, the
/// coarse ranking is least sure, and a crowded scan whose answer is still
/// rejected after the background pass gets the deeper pass
/// ([`Localizer::rank_deeper`]). Chosen on `mapc eval`'s people scans and
/// the real logs (median share of a real scan 3-13%, of a simulated crowd
/// 18-20%), reported on the independent simulator's scans
/// (docs/results.md, "A deeper search in a crowd").
pub const CROWDED_SHARE: f32 = 0.1;

/// Most candidates the deeper pass ([`Localizer::rank_deeper`]) adds: the
/// first ranking's sites after its N_C, half of the default N_C max more.
pub const DEEPER_MAX: usize = 40;

/// After the deeper pass, the odds of every hypothesis's confidence are
/// divided by this: the more candidates are examined, the likelier one of
/// them fits a wrong place well by chance, so a pose found (or lent
/// support) that deep is less likely right than the same fit among the
/// usual candidates. With the default threshold 0.8 an answer then needs
/// about 0.89 from the model to be accepted. Chosen on the independent
/// simulator's seed-5 scans and the real logs (answers the deeper pass
/// added: 90 right, 19 of them under 0.9; 3 wrong, all under 0.85),
/// reported on other sets (docs/results.md, "A deeper search in a crowd").
pub const DEEPER_ODDS: f32 = 2.0;

/// Which sites of a new ranking [`Localizer::rank_more`] may append.
#[derive(Clone, Copy, Debug)]
enum Appended {
    /// Its candidates: the N_C rule applied to it (the background pass).
    Candidates,
    /// Its first N_C max + this many sites, past the N_C rule (the deeper
    /// pass).
    Ranked(usize),
}

/// What [`Localizer::prepare`] found in the scan.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Prepared {
    /// Beams in the scan.
    pub beams: usize,
    /// Beams with a valid return.
    pub valid: usize,
    /// Angular coverage (rad).
    pub fov: f32,
    /// The scan closes a full turn.
    pub wrap: bool,
    /// The sensor's maximum range (m), bound of the verification's beams.
    pub range_max: f32,
    /// Resampled query points.
    pub points: usize,
    /// Beams on foreground surfaces ([`crate::prep::foreground_mask`]).
    pub foreground: usize,
}

/// One query, stage by stage, in the caller's scratch memory:
/// [`Localizer::new`] carves the scratch, [`Localizer::prepare`] loads a
/// scan, [`Localizer::rank`] runs the coarse stage, [`Localizer::examine`]
/// runs the fine stage on one candidate, and [`Localizer::select`] gives the
/// answer. [`localize`] is those calls in order, with the candidate search
/// of [`crate::select::Search`] (exhaustive for a sensor of short reach,
/// [`Localizer::short_reach`]) and, when the answer would be rejected, a
/// second ranking and search over the sites it adds
/// ([`Localizer::rank_background`]); each stage can also be called (and
/// measured) on its own.
pub struct Localizer<'d, 's, D: AsRef<[u8]>> {
    db: &'d RefDb<D>,
    params: &'d Params,
    b: Bufs<'s>,
    dm: DistMap<'d>,
    grid: BitGrid<'d>,
    scan: Prepared,
    window: Option<usize>,
    cells: usize,
    ranked: usize,
    nc: usize,
    /// A deeper pass added candidates: confidences are discounted.
    discount: bool,
    prior: Option<Prior>,
}

impl<'d, 's, D: AsRef<[u8]>> Localizer<'d, 's, D> {
    /// Carves `scratch` for scans of up to `max_beams` beams against `db`.
    ///
    /// A scratch too small gives [`LocalizeError::TooManyBeams`] (with the
    /// beam count it can take) when it can take some scan, else
    /// [`LocalizeError::ScratchTooSmall`].
    pub fn new(
        db: &'d RefDb<D>,
        scratch: &'s mut [u8],
        max_beams: usize,
    ) -> Result<Self, LocalizeError> {
        let params = db.params();
        let dims = Dims::new(params, max_beams);
        let needed = dims.bytes();
        let got = scratch.len();
        if got < needed {
            let cap = max_beams_for(params, got);
            if cap < max_beams && scratch_size(params, 0) <= got {
                return Err(LocalizeError::TooManyBeams {
                    beams: max_beams,
                    capacity: cap,
                });
            }
            return Err(LocalizeError::ScratchTooSmall { needed, got });
        }
        // `needed` includes the worst-case padding of every array, so this
        // cannot fail; if it did, the error still tells the truth.
        let b = carve(&dims, &mut Arena::over(scratch))
            .ok_or(LocalizeError::ScratchTooSmall { needed, got })?;
        Ok(Localizer {
            db,
            params,
            b,
            dm: DistMap::of(db),
            grid: db.grid(),
            scan: Prepared::default(),
            window: None,
            cells: 0,
            ranked: 0,
            nc: 0,
            discount: false,
            prior: None,
        })
    }

    /// Limits the following queries to a region and heading window
    /// ([`crate::prior`]); `None` (the default) considers the whole map.
    /// An invalid prior ([`Prior::is_valid`]) is refused with
    /// [`LocalizeError::BadPrior`].
    pub fn set_prior(&mut self, prior: Option<Prior>) -> Result<(), LocalizeError> {
        if prior.is_some_and(|p| !p.is_valid()) {
            return Err(LocalizeError::BadPrior);
        }
        self.prior = prior;
        Ok(())
    }

    /// Stage 1: loads `scan` (beam-ordered points, counter-clockwise),
    /// resamples it and computes the query's SSM descriptors.
    pub fn prepare(&mut self, scan: &Scan<'_>) -> Result<Prepared, LocalizeError> {
        let b = &mut self.b;
        let params = self.params;
        let n = scan.len();
        let (valid, fov, wrap, range_max) = load_scan(scan, b.in_pts, b.in_rng)?;
        let needed = params.prep.min_valid_points as usize;
        if valid < needed {
            return Err(LocalizeError::NotEnoughPoints { valid, needed });
        }
        let nq = prep::prepare(&b.in_pts[..n], wrap, params, b.q_pts, b.q_tan);
        if nq < MIN_PREPARED_POINTS {
            return Err(LocalizeError::NotEnoughPoints {
                valid: nq,
                needed: MIN_PREPARED_POINTS,
            });
        }
        let foreground = prep::foreground_mask(
            &b.in_pts[..n],
            wrap,
            params.prep.jump_distance,
            coarse::FOREGROUND_WIDTH,
            b.in_fg,
        );
        ssm::descriptors(
            &b.q_pts[..nq],
            &b.q_tan[..nq],
            params.ssm.desc_radius,
            b.work.qdesc,
        );
        self.scan = Prepared {
            beams: n,
            valid,
            fov,
            wrap,
            range_max,
            points: nq,
            foreground,
        };
        self.nc = 0;
        self.discount = false;
        Ok(self.scan)
    }

    /// The coarse histogram of the prepared scan (of a window matching a
    /// partial field of view); returns its cell count.
    pub fn histogram(&mut self) -> usize {
        self.histogram_with(0.0)
    }

    /// [`Localizer::histogram`] without the scan's foreground surfaces at
    /// most `foreground` m across ([`coarse::query_histogram_with`]).
    fn histogram_with(&mut self, foreground: f32) -> usize {
        let b = &mut self.b;
        let s = &self.scan;
        let (window, cells) = coarse::query_histogram_with(
            &b.in_pts[..s.beams],
            s.fov,
            s.wrap,
            foreground,
            self.params,
            b.r_pts,
            b.r_tan,
            b.hist,
        );
        self.window = window;
        self.cells = cells;
        cells
    }

    /// Ranks the sites by the histogram of [`Localizer::histogram`] and
    /// applies the N_C rule; returns N_C, the candidates to examine.
    pub fn rank_sites(&mut self) -> usize {
        let (ranked, nc) = self.rank_into(0, 0);
        self.ranked = ranked;
        self.nc = nc;
        nc
    }

    /// Ranks the sites by the histogram in the scratch into the ranked list
    /// from position `from` (at most N_C max + `extra` of them) and applies
    /// the N_C rule to those; returns (sites ranked, N_C).
    fn rank_into(&mut self, from: usize, extra: usize) -> (usize, usize) {
        let p = self.params;
        let b = &mut self.b;
        let rest = &mut b.top[from..];
        let room = rest.len().min(p.coarse.nc_max as usize + extra);
        let ranked = coarse::rank_sites_where(
            self.db,
            &b.hist[..self.cells],
            self.window,
            &mut rest[..room],
            self.prior.as_ref(),
        );
        let nc = coarse::candidate_count(
            &rest[..ranked],
            p.coarse.nc_min as usize,
            p.coarse.nc_max as usize,
            p.coarse.nc_margin,
        );
        (ranked, nc)
    }

    /// Stage 2, the coarse stage: [`Localizer::histogram`] then
    /// [`Localizer::rank_sites`]. Returns N_C.
    pub fn rank(&mut self) -> usize {
        self.histogram();
        self.rank_sites()
    }

    /// The background pass, stage 2 again for a scan whose answer after the
    /// first `examined` candidates would be rejected: the sites ranked by the
    /// histogram of the scan without its foreground surfaces
    /// ([`coarse::query_histogram_with`], [`coarse::FOREGROUND_WIDTH`]),
    /// the N_C rule applied to them, and those not among the first
    /// `examined` candidates appended after them (at most
    /// [`BACKGROUND_MAX`]). People, boxes and chairs standing in the open
    /// hide the walls behind them and add surfaces no site has, and the
    /// right site can fall out of the first ranking's candidates; without
    /// them it often ranks high again. Pillars and furniture the map has
    /// are foreground too, which is why this is a second chance and not
    /// the ranking (docs/results.md, "A second ranking without the
    /// foreground"). The background histogram replaces the first one in the
    /// scratch. Returns the new N_C (`examined` when nothing is added).
    pub fn rank_background(&mut self, examined: usize) -> usize {
        self.rank_more(
            examined,
            coarse::FOREGROUND_WIDTH,
            Appended::Candidates,
            BACKGROUND_MAX,
        )
    }

    /// True when the prepared scan is crowded: at least [`CROWDED_SHARE`]
    /// of its returns lie on foreground surfaces.
    pub fn crowded(&self) -> bool {
        let s = &self.scan;
        s.foreground as f32 >= CROWDED_SHARE * s.valid as f32 && s.foreground > 0
    }

    /// The deeper pass, for a crowded scan ([`Localizer::crowded`]) whose
    /// answer after the first `examined` candidates (the first ranking's
    /// and the background pass's) would still be rejected: the first
    /// ranking's sites not among the first `examined` (when every
    /// candidate was examined, those it ranks after its N_C), in its order,
    /// at most [`DEEPER_MAX`] of them, are appended. In a
    /// crowd the right site often ranks just past the candidates
    /// (docs/results.md, "A deeper search in a crowd"). The full-scan
    /// histogram replaces the background one in the scratch. Returns the
    /// new N_C (`examined` when nothing is added).
    pub fn rank_deeper(&mut self, examined: usize) -> usize {
        let kept = examined.min(self.nc);
        let nc = self.rank_more(examined, 0.0, Appended::Ranked(DEEPER_MAX), DEEPER_MAX);
        // Confidences are discounted only when there was more to examine.
        self.discount |= nc > kept;
        nc
    }

    /// A hypothesis's confidence `p` as reported: after a deeper pass that
    /// added candidates (it runs only when the answer so far would be
    /// rejected), with its odds divided by [`DEEPER_ODDS`]; else `p`.
    fn discounted(&self, p: f32) -> f32 {
        if !self.discount || !(p < 1.0) {
            return p;
        }
        let odds = p / (1.0 - p) / DEEPER_ODDS;
        odds / (1.0 + odds)
    }

    /// Ranks the sites again, by the histogram without foreground surfaces
    /// at most `foreground` m across (0 keeps them), keeping the first
    /// `examined` candidates and appending at most `most` sites not among
    /// them, taken from the new ranking as `from` says. Returns the new N_C.
    fn rank_more(
        &mut self,
        examined: usize,
        foreground: f32,
        from: Appended,
        most: usize,
    ) -> usize {
        let kept = examined.min(self.nc);
        self.histogram_with(foreground);
        let extra = match from {
            Appended::Candidates => 0,
            Appended::Ranked(extra) => extra,
        };
        let (ranked, nc) = self.rank_into(kept, extra);
        let take = match from {
            Appended::Candidates => nc,
            Appended::Ranked(_) => ranked,
        };
        let (first, rest) = self.b.top.split_at_mut(kept);
        let mut added = 0;
        for j in 0..take {
            let r = rest[j];
            if added == most {
                break;
            }
            if first.iter().any(|f| f.site == r.site) {
                continue;
            }
            rest[added] = r;
            added += 1;
        }
        self.nc = kept + added;
        self.nc
    }

    /// True when the prepared scan's sensor reaches less than
    /// [`SHORT_REACH`] of the reference sensor's range: its scans see much
    /// less of the building than the sites' reference scans, the coarse
    /// stage compares unlike histograms, and a look-alike place often
    /// explains the little the scan sees as well as the right one. The
    /// localizer then examines every candidate (no early stop), so the
    /// ambiguity test sees the look-alikes.
    pub fn short_reach(&self) -> bool {
        is_short_reach(self.scan.range_max, self.params.sensor.range_max)
    }

    /// True when the answer among the first `examined` candidates, the best
    /// `search` found, would be accepted: the decision [`Localizer::select`]
    /// makes, before the answer's skew is fitted.
    pub fn answer_accepted(&self, search: &Search, examined: usize) -> bool {
        let nc = examined.min(self.nc);
        let Some(best) = search.best().filter(|&b| b < nc) else {
            return false;
        };
        let cands = &self.b.cands[..nc];
        let c = &cands[best];
        match self.db.decision() {
            Some(m) => {
                select::accepted_with(c, self.discounted(search.confidence(cands, best)), &m)
            }
            None => select::accepted(
                c,
                select::ambiguous(cands, c, self.params.select.ambiguity_ratio),
            ),
        }
    }

    /// The coarse candidates, best first (N_C of them after
    /// [`Localizer::rank`]; then those [`Localizer::rank_background`]
    /// appended).
    pub fn ranked(&self) -> &[Ranked] {
        &self.b.top[..self.nc]
    }

    /// The candidates recorded by [`Localizer::examine`] and
    /// [`Localizer::skip`], the first `n` (at most N_C).
    pub fn candidates(&self, n: usize) -> &[Candidate] {
        &self.b.cands[..n.min(self.nc)]
    }

    /// SSM of the prepared scan against `site`'s reference scan: the
    /// site's prepared points, tangents and descriptors (stored in the
    /// database, [`RefDb::features`], or else computed here by
    /// [`reference_features`]: the same values either way), then the match.
    pub fn match_site(&mut self, site: usize) -> Option<ssm::SsmResult> {
        let p = self.params;
        let b = &mut self.b;
        let (r_pts, r_tan, r_desc): (&[[f32; 2]], &[[f32; 2]], &[DescBin]) =
            match self.db.features(site) {
                Some(f) => (f.points, f.tangents, f.desc),
                None => {
                    let nr = reference_features(
                        self.db.scan(site),
                        p,
                        b.r_dense,
                        b.r_pts,
                        b.r_tan,
                        b.r_desc,
                    );
                    (&b.r_pts[..nr], &b.r_tan[..nr], &b.r_desc[..nr * DESC_LEN])
                }
            };
        let nq = self.scan.points;
        ssm::match_scans(
            &b.q_pts[..nq],
            &b.q_tan[..nq],
            r_pts,
            r_tan,
            r_desc,
            p,
            &mut b.work,
        )
    }

    /// The sensor pose (map frame) an SSM result against `site` gives.
    pub fn sensor_pose(&self, site: usize, m: &ssm::SsmResult) -> Pose2 {
        let sxy = self.db.site_xy(site);
        Pose2::new(sxy[0], sxy[1], 0.0).compose(&m.pose)
    }

    /// Refinement of a sensor pose against the map's distance field (the
    /// pose itself when the database sets no refinement).
    pub fn refine_pose(&self, sensor: Pose2) -> Pose2 {
        let p = self.params;
        if p.refine.refine_iters == 0 {
            return sensor;
        }
        let pts = &self.b.in_pts[..self.scan.beams];
        refine::refine(
            &self.dm,
            pts,
            sensor,
            p.refine.refine_iters,
            p.refine.refine_max_dist,
        )
        .0
    }

    /// The refined sensor pose and its vicinity, from SSM's pose `sensor`:
    /// the SSM pose is verified first, and refined (then verified again)
    /// only when its evidence is at least [`REFINE_GATE`] of its maximum
    /// (or, in a crowded scan, its vicinity score at least
    /// [`CROWDED_REFINE_GATE`] of it); otherwise it is kept as it is.
    /// Without refinement in the database, the SSM pose and its vicinity.
    pub fn refine_if_promising(&self, sensor: Pose2) -> (Pose2, verify::Vicinity) {
        let (pose, v, _) = self.refine_if_promising_spread(sensor);
        (pose, v)
    }

    /// [`Localizer::refine_if_promising`] and the spread feature of its
    /// pose ([`Localizer::spread_at`]; a refined pose's from the
    /// refinement's last pass, the same value).
    fn refine_if_promising_spread(&self, sensor: Pose2) -> (Pose2, verify::Vicinity, f32) {
        let p = self.params;
        let v = self.verify_pose(&sensor);
        if p.refine.refine_iters == 0 || !self.worth_refining(&v) {
            return (sensor, v, self.spread_at(&sensor));
        }
        let res = self.db.frame().resolution;
        let (refined, spread) = refine::refine_with_spread(
            &self.dm,
            &self.b.in_pts[..self.scan.beams],
            sensor,
            p.refine.refine_iters,
            p.refine.refine_max_dist,
            res * COVARIANCE_FLOOR_CELLS,
        );
        let spread = confidence::spread_feature(spread, res);
        (refined, self.verify_pose(&refined), spread)
    }

    /// True when a pose of vicinity `v` is refined: its evidence is at
    /// least [`REFINE_GATE`] of its maximum or, in a crowded scan
    /// ([`Localizer::crowded`]), its vicinity score M is at least
    /// [`CROWDED_REFINE_GATE`] of its maximum.
    fn worth_refining(&self, v: &verify::Vicinity) -> bool {
        let p = self.params;
        let evidence = v.evidence(p.verify.short_weight, p.verify.occlusion_fit);
        verify::ratio(evidence, v.pairs) >= REFINE_GATE
            || (self.crowded() && v.vicinity_ratio() >= CROWDED_REFINE_GATE)
    }

    /// The vicinity score of a sensor pose (map frame) for the prepared scan.
    pub fn verify_pose(&self, sensor: &Pose2) -> verify::Vicinity {
        self.verify_pose_skewed(sensor, 0.0)
    }

    /// [`Localizer::verify_pose`] for a scan with a skew (rad, see
    /// [`refine::refine_skew`]): beam `k` of `n` points along its direction
    /// turned by `skew * refine::sweep_fraction(k, n)`.
    pub fn verify_pose_skewed(&self, sensor: &Pose2, skew: f32) -> verify::Vicinity {
        let verifier =
            verify::Verifier::with_dist(self.db, &self.grid, self.scan.range_max, self.dm);
        let n = self.scan.beams;
        // A beam with a return points along its point (`in_pts` is the
        // range times the unit direction); the others are skipped.
        let beams = self.b.in_pts[..n]
            .iter()
            .zip(&self.b.in_rng[..n])
            .zip(&self.b.in_fg[..n])
            .enumerate()
            .map(|(k, ((p, &r), &fg))| {
                let u = [p[0] / r, p[1] / r];
                if skew == 0.0 {
                    return (u, r, fg != 0);
                }
                let phi = skew * refine::sweep_fraction(k, n);
                let (s, c) = (libm::sinf(phi), libm::cosf(phi));
                ([c * u[0] - s * u[1], s * u[0] + c * u[1]], r, fg != 0)
            });
        verifier.score_marked(sensor, beams)
    }

    /// Refits the answer, candidate `best`, for a scanner that turned while
    /// it scanned ([`refine::skew_fit`]). The skewed fit is taken only when
    /// the turn explains most of what the rigid fit leaves (its robust cost
    /// at most [`SKEW_COST_RATIO`] of the rigid one) and it has more
    /// evidence; then the candidate becomes that pose (its vicinity,
    /// evidence and spread at the skew), the scan's points are de-skewed in
    /// place for what follows (the covariance), and the skew is returned.
    /// Otherwise nothing changes and it is 0.
    fn fit_skew(&mut self, best: usize) -> f32 {
        let p = self.params;
        let Some(&c) = self.b.cands.get(best) else {
            return 0.0;
        };
        if p.refine.refine_iters == 0 || c.has_pose == 0 {
            return 0.0;
        }
        let n = self.scan.beams;
        let sensor = Pose2::new(c.x, c.y, c.theta).compose(&p.sensor.offset);
        let (fitted, skew, rigid_cost, cost) = refine::skew_fit(
            &self.dm,
            &self.b.in_pts[..n],
            sensor,
            p.refine.refine_iters,
            p.refine.refine_max_dist,
        );
        if skew == 0.0 || !(cost <= SKEW_COST_RATIO * rigid_cost) {
            return 0.0;
        }
        let Some((robot, v)) = self.improves(&c, &fitted, skew) else {
            return 0.0;
        };
        refine::deskew(&mut self.b.in_pts[..n], skew);
        let spread = self.spread_at(&fitted);
        self.b.cands[best] = placed(c, &robot, &v, spread, p);
        skew
    }

    /// The answer's pose slid along its corridor ([`refine::slide`]) when
    /// that fits the scan better both by the refinement's cost and by the
    /// verification's evidence (robot pose, map frame; the scan's `skew`
    /// (rad) as fitted for the answer); `None` keeps the candidate's. Only
    /// the reported pose moves: the candidate's record, its evidence and
    /// the confidence stay those of the matched pose, which the model was
    /// fitted on, so the decision is the same.
    fn slide(&self, best: usize, skew: f32) -> Option<Pose2> {
        let p = self.params;
        let c = self.b.cands.get(best).filter(|c| c.has_pose != 0)?;
        if p.refine.refine_iters == 0 {
            return None;
        }
        let sensor = Pose2::new(c.x, c.y, c.theta).compose(&p.sensor.offset);
        let slid = refine::slide(
            &self.dm,
            &self.b.in_pts[..self.scan.beams],
            sensor,
            p.refine.refine_iters,
            p.refine.refine_max_dist,
        )?;
        // The cost counts points near any surface; the evidence also
        // charges beams that end short of the map or pass through it, so
        // clutter that happens to lie on a wall at the slid pose does not
        // carry it.
        self.improves(c, &slid, skew).map(|(robot, _)| robot)
    }

    /// Whether another sensor pose (map frame) for candidate `c`, the scan
    /// taken with `skew` (rad), is better than `c`'s own: inside the prior
    /// and with more evidence. Then its robot pose and its vicinity.
    fn improves(
        &self,
        c: &Candidate,
        sensor: &Pose2,
        skew: f32,
    ) -> Option<(Pose2, verify::Vicinity)> {
        let p = self.params;
        let robot = sensor.compose(&p.sensor.offset.inverse());
        if self.prior.is_some_and(|pr| !pr.allows(&robot)) {
            return None;
        }
        let v = self.verify_pose_skewed(sensor, skew);
        (v.evidence(p.verify.short_weight, p.verify.occlusion_fit) > c.evidence)
            .then_some((robot, v))
    }

    /// The confidence's spread feature ([`Candidate::spread`]) of a sensor
    /// pose.
    pub fn spread_at(&self, sensor: &Pose2) -> f32 {
        let p = self.params;
        let res = self.db.frame().resolution;
        let spread = refine::position_spread(
            &self.dm,
            &self.b.in_pts[..self.scan.beams],
            sensor,
            p.refine.refine_max_dist,
            res * COVARIANCE_FLOOR_CELLS,
        );
        confidence::spread_feature(spread, res)
    }

    /// Stage 3, the fine stage on coarse candidate `c`: SSM against its
    /// site, verification, and refinement of a promising pose
    /// ([`Localizer::refine_if_promising`]). Records and returns the candidate
    /// (`has_pose` 0 when SSM found no pose); `None` when `c` is not below
    /// N_C of the last [`Localizer::rank`].
    pub fn examine(&mut self, c: usize) -> Option<Candidate> {
        let r = *self.b.top[..self.nc].get(c)?;
        let site = r.site as usize;
        let mut cand = unexamined(c, &r);
        if let Some(m) = self.match_site(site) {
            let p = self.params;
            let (sensor, v, spread) = self.refine_if_promising_spread(self.sensor_pose(site, &m));
            let robot = sensor.compose(&p.sensor.offset.inverse());
            let matched = Candidate {
                match_score: m.score,
                matched: m.matched,
                inliers: m.inliers,
                has_pose: 1,
                ..cand
            };
            cand = placed(matched, &robot, &v, spread, p);
            // A pose the prior rules out is no answer.
            if self.prior.is_some_and(|pr| !pr.allows(&robot)) {
                cand.has_pose = 0;
            }
        }
        self.b.cands[c] = cand;
        Some(cand)
    }

    /// The corridor pass, for a crowded scan ([`Localizer::crowded`])
    /// whose answer after the first `examined` candidates would still be
    /// rejected: around each of the [`CORRIDOR_CANDIDATES`] candidates
    /// with the most evidence (at least [`REFINE_GATE`] of its maximum),
    /// [`refine::corridor_search`] looks along the candidate's corridor and
    /// turned end for end. The poses found that have more evidence than
    /// their candidate are placed in order of their gain over the place
    /// they land on, each by [`select::placement`] among the candidates as
    /// the ones before it left them: as a new candidate appended after the
    /// others (a copy of the candidate it was found from, with the new
    /// pose) when it is a new place, as the better fit of the candidate
    /// already there, or not at all. No other candidate changes, so no
    /// rival is merged away and no support is lent. In a crowd the door frames
    /// and ends that place a scan along a corridor are hidden, and SSM
    /// lands metres along it or backwards from every site near the right
    /// pose, beyond the refinement's reach (docs/results.md, "A corridor
    /// search in a crowd"). Returns the number of candidates now examined
    /// (more than `examined` when some were appended).
    pub fn corridor_pass(&mut self, examined: usize) -> usize {
        let p = self.params;
        let nc = examined.min(self.nc);
        if p.refine.refine_iters == 0 || nc >= self.b.cands.len() {
            return examined;
        }
        // The candidates to search around, most evidence first (the
        // earlier candidate on a tie).
        let mut top = [Scoring::default(); CORRIDOR_CANDIDATES];
        let mut count = 0;
        for (i, c) in self.b.cands[..nc].iter().enumerate() {
            if c.has_pose != 0 && verify::ratio(c.evidence, c.pairs) >= REFINE_GATE {
                let pick = Scoring::new(c.evidence, i, i, Pose2::default(), Default::default());
                rank::insert(&mut top, &mut count, pick);
            }
        }
        let n = self.scan.beams;
        // Every pose found with more evidence than its candidate, with its
        // gain over the place it lands on, greatest first (the earlier
        // found on a tie); at most two per candidate.
        let mut all = [Scoring::default(); 2 * CORRIDOR_CANDIDATES];
        let mut found = 0;
        for &Scoring { from: i, .. } in &top[..count] {
            let c = self.b.cands[i];
            let sensor = Pose2::new(c.x, c.y, c.theta).compose(&p.sensor.offset);
            let poses = refine::corridor_search(
                &self.dm,
                &self.b.in_pts[..n],
                sensor,
                p.refine.refine_iters,
                p.refine.refine_max_dist,
            );
            for q in poses.into_iter().flatten() {
                let Some((robot, v)) = self.improves(&c, &q, 0.0) else {
                    continue;
                };
                let posed = self.posed(i, &robot, &v);
                let base = match select::placement(&self.b.cands[..nc], &posed) {
                    Placement::Known => continue,
                    Placement::New => c.evidence,
                    Placement::Refits(j) => self.b.cands[j].evidence,
                };
                let pose = Scoring::new(posed.evidence - base, found, i, robot, v);
                rank::insert(&mut all, &mut found, pose);
            }
        }
        // Each placed among the candidates as the ones before it left them.
        let mut total = nc;
        for &Scoring {
            from: i, robot, v, ..
        } in &all[..found]
        {
            let (slot, record) =
                match select::placement(&self.b.cands[..total], &self.posed(i, &robot, &v)) {
                    Placement::Known => continue,
                    Placement::Refits(j) => (j, j),
                    Placement::New if total < self.b.cands.len() => (total, i),
                    Placement::New => break,
                };
            let spread = self.spread_at(&robot.compose(&p.sensor.offset));
            self.b.cands[slot] = placed(self.b.cands[record], &robot, &v, spread, p);
            if slot == total {
                self.b.top[total] = self.b.top[i];
                total += 1;
            }
        }
        if total == nc {
            return examined;
        }
        self.nc = total;
        total
    }

    /// Candidate `i`'s record at another robot pose with vicinity `v`: the
    /// pose and its evidence, for [`select::placement`].
    fn posed(&self, i: usize, robot: &Pose2, v: &verify::Vicinity) -> Candidate {
        let p = self.params;
        Candidate {
            x: robot.x,
            y: robot.y,
            theta: robot.theta,
            evidence: v.evidence(p.verify.short_weight, p.verify.occlusion_fit),
            ..self.b.cands[i]
        }
    }

    /// Records coarse candidate `c` (below N_C; others are ignored) as not
    /// examined (no pose).
    pub fn skip(&mut self, c: usize) {
        if c < self.nc {
            self.b.cands[c] = unexamined(c, &self.b.top[c]);
        }
    }

    /// Stage 4: the answer among the first `examined` candidates, with the
    /// best one `search` found, its ambiguity and acceptance
    /// ([`crate::select`]).
    pub fn select(
        mut self,
        search: &Search,
        examined: usize,
    ) -> Result<Localization<'s>, LocalizeError> {
        let nc = examined.min(self.nc);
        let best = search
            .best()
            .filter(|&b| b < nc)
            .ok_or(LocalizeError::NoMatch { candidates: nc })?;
        // The skew is fitted for the answer alone, so an answer another
        // (rigid) pose makes ambiguous stays as it is.
        let skew = if select::ambiguous(
            &self.b.cands[..nc],
            &self.b.cands[best],
            self.params.select.ambiguity_ratio,
        ) {
            0.0
        } else {
            self.fit_skew(best)
        };
        let slid = self.slide(best, skew);
        let cands: &'s [Candidate] = &self.b.cands[..nc];
        let c = cands[best];
        let pose = slid.unwrap_or(Pose2::new(c.x, c.y, c.theta));
        let p = self.params;
        let ambiguous = select::ambiguous(cands, &c, p.select.ambiguity_ratio);
        let model = self.db.decision();
        let decision = model.unwrap_or(Decision::DEFAULT);
        let mut hypotheses = [Hypothesis::default(); MAX_HYPOTHESES];
        let hypothesis_count =
            select::hypotheses(cands, best, p.select.selection, &decision, &mut hypotheses);
        for h in hypotheses.iter_mut().take(hypothesis_count) {
            h.confidence = self.discounted(h.confidence);
        }
        let confidence = select::capped_confidence(hypotheses[0].confidence, ambiguous);
        hypotheses[0].confidence = confidence;
        if hypothesis_count > 0 {
            hypotheses[0].pose = pose;
        }
        let accepted = match model {
            Some(m) => select::accepted_with(&c, confidence, &m),
            None => select::accepted(&c, ambiguous),
        };
        let sensor_pose = pose.compose(&p.sensor.offset);
        let covariance = refine::covariance(
            &self.dm,
            &self.b.in_pts[..self.scan.beams],
            &sensor_pose,
            p.refine.refine_max_dist,
            self.db.frame().resolution * COVARIANCE_FLOOR_CELLS,
        )
        .map(|cov| {
            let mut c = sensor_to_robot_covariance(&cov, &sensor_pose, &pose);
            let res = self.db.frame().resolution;
            c[0] += res * res;
            c[4] += res * res;
            c[8] += COVARIANCE_HEADING_FLOOR * COVARIANCE_HEADING_FLOOR;
            c
        });
        Ok(Localization {
            pose,
            sensor_pose,
            skew,
            site: c.site,
            coarse_rank: c.rank,
            gamma: c.gamma,
            match_score: c.match_score,
            inliers: c.inliers,
            vicinity: c.vicinity,
            vicinity_threshold: c.vicinity_threshold,
            evidence: c.evidence,
            accepted,
            confidence,
            covariance,
            hypotheses,
            hypothesis_count,
            ambiguous,
            valid_points: self.scan.valid as u32,
            short_beams: c.short_beams,
            long_beams: c.long_beams,
            through_beams: c.through_beams,
            free_space_ok: c.free_space_ok != 0,
            candidates: cands,
        })
    }
}

/// Floor of the covariance's noise level: the standard deviation of a
/// surface's position within its cell, `1 / sqrt(12)` of a cell (uniform).
const COVARIANCE_FLOOR_CELLS: f32 = 0.288_675_13;

/// Heading standard deviation (rad) added to the covariance, with one map
/// cell in x and y: the fit's curvature alone treats the beams' errors as
/// independent, which real ones (a wall a few centimetres off in a map from
/// another run) are not, so it is a lower bound; the map's own resolution
/// is the floor of what it can tell.
const COVARIANCE_HEADING_FLOOR: f32 = 0.01;

/// The covariance of the robot pose `robot = sensor * offset^-1` from the
/// sensor pose's: `J C J^T`, with `J` the derivative of the composition
/// with respect to the sensor pose.
fn sensor_to_robot_covariance(c: &[f32; 9], sensor: &Pose2, robot: &Pose2) -> [f32; 9] {
    let j = [
        [1.0, 0.0, -(robot.y - sensor.y)],
        [0.0, 1.0, robot.x - sensor.x],
        [0.0, 0.0, 1.0],
    ];
    let mut out = [0.0f32; 9];
    for r in 0..3 {
        for k in 0..3 {
            let mut v = 0.0;
            for a in 0..3 {
                for b in 0..3 {
                    v += j[r][a] * c[a * 3 + b] * j[k][b];
                }
            }
            out[r * 3 + k] = v;
        }
    }
    out
}

/// `c` placed at robot pose `robot` (map frame), with the vicinity `v` of
/// its sensor pose and the spread feature `spread`: its pose, vicinity and
/// evidence fields set from them, the others (site, rank, SSM figures,
/// `has_pose`) kept. The one record of a verified pose, for the fine stage
/// and the skew refit.
fn placed(c: Candidate, robot: &Pose2, v: &verify::Vicinity, spread: f32, p: &Params) -> Candidate {
    Candidate {
        x: robot.x,
        y: robot.y,
        theta: robot.theta,
        vicinity: v.score,
        vicinity_threshold: v.threshold,
        short_beams: v.short,
        long_beams: v.long,
        pairs: v.pairs,
        through_beams: v.through,
        free_space_ok: v.free_space_ok(p.verify.through_max) as u32,
        evidence: v.evidence(p.verify.short_weight, p.verify.occlusion_fit),
        spread,
        ..c
    }
}

/// A candidate record before (or without) the fine stage.
fn unexamined(c: usize, r: &Ranked) -> Candidate {
    Candidate {
        site: r.site,
        rank: c as u32,
        gamma: r.gamma,
        spread: confidence::SPREAD_MAX,
        ..Candidate::default()
    }
}

/// The reference side of SSM for a site whose reference scan has `ranges`
/// (m, one per reference beam, `INFINITY` for no return): the ranges as
/// sensor-frame points (into `dense`, one per beam), the prepared points
/// and unit tangents ([`prep::prepare`], into `pts` and `tan`) and their
/// descriptors ([`ssm::descriptors`], [`DESC_LEN`] bins per point into
/// `desc`). Returns the number of prepared points, at most
/// `params.prep.max_points` and the room in `pts`, `tan` and `desc`.
///
/// The one computation of these: the localizer runs it per candidate when
/// the database does not store them, and `mapc build` runs it per site to
/// store them in the features section ([`RefDb::features`]).
pub fn reference_features(
    ranges: &[f32],
    params: &Params,
    dense: &mut [[f32; 2]],
    pts: &mut [[f32; 2]],
    tan: &mut [[f32; 2]],
    desc: &mut [DescBin],
) -> usize {
    let s = &params.sensor;
    let n = prep::reference_points(ranges, params, dense);
    let wrap = prep::covers_full_turn(s.angle_increment, s.beams as usize);
    let room = pts.len().min(tan.len()).min(desc.len() / DESC_LEN);
    let nr = prep::prepare(
        &dense[..n],
        wrap,
        params,
        &mut pts[..room],
        &mut tan[..room],
    );
    ssm::descriptors(&pts[..nr], &tan[..nr], params.ssm.desc_radius, desc);
    nr
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
    localize_with_prior(db, scan, scratch, None)
}

/// As [`localize`], with an optional [`Prior`]: sites outside its region
/// are not ranked and poses outside its region or heading window are not
/// answers. `None` is [`localize`].
pub fn localize_with_prior<'s, D: AsRef<[u8]>>(
    db: &RefDb<D>,
    scan: &Scan<'_>,
    scratch: &'s mut [u8],
    prior: Option<Prior>,
) -> Result<Localization<'s>, LocalizeError> {
    let mut loc = Localizer::new(db, scratch, scan.len())?;
    loc.set_prior(prior)?;
    loc.prepare(scan)?;
    let nc = loc.rank();
    let decision = db.decision().unwrap_or(Decision::DEFAULT);
    let mut search = Search::new(db.params()).with_decision(decision);
    if loc.short_reach() {
        search = search.exhaustive();
    }
    let mut examined = search_candidates(&mut loc, &mut search, 0, nc);
    if !loc.answer_accepted(&search, examined) {
        // A second chance for a scan with things in front of the walls.
        let total = loc.rank_background(examined);
        search.search_on();
        examined = search_candidates(&mut loc, &mut search, examined, total);
    }
    if loc.crowded() && !loc.answer_accepted(&search, examined) {
        // A crowd hides enough of the walls that the right site can rank
        // just past the candidates: look further down the first ranking.
        let total = loc.rank_deeper(examined);
        search.search_on();
        examined = search_candidates(&mut loc, &mut search, examined, total);
    }
    if loc.crowded() && !loc.answer_accepted(&search, examined) {
        // In a crowd the matches of a corridor land along it or backwards
        // from every site: search the corridors of the best candidates.
        examined = loc.corridor_pass(examined);
        search.reselect(loc.candidates(examined));
    }
    loc.select(&search, examined)
}

/// The fine stage over candidates `from..to` with `search` deciding which
/// to examine; returns how many candidates, counted from 0, were examined
/// or skipped before it stopped (`to` when it did not).
fn search_candidates<D: AsRef<[u8]>>(
    loc: &mut Localizer<'_, '_, D>,
    search: &mut Search,
    from: usize,
    to: usize,
) -> usize {
    for c in from..to {
        let r = loc.ranked()[c];
        let site_xy = loc.db.site_xy(r.site as usize);
        match search.next(r.gamma, site_xy, loc.candidates(c)) {
            Next::Stop => return c,
            Next::Skip => loc.skip(c),
            Next::Examine => {
                if loc.examine(c).is_some_and(|e| e.has_pose != 0) {
                    search.record(loc.candidates(c + 1), r.gamma);
                }
            }
        }
    }
    to
}

/// Fills dense points and ranges in counter-clockwise order.
/// Returns (valid count, angular coverage in rad, closes a full turn, range_max).
fn load_scan(
    scan: &Scan<'_>,
    pts: &mut [[f32; 2]],
    rng: &mut [f32],
) -> Result<(usize, f32, bool, f32), LocalizeError> {
    use core::f32::consts::PI;
    let n = scan.len();
    if n > pts.len() || n > rng.len() {
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
                let ok = is_return(d, r.range_min, r.range_max) && d > 0.0;
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
                    rng[k] = r;
                    valid += 1;
                } else {
                    pts[k] = [f32::NAN, f32::NAN];
                    rng[k] = f32::INFINITY;
                }
            }
            Ok((valid, turn.min(2.0 * PI), turn > 2.0 * PI * 0.9, *range_max))
        }
    }
}
