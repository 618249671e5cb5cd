//! `mapc demo`: the README's first command. Compiles the map the project
//! ships, localizes a batch of simulated scans, prints a summary table and
//! writes figures into `build-artifacts/demo/`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use mapc::compiler::pipeline;

use crate::build::{load_map, BuildOpts, DbLimitArgs, MapLimitArgs, SelectionArg};
use crate::eval::Experiment;
use crate::util::outln;
use crate::util::{fail_err, input_err, CliResult, Ui};

/// The shipped demo map, relative to the repository root.
pub const DEMO_MAP: &str = "maps/office-demo/office-demo.yaml";

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Map to use.
    #[arg(long, default_value = DEMO_MAP, value_name = "MAP.yaml")]
    pub map: PathBuf,
    /// Output directory.
    #[arg(long, default_value = "build-artifacts/demo", value_name = "DIR")]
    pub out: PathBuf,
    /// Simulated scans per experiment (1 to 1000000).
    #[arg(long, default_value_t = 200, value_parser = crate::util::count::<1, 1_000_000>)]
    pub poses: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub limits: MapLimitArgs,
    #[command(flatten)]
    pub db_limit: DbLimitArgs,
}

/// `mapc demo`: compiles the map into `--out`, evaluates it there and
/// prints the summary.
pub fn run(a: Args, ui: &Ui) -> CliResult {
    if !a.map.exists() {
        return Err(input_err(anyhow::anyhow!(
            "{} not found: run `mapc demo` from the repository root, or pass --map MAP.yaml",
            a.map.display()
        )));
    }
    std::fs::create_dir_all(&a.out)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", a.out.display())))?;
    let compiled = compile(&a)?;
    let quiet = Ui {
        quiet: true,
        tty: ui.tty,
    };
    let report = crate::eval::evaluate(&eval_args(&a, &compiled.db_path), &quiet)?;
    let rp = a.out.join("report.json");
    std::fs::write(
        &rp,
        serde_json::to_string_pretty(&report).unwrap_or_default(),
    )
    .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", rp.display())))?;
    print_summary(&a, &compiled, &report);
    Ok(ExitCode::SUCCESS)
}

/// The demo's map compiled into `--out`.
struct Compiled {
    /// The map it was compiled from.
    src: mapc::compiler::mapfile::MapSource,
    built: pipeline::BuildOutput,
    /// Where the database is.
    db_path: PathBuf,
    /// The database's size (bytes).
    size: u64,
    /// Time of loading, compiling and writing (s).
    build_s: f64,
}

/// Loads `--map`, compiles it with the demo's options and writes the
/// database into `--out` as `<map stem>.refdb`.
fn compile(a: &Args) -> Result<Compiled, crate::util::CliError> {
    let t0 = Instant::now();
    let src = load_map(&a.map, None, None, &a.limits).map_err(input_err)?;
    let opts = build_opts(a);
    let built = pipeline::build(&src, &opts.config()).map_err(|e| input_err(anyhow::anyhow!(e)))?;
    let stem = a
        .map
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "map".into());
    let db_path = a.out.join(format!("{stem}.refdb"));
    let secs: Vec<_> = built
        .sections
        .iter()
        .map(|(k, b)| (*k, b.as_slice()))
        .collect();
    let size = mapc::compiler::writer::write_refdb(&db_path, &secs)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", db_path.display())))?;
    let build_s = t0.elapsed().as_secs_f64();
    Ok(Compiled {
        src,
        built,
        db_path,
        size,
        build_s,
    })
}

