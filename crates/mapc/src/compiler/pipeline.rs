//! `mapc build` as a library call: map source → distance field → GVD →
//! sites → compiled sections → manifest. The binary adds progress, the
//! summary and the atomic write.

use std::time::Instant;

use refloc::format::SectionKind;
use refloc::params::{
    CoarseParams, Params, PrepParams, RefineParams, SelectParams, Selection, SensorModel,
    SsmParams, VerifyParams,
};
use refloc::Pose2;
use serde::Serialize;
use sha2::Digest;

use crate::compiler::compile::{self, CompileInput, Compiled, SiteIn};
use crate::compiler::edt::DistanceField;
use crate::compiler::error::BuildError;
use crate::compiler::fit::FitReport;
use crate::compiler::gvd::{self, GvdGraph, GvdOptions};
use crate::compiler::mapfile::MapSource;
use crate::compiler::sites::{self, SiteOptions, SitePlacement};

/// Every option of a build, validated (see `mapc build --help` for the
/// command-line form and defaults).
#[derive(Clone, Debug, Serialize)]
pub struct BuildConfig {
    /// Beams per reference scan (over 360 degrees).
    pub beams: u32,
    /// Reference sensor maximum range (m).
    pub range_max: f32,
    /// Sensor mounting pose on the robot (m, m, rad).
    pub sensor_offset: [f32; 3],
    /// Unknown cells stop beams and count as obstacles for the distance map.
    pub unknown_blocks: bool,
    /// Robot radius (m): sites keep at least this clearance.
    pub robot_radius: f64,
    /// Largest spacing between sites along a GVD edge (m).
    pub site_spacing: f64,
    /// Line-of-sight range of the coverage check (m).
    pub coverage_range: f64,
    /// Simulated queries for the logistic weight fit (0 keeps defaults).
    pub fit_queries: usize,
    /// Seed of every random choice in the build.
    pub seed: u64,
    /// Most coarse candidates.
    pub nc_max: u32,
    /// Vicinity acceptance ratio (paper 0.5).
    pub accept_ratio: f32,
    /// Site selection rule; the manifest spells it [`selection_name`]
    /// ("vicinity" or "match-score", the paper's).
    #[serde(serialize_with = "serialize_selection")]
    pub selection: Selection,
    /// Pose refinement iterations against the map (0: off, as the paper).
    pub refine_iters: u32,
    /// SSM tentative correspondences per input point.
    pub tentative_k: u32,
    /// Most resampled points per scan.
    pub max_points: u32,
    /// Early-stop ratio of the candidate loop (0: examine every candidate;
    /// the confidence stops of `refloc::select` are off too).
    pub early_accept: f32,
    /// Widths (degrees) of the window histograms stored for partial fields
    /// of view, at most two, ascending; empty stores none.
    pub fov_windows_deg: Vec<f32>,
    /// Stop after this many candidates once one passes the acceptance threshold.
    pub early_min: u32,
    /// Ambiguity rejection ratio (0: off).
    pub ambiguity_ratio: f32,
    /// Most stored SSM affinity entries (8 bytes of scratch each).
    pub affinity_cap: u32,
    /// Free-space check: most beams through walls, as a share of the beams (0: off).
    pub through_max: f32,
    /// Weight of a short beam against a pose, as a share of a hit's (0: the paper's M).
    pub short_weight: f32,
    /// Free-space check: least run of consecutive through-wall beams that counts.
    pub through_run: u32,
    /// Short beams cost nothing when the other beams fit at least this well (0: always).
    pub occlusion_fit: f32,
    /// Accept a pose when its confidence (the probability that it is right,
    /// `refloc::confidence`) is at least this (0..=1); stored with the
    /// default model in the decision section.
    pub accept_confidence: f32,
    /// Store the reference side of SSM (each site's prepared points,
    /// tangents and descriptors: the features section, up to 12.8 KB per
    /// site with 160 points) so that the runtime does not compute it per
    /// candidate; off leaves the section out (smaller file, for
    /// flash-constrained targets; the answers are the same).
    pub ssm_features: bool,
    /// The coarse-search index (built for maps with at least
    /// `index.min_sites` sites; its seed is replaced by `seed`).
    pub index: crate::compiler::index::IndexOptions,
    /// Largest database the build may write (bytes, [`compile::db_size`]:
    /// every section but the coarse-search index and the manifest),
    /// checked once the sites are placed, before any per-site data is
    /// computed. A bound, not an option of the result: it is not stored in
    /// the manifest.
    #[serde(skip)]
    pub max_db_bytes: u64,
}

