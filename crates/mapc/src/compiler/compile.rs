//! Assembling a `.refdb` from a placed map: reference scans (ray cast with
//! `refloc::raycast`), PGR histograms (`refloc::pgr`, the runtime's own
//! function), the beam grid, the distance map, the logistic weights fitted
//! on the map's own simulated scans, the stored reference side of SSM
//! (`refloc::localize::reference_features`, the runtime's own function),
//! and the build manifest.

use rayon::prelude::*;
use refloc::format::{
    dist_encode, FeaturesLayout, MetaRecord, SectionKind, SiteRecord, FEATURE_POINT_BYTES,
};
use refloc::params::Params;
use refloc::raycast::BitGrid;
use refloc::{pgr, prep, MapFrame, Pose2};
use zerocopy::little_endian::{F32, U32, U64};
use zerocopy::IntoBytes;

use crate::compiler::error::BuildError;
use crate::compiler::fit::{self, FitReport};
use crate::compiler::sim::{self, Lidar};

/// A reference site as the compiler hands it to the database.
#[derive(Clone, Debug, PartialEq)]
pub struct SiteIn {
    /// Map-frame position (m).
    pub x: f64,
    /// Map-frame position (m).
    pub y: f64,
    /// Distance to the nearest obstacle (m).
    pub clearance: f64,
    /// 0 vertex, 1 end point, 2 edge, 3 fill.
    pub kind: u32,
    /// Graph neighbours (site indices).
    pub neighbours: Vec<u32>,
}

/// Everything the database is built from besides the sites.
pub struct CompileInput<'a> {
    /// Grid width (cells).
    pub width: u32,
    /// Grid height (cells).
    pub height: u32,
    /// Grid placement.
    pub frame: MapFrame,
    /// Packed beam-stopping bits (see `refloc::raycast::BitGrid`).
    pub blocked: &'a [u32],
    /// Squared distance (cells^2) from each cell centre to the nearest
    /// beam-stopping cell centre.
    pub sq_dist: &'a [f32],
    /// The distance map section ready made (a database's own, when its
    /// reference side is made again: `crate::compiler::reach`), one byte
    /// per cell; `None` computes it from `sq_dist` and the grid.
    pub dist: Option<&'a [u8]>,
    /// Whether unknown cells stop beams.
    pub unknown_blocks: bool,
    /// Free cells in the source map.
    pub free_cells: u64,
    /// Runtime parameters (the logistic weights are replaced by the fit unless `fit_queries` is 0).
    pub params: Params,
    /// Simulated queries for the logistic fit (0: keep `params.w`).
    pub fit_queries: usize,
    /// Seed of the fit.
    pub fit_seed: u64,
}

/// The result of compilation.
pub struct Compiled {
    /// The section bytes, in file order.
    pub sections: Vec<(SectionKind, Vec<u8>)>,
    /// Parameters as stored.
    pub params: Params,
    /// Reference scans (m), per site.
    pub scans: Vec<Vec<f32>>,
    /// Logistic fit report.
    pub fit: FitReport,
}

/// The reference sensor of a database.
pub fn ref_lidar(params: &Params) -> Lidar {
    let s = &params.sensor;
    Lidar {
        beams: s.beams as usize,
        angle_min: s.angle_min,
        angle_increment: s.angle_increment,
        range_min: s.range_min,
        range_max: s.range_max,
    }
}

/// Default largest database a build may write, in bytes (`mapc build
/// --max-db-bytes`, [`crate::compiler::pipeline::BuildConfig::max_db_bytes`]): 1 GiB,
/// over 60 times the largest shared map's (willow-2010: 536 sites, 9 MB
/// without the stored SSM features, about 16 MB with them), and the size
/// of the 8000 x 8000 synthetic office of `docs/scaling.md` without the
/// stored features (34,609 sites, 648 MiB); with them (up to 12.8 KB more
/// per site) it and the 16000 x 16000 office (140,415 sites, 2.6 GiB
/// without) need a higher limit. A build's peak memory is a little above
/// its database's size.
pub const DEFAULT_MAX_DB_BYTES: u64 = 1 << 30;

