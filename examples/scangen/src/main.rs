//! `refloc-scangen`: host-side inputs for the firmware demo
//! (`examples/firmware`) and the C ABI test (`crates/refloc-capi`), and the
//! flash/RAM budget of `examples/firmware/README.md`.
//!
//! ```text
//! refloc-scangen firmware MAP.refdb OUT_DIR [--seed N]
//!     OUT_DIR/scans.rs      scans simulated at seeded free poses, as Rust
//!                           statics the firmware `include!`s
//!     OUT_DIR/expected.txt  "index x y theta accepted" per scan, as
//!                           localized on this host (the firmware must agree)
//! refloc-scangen capi MAP.refdb OUT.txt [--seed N]
//!     one scan with its true pose, as text for the C test
//! refloc-scangen budget [--code BYTES] [--ram-other BYTES] MAP.refdb...
//!     measured sizes of each database and the largest office-like map that
//!     fits a 2 MiB flash / 256 KiB RAM part
//! ```
//!
//! Exit status: 0 success, 1 a check failed, 2 bad usage or input.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use mapc::compiler::rng::Rng;
use mapc::compiler::sim::{add_noise, virtual_scan, Lidar, Noise};
use mapc::tools::eval::{sample_poses, CORRECT_POS, CORRECT_THETA};
use refloc::format::SectionKind;
use refloc::{localize, scratch_size, wrap_angle, Pose2, RangeScan, RefDb, Scan};

/// Free-space clearance of the sampled poses (m).
const CLEARANCE: f32 = 0.3;
/// Flash and RAM of the target part for the budget.
const FLASH_BUDGET: u64 = 2 * 1024 * 1024;
const RAM_BUDGET: u64 = 256 * 1024;

/// One simulated sensor.
struct Spec {
    label: &'static str,
    beams: usize,
    fov_deg: f32,
    noise: f32,
    short_outliers: usize,
    clockwise: bool,
}

/// The firmware's scans: 180 to 362 beams, full and partial field of view,
/// both beam orders, exact and noisy ranges.
const FIRMWARE_SPECS: [Spec; 5] = [
    Spec {
        label: "362 beams, 360 deg, exact",
        beams: 362,
        fov_deg: 360.0,
        noise: 0.0,
        short_outliers: 0,
        clockwise: false,
    },
    Spec {
        label: "180 beams, 360 deg, 1 cm noise",
        beams: 180,
        fov_deg: 360.0,
        noise: 0.01,
        short_outliers: 0,
        clockwise: false,
    },
    Spec {
        label: "271 beams, 270 deg, 1 cm noise",
        beams: 271,
        fov_deg: 270.0,
        noise: 0.01,
        short_outliers: 0,
        clockwise: false,
    },
    Spec {
        label: "360 beams, 360 deg, clockwise, 1 cm noise",
        beams: 360,
        fov_deg: 360.0,
        noise: 0.01,
        short_outliers: 0,
        clockwise: true,
    },
    Spec {
        label: "240 beams, 360 deg, 2 cm noise, 6 clutter returns",
        beams: 240,
        fov_deg: 360.0,
        noise: 0.02,
        short_outliers: 6,
        clockwise: false,
    },
];

const CAPI_SPEC: Spec = Spec {
    label: "300 beams, 360 deg, 1 cm noise",
    beams: 300,
    fov_deg: 360.0,
    noise: 0.01,
    short_outliers: 0,
    clockwise: false,
};

/// A simulated scan in `sensor_msgs/LaserScan` form.
struct SimScan {
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    ranges: Vec<f32>,
    truth: Pose2,
}

impl SimScan {
    fn scan(&self) -> Scan<'_> {
        Scan::Ranges(RangeScan {
            angle_min: self.angle_min,
            angle_increment: self.angle_increment,
            range_min: self.range_min,
            range_max: self.range_max,
            ranges: &self.ranges,
        })
    }
}

