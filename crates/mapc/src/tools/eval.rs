//! `mapc eval` as a library: the paper's experiments on simulated scans.
//!
//! - **E4** (paper Fig. 11-12): seeded random poses in free space with a
//!   clearance, virtual scans at the true poses, localized with no initial
//!   pose. Variants: `static` (exact ranges), `dynamic` (range noise and
//!   random short returns, through the ranges input), `dynamic-swap` (range
//!   noise and the paper's x-y swap outliers, through the points input).
//! - **E5** (Fig. 16): coarse rank of the correct site (the nearest site in
//!   line of sight of the true pose) among all sites.
//! - **E1** (Table 1): scan-to-scan SSM accuracy: a scan, a disturbed copy
//!   (noise, x-y swap outliers) moved by a random transform, matched.
//! - **E2** (Fig. 6): matching rate against deformation noise and outliers.
//! - **Wrong map**: scans simulated on another map, localized against this
//!   database: how many are (wrongly) accepted.
//!
//! Every random choice comes from `Rng::stream(seed, index)`, so results do
//! not depend on the thread count.

use rayon::prelude::*;
use refloc::raycast::{cast, BitGrid};
use refloc::ssm::{self, SsmWork, DESC_LEN};
use refloc::{prep, scratch_size, MapFrame, Pose2, RangeScan, RefDb, Scan};
use serde::{Deserialize, Serialize};

use crate::compiler::connectivity::flood4;
use crate::compiler::rng::Rng;
use crate::compiler::sim::{self, Lidar, Noise};

/// A position error below this counts as correct (m).
pub const CORRECT_POS: f64 = 0.3;
/// A heading error below this counts as correct (rad): 5 degrees.
pub const CORRECT_THETA: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// Position error (m) and absolute heading error (rad) of the estimate
/// `est` (map frame) against the pose `truth` (x m, y m, theta rad).
pub fn pose_error(est: &Pose2, truth: [f64; 3]) -> (f64, f64) {
    let e = ((est.x as f64 - truth[0]).powi(2) + (est.y as f64 - truth[1]).powi(2)).sqrt();
    let et = refloc::wrap_angle(est.theta - truth[2] as f32).abs() as f64;
    (e, et)
}

/// True when `est` is within [`CORRECT_POS`] and [`CORRECT_THETA`] of
/// `truth` (see [`pose_error`]).
pub fn within_tolerance(est: &Pose2, truth: [f64; 3]) -> bool {
    let (e, et) = pose_error(est, truth);
    e < CORRECT_POS && et < CORRECT_THETA
}

/// Simulated-scan options.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ScanSpec {
    /// Beams.
    pub beams: usize,
    /// Field of view (rad).
    pub fov: f32,
    /// Maximum range (m).
    pub range_max: f32,
    /// Range noise sigma (m).
    pub noise: f32,
    /// Random short returns per scan.
    pub short_outliers: usize,
    /// x-y swap outliers per scan (sent as points).
    pub swap_outliers: usize,
    /// A disturbance of the world or the scan ([`crate::tools::disturb`]) applied
    /// before the noise and outliers above.
    pub disturbance: Option<crate::tools::disturb::Class>,
    /// A prior for every query (`refloc::Prior`): a region of this radius
    /// (m; 0: none) whose centre is the true position moved by a seeded
    /// random offset of up to half the radius ...
    #[serde(default)]
    pub prior_radius: f32,
    /// ... and a heading window of +- this (rad; 0: none) around the true
    /// heading moved by up to half of it.
    #[serde(default)]
    pub prior_heading_tol: f32,
}

impl ScanSpec {
    /// The lidar geometry.
    pub fn lidar(&self) -> Lidar {
        Lidar::new(self.beams, self.fov, self.range_max)
    }
}

/// One localized pose.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Trial {
    /// True robot pose (m, m, rad).
    pub truth: [f64; 3],
    /// Estimated pose, when any.
    pub est: Option<[f64; 3]>,
    /// Accepted by verification.
    pub accepted: bool,
    /// Position error (m), when estimated.
    pub err_pos: Option<f64>,
    /// Heading error (rad), when estimated.
    pub err_theta: Option<f64>,
    /// Coarse rank of the correct site (None: no site in line of sight).
    pub correct_rank: Option<usize>,
    /// Candidates examined by the fine stage (fewer than `nc` after an early stop).
    pub candidates: usize,
    /// N_C: the coarse stage's candidate count for this scan.
    pub nc: usize,
    /// Query time (microseconds).
    pub time_us: u64,
    /// Vicinity score as a share of its maximum, `M / (4.5 N_P)`.
    pub vicinity_ratio: f64,
    /// Share of the beams longer than the map allows at the estimate.
    pub long_ratio: f64,
    /// Error message when localization returned an error.
    pub error: Option<String>,
}