/// The size of the database sections that grow with the map and its sites,
/// known once the sites are placed and before any per-site data exists (see
/// [`db_size`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DbSize {
    /// Reference sites.
    pub sites: u64,
    /// Bytes each site adds at most: its reference scan, PGR histogram,
    /// window histograms and site record, and with the stored SSM features
    /// its offset and [`FEATURE_POINT_BYTES`] per prepared point, counted
    /// at `max_points` points.
    pub per_site: u64,
    /// The features section at its largest (every site with `max_points`
    /// prepared points; bytes, 0 without it): the only part of `total`
    /// that is a bound rather than the exact size.
    pub features: u64,
    /// All of it: the sites' bytes and their neighbour lists, the grid,
    /// the distance map, the fixed records (meta, params, decision) and
    /// the features section at its largest (bytes; saturating). The
    /// coarse-search index, the manifest and the container's header and
    /// padding come on top.
    pub total: u64,
}

/// The size of a database of `sites` sites with `neighbours` neighbour
/// links in all (the sum of their lists' lengths) on a `width` x `height`
/// grid, compiled with `params`, with the stored SSM features or without
/// (`features`): the bytes of every section of a
/// [`crate::compiler::pipeline::build`] but the index and the manifest,
/// the features section counted at its largest ([`DbSize::features`]).
pub fn db_size(
    params: &Params,
    width: u32,
    height: u32,
    sites: usize,
    neighbours: u64,
    features: bool,
) -> DbSize {
    let floats = params.sensor.beams as u64
        + params.coarse.hist_cells() as u64
        + (params.coarse.win_count() as u64)
            .saturating_mul(params.coarse.win_headings as u64)
            .saturating_mul(params.coarse.win_cells() as u64);
    let max_points = params.prep.max_points as u64;
    let features_max = if features {
        FeaturesLayout::new(sites as u64, max_points.saturating_mul(sites as u64))
            .map_or(u64::MAX, |l| l.len as u64)
    } else {
        0
    };
    let per_site_features = if features {
        4 + max_points * FEATURE_POINT_BYTES as u64
    } else {
        0
    };
    let base = floats
        .saturating_mul(4)
        .saturating_add(std::mem::size_of::<SiteRecord>() as u64);
    let cells = width as u64 * height as u64;
    let fixed = (std::mem::size_of::<MetaRecord>()
        + std::mem::size_of::<refloc::format::ParamsRecord>()
        + std::mem::size_of::<refloc::format::DecisionRecord>()) as u64;
    let total = base
        .saturating_mul(sites as u64)
        .saturating_add(features_max)
        .saturating_add(neighbours.saturating_mul(4))
        .saturating_add(BitGrid::words_for(width, height) as u64 * 4)
        .saturating_add(cells)
        .saturating_add(fixed);
    DbSize {
        sites: sites as u64,
        per_site: base.saturating_add(per_site_features),
        features: features_max,
        total,
    }
}

/// Sites whose features are computed at once (in parallel) before their
/// bytes join the section: bounds the memory held twice.
const FEATURE_BATCH: usize = 256;