fn simulate<D: AsRef<[u8]>>(db: &RefDb<D>, truth: Pose2, spec: &Spec, rng: &mut Rng) -> SimScan {
    let p = db.params();
    let lidar = Lidar::new(spec.beams, spec.fov_deg.to_radians(), p.sensor.range_max);
    let sensor = truth.compose(&p.sensor.offset);
    let mut ranges = virtual_scan(&db.grid(), &db.frame(), &sensor, &lidar);
    let noise = Noise {
        range_sigma: spec.noise,
        short_outliers: spec.short_outliers,
    };
    add_noise(&mut ranges, &lidar, &noise, rng);
    let (mut angle_min, mut angle_increment) = (lidar.angle_min, lidar.angle_increment);
    if spec.clockwise {
        ranges.reverse();
        angle_min = lidar.angle(lidar.beams - 1);
        angle_increment = -angle_increment;
    }
    SimScan {
        angle_min,
        angle_increment,
        range_min: 0.02,
        range_max: lidar.range_max,
        ranges,
        truth,
    }
}

/// Position error (m) and heading error (rad) of `est` against `truth`.
fn errors(est: &Pose2, truth: &Pose2) -> (f32, f32) {
    let d = ((est.x - truth.x).powi(2) + (est.y - truth.y).powi(2)).sqrt();
    (d, wrap_angle(est.theta - truth.theta).abs())
}

/// A float as a Rust literal (`INF` for no return).
fn lit(v: f32) -> String {
    if v.is_infinite() {
        "INF".into()
    } else {
        let s = format!("{v:?}");
        if s.contains(['.', 'e']) {
            s
        } else {
            format!("{s}.0")
        }
    }
}

fn open(path: &Path) -> Result<RefDb<Vec<u8>>, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    RefDb::new(bytes).map_err(|e| format!("{}: {e}", path.display()))
}

fn seed_arg(args: &mut Vec<String>) -> Result<u64, String> {
    take_opt(args, "--seed")?.map_or(Ok(7), |s| s.parse().map_err(|_| format!("bad --seed {s}")))
}

fn take_opt(args: &mut Vec<String>, name: &str) -> Result<Option<String>, String> {
    match args.iter().position(|a| a == name) {
        Some(i) if i + 1 < args.len() => {
            let v = args.remove(i + 1);
            args.remove(i);
            Ok(Some(v))
        }
        Some(_) => Err(format!("{name} needs a value")),
        None => Ok(None),
    }
}

/// Localizes `s` on this host; prints and returns whether it is correct.
fn host_check<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    idx: usize,
    label: &str,
    s: &SimScan,
) -> (bool, Option<(Pose2, bool)>) {
    let mut scratch = vec![0u8; scratch_size(db.params(), s.ranges.len())];
    match localize(db, &s.scan(), &mut scratch) {
        Ok(fix) => {
            let (dp, dt) = errors(&fix.pose, &s.truth);
            let ok = fix.accepted && (dp as f64) < CORRECT_POS && (dt as f64) < CORRECT_THETA;
            eprintln!(
                "host scan {idx} ({label}): est ({:.3}, {:.3}, {:.4}) truth ({:.3}, {:.3}, {:.4}) err {:.3} m {:.2} deg accepted={} {}",
                fix.pose.x, fix.pose.y, fix.pose.theta, s.truth.x, s.truth.y, s.truth.theta, dp, dt.to_degrees(),
                fix.accepted, if ok { "ok" } else { "WRONG" }
            );
            (ok, Some((fix.pose, fix.accepted)))
        }
        Err(e) => {
            eprintln!("host scan {idx} ({label}): error: {e}");
            (false, None)
        }
    }
}