impl Trial {
    /// Accepted with position error < 0.3 m and heading error < 5 degrees.
    pub fn correct(&self) -> bool {
        self.accepted
            && matches!((self.err_pos, self.err_theta), (Some(p), Some(t)) if p < CORRECT_POS && t < CORRECT_THETA)
    }
}

/// Statistics of a set of trials.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Summary {
    /// Trials.
    pub n: usize,
    /// Accepted.
    pub accepted: usize,
    /// Accepted and correct.
    pub correct: usize,
    /// Accepted but wrong.
    pub false_accepts: usize,
    /// correct / n.
    pub success_rate: f64,
    /// false_accepts / n.
    pub false_accept_rate: f64,
    /// Mean |x| error over correct trials (m).
    pub mean_abs_x: f64,
    /// Mean |y| error (m).
    pub mean_abs_y: f64,
    /// Mean |theta| error (rad).
    pub mean_abs_theta: f64,
    /// Max |x|, |y| (m), |theta| (rad) over correct trials.
    pub max_abs: [f64; 3],
    /// Min |x|, |y| (m), |theta| (rad) over correct trials.
    pub min_abs: [f64; 3],
    /// Median position error over correct trials (m).
    pub median_pos: f64,
    /// Median query time (us).
    pub median_time_us: f64,
    /// Mean query time (us).
    pub mean_time_us: f64,
    /// Share of trials (with a site in sight) whose correct site was among the N_C coarse candidates.
    pub correct_site_recall: f64,
}

/// Summarizes trials.
pub fn summarize(trials: &[Trial]) -> Summary {
    let n = trials.len();
    let correct: Vec<&Trial> = trials.iter().filter(|t| t.correct()).collect();
    let accepted = trials.iter().filter(|t| t.accepted).count();
    let mut s = Summary {
        n,
        accepted,
        correct: correct.len(),
        false_accepts: accepted - correct.len(),
        ..Summary::default()
    };
    if n == 0 {
        return s;
    }
    s.success_rate = correct.len() as f64 / n as f64;
    s.false_accept_rate = s.false_accepts as f64 / n as f64;
    let errs: Vec<[f64; 3]> = correct
        .iter()
        .filter_map(|t| {
            let e = t.est?;
            Some([
                (e[0] - t.truth[0]).abs(),
                (e[1] - t.truth[1]).abs(),
                t.err_theta?,
            ])
        })
        .collect();
    if !errs.is_empty() {
        let m = errs.len() as f64;
        s.mean_abs_x = errs.iter().map(|e| e[0]).sum::<f64>() / m;
        s.mean_abs_y = errs.iter().map(|e| e[1]).sum::<f64>() / m;
        s.mean_abs_theta = errs.iter().map(|e| e[2]).sum::<f64>() / m;
        for k in 0..3 {
            s.max_abs[k] = errs.iter().map(|e| e[k]).fold(0.0, f64::max);
            s.min_abs[k] = errs.iter().map(|e| e[k]).fold(f64::INFINITY, f64::min);
        }
        s.median_pos = median(correct.iter().filter_map(|t| t.err_pos).collect());
    }
    let times: Vec<f64> = trials.iter().map(|t| t.time_us as f64).collect();
    s.median_time_us = median(times.clone());
    s.mean_time_us = times.iter().sum::<f64>() / n as f64;
    let with_site = trials
        .iter()
        .filter(|t| t.correct_rank.is_some())
        .count()
        .max(1);
    s.correct_site_recall = trials
        .iter()
        .filter(|t| matches!(t.correct_rank, Some(r) if r < t.nc))
        .count() as f64
        / with_site as f64;
    s
}