/// The name of a site selection rule on the command line and in the
/// manifest: "vicinity" or "match-score".
pub fn selection_name(s: Selection) -> &'static str {
    match s {
        Selection::Vicinity => "vicinity",
        Selection::MatchScore => "match-score",
    }
}

fn serialize_selection<S: serde::Serializer>(s: &Selection, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_str(selection_name(*s))
}

impl Default for BuildConfig {
    fn default() -> Self {
        let p = Params::defaults(362, 30.0);
        BuildConfig {
            beams: 362,
            range_max: 30.0,
            sensor_offset: [0.0; 3],
            unknown_blocks: true,
            robot_radius: 0.2,
            site_spacing: SiteOptions::default().edge_spacing_m,
            coverage_range: 8.0,
            fit_queries: 150,
            seed: 1,
            nc_max: p.coarse.nc_max,
            accept_ratio: 0.5,
            selection: p.select.selection,
            refine_iters: p.refine.refine_iters,
            tentative_k: p.ssm.tentative_k,
            max_points: p.prep.max_points,
            early_accept: p.select.early_accept,
            fov_windows_deg: vec![180.0, 270.0],
            early_min: p.select.early_min,
            ambiguity_ratio: p.select.ambiguity_ratio,
            affinity_cap: p.ssm.affinity_cap,
            through_max: p.verify.through_max,
            short_weight: p.verify.short_weight,
            through_run: p.verify.through_run,
            occlusion_fit: p.verify.occlusion_fit,
            accept_confidence: refloc::Decision::DEFAULT.threshold,
            ssm_features: true,
            index: crate::compiler::index::IndexOptions::default(),
            max_db_bytes: compile::DEFAULT_MAX_DB_BYTES,
        }
    }
}

impl BuildConfig {
    /// Runtime parameters for this configuration (before the fit): the
    /// defaults for the sensor, with each group's options set.
    pub fn params(&self) -> Result<Params, BuildError> {
        let d = Params::defaults(self.beams, self.range_max);
        let [x, y, theta] = self.sensor_offset;
        let p = Params {
            sensor: SensorModel {
                offset: Pose2::new(x, y, theta),
                ..d.sensor
            },
            prep: PrepParams {
                max_points: self.max_points,
                ..d.prep
            },
            coarse: CoarseParams {
                nc_max: self.nc_max,
                nc_min: d.coarse.nc_min.min(self.nc_max),
                win_widths: self.win_widths()?,
                ..d.coarse
            },
            ssm: SsmParams {
                tentative_k: self.tentative_k,
                affinity_cap: self.affinity_cap,
                ..d.ssm
            },
            refine: RefineParams {
                refine_iters: self.refine_iters,
                ..d.refine
            },
            verify: VerifyParams {
                accept_ratio: self.accept_ratio,
                through_max: self.through_max,
                short_weight: self.short_weight,
                through_run: self.through_run,
                occlusion_fit: self.occlusion_fit,
                ..d.verify
            },
            select: SelectParams {
                selection: self.selection,
                early_accept: self.early_accept,
                early_min: self.early_min,
                ambiguity_ratio: self.ambiguity_ratio,
            },
        };
        p.validate().map_err(BuildError::Option)?;
        Ok(p)
    }

    /// The stored window widths (rad; 0 for an unused slot) from
    /// `fov_windows_deg` (degrees, at most two).
    fn win_widths(&self) -> Result<[f32; 2], BuildError> {
        if self.fov_windows_deg.len() > 2 {
            return Err(BuildError::TooManyWindows {
                given: self.fov_windows_deg.len(),
            });
        }
        let mut widths = [0.0; 2];
        for (slot, w) in widths.iter_mut().zip(&self.fov_windows_deg) {
            *slot = w.to_radians();
        }
        Ok(widths)
    }
}

/// Wall-clock time of each stage (s).
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageTimes {
    /// Distance transform.
    pub edt: f64,
    /// GVD and graph.
    pub gvd: f64,
    /// Site placement (with coverage fill).
    pub sites: f64,
    /// Reference scans, histograms, fit, sections.
    pub compile: f64,
    /// Finer steps, in order (`mapc build --timings` prints them).
    pub steps: Vec<StepTime>,
}

