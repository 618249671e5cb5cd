//! `mapc info`, `mapc verify`, `mapc diff`.

use std::path::PathBuf;
use std::process::ExitCode;

use refloc::format::SectionKind;
use refloc::RefDb;
use serde_json::{json, Value};

use crate::util::outln;
use crate::util::{fail_err, open_db, Check, CliResult};

#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// The database.
    pub db: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct VerifyArgs {
    /// The database.
    pub db: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct DiffArgs {
    /// The old database.
    pub a: PathBuf,
    /// The new database.
    pub b: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Sites closer than this are the same site (m).
    #[arg(long, default_value_t = 0.01, value_name = "M")]
    pub same: f32,
    /// Sites within this of an old site count as moved rather than added/removed (m).
    #[arg(long, default_value_t = 1.0, value_name = "M")]
    pub moved: f32,
}

/// All parameters as a JSON object (units in the names).
pub fn params_json(p: &refloc::Params) -> Value {
    let s = &p.sensor;
    let mut v = json!({
        "beams": s.beams, "angle_min_rad": s.angle_min, "angle_increment_rad": s.angle_increment,
        "range_min_m": s.range_min, "range_max_m": s.range_max,
        "sensor_offset": [s.offset.x, s.offset.y, s.offset.theta],
        "resample_spacing_m": p.prep.resample_spacing, "max_points": p.prep.max_points, "jump_distance_m": p.prep.jump_distance,
        "hist_rho_bins": p.coarse.hist_rho_bins, "hist_theta_bins": p.coarse.hist_theta_bins, "hist_rho_max_m": p.coarse.hist_rho_max,
        "nc_min": p.coarse.nc_min, "nc_max": p.coarse.nc_max, "nc_margin": p.coarse.nc_margin,
        "desc_radius_m": p.ssm.desc_radius, "tentative_k": p.ssm.tentative_k, "max_rho_dev_m": p.ssm.max_rho_dev,
        "logistic_w": p.ssm.w, "power_iters": p.ssm.power_iters, "binarize_frac": p.ssm.binarize_frac,
        "ransac_iters": p.ssm.ransac_iters, "ransac_threshold_m": p.ssm.ransac_threshold, "ransac_seed": p.ssm.ransac_seed,
        "min_inliers": p.ssm.min_inliers, "refine_iters": p.refine.refine_iters, "refine_max_dist_m": p.refine.refine_max_dist,
        "sigma_d_m": p.verify.sigma_d, "accept_ratio": p.verify.accept_ratio, "min_valid_points": p.prep.min_valid_points,
        "selection": format!("{:?}", p.select.selection), "early_accept": p.select.early_accept, "early_min": p.select.early_min, "ambiguity_ratio": p.select.ambiguity_ratio, "affinity_cap": p.ssm.affinity_cap,
        "window_widths_rad": p.coarse.win_widths, "window_headings": p.coarse.win_headings, "window_rho_bins": p.coarse.win_rho_bins, "window_theta_bins": p.coarse.win_theta_bins,
        "scratch_bytes_362": refloc::scratch_size(p, 362), "scratch_bytes_1081": refloc::scratch_size(p, 1081),
    });
    // Added in a second step: one json! call this long exceeds the macro recursion limit.
    v["through_max"] = json!(p.verify.through_max);
    v["through_excess_m"] = json!(p.verify.through_excess);
    v["short_weight"] = json!(p.verify.short_weight);
    v["through_run"] = json!(p.verify.through_run);
    v["occlusion_fit"] = json!(p.verify.occlusion_fit);
    v
}

/// The decision model a database stores, or null without one.
pub fn decision_json(d: Option<refloc::Decision>) -> Value {
    match d {
        Some(d) => json!({"bias": d.bias, "weights": d.weights, "accept_confidence": d.threshold}),
        None => Value::Null,
    }
}

/// The coarse-search index's shape, or null without one.
fn index_json<D: AsRef<[u8]>>(db: &RefDb<D>) -> Value {
    let Some(ix) = db.index() else {
        return Value::Null;
    };
    let (beam, leaves) = ix.widths();
    let views: Vec<String> = ix
        .kinds()
        .map(|k| match k {
            refloc::index::ViewKind::Full => "full".to_string(),
            refloc::index::ViewKind::Window(w) => {
                format!(
                    "window {:.0} deg",
                    db.params().coarse.win_widths[w].to_degrees()
                )
            }
        })
        .collect();
    json!({"views": views, "nodes": ix.node_count(), "beam": beam, "leaves": leaves})
}

fn info_json<D: AsRef<[u8]>>(db: &RefDb<D>) -> Value {
    let m = db.meta();
    let sections: Vec<Value> = SectionKind::ALL
        .iter()
        .map(|&k| json!({"kind": k.name(), "bytes": db.section(k).len(), "crc32c": format!("{:08x}", db.section_crc(k))}))
        .collect();
    let manifest: Value = serde_json::from_str(db.manifest()).unwrap_or(Value::Null);
    json!({
        "format_version": refloc::format::FORMAT_VERSION,
        "file_bytes": db.bytes().len(),
        "grid": {"width": m.width.get(), "height": m.height.get(), "resolution_m": m.resolution.get(),
                 "origin": [m.origin_x.get(), m.origin_y.get(), m.origin_yaw.get()],
                 "unknown_blocks": m.unknown_blocks.get() != 0, "free_cells": m.free_cells.get()},
        "sites": db.site_count(),
        "sections": sections,
        "index": index_json(db),
        "params": params_json(db.params()),
        "decision": decision_json(db.decision()),
        "manifest": manifest,
    })
}

pub fn info(a: InfoArgs) -> CliResult {
    let db = open_db(&a.db, Check::Full)?;
    let j = info_json(&db);
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&j).unwrap_or_default());
        return Ok(ExitCode::SUCCESS);
    }
    let m = db.meta();
    outln!(
        "{}: refdb format v{}, {} bytes",
        a.db.display(),
        refloc::format::FORMAT_VERSION,
        db.bytes().len()
    );
    outln!(
        "grid      {} x {} cells, {:.3} m/cell, origin ({:.3}, {:.3}, {:.4} rad)",
        m.width.get(),
        m.height.get(),
        m.resolution.get(),
        m.origin_x.get(),
        m.origin_y.get(),
        m.origin_yaw.get()
    );
    outln!("sites     {}", db.site_count());
    outln!("sections");
    for k in SectionKind::ALL {
        outln!(
            "  {:<10} {:>10} bytes  crc32c {:08x}",
            k.name(),
            db.section(k).len(),
            db.section_crc(k)
        );
    }
    match &j["index"] {
        Value::Null => outln!("index     none (exhaustive coarse ranking)"),
        ix => outln!(
            "index     {} nodes over {}; search keeps {} nodes per level, {} leaves",
            ix["nodes"],
            ix["views"]
                .as_array()
                .map(|v| v
                    .iter()
                    .filter_map(|s| s.as_str())
                    .collect::<Vec<_>>()
                    .join(", "))
                .unwrap_or_default(),
            ix["beam"],
            ix["leaves"]
        ),
    }
    outln!("params");
    if let Value::Object(p) = &j["params"] {
        for (k, v) in p {
            outln!("  {k:<22} {v}");
        }
    }
    if let Some(inp) = j["manifest"].get("input") {
        outln!("input     {}", inp);
    }
    Ok(ExitCode::SUCCESS)
}

