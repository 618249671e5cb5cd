//! Shared fixture of the refloc benchmarks (`benches/localize.rs`) and of
//! the instruction-count driver (`src/bin/query-count.rs`).
//!
//! - [`Database`]: the Intel Research Lab map (`shared/maps/intel/intel.yaml`)
//!   compiled with `mapc::pipeline::build` and the default `BuildConfig`,
//!   encoded with `refloc::format::encode` into a 4-byte-aligned buffer. When
//!   the shared data is absent, a synthetic 600 x 400 office
//!   (`mapc::synth`, seed 0) is used instead and [`Database::origin`] says so.
//! - [`scan_set`]: a fixed set of [`SCAN_COUNT`] simulated scans at seeded
//!   free poses (`mapc::eval::sample_poses`, clearance 0.3 m, seed
//!   [`POSE_SEED`]) for each [`Kind`] of scanner, static (exact ranges) or
//!   dynamic (5 mm range noise and 60 random short returns, as `mapc eval`).
//! - [`Work`]: the localizer's stages run one at a time on owned buffers,
//!   exactly as `refloc::localize` runs them, so each can be timed alone.

use std::path::Path;
use std::time::{Duration, Instant};

use mapc::eval;
use mapc::mapfile::{self, MapSource};
use mapc::pipeline::{self, BuildConfig};
use mapc::rng::Rng;
use mapc::sim::{self, Lidar};
use mapc::synth::{self, SynthKind, SynthOptions};
use refloc::coarse::{self, Ranked};
use refloc::refine::DistMap;
use refloc::ssm::{self, Affinity, SsmResult, SsmWork, DESC_LEN};
use refloc::verify::{self, Vicinity};
use refloc::{localize, prep, scratch_size, Params, Pose2, RangeScan, RefDb, Scan};

/// Scans per set.
pub const SCAN_COUNT: usize = 50;
/// Seed of the sampled poses.
pub const POSE_SEED: u64 = 1;
/// Seed of the range noise and outliers (scan `k` uses `Rng::stream(NOISE_SEED, k)`).
pub const NOISE_SEED: u64 = 0xBE7C;
/// Poses keep at least this distance from obstacles (m), as `mapc eval`.
pub const CLEARANCE: f32 = 0.3;
/// Sensor maximum range (m).
pub const RANGE_MAX: f32 = 30.0;
/// Range noise of the dynamic scans (m).
pub const DYNAMIC_SIGMA: f32 = 0.005;
/// Random short returns per dynamic scan.
pub const DYNAMIC_OUTLIERS: usize = 60;

/// A scanner.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// 362 beams over 360 degrees (the database's own reference scanner).
    Full362,
    /// 1081 beams over 270 degrees, 0.25 degree step (SICK / Hokuyo UTM class).
    Wide1081,
    /// 361 beams over 180 degrees, 0.5 degree step.
    Half361,
}

impl Kind {
    /// Every kind, in report order.
    pub const ALL: [Kind; 3] = [Kind::Full362, Kind::Wide1081, Kind::Half361];

    /// The scanner geometry.
    pub fn lidar(self) -> Lidar {
        use std::f32::consts::PI;
        match self {
            Kind::Full362 => Lidar::new(362, 2.0 * PI, RANGE_MAX),
            Kind::Wide1081 => Lidar::new(1081, 1.5 * PI, RANGE_MAX),
            Kind::Half361 => Lidar::new(361, PI, RANGE_MAX),
        }
    }

    /// Beams per scan.
    pub fn beams(self) -> usize {
        self.lidar().beams
    }

    /// Short name used in benchmark ids: `362x360`, `1081x270`, `361x180`.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Full362 => "362x360",
            Kind::Wide1081 => "1081x270",
            Kind::Half361 => "361x180",
        }
    }

    /// From a beam count (362, 1081, 361) or a [`Kind::name`].
    pub fn parse(s: &str) -> Option<Kind> {
        Kind::ALL
            .into_iter()
            .find(|k| s == k.name() || s == k.beams().to_string())
    }
}

/// Static (exact) or dynamic (noisy, with outliers) scans.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Condition {
    /// Exact virtual ranges.
    Static,
    /// [`DYNAMIC_SIGMA`] range noise and [`DYNAMIC_OUTLIERS`] short returns.
    Dynamic,
}

impl Condition {
    /// Both, in report order.
    pub const ALL: [Condition; 2] = [Condition::Static, Condition::Dynamic];