/// Median of a list (0 when empty).
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Free-space poses for sampling: cells with clearance >= `clearance` (m),
/// read from the database's distance map.
pub fn sample_poses<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    n: usize,
    clearance: f32,
    seed: u64,
) -> Vec<Pose2> {
    let (w, h) = db.grid_size();
    let frame = db.frame();
    let dist = db.dist();
    let grid = db.grid();
    // Distance to surface + half a cell = distance to obstacle cell centre.
    let ok = |i: usize| {
        let d = refloc::format::dist_cells(dist.get(i).copied().unwrap_or(0)) * frame.resolution;
        let (cx, cy) = ((i % w as usize) as u32, (i / w as usize) as u32);
        d + 0.5 * frame.resolution >= clearance
            && !refloc::raycast::Occupancy::blocked(&grid, cx, cy)
    };
    sample_poses_where(w, h, &frame, ok, n, seed)
}

/// Poses uniformly over the largest 4-connected region of cells for which
/// `ok(index)` holds, headings uniform; pose `k` uses `Rng::stream(seed, k)`.
pub fn sample_poses_where(
    w: u32,
    h: u32,
    frame: &MapFrame,
    ok: impl Fn(usize) -> bool,
    n: usize,
    seed: u64,
) -> Vec<Pose2> {
    let cells: Vec<u32> = (0..(w as usize * h as usize))
        .filter(|&i| ok(i))
        .map(|i| i as u32)
        .collect();
    // Keep the largest 4-connected region of such cells: the building, not
    // isolated pockets of free space outside it.
    let cells = largest_region(&cells, w, h);
    if cells.is_empty() {
        return Vec::new();
    }
    (0..n)
        .map(|k| {
            let mut r = Rng::stream(seed, k as u64);
            let c = cells[r.below(cells.len() as u64) as usize] as usize;
            let (cx, cy) = (c % w as usize, c / w as usize);
            let uv = [
                cx as f32 + r.uniform() as f32,
                cy as f32 + r.uniform() as f32,
            ];
            let p = frame.to_map(uv);
            Pose2::new(
                p[0],
                p[1],
                r.range(-std::f64::consts::PI, std::f64::consts::PI) as f32,
            )
        })
        .collect()
}

fn largest_region(cells: &[u32], w: u32, h: u32) -> Vec<u32> {
    let n = w as usize * h as usize;
    let mut label = vec![0u32; n];
    for &c in cells {
        label[c as usize] = u32::MAX;
    }
    let mut best = (0u32, 0usize);
    let mut next = 1u32;
    let mut stack: Vec<u32> = Vec::new();
    for &c in cells {
        if label[c as usize] != u32::MAX {
            continue;
        }
        let mut size = 0;
        label[c as usize] = next;
        flood4(
            w as usize,
            h as usize,
            c as usize,
            &mut stack,
            |j| {
                let take = label[j] == u32::MAX;
                if take {
                    label[j] = next;
                }
                take
            },
            |_| size += 1,
        );
        if size > best.1 {
            best = (next, size);
        }
        next += 1;
    }
    cells
        .iter()
        .copied()
        .filter(|&c| label[c as usize] == best.0)
        .collect()
}

/// The correct site for a true sensor position: the nearest site with a
/// clear line of sight.
pub fn correct_site<D: AsRef<[u8]>>(db: &RefDb<D>, p: [f32; 2]) -> Option<usize> {
    let frame = db.frame();
    let grid = db.grid();
    let uv = frame.to_cells(p);
    let mut best: Option<(usize, f32)> = None;
    for s in 0..db.site_count() {
        let q = db.site_xy(s);
        let d = ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)).sqrt();
        if best.is_some_and(|b| d >= b.1) {
            continue;
        }
        let ang = frame.angle_to_cells((q[1] - p[1]).atan2(q[0] - p[0]));
        if cast(&grid, uv[0], uv[1], ang, d / frame.resolution).is_none() {
            best = Some((s, d));
        }
    }
    best.map(|b| b.0)
}

/// The coarse stage of a query exactly as the localizer runs it: every
/// site's score (see `refloc::coarse::site_score`), from beam-ordered dense
/// points covering `fov` radians.
pub fn coarse_scores<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    dense: &[[f32; 2]],
    fov: f32,
    wrap: bool,
) -> Vec<f32> {
    let params = db.params();
    let p = params.prep.max_points as usize;
    let (mut qp, mut qt) = (vec![[0f32; 2]; p], vec![[0f32; 2]; p]);
    let mut h = vec![0f32; params.coarse.hist_cells().max(params.coarse.win_cells())];
    let (window, cells) =
        refloc::coarse::query_histogram(dense, fov, wrap, params, &mut qp, &mut qt, &mut h);
    (0..db.site_count())
        .map(|s| refloc::coarse::site_score(db, &h[..cells], window, s))
        .collect()
}