/// The features section ([`SectionKind::Features`], laid out by
/// [`FeaturesLayout`]): for every site, in site order, the reference side
/// of SSM that the runtime would otherwise compute per candidate, by the
/// runtime's own [`refloc::localize::reference_features`] with the stored
/// `params`. Deterministic whatever the thread count. The descriptors (80%
/// of the bytes) are written straight into the section; the offsets,
/// points and tangents are put in front of them at the end, in place.
pub fn features_section(scans: &[Vec<f32>], params: &Params) -> Vec<u8> {
    let m = params.prep.max_points as usize;
    let bound =
        FeaturesLayout::new(scans.len() as u64, (m * scans.len()) as u64).map_or(0, |l| l.len);
    let mut out: Vec<u8> = Vec::with_capacity(bound);
    let (mut offsets, mut pts, mut tans) = (vec![0u32], Vec::new(), Vec::new());
    let le = |v: &[[f32; 2]], to: &mut Vec<u8>| {
        to.extend(v.iter().flatten().flat_map(|x| x.to_le_bytes()));
    };
    for batch in scans.chunks(FEATURE_BATCH) {
        let done: Vec<_> = batch
            .par_iter()
            .map(|ranges| {
                let mut dense = vec![[0f32; 2]; ranges.len()];
                let (mut p, mut t) = point_buffers(params);
                let mut d = vec![0 as refloc::ssm::DescBin; m * refloc::ssm::DESC_LEN];
                let n = refloc::localize::reference_features(
                    ranges, params, &mut dense, &mut p, &mut t, &mut d,
                );
                p.truncate(n);
                t.truncate(n);
                d.truncate(n * refloc::ssm::DESC_LEN);
                (p, t, d)
            })
            .collect();
        for (p, t, d) in done {
            let last = offsets[offsets.len() - 1];
            offsets.push(last + p.len() as u32);
            le(&p, &mut pts);
            le(&t, &mut tans);
            out.extend(d.iter().flat_map(|v| v.to_le_bytes()));
        }
    }
    let total = offsets[offsets.len() - 1] as u64;
    let layout = FeaturesLayout::new(scans.len() as u64, total)
        .unwrap_or_else(|| unreachable!("{total} points of {} sites fit in memory", scans.len()));
    let desc_len = out.len();
    out.extend(offsets.iter().flat_map(|o| o.to_le_bytes()));
    out.resize(desc_len + layout.points_at, 0);
    out.extend_from_slice(&pts);
    out.extend_from_slice(&tans);
    let head = out.len() - desc_len;
    out.rotate_right(head);
    debug_assert_eq!(out.len(), layout.len);
    out
}

/// Reference scan ranges of every site (m; `INFINITY` for no return). The
/// sensor sits on the site, heading along the map's +x axis.
pub fn reference_scans(
    grid: &BitGrid<'_>,
    frame: &MapFrame,
    sites: &[SiteIn],
    params: &Params,
) -> Vec<Vec<f32>> {
    let lidar = ref_lidar(params);
    sites
        .par_iter()
        .map(|s| {
            sim::virtual_scan(
                grid,
                frame,
                &Pose2::new(s.x as f32, s.y as f32, 0.0),
                &lidar,
            )
        })
        .collect()
}

/// Sensor-frame points of a reference scan's ranges (one per beam; a beam
/// with no return is a NaN point), as the runtime reads a range scan.
fn reference_points(ranges: &[f32], params: &Params) -> Vec<[f32; 2]> {
    let mut dense = vec![[0f32; 2]; ranges.len()];
    let n = prep::reference_points(ranges, params, &mut dense);
    dense.truncate(n);
    dense
}

/// Point and tangent buffers for `prep::prepare`, `max_points` long.
fn point_buffers(params: &Params) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let p = params.prep.max_points as usize;
    (vec![[0f32; 2]; p], vec![[0f32; 2]; p])
}

/// PGR histogram of a range scan taken with the reference sensor.
pub fn scan_histogram(ranges: &[f32], params: &Params) -> Vec<f32> {
    let s = &params.sensor;
    let dense = reference_points(ranges, params);
    let (mut pts, mut tan) = point_buffers(params);
    let wrap = prep::covers_full_turn(s.angle_increment, s.beams as usize);
    let m = prep::prepare(&dense, wrap, params, &mut pts, &mut tan);
    let mut h = vec![0f32; params.coarse.hist_cells()];
    pgr::histogram(&pts[..m], &tan[..m], params, &mut h);
    h
}