    /// `static` or `dynamic`.
    pub fn name(self) -> &'static str {
        match self {
            Condition::Static => "static",
            Condition::Dynamic => "dynamic",
        }
    }

    /// From [`Condition::name`].
    pub fn parse(s: &str) -> Option<Condition> {
        Condition::ALL.into_iter().find(|c| c.name() == s)
    }

    /// The simulator's noise model.
    pub fn noise(self) -> sim::Noise {
        match self {
            Condition::Static => sim::Noise::default(),
            Condition::Dynamic => sim::Noise {
                range_sigma: DYNAMIC_SIGMA,
                short_outliers: DYNAMIC_OUTLIERS,
            },
        }
    }
}

/// A compiled database in a 4-byte-aligned buffer.
pub struct Database {
    words: Vec<u32>,
    len: usize,
    /// Where the map came from (printed by the benchmarks).
    pub origin: String,
}

impl Database {
    /// Compiles the Intel map (or, when the shared data is absent, a
    /// synthetic office) with the default `BuildConfig`.
    pub fn build() -> Result<Database, String> {
        let t = Instant::now();
        let (src, what, _tmp) = match mapc::testdata::shared("maps/intel/intel.yaml") {
            Some(p) => (
                mapfile::load_yaml(&p).map_err(|e| e.to_string())?,
                format!("Intel Research Lab ({})", p.display()),
                None,
            ),
            None => {
                let (src, tmp) = synthetic_office()?;
                (
                    src,
                    "SYNTHETIC office 600 x 400 cells (mapc::synth, seed 0): \
                     shared/maps/intel/intel.yaml not found, numbers are NOT the Intel map's"
                        .to_string(),
                    Some(tmp),
                )
            }
        };
        let out = pipeline::build(&src, &BuildConfig::default())?;
        let mut bytes = Vec::new();
        let refs: Vec<_> = out
            .sections
            .iter()
            .map(|(k, b)| (*k, b.as_slice()))
            .collect();
        refloc::format::encode(&refs, |b: &[u8]| -> Result<(), ()> {
            bytes.extend_from_slice(b);
            Ok(())
        })
        .map_err(|_| "encode failed".to_string())?;
        let mut db = Database::from_bytes(&bytes, what)?;
        db.origin = format!(
            "{}; {} sites, {} bytes, built in {:.1} s",
            db.origin,
            out.sites.len(),
            bytes.len(),
            t.elapsed().as_secs_f64()
        );
        Ok(db)
    }

    /// A copy of a file image (validated).
    pub fn from_bytes(bytes: &[u8], origin: String) -> Result<Database, String> {
        let mut words = vec![0u32; bytes.len().div_ceil(4)];
        let all: &mut [u8] = zerocopy::IntoBytes::as_mut_bytes(&mut words[..]);
        all[..bytes.len()].copy_from_slice(bytes);
        let db = Database {
            words,
            len: bytes.len(),
            origin,
        };
        let v = db.try_open()?;
        v.verify().map_err(|e| e.to_string())?;
        Ok(db)
    }

    /// Reads a `.refdb` file.
    pub fn load(path: &Path) -> Result<Database, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Database::from_bytes(&bytes, path.display().to_string())
    }

    /// The file image.
    pub fn bytes(&self) -> &[u8] {
        &zerocopy::IntoBytes::as_bytes(&self.words[..])[..self.len]
    }

    fn try_open(&self) -> Result<RefDb<&[u8]>, String> {
        RefDb::new(self.bytes()).map_err(|e| e.to_string())
    }

    /// The database view.
    pub fn open(&self) -> RefDb<&[u8]> {
        self.try_open().expect("validated when loaded")
    }
}

fn synthetic_office() -> Result<(MapSource, tempfile::TempDir), String> {
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let map = synth::generate(&SynthOptions::new(SynthKind::Office, 600, 400));
    let (yaml, _) = synth::write_ros_map(dir.path(), "office", &map, [0.0, 0.0, 0.0])
        .map_err(|e| e.to_string())?;
    let src = mapfile::load_yaml(&yaml).map_err(|e| e.to_string())?;
    Ok((src, dir))
}

/// One simulated query, with the localizer's view of it precomputed.
pub struct Query {
    /// True robot pose.
    pub truth: Pose2,
    /// The scanner.
    pub lidar: Lidar,
    /// Ranges (m; `INFINITY`: no return).
    pub ranges: Vec<f32>,
    /// Beam-ordered sensor-frame points (NaN: no return), as the localizer loads them.
    pub dense: Vec<[f32; 2]>,
    /// Beam angles (rad).
    pub angles: Vec<f32>,
    /// Ranges with `INFINITY` for every invalid beam.
    pub valid_ranges: Vec<f32>,
    /// Angular coverage (rad).
    pub fov: f32,
    /// Closes a full turn.
    pub wrap: bool,
    /// The nearest site in line of sight of the true sensor position.
    pub correct_site: Option<usize>,
}