/// Coarse rank (0 = best; ties by lower index) of `site` given all scores.
pub fn coarse_rank(scores: &[f32], site: usize) -> usize {
    let g = scores.get(site).copied().unwrap_or(f32::NEG_INFINITY);
    scores
        .iter()
        .enumerate()
        .filter(|&(s, &v)| v > g || (v == g && s < site))
        .count()
}

/// N_C for the given scores, by the database's rule.
pub fn coarse_nc<D: AsRef<[u8]>>(db: &RefDb<D>, scores: &[f32]) -> usize {
    let p = db.params();
    let mut top = vec![refloc::coarse::Ranked::default(); p.coarse.nc_max as usize];
    let n = refloc::coarse::rank_top_scores(scores.iter().copied(), &mut top);
    refloc::coarse::candidate_count(
        &top[..n],
        p.coarse.nc_min as usize,
        p.coarse.nc_max as usize,
        p.coarse.nc_margin,
    )
}

/// A simulated scan at `truth` (robot pose) seen through `db`'s grid (or
/// another map's, for the wrong-map test).
pub struct SimScan {
    /// Ranges (m).
    pub ranges: Vec<f32>,
    /// Points (sensor frame), when the spec asks for x-y swap outliers.
    pub points: Option<Vec<[f32; 2]>>,
}

/// Simulates a scan.
pub fn simulate(
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    sensor: &Pose2,
    spec: &ScanSpec,
    rng: &mut Rng,
) -> SimScan {
    let lidar = spec.lidar();
    let mut ranges = match spec.disturbance {
        Some(class) => crate::tools::disturb::scan(class, grid, frame, sensor, &lidar, rng),
        None => sim::virtual_scan(grid, frame, sensor, &lidar),
    };
    sim::add_noise(
        &mut ranges,
        &lidar,
        &Noise {
            range_sigma: spec.noise,
            short_outliers: spec.short_outliers,
        },
        rng,
    );
    let points = if spec.swap_outliers > 0 {
        let mut pts: Vec<[f32; 2]> = ranges
            .iter()
            .enumerate()
            .map(|(k, &r)| {
                if r.is_finite() {
                    let a = lidar.angle(k);
                    [r * a.cos(), r * a.sin()]
                } else {
                    [f32::NAN, f32::NAN]
                }
            })
            .collect();
        sim::swap_outliers(&mut pts, spec.swap_outliers, rng);
        Some(pts)
    } else {
        None
    };
    SimScan { ranges, points }
}

/// The random stream of E4 pose `k`'s scan (noise and outliers): with
/// [`simulate`] at the pose's sensor pose it gives the scan [`run_e4`]
/// localizes (`mapc eval --dump` writes them).
pub fn e4_rng(seed: u64, k: usize) -> Rng {
    Rng::stream(seed ^ 0xE4, k as u64)
}

/// The prior of E4 pose `k` (see [`ScanSpec::prior_radius`]), from its own
/// random stream (the scans do not change with it).
pub fn e4_prior(spec: &ScanSpec, truth: &Pose2, seed: u64, k: usize) -> Option<refloc::Prior> {
    if !(spec.prior_radius > 0.0 || spec.prior_heading_tol > 0.0) {
        return None;
    }
    let mut rng = Rng::stream(seed ^ 0x0981_00E4, k as u64);
    let mut p = refloc::Prior::NONE;
    if spec.prior_radius > 0.0 {
        let (d, a) = (
            rng.range(0.0, 0.5 * spec.prior_radius as f64) as f32,
            rng.range(-std::f64::consts::PI, std::f64::consts::PI) as f32,
        );
        p = refloc::Prior::circle(
            truth.x + d * a.cos(),
            truth.y + d * a.sin(),
            spec.prior_radius,
        );
    }
    if spec.prior_heading_tol > 0.0 {
        let h = spec.prior_heading_tol as f64;
        p = p.with_heading(
            truth.theta + rng.range(-0.5 * h, 0.5 * h) as f32,
            spec.prior_heading_tol,
        );
    }
    Some(p)
}

