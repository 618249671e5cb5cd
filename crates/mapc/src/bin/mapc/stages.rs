//! `mapc stages` (hidden): the distance transform and GVD stages of `mapc
//! build` on their own, timed, with their outputs written as `.npy` arrays
//! for comparisons with other implementations (`bench/peers`).
//!
//! Arrays are `height x width`, row `cy` (0 = the map's bottom row, as in
//! the grid), column `cx`:
//! - `cells.npy` (u8): 0 free, 1 occupied, 2 unknown;
//! - `obstacle.npy` (u8): 1 where the distance transform counts an
//!   obstacle (occupied, unknown unless `--unknown-free`, the border ring);
//! - `sqdist.npy` (f32): squared distance (cells^2) from each cell centre
//!   to the nearest obstacle cell centre;
//! - `gvd.npy` (u8): 1 on the GVD skeleton cells.
//!
//! A JSON summary (times in seconds: minimum and median over `--repeat`
//! runs) goes to stdout and to `stages.json`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use mapc::compiler::edt::{self, DistanceField};
use mapc::compiler::gvd::{self, GvdOptions};
use mapc::compiler::mapfile::Cell;
use serde_json::json;

use crate::build::{load_map, BuildOpts, MapLimitArgs};
use crate::util::outln;
use crate::util::{fail_err, input_err, parse_triple, CliResult, Ui};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The map (YAML, or image with --resolution).
    pub map: PathBuf,
    /// Output directory for the arrays and stages.json.
    #[arg(long, default_value = "build-artifacts/stages", value_name = "DIR")]
    pub out: PathBuf,
    /// Metres per cell, for an image without a YAML.
    #[arg(long, value_name = "M")]
    pub resolution: Option<f64>,
    /// Origin "x,y,yaw" for an image without a YAML.
    #[arg(long, value_name = "X,Y,YAW", value_parser = parse_triple, allow_hyphen_values = true)]
    pub origin: Option<[f64; 3]>,
    /// Timed runs of each stage.
    #[arg(long, default_value_t = 5)]
    pub repeat: usize,
    #[command(flatten)]
    pub opts: BuildOpts,
    #[command(flatten)]
    pub limits: MapLimitArgs,
}

/// Writes a 2-D `.npy` array (format 1.0, C order).
fn write_npy(path: &Path, descr: &str, h: u32, w: u32, data: &[u8]) -> std::io::Result<()> {
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({h}, {w}), }}");
    // Magic (6) + version (2) + length (2) + header + '\n', padded to 64.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + data.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    std::fs::write(path, out)
}

/// Runs `f` `n` times; (min, median) seconds and the last result.
fn timed<T>(n: usize, mut f: impl FnMut() -> T) -> (f64, f64, T) {
    let mut times = Vec::with_capacity(n.max(1));
    let mut last = None;
    for _ in 0..n.max(1) {
        let t = Instant::now();
        let r = f();
        times.push(t.elapsed().as_secs_f64());
        last = Some(r);
    }
    times.sort_by(|a, b| a.total_cmp(b));
    let r = last.expect("at least one run");
    (times[0], times[times.len() / 2], r)
}

pub fn run(a: Args, _ui: &Ui) -> CliResult {
    let src = load_map(&a.map, a.resolution, a.origin, &a.limits).map_err(input_err)?;
    let cfg = a.opts.config();
    let g = &src.grid;
    let (w, h) = (g.width as usize, g.height as usize);
    // The same calls, with the same options, as `pipeline::build`.
    let (edt_min, edt_med, df) =
        timed(a.repeat, || DistanceField::from_grid(g, cfg.unknown_blocks));
    let obstacle: Vec<u8> = (0..w * h).map(|i| df.is_obstacle(i) as u8).collect();
    // Distances only (no feature transform), same obstacles.
    let (sq_min, sq_med, sq) = timed(a.repeat, || edt::squared_edt(w, h, |i| obstacle[i] != 0));
    let gopts = GvdOptions {
        robot_radius_m: cfg.robot_radius,
        unknown_is_obstacle: cfg.unknown_blocks,
        ..GvdOptions::default()
    };
    let (gvd_min, gvd_med, graph) = timed(a.repeat, || gvd::extract(g, &df, &gopts));
    let same = sq == df.sq;

    let cells: Vec<u8> = g
        .cells
        .iter()
        .map(|c| match c {
            Cell::Free => 0,
            Cell::Occupied => 1,
            Cell::Unknown => 2,
        })
        .collect();
    let sqdist: Vec<u8> = df.sq.iter().flat_map(|v| v.to_le_bytes()).collect();
    let mut gvd_mask = vec![0u8; w * h];
    for &(cx, cy) in &graph.cells {
        gvd_mask[cy as usize * w + cx as usize] = 1;
    }
    std::fs::create_dir_all(&a.out)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", a.out.display())))?;
    for (name, descr, data) in [
        ("cells.npy", "|u1", &cells),
        ("obstacle.npy", "|u1", &obstacle),
        ("sqdist.npy", "<f4", &sqdist),
        ("gvd.npy", "|u1", &gvd_mask),
    ] {
        let p = a.out.join(name);
        write_npy(&p, descr, g.height, g.width, data)
            .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", p.display())))?;
    }
    let summary = json!({
        "map": a.map.display().to_string(),
        "width": g.width, "height": g.height, "resolution": g.resolution, "origin": g.origin,
        "threads": rayon::current_num_threads(),
        "repeat": a.repeat.max(1),
        "unknown_is_obstacle": cfg.unknown_blocks,
        "robot_radius_m": cfg.robot_radius,
        "edt_with_features_s": {"min": edt_min, "median": edt_med},
        "edt_distances_only_s": {"min": sq_min, "median": sq_med},
        "distances_only_equal": same,
        "gvd_s": {"min": gvd_min, "median": gvd_med},
        "gvd_cells": graph.cells.len(),
        "gvd_nodes": graph.nodes.len(),
        "gvd_edges": graph.edges.len(),
        "gvd_length_m": graph.total_length_m(),
    });
    let text = serde_json::to_string_pretty(&summary).unwrap_or_default();
    let p = a.out.join("stages.json");
    std::fs::write(&p, &text).map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", p.display())))?;
    outln!("{text}");
    Ok(ExitCode::SUCCESS)
}