pub fn verify(a: VerifyArgs) -> CliResult {
    let db = open_db(&a.db, Check::Structure)?;
    db.verify()
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", a.db.display())))?;
    outln!(
        "{}: ok ({} sites, {} bytes, all checksums match)",
        a.db.display(),
        db.site_count(),
        db.bytes().len()
    );
    Ok(ExitCode::SUCCESS)
}

/// One entry per section kind (bytes old and new, CRC-32C old and new,
/// same or not); a `section.<kind>` change for each that differs. The
/// manifest is compared through its fields (inputs, options) instead.
fn section_changes<D: AsRef<[u8]>>(
    da: &RefDb<D>,
    db: &RefDb<D>,
    changes: &mut Vec<Value>,
) -> Vec<Value> {
    let mut out = Vec::new();
    for &k in SectionKind::ALL.iter() {
        let (x, y) = (da.section(k), db.section(k));
        let same = x == y;
        let crc = |d: &RefDb<D>| format!("{:08x}", d.section_crc(k));
        out.push(
            json!({"kind": k.name(), "same": same, "old_bytes": x.len(), "new_bytes": y.len(),
            "old_crc32c": crc(da), "new_crc32c": crc(db)}),
        );
        if !same && k != SectionKind::Manifest {
            changes.push(json!({"what": format!("section.{}", k.name()),
                "old": format!("{} bytes, crc32c {}", x.len(), crc(da)),
                "new": format!("{} bytes, crc32c {}", y.len(), crc(db))}));
        }
    }
    out
}