/// Runs E4 on `poses` (robot poses) with scans simulated in `scan_grid`
/// (`None`: the database's own grid) and returns one trial per pose.
pub fn run_e4<D: AsRef<[u8]> + Sync>(
    db: &RefDb<D>,
    poses: &[Pose2],
    spec: &ScanSpec,
    seed: u64,
    foreign: Option<(&BitGrid<'_>, &MapFrame)>,
    progress: &(dyn Fn() + Sync),
) -> Vec<Trial> {
    let lidar = spec.lidar();
    let scratch_len = scratch_size(db.params(), spec.beams);
    let own_grid = db.grid();
    let own_frame = db.frame();
    let (grid, frame) = foreign.unwrap_or((&own_grid, &own_frame));
    let offset = db.params().sensor.offset;
    poses
        .par_iter()
        .enumerate()
        .map_init(
            || vec![0u8; scratch_len],
            |scratch, (k, truth)| {
                let mut rng = e4_rng(seed, k);
                let sensor = truth.compose(&offset);
                let s = simulate(grid, frame, &sensor, spec, &mut rng);
                let scan = match &s.points {
                    Some(p) => Scan::Points {
                        points: p,
                        range_max: spec.range_max,
                    },
                    None => Scan::Ranges(RangeScan {
                        angle_min: lidar.angle_min,
                        angle_increment: lidar.angle_increment,
                        range_min: lidar.range_min,
                        range_max: lidar.range_max,
                        ranges: &s.ranges,
                    }),
                };
                let prior = e4_prior(spec, truth, seed, k);
                let t0 = std::time::Instant::now();
                let r = refloc::localize_with_prior(db, &scan, scratch, prior);
                let time_us = t0.elapsed().as_micros() as u64;
                let mut trial = Trial {
                    truth: [truth.x as f64, truth.y as f64, truth.theta as f64],
                    est: None,
                    accepted: false,
                    err_pos: None,
                    err_theta: None,
                    correct_rank: None,
                    candidates: 0,
                    nc: 0,
                    time_us,
                    vicinity_ratio: 0.0,
                    long_ratio: 0.0,
                    error: None,
                };
                match r {
                    Ok(l) => {
                        trial.est = Some([l.pose.x as f64, l.pose.y as f64, l.pose.theta as f64]);
                        trial.accepted = l.accepted;
                        trial.long_ratio = l.long_beams as f64 / l.valid_points.max(1) as f64;
                        // threshold = 4.5 N_P accept_ratio, so M / (4.5 N_P) = M / threshold * ratio.
                        if l.vicinity_threshold > 0.0 {
                            trial.vicinity_ratio = (l.vicinity / l.vicinity_threshold
                                * db.params().verify.accept_ratio)
                                as f64;
                        }
                        trial.candidates = l.candidates.len();
                        if foreign.is_none() {
                            let (dx, dy) =
                                ((l.pose.x - truth.x) as f64, (l.pose.y - truth.y) as f64);
                            trial.err_pos = Some((dx * dx + dy * dy).sqrt());
                            trial.err_theta =
                                Some(refloc::wrap_angle(l.pose.theta - truth.theta).abs() as f64);
                        }
                    }
                    Err(e) => trial.error = Some(e.to_string()),
                }
                if foreign.is_none() {
                    if let Some(site) = correct_site(db, [sensor.x, sensor.y]) {
                        let pts: Vec<[f32; 2]> = match &s.points {
                            Some(p) => p.clone(),
                            None => {
                                let mut d = vec![[0f32; 2]; s.ranges.len()];
                                prep::ranges_to_points(
                                    &s.ranges,
                                    lidar.angle_min,
                                    lidar.angle_increment,
                                    lidar.range_min,
                                    lidar.range_max,
                                    &mut d,
                                );
                                d
                            }
                        };
                        let full = spec.fov >= 2.0 * std::f32::consts::PI - 1e-3;
                        let fov = if full {
                            2.0 * std::f32::consts::PI
                        } else {
                            lidar.angle_increment * lidar.beams as f32
                        };
                        let scores = coarse_scores(db, &pts, fov, full);
                        trial.correct_rank = Some(coarse_rank(&scores, site));
                        trial.nc = coarse_nc(db, &scores);
                    }
                }
                progress();
                trial
            },
        )
        .collect()
}

/// One E1 trial's pose error (x m, y m, theta rad), or `None` when SSM failed.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct E1Trial {
    /// Error of x, y (m) and theta (rad): estimate minus truth.
    pub err: Option<[f64; 3]>,
    /// Matching rate: correct accepted correspondences / inlier points.
    pub matching_rate: f64,
    /// Time of the match from raw points (preparation, descriptors, SSM), µs.
    #[serde(default)]
    pub time_us: u64,
}

