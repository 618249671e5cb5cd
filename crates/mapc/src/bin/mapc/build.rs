//! `mapc build`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use mapc::compiler::mapfile;
use mapc::compiler::pipeline::{self, BuildConfig};
use refloc::Selection;

use crate::util::{fail_err, input_err, parse_triple, CliResult, Ui};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The map: a ROS map_server YAML, or its PGM/PNG image (then the YAML
    /// beside it with the same stem is used, else --resolution is required).
    pub map: PathBuf,
    /// Output database [default: <map stem>.refdb in the current directory].
    #[arg(short, long, value_name = "OUT.refdb")]
    pub output: Option<PathBuf>,
    /// Metres per cell, for an image without a YAML beside it (with a YAML
    /// it must agree with the YAML's).
    #[arg(long, value_name = "M")]
    pub resolution: Option<f64>,
    /// Map-frame pose of the image's lower-left corner, for an image without
    /// a YAML: "x,y,yaw" (m, m, rad) (with a YAML it must agree with the
    /// YAML's).
    #[arg(long, value_name = "X,Y,YAW", value_parser = parse_triple, allow_hyphen_values = true)]
    pub origin: Option<[f64; 3]>,
    /// Print every step's wall-clock time, process CPU time and the peak
    /// resident set after it (Linux) on stderr, even with --quiet.
    #[arg(long)]
    pub timings: bool,
    #[command(flatten)]
    pub opts: BuildOpts,
    #[command(flatten)]
    pub limits: MapLimitArgs,
}

/// The map-size limit of every command that loads a map image.
#[derive(clap::Args, Debug, Clone)]
pub struct MapLimitArgs {
    /// Largest map accepted, in cells (width x height), checked on the image
    /// header before any pixel is decoded; the decoded image may take up to 4
    /// bytes per cell of this limit, and the file twice that plus 1 MiB
    /// [default: 268435456 = 16384 x 16384; at most 2147483648].
    #[arg(
        long,
        value_name = "CELLS",
        default_value_t = mapfile::DEFAULT_MAX_CELLS,
        hide_default_value = true,
        value_parser = clap::value_parser!(u64).range(1..=mapfile::MAX_CELLS)
    )]
    pub max_cells: u64,
}

impl MapLimitArgs {
    pub fn limits(&self) -> mapfile::MapLimits {
        mapfile::MapLimits {
            max_cells: self.max_cells,
        }
    }
}

