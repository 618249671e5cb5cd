//! Shared fixture of the refloc benchmarks (`benches/localize.rs`) and of
//! the instruction-count driver (`src/bin/query-count.rs`).
//!
//! - [`Database`]: the Intel Research Lab map (`shared/maps/intel/intel.yaml`)
//!   compiled with `mapc::compiler::pipeline::build` and the default `BuildConfig`,
//!   encoded with `refloc::format::encode` into a 4-byte-aligned buffer. When
//!   the shared data is absent, a synthetic 600 x 400 office
//!   (`mapc::tools::synth`, seed 0) is used instead and [`Database::origin`] says so.
//! - [`scan_set`]: a fixed set of [`SCAN_COUNT`] simulated scans at seeded
//!   free poses (`mapc::tools::eval::sample_poses`, clearance 0.3 m, seed
//!   [`POSE_SEED`]) for each [`Kind`] of scanner, static (exact ranges) or
//!   dynamic (5 mm range noise and 60 random short returns, as `mapc eval`).
//! - [`Work`]: an owned scratch for a `refloc::Localizer`, whose stages
//!   the benchmarks run (and time) one at a time.

use std::path::Path;
use std::time::{Duration, Instant};

use mapc::compiler::mapfile::{self, MapSource};
use mapc::compiler::pipeline::{self, BuildConfig};
use mapc::compiler::rng::Rng;
use mapc::compiler::sim::{self, Lidar};
use mapc::tools::eval;
use mapc::tools::synth::{self, SynthKind, SynthOptions};
use refloc::verify;
use refloc::{localize, scratch_size, Localizer, Pose2, RangeScan, RefDb, Scan};

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
                    "SYNTHETIC office 600 x 400 cells (mapc::tools::synth, seed 0): \
                     shared/maps/intel/intel.yaml not found, numbers are NOT the Intel map's"
                        .to_string(),
                    Some(tmp),
                )
            }
        };
        let out = pipeline::build(&src, &BuildConfig::default()).map_err(|e| e.to_string())?;
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

/// One simulated query.
pub struct Query {
    /// True robot pose.
    pub truth: Pose2,
    /// The scanner.
    pub lidar: Lidar,
    /// Ranges (m; `INFINITY`: no return).
    pub ranges: Vec<f32>,
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
/// poses of `mapc::tools::eval::sample_poses(db, n, CLEARANCE, POSE_SEED)`.
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
            Query {
                truth: *truth,
                lidar,
                ranges,
                correct_site: eval::correct_site(db, [sensor.x, sensor.y]),
            }
        })
        .collect()
}

/// The scratch memory of a [`Localizer`], owned, so the benchmarks can run
/// the localizer's stages one at a time exactly as `refloc::localize` runs
/// them (the stages are the localizer's own methods).
pub struct Work {
    scratch: Vec<u8>,
    beams: usize,
}

impl Work {
    /// Scratch for scans of up to `beams` beams against `db`.
    pub fn new<D: AsRef<[u8]>>(db: &RefDb<D>, beams: usize) -> Work {
        Work {
            scratch: vec![0u8; scratch_size(db.params(), beams)],
            beams,
        }
    }

    /// A localizer over this scratch, no scan loaded yet.
    pub fn localizer<'d, 's, D: AsRef<[u8]>>(
        &'s mut self,
        db: &'d RefDb<D>,
    ) -> Option<Localizer<'d, 's, D>> {
        Localizer::new(db, &mut self.scratch, self.beams).ok()
    }

    /// A localizer with `q` loaded and prepared (stage 1 done); `None` when
    /// the localizer rejects the scan.
    pub fn prepared<'d, 's, D: AsRef<[u8]>>(
        &'s mut self,
        db: &'d RefDb<D>,
        q: &Query,
    ) -> Option<Localizer<'d, 's, D>> {
        let mut loc = self.localizer(db)?;
        loc.prepare(&q.scan()).ok()?;
        Some(loc)
    }
}

/// The coarse candidates (sites, best first) `refloc::localize` would
/// examine for `q` at most.
pub fn candidates<D: AsRef<[u8]>>(db: &RefDb<D>, q: &Query, work: &mut Work) -> Vec<usize> {
    let Some(mut loc) = work.prepared(db, q) else {
        return Vec::new();
    };
    loc.rank();
    loc.ranked().iter().map(|r| r.site as usize).collect()
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
    let mut work = Work::new(db, beams);
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
                                (
                                    verify::ratio(l.vicinity, pairs),
                                    verify::ratio(l.vicinity, pairs.saturating_sub(l.short_beams)),
                                )
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