/// One E1/E2 scan pair: the reference scan's points and the disturbed,
/// moved copy, both in their own sensor frames (`NaN` where a beam has no
/// return), and the true motion that maps query points into the
/// reference frame.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct E1Pair {
    /// Reference scan points (m).
    pub reference: Vec<[f32; 2]>,
    /// Query points (m): noise, x-y swap outliers, then `motion^-1`.
    pub query: Vec<[f32; 2]>,
    /// True motion `[x, y, theta]` (m, m, rad): `reference ≈ motion * query`.
    pub motion: [f32; 3],
    /// Query points that are not outliers (finite beams).
    pub inliers: usize,
}

/// Scan-to-scan SSM (E1/E2): the scan at `pose` against a disturbed,
/// moved copy. `noise` (m), `outliers` (x-y swaps), motion up to
/// `max_shift` (m) and `max_rot` (rad).
#[allow(clippy::too_many_arguments)]
pub fn ssm_trial<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    pose: &Pose2,
    noise: f32,
    outliers: usize,
    max_shift: f32,
    max_rot: f32,
    rng: &mut Rng,
) -> E1Trial {
    let pair = e1_pair(db, pose, noise, outliers, max_shift, max_rot, rng);
    ssm_match_pair(db, &pair)
}

/// The scan pair of [`ssm_trial`] (every random choice of the trial).
#[allow(clippy::too_many_arguments)]
pub fn e1_pair<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    pose: &Pose2,
    noise: f32,
    outliers: usize,
    max_shift: f32,
    max_rot: f32,
    rng: &mut Rng,
) -> E1Pair {
    let params = db.params();
    let lidar = crate::compiler::compile::ref_lidar(params);
    let grid = db.grid();
    let frame = db.frame();
    let ranges = sim::virtual_scan(&grid, &frame, pose, &lidar);
    let mut ref_pts = vec![[0f32; 2]; ranges.len()];
    prep::ranges_to_points(
        &ranges,
        lidar.angle_min,
        lidar.angle_increment,
        lidar.range_min,
        lidar.range_max,
        &mut ref_pts,
    );
    // Disturbed copy: noise along each point, swap outliers, then a rigid motion.
    let motion = Pose2::new(
        rng.range(-max_shift as f64, max_shift as f64) as f32,
        rng.range(-max_shift as f64, max_shift as f64) as f32,
        rng.range(-max_rot as f64, max_rot as f64) as f32,
    );
    let mut q: Vec<[f32; 2]> = ref_pts
        .iter()
        .map(|p| {
            if p[0].is_finite() {
                [
                    p[0] + noise * rng.normal() as f32,
                    p[1] + noise * rng.normal() as f32,
                ]
            } else {
                *p
            }
        })
        .collect();
    let n_in = q.iter().filter(|p| p[0].is_finite()).count();
    sim::swap_outliers(&mut q, outliers, rng);
    // q_moved = motion^-1 * q, so that the true input->reference transform is `motion`.
    let inv = motion.inverse();
    let q: Vec<[f32; 2]> = q
        .iter()
        .map(|p| if p[0].is_finite() { inv.apply(*p) } else { *p })
        .collect();
    E1Pair {
        reference: ref_pts,
        query: q,
        motion: [motion.x, motion.y, motion.theta],
        inliers: n_in,
    }
}