/// One step of a build: its wall-clock and process CPU time, and the peak
/// resident set of the process when it ended.
#[derive(Clone, Debug, Serialize)]
pub struct StepTime {
    /// Step name ("edt", "compile.windows", ...).
    pub name: &'static str,
    /// Wall-clock time (s).
    pub wall: f64,
    /// CPU time of the whole process, all threads, user + system (s); `None`
    /// where `/proc/self/stat` cannot be read.
    pub cpu: Option<f64>,
    /// Peak resident set size of the process so far (bytes, `VmHWM`);
    /// `None` where `/proc/self/status` cannot be read.
    pub peak_rss: Option<u64>,
}

/// CPU time (user + system, all threads) of this process so far (s), from
/// `/proc/self/stat` (Linux; in USER_HZ = 100 ticks per second).
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name; utime and stime are the
    // 14th and 15th fields of the line, the 12th and 13th after it.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut f = rest.split_whitespace().skip(11);
    let utime: u64 = f.next()?.parse().ok()?;
    let stime: u64 = f.next()?.parse().ok()?;
    Some((utime + stime) as f64 / 100.0)
}

/// Peak resident set size of this process so far (bytes, `VmHWM` of
/// `/proc/self/status`; Linux).
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Measures consecutive steps: each [`Laps::lap`] ends one.
pub struct Laps {
    wall: Instant,
    cpu: Option<f64>,
    steps: Vec<StepTime>,
}

impl Laps {
    /// Starts the first step now.
    pub fn start() -> Self {
        Laps {
            wall: Instant::now(),
            cpu: process_cpu_seconds(),
            steps: Vec::new(),
        }
    }

    /// Ends the current step, naming it, and starts the next.
    pub fn lap(&mut self, name: &'static str) {
        let cpu = process_cpu_seconds();
        self.steps.push(StepTime {
            name,
            wall: self.wall.elapsed().as_secs_f64(),
            cpu: cpu.zip(self.cpu).map(|(b, a)| b - a),
            peak_rss: peak_rss_bytes(),
        });
        self.wall = Instant::now();
        self.cpu = cpu;
    }

    /// The steps measured so far.
    pub fn steps(&self) -> &[StepTime] {
        &self.steps
    }

    /// The measured steps.
    pub fn into_steps(self) -> Vec<StepTime> {
        self.steps
    }
}