/// Window histograms of one site's reference scan (see `refloc::coarse`):
/// for each used width and each heading `h * 2 pi / win_headings` (map
/// frame), the histogram of the beams within `width / 2` of that heading.
pub fn window_histograms(ranges: &[f32], params: &Params) -> Vec<f32> {
    let s = &params.sensor;
    let dense = reference_points(ranges, params);
    let (mut pts, mut tan) = point_buffers(params);
    let k = params.coarse.win_cells();
    let nh = params.coarse.win_headings as usize;
    let mut out = Vec::with_capacity(params.coarse.win_count() * nh * k);
    let mut window: Vec<[f32; 2]> = Vec::with_capacity(ranges.len());
    for &width in &params.coarse.win_widths[..params.coarse.win_count()] {
        for h in 0..nh {
            let heading = h as f32 * 2.0 * std::f32::consts::PI / nh as f32;
            // Beams within width/2 of the heading, in counter-clockwise order
            // starting at heading - width/2.
            let first = heading - width / 2.0;
            window.clear();
            let n = ranges.len();
            // The first beam of the window: the smallest angle offset from `first`.
            let start = (0..n)
                .min_by(|&x, &y| {
                    let ox = (s.angle_min + x as f32 * s.angle_increment - first)
                        .rem_euclid(2.0 * std::f32::consts::PI);
                    let oy = (s.angle_min + y as f32 * s.angle_increment - first)
                        .rem_euclid(2.0 * std::f32::consts::PI);
                    ox.total_cmp(&oy)
                })
                .unwrap_or(0);
            let count = ((width / s.angle_increment).round() as usize).min(n);
            for j in 0..count {
                window.push(dense[(start + j) % n]);
            }
            let m = prep::prepare(&window, false, params, &mut pts, &mut tan);
            let mut hh = vec![0f32; k];
            pgr::histogram_binned(
                &pts[..m],
                &tan[..m],
                params.coarse.win_rho_bins as usize,
                params.coarse.win_theta_bins as usize,
                params.coarse.hist_rho_max,
                &mut hh,
            );
            out.extend_from_slice(&hh);
        }
    }
    out
}

/// The quantized signed distance map: for a free cell, the distance from
/// its centre to the nearest obstacle cell centre minus half a cell; for an
/// obstacle cell, minus (the distance to the nearest free cell centre minus
/// half a cell). Interpolated between centres, its zero then lies on the
/// boundary between free and obstacle cells, where a beam stops.
/// `sq_out`: squared distances (cells^2) to obstacles; `sq_in`: squared
/// distances from obstacle cells to free cells.
pub fn dist_section(sq_out: &[f32], sq_in: &[f32]) -> Vec<u8> {
    sq_out
        .iter()
        .zip(sq_in)
        .map(|(&o, &i)| {
            let d = if o > 0.0 {
                o.sqrt() - 0.5
            } else {
                -(i.max(0.0).sqrt() - 0.5).max(0.0)
            };
            dist_encode(d)
        })
        .collect()
}

/// `f(scan)` for every scan, `per` values each, as little-endian bytes in
/// scan order, written straight into the section: a large map's per-site
/// vectors are never held next to their serialized copy.
fn per_scan_bytes(
    scans: &[Vec<f32>],
    per: usize,
    f: impl Fn(&[f32]) -> Vec<f32> + Sync,
) -> Vec<u8> {
    let mut out = vec![0u8; scans.len() * per * 4];
    if per == 0 {
        return out;
    }
    out.par_chunks_mut(per * 4)
        .zip(scans.par_iter())
        .for_each(|(bytes, s)| {
            let v = f(s);
            assert_eq!(v.len(), per, "per-site section record of the wrong length");
            for (b, x) in bytes.chunks_exact_mut(4).zip(&v) {
                b.copy_from_slice(&x.to_le_bytes());
            }
        });
    out
}

/// Compiles everything but the manifest, which the caller appends.
pub fn compile(input: &CompileInput<'_>, sites: &[SiteIn]) -> Result<Compiled, BuildError> {
    compile_with(input, sites, &mut |_| {})
}