/// SSM of one [`E1Pair`] from raw points, scored against its true motion.
pub fn ssm_match_pair<D: AsRef<[u8]>>(db: &RefDb<D>, pair: &E1Pair) -> E1Trial {
    let params = db.params();
    let (q, ref_pts, n_in) = (&pair.query, &pair.reference, pair.inliers);
    let motion = Pose2::new(pair.motion[0], pair.motion[1], pair.motion[2]);
    let np = params.prep.max_points as usize;
    let (mut qp, mut qt, mut rp, mut rt) = (
        vec![[0f32; 2]; np],
        vec![[0f32; 2]; np],
        vec![[0f32; 2]; np],
        vec![[0f32; 2]; np],
    );
    let t0 = std::time::Instant::now();
    let nq = prep::prepare(q, true, params, &mut qp, &mut qt);
    let nr = prep::prepare(ref_pts, true, params, &mut rp, &mut rt);
    let nl = np * params.ssm.tentative_k as usize;
    let (mut qd, mut rd) = (
        vec![0 as ssm::DescBin; np * DESC_LEN],
        vec![0 as ssm::DescBin; np * DESC_LEN],
    );
    ssm::descriptors(&qp[..nq], &qt[..nq], params.ssm.desc_radius, &mut qd);
    ssm::descriptors(&rp[..nr], &rt[..nr], params.ssm.desc_radius, &mut rd);
    let (mut tent, mut aff) = (
        vec![[0u16; 2]; nl],
        vec![ssm::Affinity::default(); params.ssm.affinity_cap as usize],
    );
    let (mut x, mut y, mut order) = (vec![0f32; nl], vec![0f32; nl], vec![0u16; nl]);
    let (mut acc, mut flags) = (vec![[0u16; 2]; np], vec![0u8; 3 * np + nl]);
    let mut ends = vec![0f32; 4 * nl];
    let mut rcols = vec![0 as ssm::DescBin; np * DESC_LEN];
    let (mut rsum, mut shared, mut dist) = (vec![0u32; np], vec![0u16; np], vec![0u32; np]);
    let mut work = SsmWork {
        qdesc: &mut qd,
        tent: &mut tent,
        ends: &mut ends,
        aff: &mut aff,
        x: &mut x,
        y: &mut y,
        order: &mut order,
        acc: &mut acc,
        flags: &mut flags,
        bins: ssm::BinWork {
            cols: &mut rcols,
            sums: &mut rsum,
            shared: &mut shared,
            dist: &mut dist,
        },
    };
    let matched = ssm::match_scans(
        &qp[..nq],
        &qt[..nq],
        &rp[..nr],
        &rt[..nr],
        &rd,
        params,
        &mut work,
    );
    let time_us = t0.elapsed().as_micros() as u64;
    match matched {
        Some(m) => {
            let e = [
                (m.pose.x - motion.x) as f64,
                (m.pose.y - motion.y) as f64,
                refloc::wrap_angle(m.pose.theta - motion.theta) as f64,
            ];
            // Correct accepted correspondences: the true motion maps the input point near its partner.
            let good = work.acc[..m.matched as usize]
                .iter()
                .filter(|&&[i, ii]| {
                    let p = motion.apply(qp[i as usize]);
                    let r = rp[ii as usize];
                    ((p[0] - r[0]).powi(2) + (p[1] - r[1]).powi(2)).sqrt() < 0.1
                })
                .count();
            let inl = nq.min(nr).min(n_in).max(1);
            E1Trial {
                err: Some(e),
                matching_rate: (good as f64 / inl as f64).min(1.0),
                time_us,
            }
        }
        None => E1Trial {
            err: None,
            matching_rate: 0.0,
            time_us,
        },
    }
}

/// Mean and standard deviation of each component.
pub fn mean_sd(v: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let n = v.len().max(1) as f64;
    let mut m = [0.0; 3];
    for e in v {
        for k in 0..3 {
            m[k] += e[k] / n;
        }
    }
    let mut s = [0.0; 3];
    for e in v {
        for k in 0..3 {
            s[k] += (e[k] - m[k]).powi(2) / (n - 1.0).max(1.0);
        }
    }
    (m, [s[0].sqrt(), s[1].sqrt(), s[2].sqrt()])
}

/// A regression found by `--check`.
#[derive(Clone, Debug, Serialize)]
pub struct Regression {
    /// What regressed.
    pub metric: String,
    /// Baseline value.
    pub baseline: f64,
    /// This run's value.
    pub current: f64,
    /// The allowed limit.
    pub limit: f64,
}

/// Tolerances of `--check`.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Tolerance {
    /// Allowed drop of a success rate (absolute, e.g. 0.02 = 2 points).
    pub rate: f64,
    /// Allowed rise of a false-accept rate (absolute).
    pub false_accept: f64,
    /// Allowed growth factor of mean errors.
    pub error_factor: f64,
    /// Slack added to error limits (m for positions, rad/10 for headings).
    pub error_slack: f64,
}

impl Default for Tolerance {
    fn default() -> Self {
        Tolerance {
            rate: 0.02,
            false_accept: 0.01,
            error_factor: 1.5,
            error_slack: 0.002,
        }
    }
}