/// What a build produced.
pub struct BuildOutput {
    /// The section bytes, manifest last.
    pub sections: Vec<(SectionKind, Vec<u8>)>,
    /// The GVD graph.
    pub gvd: GvdGraph,
    /// The sites.
    pub sites: Vec<SitePlacement>,
    /// Coverage of the sites.
    pub coverage: sites::Coverage,
    /// Stored runtime parameters.
    pub params: Params,
    /// Logistic fit.
    pub fit: FitReport,
    /// Stage times.
    pub times: StageTimes,
    /// Reference scans (m) per site.
    pub scans: Vec<Vec<f32>>,
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// Refuses a build whose database would exceed `max_db_bytes` (see
/// [`compile::db_size`]), saying how large it would be and why: a map with
/// a resolution far from its scale (say 100 m per cell) makes a site of
/// almost every free cell, some 16 KB each.
fn check_db_size(
    src: &MapSource,
    params: &Params,
    sites: &[sites::SitePlacement],
    cfg: &BuildConfig,
) -> Result<(), BuildError> {
    let grid = &src.grid;
    let links = sites.iter().map(|s| s.neighbours.len() as u64).sum();
    let size = compile::db_size(
        params,
        grid.width,
        grid.height,
        sites.len(),
        links,
        cfg.ssm_features,
    );
    let max_db_bytes = cfg.max_db_bytes;
    if size.total <= max_db_bytes {
        return Ok(());
    }
    Err(BuildError::TooLarge {
        total: size.total,
        sites: size.sites,
        per_site: size.per_site,
        free_cells: grid.free_count(),
        resolution: grid.resolution,
        limit: max_db_bytes,
    })
}

/// Builds the database sections of `src` with `cfg`. Deterministic: the
/// same inputs and options give identical bytes whatever the thread count.
pub fn build(src: &MapSource, cfg: &BuildConfig) -> Result<BuildOutput, BuildError> {
    let params = cfg.params()?;
    let grid = &src.grid;
    let mut times = StageTimes::default();
    let mut laps = Laps::start();
    let t = Instant::now();
    let mut df = DistanceField::from_grid(grid, cfg.unknown_blocks);
    times.edt = t.elapsed().as_secs_f64();
    laps.lap("edt");
    let t = Instant::now();
    let gopts = GvdOptions {
        robot_radius_m: cfg.robot_radius,
        unknown_is_obstacle: cfg.unknown_blocks,
        ..GvdOptions::default()
    };
    let graph = gvd::extract_with(grid, &df, &gopts, &mut |name| laps.lap(name));
    // Only the GVD needs the nearest obstacles (4 bytes per cell): free them.
    df.nearest = Vec::new();
    times.gvd = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let sopts = SiteOptions {
        robot_radius_m: cfg.robot_radius,
        edge_spacing_m: cfg.site_spacing,
        coverage_range_m: cfg.coverage_range,
        ..SiteOptions::default()
    };
    let blocked = grid.blocked_bits(cfg.unknown_blocks);
    let bitgrid = refloc::raycast::BitGrid::new(grid.width, grid.height, &blocked).ok_or(
        BuildError::GridTooLarge {
            width: grid.width,
            height: grid.height,
        },
    )?;
    let placed = sites::place_sites(grid, &df, &graph, &sopts);
    laps.lap("sites.place");
    check_db_size(src, &params, &placed, cfg)?;
    let coverage = sites::coverage(grid, &bitgrid, &df, &placed, 0.25, cfg.coverage_range);
    times.sites = t.elapsed().as_secs_f64();
    laps.lap("sites.coverage");
    let t = Instant::now();
    let site_in: Vec<SiteIn> = placed
        .iter()
        .map(|s| SiteIn {
            x: s.x,
            y: s.y,
            clearance: s.clearance_m,
            kind: s.kind as u32,
            neighbours: s.neighbours.clone(),
        })
        .collect();
    let input = CompileInput {
        width: grid.width,
        height: grid.height,
        frame: grid.frame(),
        blocked: &blocked,
        sq_dist: &df.sq,
        dist: None,
        unknown_blocks: cfg.unknown_blocks,
        free_cells: grid.free_count() as u64,
        params,
        fit_queries: cfg.fit_queries,
        fit_seed: cfg.seed,
    };
    let Compiled {
        mut sections,
        params,
        scans,
        fit,
    } = compile::compile_with(&input, &site_in, &mut |name| laps.lap(name))?;
    let index_opts = crate::compiler::index::IndexOptions {
        seed: cfg.seed,
        ..cfg.index.clone()
    };
    let section = |k: SectionKind| {
        sections
            .iter()
            .find(|(kind, _)| *kind == k)
            .map(|(_, b)| b.as_slice())
            .unwrap_or(&[])
    };
    let index = crate::compiler::index::build(
        section(SectionKind::Hists),
        section(SectionKind::Windows),
        &params,
        site_in.len(),
        &index_opts,
    )?;
    if let Some(bytes) = index {
        sections.push((SectionKind::Index, bytes));
    }
    let decision = refloc::Decision {
        threshold: cfg.accept_confidence,
        ..refloc::Decision::DEFAULT
    };
    if !decision.is_valid() {
        return Err(BuildError::AcceptConfidence(cfg.accept_confidence));
    }
    sections.push((
        SectionKind::Decision,
        zerocopy::IntoBytes::as_bytes(&refloc::format::DecisionRecord::of(&decision)).to_vec(),
    ));
    laps.lap("index");
    if cfg.ssm_features {
        sections.push((
            SectionKind::Features,
            compile::features_section(&scans, &params),
        ));
        laps.lap("features");
    }
    times.compile = t.elapsed().as_secs_f64();
    let manifest = serde_json::json!({
        "generator": "mapc",
        "mapc_version": env!("CARGO_PKG_VERSION"),
        "format_version": refloc::format::FORMAT_VERSION,
        "input": {
            "yaml": src.yaml_path.as_ref().and_then(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned()),
            "yaml_sha256": src.yaml_sha256.map(|h| hex(&h)),
            "image": src.image_path.file_name().map(|n| n.to_string_lossy().into_owned()),
            "image_sha256": hex(&src.image_sha256),
            "resolution": grid.resolution,
            "origin": grid.origin,
        },
        "options": cfg,
        "fit": fit,
        "sites": placed.len(),
        "coverage": coverage.fraction,
    });
    sections.push((SectionKind::Manifest, serde_json::to_vec_pretty(&manifest)?));
    laps.lap("manifest");
    times.steps = laps.into_steps();
    Ok(BuildOutput {
        sections,
        gvd: graph,
        sites: placed,
        coverage,
        params,
        fit,
        times,
        scans,
    })
}

/// SHA-256 of bytes, hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&sha2::Sha256::digest(bytes))
}

#[cfg(test)]
pub(crate) mod tests;