impl Query {
    /// As the localizer's input.
    pub fn scan(&self) -> Scan<'_> {
        Scan::Ranges(RangeScan {
            angle_min: self.lidar.angle_min,
            angle_increment: self.lidar.angle_increment,
            range_min: self.lidar.range_min,
            range_max: self.lidar.range_max,
            ranges: &self.ranges,
        })
    }
}

/// The fixed scan set of `kind` under `cond`: `n` scans at the first `n`
/// poses of `mapc::eval::sample_poses(db, n, CLEARANCE, POSE_SEED)`.
/// Deterministic.
pub fn scan_set<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    kind: Kind,
    cond: Condition,
    n: usize,
) -> Vec<Query> {
    let poses = eval::sample_poses(db, n, CLEARANCE, POSE_SEED);
    let grid = db.grid();
    let frame = db.frame();
    let offset = db.params().sensor.offset;
    let lidar = kind.lidar();
    poses
        .iter()
        .enumerate()
        .map(|(k, truth)| {
            let sensor = truth.compose(&offset);
            let mut ranges = sim::virtual_scan(&grid, &frame, &sensor, &lidar);
            let mut rng = Rng::stream(NOISE_SEED, k as u64);
            sim::add_noise(&mut ranges, &lidar, &cond.noise(), &mut rng);
            let mut dense = vec![[0f32; 2]; ranges.len()];
            prep::ranges_to_points(
                &ranges,
                lidar.angle_min,
                lidar.angle_increment,
                lidar.range_min,
                lidar.range_max,
                &mut dense,
            );
            let angles: Vec<f32> = (0..ranges.len())
                .map(|i| lidar.angle_min + i as f32 * lidar.angle_increment)
                .collect();
            let valid_ranges = dense
                .iter()
                .zip(&ranges)
                .map(|(p, &r)| if p[0].is_finite() { r } else { f32::INFINITY })
                .collect();
            // As refloc::localize's load_scan (increment > 0 here).
            let inc = lidar.angle_increment;
            let span = inc * lidar.beams as f32;
            let fov = span.min(2.0 * std::f32::consts::PI);
            let wrap = span >= 2.0 * std::f32::consts::PI - 1.5 * inc;
            Query {
                truth: *truth,
                lidar,
                ranges,
                dense,
                angles,
                valid_ranges,
                fov,
                wrap,
                correct_site: eval::correct_site(db, [sensor.x, sensor.y]),
            }
        })
        .collect()
}

/// SSM working memory as owned vectors (see `mapc::eval::ssm_trial`).
pub struct SsmBufs {
    qdesc: Vec<f32>,
    rdesc: Vec<f32>,
    tent: Vec<[u16; 2]>,
    aff: Vec<Affinity>,
    x: Vec<f32>,
    y: Vec<f32>,
    order: Vec<u16>,
    acc: Vec<[u16; 2]>,
    flags: Vec<u8>,
}

impl SsmBufs {
    fn new(params: &Params) -> SsmBufs {
        let np = params.max_points as usize;
        let nl = np * params.tentative_k as usize;
        SsmBufs {
            qdesc: vec![0.0; np * DESC_LEN],
            rdesc: vec![0.0; np * DESC_LEN],
            tent: vec![[0; 2]; nl],
            aff: vec![Affinity::default(); params.affinity_cap as usize],
            x: vec![0.0; nl],
            y: vec![0.0; nl],
            order: vec![0; nl],
            acc: vec![[0; 2]; np],
            flags: vec![0; 3 * np + nl],
        }
    }

    fn work(&mut self) -> SsmWork<'_> {
        SsmWork {
            qdesc: &mut self.qdesc,
            rdesc: &mut self.rdesc,
            tent: &mut self.tent,
            aff: &mut self.aff,
            x: &mut self.x,
            y: &mut self.y,
            order: &mut self.order,
            acc: &mut self.acc,
            flags: &mut self.flags,
        }
    }
}

/// The localizer's stages on owned buffers, one call per stage, computed as
/// `refloc::localize` computes them.
pub struct Work {
    h_pts: Vec<[f32; 2]>,
    h_tan: Vec<[f32; 2]>,
    /// The query histogram (first `cells` entries after [`Work::histogram`]).
    pub hist: Vec<f32>,
    /// Coarse ranking buffer, `nc_max` long.
    pub top: Vec<Ranked>,
    q_pts: Vec<[f32; 2]>,
    q_tan: Vec<[f32; 2]>,
    nq: usize,
    r_dense: Vec<[f32; 2]>,
    r_pts: Vec<[f32; 2]>,
    r_tan: Vec<[f32; 2]>,
    ssm: SsmBufs,
}