fn cmd_firmware(mut args: Vec<String>) -> Result<bool, String> {
    let seed = seed_arg(&mut args)?;
    let [db_path, out_dir] = <[String; 2]>::try_from(args)
        .map_err(|_| "usage: firmware MAP.refdb OUT_DIR [--seed N]".to_string())?;
    let db = open(Path::new(&db_path))?;
    let poses = sample_poses(&db, FIRMWARE_SPECS.len(), CLEARANCE, seed);
    if poses.len() != FIRMWARE_SPECS.len() {
        return Err(format!(
            "{db_path}: no free space with {CLEARANCE} m clearance"
        ));
    }
    let max_beams = FIRMWARE_SPECS.iter().map(|s| s.beams).max().unwrap_or(0);
    let scratch = scratch_size(db.params(), max_beams);
    let mut src = String::new();
    let mut expected = String::new();
    let _ = writeln!(
        src,
        "// @generated by refloc-scangen (examples/scangen) from {} with seed {seed}: do not edit.",
        Path::new(&db_path)
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
    );
    let _ = writeln!(
        src,
        "// Included by examples/firmware/src/main.rs, which defines `TestScan`.\n"
    );
    let _ = writeln!(
        src,
        "/// Bytes of the .refdb these scans were made for.\npub(crate) const DB_LEN: usize = {};",
        db.bytes().len()
    );
    let _ = writeln!(
        src,
        "/// Most beams of any scan below.\npub(crate) const MAX_BEAMS: usize = {max_beams};"
    );
    let _ = writeln!(src, "/// `refloc::scratch_size(db.params(), MAX_BEAMS)`, computed on the host.\npub(crate) const SCRATCH_BYTES: usize = {scratch};");
    let _ = writeln!(
        src,
        "#[allow(dead_code)]\nconst INF: f32 = f32::INFINITY;\n"
    );
    let mut all_ok = true;
    let mut entries = String::new();
    for (k, (spec, truth)) in FIRMWARE_SPECS.iter().zip(&poses).enumerate() {
        let mut rng = Rng::stream(seed ^ 0x5CA7, k as u64);
        let s = simulate(&db, *truth, spec, &mut rng);
        let (ok, fix) = host_check(&db, k, spec.label, &s);
        all_ok &= ok;
        match fix {
            Some((p, acc)) => {
                let _ = writeln!(
                    expected,
                    "{k} {:.6} {:.6} {:.6} {}",
                    p.x, p.y, p.theta, acc as u8
                );
            }
            None => {
                let _ = writeln!(expected, "{k} error");
            }
        }
        let _ = write!(src, "static RANGES_{k}: [f32; {}] = [", s.ranges.len());
        for (i, r) in s.ranges.iter().enumerate() {
            if i % 8 == 0 {
                src.push_str("\n   ");
            }
            let _ = write!(src, " {},", lit(*r));
        }
        src.push_str("\n];\n\n");
        let _ = writeln!(
            entries,
            "    TestScan {{\n        label: {:?},\n        angle_min: {},\n        angle_increment: {},\n        range_min: {},\n        range_max: {},\n        ranges: &RANGES_{k},\n        truth: [{}, {}, {}],\n    }},",
            spec.label,
            lit(s.angle_min),
            lit(s.angle_increment),
            lit(s.range_min),
            lit(s.range_max),
            lit(truth.x),
            lit(truth.y),
            lit(truth.theta)
        );
    }
    let _ = writeln!(src, "/// The scans with their true robot poses (m, m, rad).\npub(crate) static SCANS: [TestScan; {}] = [\n{entries}];", FIRMWARE_SPECS.len());
    let out = PathBuf::from(out_dir);
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    write_if_changed(&out.join("scans.rs"), &src)?;
    write_if_changed(&out.join("expected.txt"), &expected)?;
    if !all_ok {
        eprintln!("warning: not every scan localizes correctly on the host; the firmware will report the same");
    }
    Ok(true)
}