/// Compile options shared by `build`, `demo` and `eval`.
#[derive(clap::Args, Debug, Clone)]
pub struct BuildOpts {
    /// Beams per 360-degree reference scan.
    #[arg(long, default_value_t = 362)]
    pub beams: u32,
    /// Maximum sensor range (m).
    #[arg(long, default_value_t = 30.0, value_name = "M")]
    pub range_max: f32,
    /// Sensor mounting pose on the robot "x,y,yaw" (m, m, rad).
    #[arg(long, value_name = "X,Y,YAW", value_parser = parse_triple, allow_hyphen_values = true)]
    pub sensor_offset: Option<[f64; 3]>,
    /// Treat unknown cells as free space (default: they stop beams and count as obstacles).
    #[arg(long)]
    pub unknown_free: bool,
    /// Robot radius (m): reference sites keep at least this clearance.
    #[arg(long, default_value_t = 0.2, value_name = "M")]
    pub robot_radius: f64,
    /// Largest spacing between reference sites along a GVD edge (m).
    #[arg(long, value_name = "M")]
    pub site_spacing: Option<f64>,
    /// Simulated queries used to fit the logistic weights (0: built-in weights; at most 100000).
    #[arg(long, default_value_t = 150, value_parser = crate::util::count::<0, 100_000>)]
    pub fit_queries: usize,
    /// Seed of every random choice in the build.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Most candidate sites for the fine stage.
    #[arg(long)]
    pub nc_max: Option<u32>,
    /// Vicinity acceptance ratio: accept when M > 4.5 * N_P * ratio (paper: 0.5).
    #[arg(long, default_value_t = 0.5)]
    pub accept_ratio: f32,
    /// Site selection rule.
    #[arg(long, value_enum, default_value_t = SelectionArg(Selection::Vicinity))]
    pub selection: SelectionArg,
    /// Gauss-Newton refinement iterations against the map (0: off, as in the paper).
    #[arg(long)]
    pub refine_iters: Option<u32>,
    /// SSM: tentative correspondences per input point (descriptor pruning).
    #[arg(long)]
    pub tentative_k: Option<u32>,
    /// Most resampled points per scan (SSM and histograms).
    #[arg(long)]
    pub max_points: Option<u32>,
    /// Stop examining candidates once one reaches M >= 4.5 N_P * ratio (0: examine every candidate, with no early or confidence stop: 3-5x the time, fewer false accepts for short-range sensors, docs/robot.md).
    #[arg(long)]
    pub early_accept: Option<f32>,
    /// Window widths (degrees, ascending, at most two) stored for scans with a
    /// partial field of view, or "none" for a 360-degree-only database.
    #[arg(long, default_value = "180,270", value_name = "DEG,DEG")]
    pub fov_windows: String,
    /// Also stop after this many candidates once one passes the acceptance threshold.
    #[arg(long)]
    pub early_min: Option<u32>,
    /// Reject as ambiguous when a clearly different pose scores at least this share of the best M (0: off).
    #[arg(long)]
    pub ambiguity_ratio: Option<f32>,
    /// Most stored SSM affinity entries per match (8 bytes of robot RAM each; the main part of the scratch).
    #[arg(long)]
    pub affinity_cap: Option<u32>,
    /// Free-space check: reject a pose when more than this share of the beams pass through a wall of the map (0: off).
    #[arg(long, value_name = "SHARE")]
    pub through_max: Option<f32>,
    /// Weight of a beam that ends short of the map's surface against the pose, as a share of a hit's (0: the paper's M).
    #[arg(long, value_name = "SHARE")]
    pub short_weight: Option<f32>,
    /// Free-space check: beams through a wall count only in runs of at least this many consecutive beams.
    #[arg(long, value_name = "BEAMS")]
    pub through_run: Option<u32>,
    /// Short beams cost nothing when the other beams fit the map at least this well (explained share; 0: they always cost --short-weight).
    #[arg(long, value_name = "SHARE")]
    pub occlusion_fit: Option<f32>,
    /// Accept a pose when its confidence (probability that it is right, 0-1) is at least this; stored in the .refdb.
    #[arg(long, value_name = "P", default_value_t = refloc::Decision::DEFAULT.threshold)]
    pub accept_confidence: f32,
    /// Leave out the stored reference side of SSM (each site's prepared points, tangents and descriptors, up to 80 bytes per point: 12.8 KB per site with 160 points); the runtime then computes it for every candidate (slower queries, same answers, smaller file for flash-constrained targets).
    #[arg(long)]
    pub no_ssm_features: bool,
    /// Build the coarse-search index (sublinear ranking of the sites) for maps with at least this many sites; smaller maps are ranked exhaustively.
    #[arg(long, value_name = "SITES", default_value_t = mapc::compiler::index::IndexOptions::default().min_sites)]
    pub index_min_sites: usize,
    /// Coarse-search index: internal nodes kept per level of the search (1-32; more: better recall, slower).
    #[arg(long, value_name = "NODES", default_value_t = mapc::compiler::index::IndexOptions::default().beam)]
    pub index_beam: u32,
    /// Coarse-search index: leaves whose sites are scored exactly (1-64; more: better recall, slower).
    #[arg(long, value_name = "LEAVES", default_value_t = mapc::compiler::index::IndexOptions::default().leaves)]
    pub index_leaves: u32,
    /// Coarse-search index: a tree node with at most this many sites (or site headings) is a leaf.
    #[arg(long, value_name = "ENTRIES", default_value_t = mapc::compiler::index::IndexOptions::default().leaf_size)]
    pub index_leaf_size: usize,
    #[command(flatten)]
    pub db_limit: DbLimitArgs,
}

/// One value of `mapc build --selection`: a site selection rule, spelt as
/// the manifest spells it ([`pipeline::selection_name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SelectionArg(pub Selection);

impl clap::ValueEnum for SelectionArg {
    fn value_variants<'a>() -> &'a [Self] {
        &[
            SelectionArg(Selection::Vicinity),
            SelectionArg(Selection::MatchScore),
        ]
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        let help = match self.0 {
            Selection::Vicinity => "largest vicinity score M",
            Selection::MatchScore => "largest matching score E (the paper)",
        };
        Some(clap::builder::PossibleValue::new(pipeline::selection_name(self.0)).help(help))
    }
}