/// As [`compile`], calling `lap(step)` at the end of each step
/// ("compile.scans", "compile.fit", ...) so that the caller can time them.
pub fn compile_with(
    input: &CompileInput<'_>,
    sites: &[SiteIn],
    lap: &mut dyn FnMut(&'static str),
) -> Result<Compiled, BuildError> {
    let mut params = input.params;
    params.validate().map_err(BuildError::Param)?;
    if sites.is_empty() {
        return Err(BuildError::NoSites);
    }
    let grid =
        BitGrid::new(input.width, input.height, input.blocked).ok_or(BuildError::GridBits {
            width: input.width,
            height: input.height,
        })?;
    let frame = input.frame;
    // The distance map first, before any per-site data exists: its distance
    // transform needs 12 bytes per cell while it runs (peak memory).
    let dist_bytes = if let Some(d) = input.dist {
        d.to_vec()
    } else {
        let bits = grid;
        let (w, h) = (input.width as usize, input.height as usize);
        let sq_in = crate::compiler::edt::squared_edt(w, h, |i| {
            !refloc::raycast::Occupancy::blocked(&bits, (i % w) as u32, (i / w) as u32)
        });
        dist_section(input.sq_dist, &sq_in)
    };
    lap("compile.dist");
    let scans = reference_scans(&grid, &frame, sites, &params);
    lap("compile.scans");
    // Logistic weights from the map's own simulated scans.
    let res = frame.resolution;
    let (w, h) = (input.width as i64, input.height as i64);
    let sq = input.sq_dist;
    let clearance_ok = move |p: [f32; 2]| {
        let uv = frame.to_cells(p);
        let (cx, cy) = (uv[0].floor() as i64, uv[1].floor() as i64);
        if cx < 0 || cy < 0 || cx >= w || cy >= h {
            return false;
        }
        let d = sq[(cy * w + cx) as usize].sqrt() * res;
        d >= 0.25
    };
    let site_xy: Vec<[f32; 2]> = sites.iter().map(|s| [s.x as f32, s.y as f32]).collect();
    let fit = if input.fit_queries > 0 {
        fit::fit_weights(
            &grid,
            &frame,
            &clearance_ok,
            &site_xy,
            &scans,
            &params,
            input.fit_queries,
            input.fit_seed,
        )
    } else {
        FitReport {
            queries: 0,
            samples: 0,
            positives: 0,
            w: params.ssm.w,
            seed: input.fit_seed,
        }
    };
    params.ssm.w = fit.w;
    lap("compile.fit");
    params.validate().map_err(BuildError::FittedParam)?;
    let hist_bytes = per_scan_bytes(&scans, params.coarse.hist_cells(), |s| {
        scan_histogram(s, &params)
    });
    lap("compile.hists");
    let window_bytes = per_scan_bytes(
        &scans,
        params.coarse.win_count() * params.coarse.win_headings as usize * params.coarse.win_cells(),
        |s| window_histograms(s, &params),
    );
    lap("compile.windows");

    let meta = MetaRecord {
        width: U32::new(input.width),
        height: U32::new(input.height),
        resolution: F32::new(frame.resolution),
        origin_x: F32::new(frame.origin.x),
        origin_y: F32::new(frame.origin.y),
        origin_yaw: F32::new(frame.origin.theta),
        site_count: U32::new(sites.len() as u32),
        unknown_blocks: U32::new(input.unknown_blocks as u32),
        free_cells: U64::new(input.free_cells),
        reserved: [0; 24],
    };
    let mut neighbours: Vec<u32> = Vec::new();
    let site_records: Vec<SiteRecord> = sites
        .iter()
        .map(|s| {
            let start = neighbours.len() as u32;
            neighbours.extend(
                s.neighbours
                    .iter()
                    .copied()
                    .filter(|&n| (n as usize) < sites.len()),
            );
            SiteRecord {
                x: F32::new(s.x as f32),
                y: F32::new(s.y as f32),
                clearance: F32::new(s.clearance as f32),
                kind: U32::new(s.kind),
                neighbor_start: U32::new(start),
                neighbor_count: U32::new(neighbours.len() as u32 - start),
            }
        })
        .collect();
    let scan_bytes: Vec<u8> = scans
        .iter()
        .flat_map(|s| s.iter().flat_map(|v| v.to_le_bytes()))
        .collect();
    let grid_bytes: Vec<u8> = input.blocked[..BitGrid::words_for(input.width, input.height)]
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    let sections = vec![
        (SectionKind::Meta, meta.as_bytes().to_vec()),
        (SectionKind::Params, params.to_record().as_bytes().to_vec()),
        (SectionKind::Grid, grid_bytes),
        (SectionKind::Dist, dist_bytes),
        (SectionKind::Sites, site_records.as_bytes().to_vec()),
        (
            SectionKind::Neighbors,
            neighbours.iter().flat_map(|n| n.to_le_bytes()).collect(),
        ),
        (SectionKind::Scans, scan_bytes),
        (SectionKind::Hists, hist_bytes),
        (SectionKind::Windows, window_bytes),
    ];
    lap("compile.sections");
    Ok(Compiled {
        sections,
        params,
        scans,
        fit,
    })
}