/// The options `mapc build` would take for the demo: the defaults with
/// `--seed` and the database limits of the arguments.
fn build_opts(a: &Args) -> BuildOpts {
    BuildOpts {
        beams: 362,
        range_max: 30.0,
        sensor_offset: None,
        unknown_free: false,
        robot_radius: 0.2,
        site_spacing: None,
        fit_queries: 150,
        seed: a.seed,
        nc_max: None,
        accept_ratio: 0.5,
        selection: SelectionArg(refloc::Selection::Vicinity),
        refine_iters: None,
        tentative_k: None,
        max_points: None,
        early_accept: None,
        fov_windows: "180,270".into(),
        early_min: None,
        ambiguity_ratio: None,
        affinity_cap: None,
        through_max: None,
        short_weight: None,
        through_run: None,
        occlusion_fit: None,
        accept_confidence: refloc::Decision::DEFAULT.threshold,
        no_ssm_features: false,
        index_min_sites: mapc::compiler::index::IndexOptions::default().min_sites,
        index_beam: mapc::compiler::index::IndexOptions::default().beam,
        index_leaves: mapc::compiler::index::IndexOptions::default().leaves,
        index_leaf_size: mapc::compiler::index::IndexOptions::default().leaf_size,
        db_limit: a.db_limit.clone(),
    }
}

/// The `mapc eval` the demo runs on the database at `db_path`: E4
/// static, dynamic and dynamic-swap with `--poses` scans each, and E1,
/// report and figures into `--out`.
fn eval_args(a: &Args, db_path: &std::path::Path) -> crate::eval::Args {
    crate::eval::Args {
        db: db_path.to_path_buf(),
        poses: a.poses,
        seed: a.seed,
        clearance: 0.3,
        beams: 362,
        prior_radius: 0.0,
        prior_heading_tol: 0.0,
        fov: 360.0,
        range_max: 30.0,
        noise: 0.005,
        outliers: 60,
        experiments: vec![
            Experiment::Static,
            Experiment::Dynamic,
            Experiment::DynamicSwap,
            Experiment::E1,
        ],
        e1_trials: 100,
        e2_trials: 10,
        foreign: None,
        out: a.out.clone(),
        no_figures: false,
        dump: None,
        check: None,
        tol_rate: 0.02,
        tol_false_accept: 0.01,
        tol_error_factor: 1.5,
        limits: a.limits.clone(),
    }
}

/// The summary on stdout: the map, the database, a table of the E4 runs
/// and the E1 result of `report`.
fn print_summary(a: &Args, c: &Compiled, report: &serde_json::Value) {
    let g = &c.src.grid;
    outln!(
        "refloc demo: {} ({} x {} cells, {:.1} m x {:.1} m)",
        a.map.display(),
        g.width,
        g.height,
        g.width as f64 * g.resolution,
        g.height as f64 * g.resolution
    );
    outln!(
        "compiled {} sites, coverage {:.2}%, {} bytes in {:.2} s -> {}",
        c.built.sites.len(),
        100.0 * c.built.coverage.fraction,
        c.size,
        c.build_s,
        c.db_path.display()
    );
    outln!();
    print_table(report);
    if let Some(e1) = report.get("e1") {
        outln!();
        outln!(
            "scan-to-scan SSM (E1, {} trials): sd x {:.2} mm, y {:.2} mm, theta {:.3} deg (paper: 10.51 mm, 7.99 mm, 0.09 deg)",
            e1["trials"], e1["sd_mm_mm_deg"][0].as_f64().unwrap_or(f64::NAN), e1["sd_mm_mm_deg"][1].as_f64().unwrap_or(f64::NAN), e1["sd_mm_mm_deg"][2].as_f64().unwrap_or(f64::NAN)
        );
    }
    outln!();
    outln!("figures and report in {}/", a.out.display());
}

/// The table of the report's summaries, one row a run.
fn print_table(report: &serde_json::Value) {
    outln!(
        "{:<14} {:>6} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "scans",
        "n",
        "correct",
        "false acc",
        "|x| mm",
        "|y| mm",
        "|th| deg",
        "ms/query"
    );
    if let Some(m) = report["summaries"].as_object() {
        for (name, s) in m {
            let f = |k: &str| s[k].as_f64().unwrap_or(f64::NAN);
            outln!(
                "{:<14} {:>6} {:>9.1}% {:>9.1}% {:>10.1} {:>10.1} {:>10.2} {:>10.2}",
                name,
                s["n"],
                100.0 * f("success_rate"),
                100.0 * f("false_accept_rate"),
                1000.0 * f("mean_abs_x"),
                1000.0 * f("mean_abs_y"),
                f("mean_abs_theta").to_degrees(),
                f("median_time_us") / 1000.0
            );
        }
    }
}