/// Leaves the file (and its mtime, so cargo does not rebuild) alone when
/// the content is the same.
fn write_if_changed(path: &Path, text: &str) -> Result<(), String> {
    if std::fs::read_to_string(path).is_ok_and(|old| old == text) {
        return Ok(());
    }
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

fn cmd_capi(mut args: Vec<String>) -> Result<bool, String> {
    let seed = seed_arg(&mut args)?;
    let [db_path, out] = <[String; 2]>::try_from(args)
        .map_err(|_| "usage: capi MAP.refdb OUT.txt [--seed N]".to_string())?;
    let db = open(Path::new(&db_path))?;
    let truth = *sample_poses(&db, 1, CLEARANCE, seed)
        .first()
        .ok_or("no free space")?;
    let mut rng = Rng::stream(seed ^ 0xCA91, 0);
    let s = simulate(&db, truth, &CAPI_SPEC, &mut rng);
    let (ok, _) = host_check(&db, 0, CAPI_SPEC.label, &s);
    let mut t = String::new();
    let _ = writeln!(
        t,
        "# refloc C ABI test scan (refloc-scangen capi, seed {seed}); ranges in m, inf = no return"
    );
    let _ = writeln!(t, "truth {:?} {:?} {:?}", truth.x, truth.y, truth.theta);
    let _ = writeln!(
        t,
        "scan {:?} {:?} {:?} {:?} {}",
        s.angle_min,
        s.angle_increment,
        s.range_min,
        s.range_max,
        s.ranges.len()
    );
    for chunk in s.ranges.chunks(8) {
        let line: Vec<String> = chunk.iter().map(|r| format!("{r:?}")).collect();
        let _ = writeln!(t, "{}", line.join(" "));
    }
    write_if_changed(Path::new(&out), &t)?;
    if !ok {
        eprintln!("warning: this scan does not localize correctly on the host");
    }
    Ok(true)
}

/// Measured composition of one database.
struct Measured {
    name: String,
    params: refloc::Params,
    cells: f64,
    cells_per_m2: f64,
    area_m2: f64,
    free_m2: f64,
    sites: f64,
    file: f64,
    /// (section name, bytes) for every section kind this refloc knows.
    sections: Vec<(&'static str, f64)>,
}

fn measure(path: &Path) -> Result<Measured, String> {
    let db = open(path)?;
    let (w, h) = db.grid_size();
    let res = db.frame().resolution as f64;
    let grid = db.grid();
    let free = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| !refloc::raycast::Occupancy::blocked(&grid, x, y))
        .count() as f64;
    let cells = w as f64 * h as f64;
    Ok(Measured {
        name: path.display().to_string(),
        params: *db.params(),
        cells,
        cells_per_m2: 1.0 / (res * res),
        area_m2: cells * res * res,
        free_m2: free * res * res,
        sites: db.site_count() as f64,
        file: db.bytes().len() as f64,
        sections: SectionKind::ALL
            .iter()
            .map(|k| (k.name(), db.section(*k).len() as f64))
            .collect(),
    })
}

/// How a section's size scales, decided from the measured databases: the
/// quantity (per cell, per site, or none) its size is most nearly
/// proportional to, with the largest measured ratio (conservative).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Scale {
    Fixed(f64),
    PerCell(f64),
    PerSite(f64),
}