/// What differs between site `j` of `da` and site `i` of `db` besides its
/// position: its reference scan, its full-view histogram, its window
/// histograms (compared bit for bit where the layouts agree).
fn site_data_changes<D: AsRef<[u8]>>(
    da: &RefDb<D>,
    j: usize,
    db: &RefDb<D>,
    i: usize,
) -> Vec<&'static str> {
    let differ = |x: &[f32], y: &[f32]| {
        !x.iter()
            .map(|v| v.to_bits())
            .eq(y.iter().map(|v| v.to_bits()))
    };
    let mut what = Vec::new();
    if differ(da.scan(j), db.scan(i)) {
        what.push("scan");
    }
    if differ(da.hist(j), db.hist(i)) {
        what.push("histogram");
    }
    let (pa, pb) = (&da.params().coarse, &db.params().coarse);
    let layout = |p: &refloc::params::CoarseParams| (p.win_count(), p.win_headings);
    if layout(pa) != layout(pb) {
        return what;
    }
    let (nw, nh) = layout(pa);
    let windows_differ = (0..nw)
        .flat_map(|w| (0..nh as usize).map(move |h| (w, h)))
        .any(|(w, h)| differ(da.window_hist(j, w, h), db.window_hist(i, w, h)));
    if windows_differ {
        what.push("window histograms");
    }
    what
}

pub fn diff(a: DiffArgs) -> CliResult {
    let da = open_db(&a.a, Check::Full)?;
    let db = open_db(&a.b, Check::Full)?;
    let (ja, jb) = (info_json(&da), info_json(&db));
    let mut changes: Vec<Value> = Vec::new();
    // Parameters and grid.
    for group in ["grid", "params"] {
        if let (Value::Object(pa), Value::Object(pb)) = (&ja[group], &jb[group]) {
            for (k, va) in pa {
                let vb = pb.get(k).cloned().unwrap_or(Value::Null);
                if *va != vb {
                    changes.push(json!({"what": format!("{group}.{k}"), "old": va, "new": vb}));
                }
            }
        }
    }
    // Inputs.
    for k in ["yaml_sha256", "image_sha256", "yaml", "image"] {
        let (va, vb) = (&ja["manifest"]["input"][k], &jb["manifest"]["input"][k]);
        if va != vb {
            changes.push(json!({"what": format!("input.{k}"), "old": va, "new": vb}));
        }
    }
    // Section contents, byte for byte: a grid, scan or histogram that
    // differs is a change even where the sites and parameters agree.
    let sections = section_changes(&da, &db, &mut changes);
    // Sites: one-to-one greedy matching by distance (closest pairs first).
    let sa: Vec<[f32; 2]> = (0..da.site_count()).map(|i| da.site_xy(i)).collect();
    let sb: Vec<[f32; 2]> = (0..db.site_count()).map(|i| db.site_xy(i)).collect();
    let mut pairs: Vec<(f32, usize, usize)> = Vec::new();
    for (j, p) in sa.iter().enumerate() {
        for (i, q) in sb.iter().enumerate() {
            let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
            if d <= a.moved {
                pairs.push((d, j, i));
            }
        }
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let (mut used_a, mut used_b) = (vec![false; sa.len()], vec![false; sb.len()]);
    let mut moved = Vec::new();
    let mut rescanned = Vec::new();
    for (d, j, i) in pairs {
        if used_a[j] || used_b[i] {
            continue;
        }
        used_a[j] = true;
        used_b[i] = true;
        if d > a.same {
            moved.push(json!({"old": j, "new": i, "from": sa[j], "to": sb[i], "distance_m": d}));
        }
        let what = site_data_changes(&da, j, &db, i);
        if !what.is_empty() {
            rescanned.push(json!({"old": j, "new": i, "at": sb[i], "what": what}));
        }
    }
    let added: Vec<Value> = (0..sb.len())
        .filter(|&i| !used_b[i])
        .map(|i| json!({"site": i, "at": sb[i]}))
        .collect();
    let removed: Vec<Value> = (0..sa.len())
        .filter(|&j| !used_a[j])
        .map(|j| json!({"site": j, "at": sa[j]}))
        .collect();
    let same = changes.is_empty()
        && added.is_empty()
        && moved.is_empty()
        && removed.is_empty()
        && rescanned.is_empty()
        && sa.len() == sb.len();
    let report = json!({"identical_bytes": da.bytes() == db.bytes(), "same": same, "changes": changes,
        "sections": sections,
        "sites": {"old": sa.len(), "new": sb.len(), "added": added, "removed": removed, "moved": moved,
            "other_data": rescanned}});
    if a.json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&report).unwrap_or_default()
        );
    } else {
        outln!("{} -> {}", a.a.display(), a.b.display());
        if da.bytes() == db.bytes() {
            outln!("identical files");
        }
        for c in &changes {
            outln!(
                "  changed {}: {} -> {}",
                c["what"].as_str().unwrap_or(""),
                c["old"],
                c["new"]
            );
        }
        outln!(
            "  sites: {} -> {} ({} added, {} removed, {} moved, {} with other scan or histograms)",
            sa.len(),
            sb.len(),
            added.len(),
            removed.len(),
            moved.len(),
            rescanned.len()
        );
        for m in &moved {
            outln!(
                "    moved site {} -> {}: {:.3} m",
                m["old"],
                m["new"],
                m["distance_m"].as_f64().unwrap_or(0.0)
            );
        }
    }
    Ok(if same {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}
