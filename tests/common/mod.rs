//! Helpers shared by the top-level integration tests (`no_alloc`, `threads`),
//! which build as tests of the mapc package: make a map, compile it into a
//! `.refdb` in memory, and simulate scans in it.
#![allow(dead_code)]

use std::path::Path;
use std::time::Instant;

use mapc::compiler::mapfile::{self, Cell, MapSource};
use mapc::compiler::pipeline::{self, BuildConfig};
use mapc::compiler::rng::Rng;
use mapc::compiler::sim::{self, Lidar, Noise};
use mapc::tools::synth::{self, SynthKind, SynthOptions};
use refloc::format::SectionKind;
use refloc::{Pose2, RangeScan, RefDb, Scan};

/// The Intel Research Lab map, when the shared data is present.
pub const INTEL_YAML: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../../shared/maps/intel/intel.yaml"
);

/// A compiled database held in a `u32`-backed (4-byte aligned) buffer.
pub struct Db {
    words: Vec<u32>,
    len: usize,
    /// The map it was built from.
    pub source: MapSource,
}

impl Db {
    /// The file image.
    pub fn bytes(&self) -> &[u8] {
        let all: &[u8] = zerocopy::IntoBytes::as_bytes(&self.words[..]);
        &all[..self.len]
    }

    /// A validated view.
    pub fn open(&self) -> RefDb<&[u8]> {
        let db = RefDb::new(self.bytes()).expect("a freshly built database is valid");
        db.verify().expect("checksums of a freshly built database");
        db
    }
}

/// Encodes sections into a file image.
pub fn encode(sections: &[(SectionKind, Vec<u8>)]) -> Vec<u8> {
    let refs: Vec<(SectionKind, &[u8])> =
        sections.iter().map(|(k, b)| (*k, b.as_slice())).collect();
    let mut out = Vec::new();
    refloc::format::encode(&refs, |b: &[u8]| -> Result<(), ()> {
        out.extend_from_slice(b);
        Ok(())
    })
    .expect("encoding into a Vec cannot fail");
    out
}

/// Generates a synthetic office of `width x height` cells, writes it as a ROS
/// map into `dir` and loads it back the way `mapc build` does.
pub fn office_map(dir: &Path, width: u32, height: u32, seed: u64) -> MapSource {
    let opts = SynthOptions {
        seed,
        ..SynthOptions::new(SynthKind::Office, width, height)
    };
    let map = synth::generate(&opts);
    let (yaml, _) = synth::write_ros_map(dir, "office", &map, [0.0, 0.0, 0.0])
        .expect("write the synthetic map");
    mapfile::load_yaml(&yaml).expect("load the synthetic map")
}

/// Compiles `source` into a database (in memory, 4-byte aligned).
pub fn build(source: MapSource, fit_queries: usize) -> Db {
    build_with(
        source,
        &BuildConfig {
            fit_queries,
            ..Default::default()
        },
    )
}

/// Compiles `source` with `cfg` into a database (in memory, 4-byte aligned).
pub fn build_with(source: MapSource, cfg: &BuildConfig) -> Db {
    let t = Instant::now();
    let out = pipeline::build(&source, cfg).expect("build the database");
    let bytes = encode(&out.sections);
    let mut words = vec![0u32; bytes.len().div_ceil(4)];
    zerocopy::IntoBytes::as_mut_bytes(&mut words[..])[..bytes.len()].copy_from_slice(&bytes);
    eprintln!(
        "built a {} x {} map: {} sites, {} bytes, {:.1} s",
        source.grid.width,
        source.grid.height,
        out.sites.len(),
        bytes.len(),
        t.elapsed().as_secs_f64()
    );
    Db {
        words,
        len: bytes.len(),
        source,
    }
}

/// A simulated input scan.
pub enum TestScan {
    /// Ranges with beam geometry.
    Ranges { lidar: Lidar, ranges: Vec<f32> },
    /// Sensor-frame points.
    Points {
        points: Vec<[f32; 2]>,
        range_max: f32,
    },
}

impl TestScan {
    /// As the localizer's input.
    pub fn scan(&self) -> Scan<'_> {
        match self {
            TestScan::Ranges { lidar, ranges } => Scan::Ranges(RangeScan {
                angle_min: lidar.angle_min,
                angle_increment: lidar.angle_increment,
                range_min: lidar.range_min,
                range_max: lidar.range_max,
                ranges,
            }),
            TestScan::Points { points, range_max } => Scan::Points {
                points,
                range_max: *range_max,
            },
        }
    }

    /// Beams or points.
    pub fn len(&self) -> usize {
        self.scan().len()
    }

    /// What kind of scan, for messages.
    pub fn describe(&self) -> String {
        match self {
            TestScan::Ranges { lidar, .. } => format!(
                "{} beams over {:.0} deg",
                lidar.beams,
                (lidar.angle_increment * lidar.beams as f32).to_degrees()
            ),
            TestScan::Points { points, .. } => format!("{} points", points.len()),
        }
    }
}