/// The database-size limit of every command that compiles a map.
#[derive(clap::Args, Debug, Clone)]
pub struct DbLimitArgs {
    /// Largest database written, in bytes: the reference sites' data (about
    /// 16 KB per site with the default sensor and windows, and up to 12.8 KB
    /// more of stored SSM features unless --no-ssm-features), the grid and
    /// the distance map, checked once the sites are placed and before their
    /// scans and histograms are computed [default: 1073741824 = 1 GiB].
    #[arg(
        long,
        value_name = "BYTES",
        default_value_t = mapc::compiler::compile::DEFAULT_MAX_DB_BYTES,
        hide_default_value = true,
        value_parser = clap::value_parser!(u64).range(1..)
    )]
    pub max_db_bytes: u64,
}

impl BuildOpts {
    pub fn config(&self) -> BuildConfig {
        let d = BuildConfig::default();
        BuildConfig {
            beams: self.beams,
            range_max: self.range_max,
            sensor_offset: self
                .sensor_offset
                .map(|o| [o[0] as f32, o[1] as f32, o[2] as f32])
                .unwrap_or([0.0; 3]),
            unknown_blocks: !self.unknown_free,
            robot_radius: self.robot_radius,
            site_spacing: self.site_spacing.unwrap_or(d.site_spacing),
            coverage_range: d.coverage_range,
            fit_queries: self.fit_queries,
            seed: self.seed,
            nc_max: self.nc_max.unwrap_or(d.nc_max),
            accept_ratio: self.accept_ratio,
            selection: self.selection.0,
            refine_iters: self.refine_iters.unwrap_or(d.refine_iters),
            tentative_k: self.tentative_k.unwrap_or(d.tentative_k),
            max_points: self.max_points.unwrap_or(d.max_points),
            early_accept: self.early_accept.unwrap_or(d.early_accept),
            early_min: self.early_min.unwrap_or(d.early_min),
            ambiguity_ratio: self.ambiguity_ratio.unwrap_or(d.ambiguity_ratio),
            affinity_cap: self.affinity_cap.unwrap_or(d.affinity_cap),
            through_max: self.through_max.unwrap_or(d.through_max),
            short_weight: self.short_weight.unwrap_or(d.short_weight),
            through_run: self.through_run.unwrap_or(d.through_run),
            occlusion_fit: self.occlusion_fit.unwrap_or(d.occlusion_fit),
            accept_confidence: self.accept_confidence,
            ssm_features: !self.no_ssm_features,
            index: mapc::compiler::index::IndexOptions {
                min_sites: self.index_min_sites,
                beam: self.index_beam,
                leaves: self.index_leaves,
                leaf_size: self.index_leaf_size,
                ..d.index.clone()
            },
            max_db_bytes: self.db_limit.max_db_bytes,
            fov_windows_deg: if self.fov_windows.trim() == "none" {
                Vec::new()
            } else {
                self.fov_windows
                    .split(',')
                    .filter_map(|t| t.trim().parse::<f32>().ok())
                    .collect()
            },
        }
    }
}

/// Loads a map given as YAML or image.
pub fn load_map(
    map: &std::path::Path,
    resolution: Option<f64>,
    origin: Option<[f64; 3]>,
    limits: &MapLimitArgs,
) -> Result<mapfile::MapSource, mapfile::MapError> {
    let limits = limits.limits();
    let is_yaml = matches!(
        map.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("yaml") | Some("yml")
    );
    if is_yaml {
        // The YAML gives both; a value given as well must agree with it.
        let src = mapfile::load_yaml_within(map, &limits)?;
        mapfile::check_given(&src, map, resolution, origin)?;
        Ok(src)
    } else {
        mapfile::load_image_within(map, resolution, origin, &limits)
    }
}