/// Compares summaries with a baseline's (matched by name).
pub fn check(
    current: &[(String, Summary)],
    baseline: &[(String, Summary)],
    tol: &Tolerance,
) -> Vec<Regression> {
    let mut out = Vec::new();
    for (name, b) in baseline {
        let Some((_, c)) = current.iter().find(|(n, _)| n == name) else {
            out.push(Regression {
                metric: format!("{name}: missing from this run"),
                baseline: 1.0,
                current: 0.0,
                limit: 1.0,
            });
            continue;
        };
        let mut lower = |metric: &str, bv: f64, cv: f64, lim: f64| {
            if cv < lim {
                out.push(Regression {
                    metric: format!("{name}.{metric}"),
                    baseline: bv,
                    current: cv,
                    limit: lim,
                });
            }
        };
        lower(
            "success_rate",
            b.success_rate,
            c.success_rate,
            b.success_rate - tol.rate,
        );
        let mut higher = |metric: &str, bv: f64, cv: f64, lim: f64| {
            if cv > lim {
                out.push(Regression {
                    metric: format!("{name}.{metric}"),
                    baseline: bv,
                    current: cv,
                    limit: lim,
                });
            }
        };
        higher(
            "false_accept_rate",
            b.false_accept_rate,
            c.false_accept_rate,
            b.false_accept_rate + tol.false_accept,
        );
        higher(
            "mean_abs_x",
            b.mean_abs_x,
            c.mean_abs_x,
            b.mean_abs_x * tol.error_factor + tol.error_slack,
        );
        higher(
            "mean_abs_y",
            b.mean_abs_y,
            c.mean_abs_y,
            b.mean_abs_y * tol.error_factor + tol.error_slack,
        );
        higher(
            "mean_abs_theta",
            b.mean_abs_theta,
            c.mean_abs_theta,
            b.mean_abs_theta * tol.error_factor + tol.error_slack / 10.0,
        );
    }
    out
}

/// The robot pose that the given truth `sensor` pose (map frame) becomes
/// when corrected locally against the map with the scan's own points: the
/// best pose of a search within 0.5 m (0.1 m steps) and 15 degrees (1 degree
/// steps) of the truth, scored by the summed squared distance of the points
/// to the nearest surface (capped at 0.3 m), then 30 robust Gauss-Newton
/// steps (`refloc::refine`, points within 1 m of a surface). The search
/// uses only the truth, the scan and the map, never the localizer's result.
///
/// `beams` are (angle in the sensor frame (rad), range (m)) pairs, no return
/// as a non-finite range; `sensor` is the given truth's sensor pose (map
/// frame, m and rad). Returns the corrected *robot* pose (map frame). For
/// logs whose poses come from another SLAM run than the map (the shared
/// CARMEN logs), where the given pose can be off by more than the
/// correctness tolerance although the map places the scan unambiguously.
pub fn correct_truth_locally<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    beams: &[(f32, f32)],
    sensor: Pose2,
) -> Pose2 {
    let pts: Vec<[f32; 2]> = beams
        .iter()
        .map(|&(a, r)| {
            if r.is_finite() {
                [r * a.cos(), r * a.sin()]
            } else {
                [f32::NAN, f32::NAN]
            }
        })
        .collect();
    let dm = refloc::refine::DistMap::of(db);
    let cap = 0.3f32;
    let cost = |p: &Pose2| -> f32 {
        let (s, c) = p.theta.sin_cos();
        pts.iter()
            .filter(|q| q[0].is_finite())
            .map(|q| {
                let m = [p.x + c * q[0] - s * q[1], p.y + s * q[0] + c * q[1]];
                let d = dm.sample(m).map_or(cap, |(d, _)| d.abs().min(cap));
                d * d
            })
            .sum()
    };
    let mut best = (cost(&sensor), sensor);
    for dt in -15..=15 {
        for dx in -5..=5 {
            for dy in -5..=5 {
                let p = Pose2::new(
                    sensor.x + 0.1 * dx as f32,
                    sensor.y + 0.1 * dy as f32,
                    sensor.theta + (dt as f32).to_radians(),
                );
                let c = cost(&p);
                if c < best.0 {
                    best = (c, p);
                }
            }
        }
    }
    let (refined, _) = refloc::refine::refine(&dm, &pts, best.1, 30, 1.0);
    refined.compose(&db.params().sensor.offset.inverse())
}