impl Work {
    /// Buffers for a database with `params`.
    pub fn new(params: &Params) -> Work {
        let np = params.max_points as usize;
        Work {
            h_pts: vec![[0.0; 2]; np],
            h_tan: vec![[0.0; 2]; np],
            hist: vec![0.0; params.hist_cells().max(params.win_cells())],
            top: vec![Ranked::default(); params.nc_max as usize],
            q_pts: vec![[0.0; 2]; np],
            q_tan: vec![[0.0; 2]; np],
            nq: 0,
            r_dense: vec![[0.0; 2]; params.sensor.beams as usize],
            r_pts: vec![[0.0; 2]; np],
            r_tan: vec![[0.0; 2]; np],
            ssm: SsmBufs::new(params),
        }
    }

    /// Stage "histogram": `coarse::query_histogram` (preparation of the
    /// possibly cropped scan and its PGR histogram). Returns (window, cells).
    pub fn histogram(&mut self, params: &Params, q: &Query) -> (Option<usize>, usize) {
        coarse::query_histogram(
            &q.dense,
            q.fov,
            q.wrap,
            params,
            &mut self.h_pts,
            &mut self.h_tan,
            &mut self.hist,
        )
    }

    /// Stage "query prep": `prep::prepare` of the whole scan and the query
    /// descriptors (done once per query). Returns the prepared point count.
    pub fn prepare_query(&mut self, params: &Params, q: &Query) -> usize {
        self.nq = prep::prepare(&q.dense, q.wrap, params, &mut self.q_pts, &mut self.q_tan);
        ssm::descriptors(
            &self.q_pts[..self.nq],
            &self.q_tan[..self.nq],
            params.desc_radius,
            &mut self.ssm.qdesc,
        );
        self.nq
    }

    /// Stage "SSM per candidate", after [`Work::prepare_query`]: the site's
    /// reference scan to points, `prep::prepare`, `ssm::descriptors`,
    /// `ssm::match_scans`.
    pub fn ssm<D: AsRef<[u8]>>(&mut self, db: &RefDb<D>, site: usize) -> Option<SsmResult> {
        let params = db.params();
        let s = &params.sensor;
        let ref_wrap = s.angle_increment * s.beams as f32
            >= 2.0 * std::f32::consts::PI - 1.5 * s.angle_increment;
        let n = prep::ranges_to_points(
            db.scan(site),
            s.angle_min,
            s.angle_increment,
            s.range_min,
            s.range_max,
            &mut self.r_dense,
        );
        let nr = prep::prepare(
            &self.r_dense[..n],
            ref_wrap,
            params,
            &mut self.r_pts,
            &mut self.r_tan,
        );
        ssm::descriptors(
            &self.r_pts[..nr],
            &self.r_tan[..nr],
            params.desc_radius,
            &mut self.ssm.rdesc,
        );
        let nq = self.nq;
        ssm::match_scans(
            &self.q_pts[..nq],
            &self.q_tan[..nq],
            &self.r_pts[..nr],
            &self.r_tan[..nr],
            params,
            &mut self.ssm.work(),
        )
    }
}

/// Stage "coarse": every site's score against a query histogram from
/// [`Work::histogram`] (its first `cells` entries, with `window`), the top
/// `top.len()` sites into `top`, and the N_C rule. Returns N_C.
pub fn rank<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    hist: &[f32],
    window: Option<usize>,
    top: &mut [Ranked],
) -> usize {
    let ranked = coarse::rank_top_scores(
        (0..db.site_count()).map(|s| coarse::site_score(db, hist, window, s)),
        top,
    );
    let p = db.params();
    coarse::candidate_count(
        &top[..ranked],
        p.nc_min as usize,
        p.nc_max as usize,
        p.nc_margin,
    )
}

/// The coarse candidates (sites, best first) `refloc::localize` would
/// examine for `q` at most.
pub fn candidates<D: AsRef<[u8]>>(db: &RefDb<D>, q: &Query, work: &mut Work) -> Vec<usize> {
    let (w, cells) = work.histogram(db.params(), q);
    let nc = rank(db, &work.hist[..cells], w, &mut work.top);
    work.top[..nc].iter().map(|r| r.site as usize).collect()
}

/// The sensor pose (map frame) an SSM result against `site` gives.
pub fn sensor_pose<D: AsRef<[u8]>>(db: &RefDb<D>, site: usize, m: &SsmResult) -> Pose2 {
    let sxy = db.site_xy(site);
    Pose2::new(sxy[0], sxy[1], 0.0).compose(&m.pose)
}