pub fn run(a: Args, ui: &Ui) -> CliResult {
    let t0 = Instant::now();
    let cfg = a.opts.config();
    cfg.params().map_err(|e| input_err(anyhow::anyhow!(e)))?;
    cfg.index
        .validate()
        .map_err(|e| input_err(anyhow::anyhow!(e)))?;
    let out = a.output.clone().unwrap_or_else(|| {
        let stem = a
            .map
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "map".into());
        PathBuf::from(format!("{stem}.refdb"))
    });
    // Fail now, not after minutes of compiling, when the result could not
    // be saved (read-only or missing directory). Any existing file stays.
    // The output path is checked twice, each time against the inputs known
    // then: here against the map given (before check_writable, which would
    // otherwise report "." or a device as unwritable), and after loading
    // against the image and YAML the map names.
    let refuse_out = |e: std::io::Error| input_err(anyhow::anyhow!("-o {}: {e}", out.display()));
    mapc::compiler::writer::check_output_path(&out, &[&a.map]).map_err(refuse_out)?;
    mapc::compiler::writer::check_writable(&out)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: cannot write: {e}", out.display())))?;
    let sp = ui.stage("loading map");
    let mut laps = pipeline::Laps::start();
    let src = load_map(&a.map, a.resolution, a.origin, &a.limits).map_err(input_err)?;
    // The image (and the YAML) the map named are inputs too.
    mapc::compiler::writer::check_output_path(&out, &src.input_files()).map_err(refuse_out)?;
    laps.lap("load");
    sp.set_message("compiling");
    let mut built = pipeline::build(&src, &cfg)
        .map_err(|e| input_err(anyhow::anyhow!("{}: {e}", a.map.display())))?;
    laps.lap("build");
    sp.set_message("writing");
    let secs: Vec<_> = built
        .sections
        .iter()
        .map(|(k, b)| (*k, b.as_slice()))
        .collect();
    // The writer reads the new file back and verifies it before it takes
    // the name: a database that would not load is refused (exit 2, the
    // input made it) and an old file under `out` stays as it was.
    let size = mapc::compiler::writer::write_refdb(&out, &secs).map_err(|e| {
        let err = anyhow::anyhow!("{}: {e}", out.display());
        if e.kind() == std::io::ErrorKind::InvalidData {
            input_err(err.context(format!("{}: not compiled", a.map.display())))
        } else {
            fail_err(anyhow::anyhow!("{}: cannot write: {e}", out.display()))
        }
    })?;
    laps.lap("write and verify");
    drop(secs);
    built.sections = Vec::new();
    sp.finish_and_clear();
    if a.timings {
        let mut steps = laps.into_steps();
        // The pipeline's own steps replace the "build" lap.
        if let Some(k) = steps.iter().position(|s| s.name == "build") {
            steps.splice(k..=k, built.times.steps.iter().cloned());
        }
        eprintln!("  step              wall s     cpu s  peak RSS after (MiB)");
        for s in &steps {
            let cpu = s.cpu.map_or("-".into(), |c| format!("{c:.2}"));
            let rss = s
                .peak_rss
                .map_or("-".into(), |b| format!("{:.1}", b as f64 / 1048576.0));
            eprintln!("  {:<16} {:>7.3} {:>9} {:>10}", s.name, s.wall, cpu, rss);
        }
    }
    if !ui.quiet {
        let g = &src.grid;
        let res = g.resolution;
        let free = g.free_count();
        let gvd_len: f64 = built.gvd.edges.iter().map(|e| e.length_m).sum();
        eprintln!("mapc build {} -> {}", a.map.display(), out.display());
        eprintln!(
            "  grid           {} x {} cells at {:.3} m ({:.1} m x {:.1} m)",
            g.width,
            g.height,
            res,
            g.width as f64 * res,
            g.height as f64 * res
        );
        if res as f32 > refloc::verify::REFERENCE_CELL * 1.01 {
            eprintln!(
                "  note           cells coarser than the {} m the confidence model was fitted on: \
                 expect fewer scans accepted (docs/robot.md, \"Map cell size\"); \
                 save the map at {} m if you can",
                refloc::verify::REFERENCE_CELL,
                refloc::verify::REFERENCE_CELL
            );
        }
        eprintln!(
            "  free area      {:.1} m^2 ({} cells)",
            free as f64 * res * res,
            free
        );
        eprintln!(
            "  GVD            {:.1} m, {} nodes, {} edges",
            gvd_len,
            built.gvd.nodes.len(),
            built.gvd.edges.len()
        );
        eprintln!("  sites          {}", built.sites.len());
        eprintln!(
            "  coverage       {:.2}% of {} free cells (clearance >= 0.25 m) see a site within {:.0} m",
            100.0 * built.coverage.fraction,
            built.coverage.considered,
            cfg.coverage_range
        );
        eprintln!(
            "  logistic w     [{:.3}, {:.3}, {:.3}] from {} pairs of {} simulated scans",
            built.fit.w[0], built.fit.w[1], built.fit.w[2], built.fit.samples, built.fit.queries
        );
        let t = &built.times;
        eprintln!(
            "  stages         edt {:.3} s, gvd {:.3} s, sites {:.3} s, compile {:.3} s",
            t.edt, t.gvd, t.sites, t.compile
        );
        eprintln!("  build time     {:.2} s", t0.elapsed().as_secs_f64());
        eprintln!(
            "  file size      {} bytes ({:.2} MiB)",
            size,
            size as f64 / 1048576.0
        );
    }
    Ok(ExitCode::SUCCESS)
}