fn classify(ms: &[&Measured], section: usize) -> Scale {
    let spread = |f: &dyn Fn(&Measured) -> f64| {
        let v: Vec<f64> = ms.iter().map(|m| f(m)).collect();
        let (lo, hi) = v
            .iter()
            .fold((f64::MAX, 0.0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        (if hi > 0.0 { (hi - lo) / hi } else { 0.0 }, hi)
    };
    let bytes = |m: &Measured| m.sections[section].1;
    let (s_fixed, fixed) = spread(&|m| bytes(m));
    let (s_cell, per_cell) = spread(&|m| bytes(m) / m.cells);
    let (s_site, per_site) = spread(&|m| bytes(m) / m.sites);
    if fixed == 0.0 || (s_fixed <= s_cell && s_fixed <= s_site) {
        Scale::Fixed(fixed)
    } else if s_cell <= s_site {
        Scale::PerCell(per_cell)
    } else {
        Scale::PerSite(per_site)
    }
}

fn cmd_budget(mut args: Vec<String>) -> Result<bool, String> {
    let num = |v: Option<String>, name: &str| -> Result<u64, String> {
        v.map_or(Ok(0), |s| s.parse().map_err(|_| format!("bad {name} {s}")))
    };
    let code = num(take_opt(&mut args, "--code")?, "--code")?;
    let ram_other = num(take_opt(&mut args, "--ram-other")?, "--ram-other")?;
    if args.is_empty() {
        return Err("usage: budget [--code BYTES] [--ram-other BYTES] MAP.refdb... (at least 2 map sizes per beam count)".into());
    }
    let ms: Vec<Measured> = args
        .iter()
        .map(|a| measure(Path::new(a)))
        .collect::<Result<_, _>>()?;
    println!("| database | beams | map m^2 | free m^2 | sites | sites per 100 m^2 | .refdb bytes | bytes per m^2 |");
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    for m in &ms {
        println!(
            "| {} | {} | {:.0} | {:.0} | {} | {:.1} | {} | {:.0} |",
            m.name,
            m.params.sensor.beams,
            m.area_m2,
            m.free_m2,
            m.sites,
            100.0 * m.sites / m.area_m2,
            m.file,
            m.file / m.area_m2
        );
    }
    // Site density of office-like maps: the densest measured (conservative).
    let density = ms.iter().map(|m| m.sites / m.area_m2).fold(0.0, f64::max);
    println!();
    println!(
        "Budget: {} KiB flash, of which {code} bytes code and constants besides the map; {} KiB RAM, of which {ram_other} bytes besides refloc's scratch. Site density {:.1} per 100 m^2 (densest measured).",
        FLASH_BUDGET / 1024,
        RAM_BUDGET / 1024,
        100.0 * density
    );
    let mut beams: Vec<u32> = ms.iter().map(|m| m.params.sensor.beams).collect();
    beams.sort_unstable();
    beams.dedup();
    let aff_each = std::mem::size_of::<refloc::ssm::Affinity>() as u64;
    let aff_bytes = refloc::localize::AFFINITY_CAP as u64 * aff_each;
    let mut rows = Vec::new();
    for b in beams {
        let group: Vec<&Measured> = ms.iter().filter(|m| m.params.sensor.beams == b).collect();
        if group.len() < 2 {
            eprintln!("note: one database with {b} beams: need two map sizes to tell fixed from growing sections");
            continue;
        }
        let (mut fixed, mut per_cell, mut per_site) = (0.0, 0.0, 0.0);
        let mut how = Vec::new();
        for (i, (name, _)) in group[0].sections.iter().enumerate() {
            match classify(&group, i) {
                Scale::Fixed(v) => {
                    fixed += v;
                    if v > 0.0 {
                        how.push(format!("{name} {v:.0} B"));
                    }
                }
                Scale::PerCell(v) => {
                    per_cell += v;
                    how.push(format!("{name} {v:.3} B/cell"));
                }
                Scale::PerSite(v) => {
                    per_site += v;
                    how.push(format!("{name} {v:.0} B/site"));
                }
            }
        }
        // Header, section table and alignment padding.
        fixed += group
            .iter()
            .map(|m| m.file - m.sections.iter().map(|s| s.1).sum::<f64>())
            .fold(0.0, f64::max);
        println!("- {b} beams: {}; {fixed:.0} B fixed in all, with the header, section table and padding.", how.join(", "));
        let per_m2 = per_cell * group[0].cells_per_m2 + density * per_site;
        let room = FLASH_BUDGET as f64 - code as f64 - fixed;
        let area = (room / per_m2).max(0.0);
        let p = group[0].params;
        let scratch = scratch_size(&p, b as usize) as u64;
        let ram = scratch + ram_other;
        let cap = RAM_BUDGET.saturating_sub(ram - aff_bytes) / aff_each;
        rows.push(format!(
            "| {b} | {per_site:.0} | {per_m2:.0} | {area:.0} m^2 ({:.1} m square) | {scratch} B ({:.1} KiB), {aff_bytes} B affinity | {} | {cap} entries ({:.0} KiB) |",
            area.sqrt(),
            scratch as f64 / 1024.0,
            if ram <= RAM_BUDGET {
                format!("yes: {:.1} KiB", ram as f64 / 1024.0)
            } else {
                format!("no: {:.1} KiB, {:.1} KiB over", ram as f64 / 1024.0, (ram - RAM_BUDGET) as f64 / 1024.0)
            },
            (cap * aff_each) as f64 / 1024.0
        ));
    }
    println!();
    println!("| beams (reference = scan) | .refdb bytes per site | .refdb bytes per m^2 | largest map in 2 MiB flash | scratch (RAM) | fits 256 KiB RAM | largest AFFINITY_CAP that fits |");
    println!("|---:|---:|---:|---|---|---|---:|");
    for r in rows {
        println!("{r}");
    }
    Ok(true)
}

fn main() -> ExitCode {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() {
        eprintln!("usage: refloc-scangen firmware|capi|budget ...");
        return ExitCode::from(2);
    }
    let cmd = args.remove(0);
    let r = match cmd.as_str() {
        "firmware" => cmd_firmware(args),
        "capi" => cmd_capi(args),
        "budget" => cmd_budget(args),
        _ => Err(format!("unknown command {cmd}")),
    };
    match r {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