/// A scan and the robot pose it was taken at.
pub struct Sample {
    /// True robot (= sensor) pose in the map frame.
    pub truth: Pose2,
    /// The scan.
    pub scan: TestScan,
}

/// A random free pose at least `clearance` metres from any non-free cell.
pub fn free_pose(src: &MapSource, clearance: f64, rng: &mut Rng) -> Pose2 {
    let g = &src.grid;
    let r = (clearance / g.resolution).ceil() as i64;
    for _ in 0..100_000 {
        let (cx, cy) = (
            rng.below(g.width as u64) as i64,
            rng.below(g.height as u64) as i64,
        );
        let clear = (-r..=r).all(|dy| {
            (-r..=r).all(|dx| {
                let (x, y) = (cx + dx, cy + dy);
                x >= 0
                    && y >= 0
                    && x < g.width as i64
                    && y < g.height as i64
                    && g.get(x as u32, y as u32) == Cell::Free
            })
        });
        if clear {
            let c = g.cell_to_map([cx as f64 + rng.uniform(), cy as f64 + rng.uniform()]);
            return Pose2::new(
                c[0] as f32,
                c[1] as f32,
                rng.range(-std::f64::consts::PI, std::f64::consts::PI) as f32,
            );
        }
    }
    panic!("no free pose with {clearance} m clearance");
}

/// `n` noisy scans at random free poses, cycling through a 362-beam
/// 360-degree scanner, a 181-beam 180-degree one, and point input from the
/// 362-beam scanner.
pub fn simulate(db: &RefDb<&[u8]>, src: &MapSource, n: usize, seed: u64) -> Vec<Sample> {
    let mut rng = Rng::new(seed);
    let grid = db.grid();
    let frame = db.frame();
    let full = Lidar::new(362, 2.0 * std::f32::consts::PI, 30.0);
    let half = Lidar::new(181, std::f32::consts::PI, 30.0);
    let noise = Noise {
        range_sigma: 0.01,
        short_outliers: 3,
    };
    (0..n)
        .map(|i| {
            let truth = free_pose(src, 0.4, &mut rng);
            let lidar = if i % 3 == 1 { half } else { full };
            let mut ranges = sim::virtual_scan(&grid, &frame, &truth, &lidar);
            sim::add_noise(&mut ranges, &lidar, &noise, &mut rng);
            let scan = if i % 3 == 2 {
                TestScan::Points {
                    points: sim::to_points(&ranges, &lidar),
                    range_max: lidar.range_max,
                }
            } else {
                TestScan::Ranges { lidar, ranges }
            };
            Sample { truth, scan }
        })
        .collect()
}

/// Position and heading error of `pose` against `truth` (m, rad).
pub fn error(pose: &Pose2, truth: &Pose2) -> (f32, f32) {
    (
        ((pose.x - truth.x).powi(2) + (pose.y - truth.y).powi(2)).sqrt(),
        refloc::wrap_angle(pose.theta - truth.theta).abs(),
    )
}

/// Simulated scans of a database file, for tests that run `mapc localize`:
/// `n` poses sampled in its free space (seed `seed`), a noise-free 362-beam
/// full-turn scan at each, written as JSON Lines with ids `s0`, `s1`, ...
/// (no return as null). Returns the poses and the text.
pub fn jsonl_scans(db_file: &[u8], n: usize, seed: u64) -> (Vec<Pose2>, String) {
    let mut words = vec![0u32; db_file.len().div_ceil(4)];
    zerocopy::IntoBytes::as_mut_bytes(&mut words[..])[..db_file.len()].copy_from_slice(db_file);
    let db = RefDb::new(&zerocopy::IntoBytes::as_bytes(&words[..])[..db_file.len()])
        .expect("a database built by mapc reads");
    let poses = mapc::tools::eval::sample_poses(&db, n, 0.4, seed);
    let lidar = Lidar::new(362, 2.0 * std::f32::consts::PI, 30.0);
    let mut lines = String::new();
    for (k, p) in poses.iter().enumerate() {
        let ranges = sim::virtual_scan(&db.grid(), &db.frame(), p, &lidar);
        let data = mapc::tools::scanio::ScanData::Ranges {
            angle_min: lidar.angle_min,
            angle_increment: lidar.angle_increment,
            range_min: 0.0,
            range_max: 30.0,
            ranges: ranges
                .iter()
                .map(|r| if r.is_finite() { *r } else { f32::NAN })
                .collect(),
        };
        lines.push_str(&mapc::tools::scanio::scan_to_json(
            &data,
            &format!("s{k}"),
            None,
        ));
        lines.push('\n');
    }
    (poses, lines)
}