/// Stage "refine": `refine::refine` of `sensor` with the database's settings.
pub fn refine<D: AsRef<[u8]>>(db: &RefDb<D>, q: &Query, sensor: Pose2) -> Pose2 {
    let p = db.params();
    let dm = DistMap::of(db);
    refloc::refine::refine(&dm, &q.dense, sensor, p.refine_iters, p.refine_max_dist).0
}

/// Stage "verify": the vicinity score of `sensor`.
pub fn verify<D: AsRef<[u8]>>(db: &RefDb<D>, q: &Query, sensor: &Pose2) -> Vicinity {
    let grid = db.grid();
    verify::Verifier::new(db, &grid, q.lidar.range_max).score(
        sensor,
        q.angles.iter().copied().zip(q.valid_ranges.iter().copied()),
    )
}

/// One query's outcome in [`query_stats`].
#[derive(Clone, Debug)]
pub struct QueryStat {
    /// Fastest of the repetitions.
    pub time: Duration,
    /// Candidates the fine stage examined.
    pub examined: usize,
    /// N_C of the coarse stage.
    pub nc: usize,
    /// Accepted.
    pub accepted: bool,
    /// Accepted within 0.3 m and 5 degrees of the truth.
    pub correct: bool,
    /// The answer's vicinity score as a share of its maximum, `M / (4.5 N_P)`.
    pub vicinity_ratio: f32,
    /// The same over the beams that are not short (blocked by something
    /// unmapped), `M / (4.5 (N_P - short))`: the localizer stops early when
    /// this reaches `early_accept` (0.9 by default) with at most a fifth of
    /// the beams short.
    pub explained_ratio: f32,
}

/// Localizes every query `reps` times (single thread) and keeps each one's
/// fastest time, with what it did.
pub fn query_stats<D: AsRef<[u8]>>(db: &RefDb<D>, qs: &[Query], reps: usize) -> Vec<QueryStat> {
    let beams = qs.iter().map(|q| q.ranges.len()).max().unwrap_or(0);
    let mut scratch = vec![0u8; scratch_size(db.params(), beams)];
    let mut work = Work::new(db.params());
    qs.iter()
        .map(|q| {
            let mut best = Duration::MAX;
            let mut out = None;
            for _ in 0..reps.max(1) {
                let t = Instant::now();
                let r = localize(db, &q.scan(), &mut scratch);
                best = best.min(t.elapsed());
                out = Some(match r {
                    Ok(l) => {
                        let dp = ((l.pose.x - q.truth.x).powi(2) + (l.pose.y - q.truth.y).powi(2))
                            .sqrt();
                        let dt = refloc::wrap_angle(l.pose.theta - q.truth.theta).abs();
                        (
                            l.candidates.len(),
                            l.accepted,
                            l.accepted
                                && (dp as f64) < eval::CORRECT_POS
                                && (dt as f64) < eval::CORRECT_THETA,
                            {
                                let pairs = l
                                    .candidates
                                    .iter()
                                    .find(|c| c.rank == l.coarse_rank)
                                    .map_or(0, |c| c.pairs);
                                let ratio = |n: u32| {
                                    if n > 0 {
                                        l.vicinity / (4.5 * n as f32)
                                    } else {
                                        0.0
                                    }
                                };
                                (ratio(pairs), ratio(pairs.saturating_sub(l.short_beams)))
                            },
                        )
                    }
                    Err(_) => (0, false, false, (0.0, 0.0)),
                });
            }
            let (examined, accepted, correct, (vicinity_ratio, explained_ratio)) =
                out.unwrap_or((0, false, false, (0.0, 0.0)));
            let nc = candidates(db, q, &mut work).len();
            QueryStat {
                time: best,
                examined,
                nc,
                accepted,
                correct,
                vicinity_ratio,
                explained_ratio,
            }
        })
        .collect()
}

/// The `p`-quantile (0..=1, nearest rank) of durations.
pub fn quantile(v: &[Duration], p: f64) -> Duration {
    if v.is_empty() {
        return Duration::ZERO;
    }
    let mut s = v.to_vec();
    s.sort();
    let i = ((p * (s.len() - 1) as f64).round() as usize).min(s.len() - 1);
    s[i]
}

/// The median of durations (mean of the middle two for an even count).
pub fn median(v: &[Duration]) -> Duration {
    if v.is_empty() {
        return Duration::ZERO;
    }
    let mut s = v.to_vec();
    s.sort();
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        (s[n / 2 - 1] + s[n / 2]) / 2
    }
}
