//! `mapc render`: the map with its GVD, graph and sites (the paper's Fig.
//! 7b), optionally one site's virtual scan (Fig. 4) and its PGR histogram
//! (Fig. 9).

use std::path::PathBuf;
use std::process::ExitCode;

use mapc::compiler::pipeline;
use mapc::tools::plot;
use mapc::tools::render::{color, Corner, MapCanvas, MapLayer, Mark};

use crate::build::{load_map, BuildOpts, MapLimitArgs};
use crate::util::outln;
use crate::util::{fail_err, input_err, parse_triple, CliResult, Ui};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The map (YAML, or image with --resolution).
    pub map: PathBuf,
    /// Output PNG [default: build-artifacts/<stem>.png].
    #[arg(short, long, value_name = "OUT.png")]
    pub output: Option<PathBuf>,
    /// Metres per cell, for an image without a YAML.
    #[arg(long, value_name = "M")]
    pub resolution: Option<f64>,
    /// Origin "x,y,yaw" for an image without a YAML.
    #[arg(long, value_name = "X,Y,YAW", value_parser = parse_triple, allow_hyphen_values = true)]
    pub origin: Option<[f64; 3]>,
    /// Also draw this site's virtual scan, and write its PGR histogram to <OUT>-site<N>-hist.png.
    #[arg(long, value_name = "N")]
    pub site: Option<usize>,
    /// Longest side of the image (pixels, 64 to 16384).
    #[arg(long, default_value_t = 1600, value_parser = clap::value_parser!(u32).range(64..=16384))]
    pub size: u32,
    #[command(flatten)]
    pub opts: BuildOpts,
    #[command(flatten)]
    pub limits: MapLimitArgs,
}

pub fn run(a: Args, ui: &Ui) -> CliResult {
    let src = load_map(&a.map, a.resolution, a.origin, &a.limits).map_err(input_err)?;
    if let Some(out) = &a.output {
        let mut inputs = src.input_files();
        inputs.push(&a.map);
        mapc::compiler::writer::check_output_path(out, &inputs)
            .map_err(|e| input_err(anyhow::anyhow!("-o {}: {e}", out.display())))?;
    }
    let cfg = BuildOpts {
        fit_queries: 0,
        ..a.opts.clone()
    }
    .config();
    let built = pipeline::build(&src, &cfg)
        .map_err(|e| input_err(anyhow::anyhow!("{}: {e}", a.map.display())))?;
    let g = &src.grid;
    let out = a.output.clone().unwrap_or_else(|| {
        let stem = a
            .map
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "map".into());
        PathBuf::from(format!("build-artifacts/{stem}.png"))
    });
    if let Some(dir) = out.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)
                .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", dir.display())))?;
        }
    }
    let gray = gray_image(g);
    let layer = MapLayer {
        width: g.width,
        height: g.height,
        gray: &gray,
        resolution: g.resolution,
        origin: g.origin,
    };
    let mut c = MapCanvas::with_long_side(&layer, a.size);
    draw_graph(&mut c, &built);
    if let Some(k) = a.site {
        draw_site(&mut c, &built, k, &out, ui)?;
    }
    c.title(&format!(
        "{}: GVD, graph and {} reference sites",
        a.map
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        built.sites.len()
    ));
    c.legend(
        &[
            ("GVD", color::BLUE, Mark::Line),
            ("site: vertex", color::RED, Mark::Dot),
            ("site: end point", color::ORANGE, Mark::Dot),
            ("site: on edge", color::GREEN, Mark::Dot),
            ("site: coverage fill", color::PURPLE, Mark::Dot),
        ],
        Corner::TopRight,
    );
    c.scale_bar(Corner::BottomLeft);
    c.save_png(&out)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", out.display())))?;
    outln!("{}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// The map as a gray image, top row first: free white, occupied dark,
/// unknown the ROS gray.
fn gray_image(g: &mapc::compiler::mapfile::OccupancyGrid) -> Vec<u8> {
    let (w, h) = (g.width, g.height);
    let mut gray = vec![0u8; (w * h) as usize];
    for cy in 0..h {
        for cx in 0..w {
            gray[((h - 1 - cy) * w + cx) as usize] = match g.get(cx, cy) {
                mapc::compiler::mapfile::Cell::Free => 255,
                mapc::compiler::mapfile::Cell::Occupied => 40,
                mapc::compiler::mapfile::Cell::Unknown => 205,
            };
        }
    }
    gray
}

/// The GVD cells and edges, the site graph and the sites (labelled when
/// there are at most 400).
fn draw_graph(c: &mut MapCanvas, built: &pipeline::BuildOutput) {
    c.fill_cells(
        built.gvd.cells.iter().map(|&(x, y)| (x as i64, y as i64)),
        [170, 190, 255],
    );
    for e in &built.gvd.edges {
        c.cell_polyline(
            e.cells
                .iter()
                .map(|&(x, y)| (x as f64 + 0.5, y as f64 + 0.5)),
            1.5,
            color::BLUE,
        );
    }
    for (i, s) in built.sites.iter().enumerate() {
        for &n in &s.neighbours {
            if (n as usize) > i {
                if let Some(t) = built.sites.get(n as usize) {
                    c.line(s.x, s.y, t.x, t.y, 1.0, color::GRAY);
                }
            }
        }
    }
    for (i, s) in built.sites.iter().enumerate() {
        let col = match s.kind as u32 {
            0 => color::RED,
            1 => color::ORANGE,
            2 => color::GREEN,
            _ => color::PURPLE,
        };
        c.marker(s.x, s.y, 4.0, col, color::BLACK);
        if built.sites.len() <= 400 {
            c.label(s.x, s.y, &i.to_string(), color::DARK_GRAY);
        }
    }
}

/// Site `k`'s virtual scan on the map, and its PGR histogram written
/// beside `out` as `<stem>-site<k>-hist.png`.
fn draw_site(
    c: &mut MapCanvas,
    built: &pipeline::BuildOutput,
    k: usize,
    out: &std::path::Path,
    ui: &Ui,
) -> Result<(), crate::util::CliError> {
    let s = built.sites.get(k).ok_or_else(|| {
        input_err(anyhow::anyhow!(
            "--site {k}: the map has {} sites",
            built.sites.len()
        ))
    })?;
    let p = &built.params.sensor;
    let scan = &built.scans[k];
    for (b, r) in scan.iter().enumerate() {
        if r.is_finite() {
            let ang = (p.angle_min + b as f32 * p.angle_increment) as f64;
            let (ex, ey) = (s.x + *r as f64 * ang.cos(), s.y + *r as f64 * ang.sin());
            c.line(s.x, s.y, ex, ey, 0.6, [255, 170, 170]);
            c.dot(ex, ey, 2.0, color::RED);
        }
    }
    let hist = mapc::compiler::compile::scan_histogram(scan, &built.params);
    let (rb, tb) = (
        built.params.coarse.hist_rho_bins as usize,
        built.params.coarse.hist_theta_bins as usize,
    );
    let chart = plot::heatmap(
        &hist,
        rb,
        tb,
        (-180.0, 180.0),
        (0.0, built.params.coarse.hist_rho_max as f64),
    )
    .title(&format!("PGR histogram of site {k} (Fig. 9)"))
    .x_label("theta (deg)")
    .y_label("rho (m)")
    .colorbar_label("share of pairs");
    let hp = out.with_file_name(format!(
        "{}-site{k}-hist.png",
        out.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    ));
    chart
        .save_png(&hp)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", hp.display())))?;
    ui.note(&format!("histogram: {}", hp.display()));
    Ok(())
}
