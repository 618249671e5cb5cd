//! End-to-end runs of the `mapc` binary on the map the project ships.
//!
//! Registered as an integration test of the `mapc` package (see
//! crates/mapc/Cargo.toml) so `CARGO_BIN_EXE_mapc` points at the binary.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;

fn mapc(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mapc"))
        .args(args)
        .current_dir(cwd)
        .env("NO_COLOR", "1")
        .output()
        .expect("run mapc")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn demo_map() -> PathBuf {
    repo().join("maps/office-demo/office-demo.yaml")
}

/// Builds the demo map once per test into its own temporary directory.
fn built(dir: &Path, extra: &[&str]) -> PathBuf {
    let db = dir.join("demo.refdb");
    let map = demo_map();
    let mut args = vec![
        "build",
        map.to_str().unwrap(),
        "-o",
        db.to_str().unwrap(),
        "--fit-queries",
        "40",
    ];
    args.extend_from_slice(extra);
    let o = mapc(&args, dir);
    assert!(o.status.success(), "build failed: {}", text(&o));
    db
}

/// `mapc eval` of `db` on 60 static poses (seed 3) into `out`, checked
/// against the `check` baseline report when given.
fn eval_static(db: &Path, out: &Path, check: Option<&Path>, cwd: &Path) -> Output {
    eval_static_with(db, out, check, &[], cwd)
}

/// [`eval_static`] with `extra` options (the simulated sensor, `--dump`).
fn eval_static_with(
    db: &Path,
    out: &Path,
    check: Option<&Path>,
    extra: &[&str],
    cwd: &Path,
) -> Output {
    let mut args = vec![
        "eval",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--poses",
        "60",
        "--experiments",
        "static",
        "--no-figures",
        "--seed",
        "3",
    ];
    if let Some(c) = check {
        args.extend(["--check", c.to_str().unwrap()]);
    }
    args.extend_from_slice(extra);
    mapc(&args, cwd)
}

#[test]
fn build_verify_info_and_determinism() {
    let dir = tempfile::tempdir().unwrap();
    let db = built(dir.path(), &["--threads", "1"]);
    let o = mapc(&["verify", db.to_str().unwrap()], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let o = mapc(&["info", db.to_str().unwrap(), "--json"], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["sites"].as_u64().unwrap() > 20);
    assert_eq!(j["params"]["beams"], 362);
    // Same inputs and options, two threads: byte-identical.
    let db2 = dir.path().join("demo2.refdb");
    let map = demo_map();
    let o = mapc(
        &[
            "build",
            map.to_str().unwrap(),
            "-o",
            db2.to_str().unwrap(),
            "--fit-queries",
            "40",
            "--threads",
            "2",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        std::fs::read(&db).unwrap(),
        std::fs::read(&db2).unwrap(),
        "build is not deterministic across thread counts"
    );
    let o = mapc(
        &["diff", db.to_str().unwrap(), db2.to_str().unwrap()],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("identical"));
}

/// `mapc build` says when a map's cells are coarser than the 0.05 m the
/// confidence model was fitted on (docs/robot.md, "Map cell size"), and
/// only then: the demo map's image read as 0.1 m cells.
#[test]
fn build_notes_a_map_of_coarse_cells() {
    let dir = tempfile::tempdir().unwrap();
    let build = |yaml: &Path, out: &str, quiet: bool| {
        let out = dir.path().join(out);
        let mut args = vec!["build", yaml.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend(["--fit-queries", "40"]);
        if quiet {
            args.push("-q");
        }
        let o = mapc(&args, dir.path());
        assert!(o.status.success(), "{}", text(&o));
        o
    };
    let fine = build(&demo_map(), "fine.refdb", false);
    assert!(!text(&fine).contains("coarser than"), "{}", text(&fine));
    let image = repo().join("maps/office-demo/office-demo.pgm");
    let yaml = dir.path().join("coarse.yaml");
    std::fs::write(
        &yaml,
        format!(
            "image: {}\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.196\n",
            image.display()
        ),
    )
    .unwrap();
    let t = text(&build(&yaml, "coarse.refdb", false));
    assert!(
        t.contains("cells coarser than the 0.05 m") && t.contains("Map cell size"),
        "{t}"
    );
    // Quiet is quiet.
    assert!(build(&yaml, "quiet.refdb", true).stderr.is_empty());
}

#[test]
fn diff_reports_changes() {
    let dir = tempfile::tempdir().unwrap();
    let a = built(dir.path(), &[]);
    let b = dir.path().join("b.refdb");
    let map = demo_map();
    let o = mapc(
        &[
            "build",
            map.to_str().unwrap(),
            "-o",
            b.to_str().unwrap(),
            "--fit-queries",
            "40",
            "--site-spacing",
            "1.0",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let o = mapc(
        &["diff", a.to_str().unwrap(), b.to_str().unwrap(), "--json"],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j["sites"]["new"].as_u64().unwrap() > j["sites"]["old"].as_u64().unwrap());
    assert!(!j["sites"]["added"].as_array().unwrap().is_empty());
}

/// Two databases with the same sites and parameters whose scans differ
/// (one value of one reference scan changed; its CRC left stale, so the
/// copy is read with `--no-verify`) are not "the same": `diff` compares
/// section contents and names the site.
#[test]
fn diff_compares_section_contents() {
    let dir = tempfile::tempdir().unwrap();
    let a = built(dir.path(), &[]);
    let bytes = std::fs::read(&a).unwrap();
    let (offset, site) = {
        let db = refloc::RefDb::new(bytes.as_slice()).unwrap();
        let scans = db.section(refloc::format::SectionKind::Scans);
        let base = scans.as_ptr() as usize - bytes.as_ptr() as usize;
        // Site 1's first beam: a different range, same everything else.
        let site = 1;
        (base + site * db.params().sensor.beams as usize * 4, site)
    };
    let mut changed = bytes.clone();
    let v = f32::from_le_bytes(changed[offset..offset + 4].try_into().unwrap());
    changed[offset..offset + 4].copy_from_slice(&(v + 0.5).to_le_bytes());
    let b = dir.path().join("b.refdb");
    std::fs::write(&b, &changed).unwrap();
    let args = |json: bool| {
        let mut v = vec![
            "--no-verify",
            "diff",
            a.to_str().unwrap(),
            b.to_str().unwrap(),
        ];
        if json {
            v.push("--json");
        }
        v.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let run = |json: bool| {
        let owned = args(json);
        let refs: Vec<&str> = owned.iter().map(String::as_str).collect();
        mapc(&refs, dir.path())
    };
    let o = run(true);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["same"], false);
    let scans = j["sections"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["kind"] == "scans")
        .unwrap();
    assert_eq!(scans["same"], false);
    assert!(j["changes"]
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["what"] == "section.scans"));
    let other = j["sites"]["other_data"].as_array().unwrap();
    assert_eq!(other.len(), 1, "{other:?}");
    assert_eq!(other[0]["old"], site);
    assert_eq!(other[0]["what"][0], "scan");
    assert!(j["sites"]["moved"].as_array().unwrap().is_empty());
    let o = run(false);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("changed section.scans"), "{}", text(&o));
    assert!(
        text(&o).contains("1 with other scan or histograms"),
        "{}",
        text(&o)
    );
    // A database against itself is the same.
    let o = mapc(
        &["diff", a.to_str().unwrap(), a.to_str().unwrap()],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

#[test]
fn localize_a_batch_of_json_lines() {
    let dir = tempfile::tempdir().unwrap();
    let dbp = built(dir.path(), &[]);
    let (poses, mut lines) = common::jsonl_scans(&std::fs::read(&dbp).unwrap(), 6, 11);
    // One malformed line in the middle: reported, the batch goes on.
    lines.push_str("{\"id\": \"bad\", \"angle_min\": \"x\"}\n");
    let input = dir.path().join("scans.jsonl");
    std::fs::write(&input, &lines).unwrap();
    let o = mapc(
        &["localize", dbp.to_str().unwrap(), input.to_str().unwrap()],
        dir.path(),
    );
    assert_eq!(
        o.status.code(),
        Some(1),
        "a failed line must set the exit code: {}",
        text(&o)
    );
    let out: Vec<serde_json::Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(out.len(), poses.len() + 1);
    for (k, p) in poses.iter().enumerate() {
        let r = &out[k];
        assert_eq!(r["id"], format!("s{k}"));
        assert_eq!(r["accepted"], true, "{r}");
        let (x, y) = (r["x"].as_f64().unwrap(), r["y"].as_f64().unwrap());
        assert!(
            ((x - p.x as f64).powi(2) + (y - p.y as f64).powi(2)).sqrt() < 0.1,
            "{r} vs {p:?}"
        );
        for key in [
            "theta",
            "site",
            "match_score",
            "vicinity",
            "vicinity_threshold",
            "candidates",
            "time_us",
        ] {
            assert!(r.get(key).is_some(), "missing {key}");
        }
    }
    assert!(out.last().unwrap()["error"]
        .as_str()
        .unwrap()
        .contains("angle_min"));
    assert!(!text(&o).contains("--range-max"), "{}", text(&o));
    // A sensor of much shorter reach than the reference scans': the
    // summary says so and how to build for it.
    let first: serde_json::Value = serde_json::from_str(lines.lines().next().unwrap()).unwrap();
    let mut short = first.clone();
    short["range_max"] = serde_json::json!(4.0);
    let short_input = dir.path().join("short.jsonl");
    std::fs::write(&short_input, format!("{short}\n")).unwrap();
    let o = mapc(
        &[
            "localize",
            dbp.to_str().unwrap(),
            short_input.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(
        text(&o).contains("mapc build --range-max 4.0"),
        "{}",
        text(&o)
    );
    // Text output and stdin.
    let o = Command::new(env!("CARGO_BIN_EXE_mapc"))
        .args(["localize", dbp.to_str().unwrap(), "-", "--format", "text"])
        .stdin(std::fs::File::open(&input).unwrap())
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&o.stdout).contains("yes"));
}

/// `--no-ssm-features` leaves the features section out (a smaller file,
/// recorded in the manifest); localizing with either database gives the
/// same answers, field for field but the time.
#[test]
fn a_database_without_stored_ssm_features_gives_the_same_answers() {
    let dir = tempfile::tempdir().unwrap();
    let without = dir.path().join("nofeat.refdb");
    std::fs::rename(built(dir.path(), &["--no-ssm-features"]), &without).unwrap();
    let with = built(dir.path(), &[]);
    let info = |db: &Path| {
        let o = mapc(&["info", db.to_str().unwrap(), "--json"], dir.path());
        assert!(o.status.success(), "{}", text(&o));
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let (ia, ib) = (info(&with), info(&without));
    let features = |j: &serde_json::Value| {
        j["sections"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["kind"] == "features")
            .expect("info lists the features section")["bytes"]
            .as_u64()
            .unwrap()
    };
    let sites = ia["sites"].as_u64().unwrap();
    // Offsets, then 80 bytes per prepared point, at most 160 per site.
    assert!(features(&ia) > sites * 8 * 80, "{ia}");
    assert!(features(&ia) <= 16 + sites * (4 + 160 * 80), "{ia}");
    assert_eq!(features(&ib), 0);
    // The section, its table entry and the padding of both (the manifests
    // differ by a letter: "ssm_features": true, or false).
    let grew = ia["file_bytes"].as_u64().unwrap() - ib["file_bytes"].as_u64().unwrap();
    assert!(
        grew >= features(&ia) && grew <= features(&ia) + 64,
        "{grew} {}",
        features(&ia)
    );
    assert_eq!(ia["manifest"]["options"]["ssm_features"], true);
    assert_eq!(ib["manifest"]["options"]["ssm_features"], false);
    let o = mapc(&["verify", without.to_str().unwrap()], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let (_, lines) = common::jsonl_scans(&std::fs::read(&with).unwrap(), 8, 5);
    let input = dir.path().join("scans.jsonl");
    std::fs::write(&input, lines).unwrap();
    let answers = |db: &Path| {
        let o = mapc(
            &["localize", db.to_str().unwrap(), input.to_str().unwrap()],
            dir.path(),
        );
        assert!(o.status.success(), "{}", text(&o));
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .map(|l| {
                let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
                v.as_object_mut().unwrap().remove("time_us");
                v
            })
            .collect::<Vec<_>>()
    };
    let (a, b) = (answers(&with), answers(&without));
    assert_eq!(a.len(), 8);
    assert_eq!(a, b);
}

#[test]
fn localize_against_several_maps_says_which_map() {
    let dir = tempfile::tempdir().unwrap();
    let demo = built(dir.path(), &[]);
    // A second building: a synthetic office (another layout).
    let other_dir = dir.path().join("other");
    std::fs::create_dir_all(&other_dir).unwrap();
    let src = common::office_map(&other_dir, 240, 200, 7);
    let other = dir.path().join("other.refdb");
    let o = mapc(
        &[
            "build",
            src.yaml_path.as_ref().unwrap().to_str().unwrap(),
            "-o",
            other.to_str().unwrap(),
            "--fit-queries",
            "40",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "build failed: {}", text(&o));
    let (poses, lines) = common::jsonl_scans(&std::fs::read(&demo).unwrap(), 8, 5);
    let input = dir.path().join("scans.jsonl");
    std::fs::write(&input, lines).unwrap();
    // The demo map second: the answer names it whatever the order.
    let o = mapc(
        &[
            "localize",
            other.to_str().unwrap(),
            demo.to_str().unwrap(),
            input.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let out: Vec<serde_json::Value> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(out.len(), poses.len());
    for (r, p) in out.iter().zip(&poses) {
        assert_eq!(r["accepted"], true, "{r}");
        assert_eq!(r["map_index"], 1, "{r}");
        assert_eq!(r["map"], demo.display().to_string());
        let (x, y) = (r["x"].as_f64().unwrap(), r["y"].as_f64().unwrap());
        assert!(((x - p.x as f64).powi(2) + (y - p.y as f64).powi(2)).sqrt() < 0.1);
        let maps = r["maps"].as_array().unwrap();
        assert_eq!(maps.len(), 2);
        // The other office may accept a scan taken in a room its own
        // same-sized room explains (docs/confidence.md: 12-18% of scans of
        // one synthetic office accepted on another's map); it must be the
        // less confident map.
        let other_conf = maps[0]["confidence"].as_f64().unwrap();
        let demo_conf = maps[1]["confidence"].as_f64().unwrap();
        assert!(other_conf < demo_conf, "the other building won {r}");
    }
    assert!(text(&o).contains("none: 0"), "{}", text(&o));
    // Options that belong to one map are refused with several.
    let o = mapc(
        &[
            "localize",
            other.to_str().unwrap(),
            demo.to_str().unwrap(),
            input.to_str().unwrap(),
            "--prior",
            "1,1,5",
        ],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("belong to one map"), "{}", text(&o));
    // With one map the prior is X,Y,R in one argument; a negative heading
    // is a value, not an option.
    let p0 = poses[0];
    let region = format!("{},{},5", p0.x, p0.y);
    let o = mapc(
        &[
            "localize",
            demo.to_str().unwrap(),
            input.to_str().unwrap(),
            "--prior",
            &region,
            "--prior-heading",
            "-180,180",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let first: serde_json::Value =
        serde_json::from_str(String::from_utf8_lossy(&o.stdout).lines().next().unwrap()).unwrap();
    assert_eq!(first["accepted"], true, "{first}");
    let o = mapc(
        &[
            "localize",
            demo.to_str().unwrap(),
            input.to_str().unwrap(),
            "--prior",
            "1,2",
        ],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("takes 3 comma-separated numbers"),
        "{}",
        text(&o)
    );
}

#[test]
fn localize_with_a_polygon_prior() {
    let dir = tempfile::tempdir().unwrap();
    let db = built(dir.path(), &[]);
    let db = db.to_str().unwrap();
    let (poses, lines) = common::jsonl_scans(&std::fs::read(db).unwrap(), 4, 9);
    let input = dir.path().join("scans.jsonl");
    std::fs::write(&input, lines).unwrap();
    let input = input.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["localize", db, input, "--no-candidates"];
        args.extend_from_slice(extra);
        mapc(&args, dir.path())
    };
    let answers = |o: &Output| -> Vec<serde_json::Value> {
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    };
    // A square of 4 m around the first pose: that scan is localized there.
    let p = poses[0];
    let square = |cx: f32, cy: f32| {
        let v = [(-2.0, -2.0), (2.0, -2.0), (2.0, 2.0), (-2.0, 2.0)];
        v.map(|(dx, dy)| format!("{},{}", cx + dx, cy + dy))
            .join(",")
    };
    let o = run(&["--prior-polygon", &square(p.x, p.y)]);
    let first = &answers(&o)[0];
    assert_eq!(first["accepted"], true, "{first}");
    let (x, y) = (first["x"].as_f64().unwrap(), first["y"].as_f64().unwrap());
    assert!((x - p.x as f64).hypot(y - p.y as f64) < 0.1, "{first}");
    // With a heading window too (a negative value is a value).
    let o = run(&[
        "--prior-polygon",
        &square(p.x, p.y),
        "--prior-heading",
        "-180,180",
    ]);
    assert_eq!(answers(&o)[0]["accepted"], true, "{}", text(&o));
    // A square far from every site ranks none: no answer, which is a
    // reason, not a failure.
    let o = run(&["--prior-polygon", &square(p.x + 500.0, p.y + 500.0)]);
    assert!(o.status.success(), "{}", text(&o));
    for r in answers(&o) {
        assert_eq!(r["accepted"], false, "{r}");
        assert!(r["reason"].as_str().unwrap().contains("0 examined"), "{r}");
    }
    // Bad polygons are clap errors (exit 2) that say why.
    let many = (0..33)
        .map(|k| format!("{k},{}", k * k))
        .collect::<Vec<_>>()
        .join(",");
    for (bad, why) in [
        ("0,0,1,0,1", "x, y pairs, got 5 numbers"),
        ("0,0,1,0", "at least 3 vertices, got 2"),
        (many.as_str(), "at most 32 vertices, got 33"),
        ("0,0,1,1,2,2", "on one line"),
        ("0,0,1,x,0,1", "is not a number"),
    ] {
        let o = run(&["--prior-polygon", bad]);
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", text(&o));
        assert!(text(&o).contains(why), "{bad}: {}", text(&o));
        assert!(text(&o).contains("--prior-polygon"), "{}", text(&o));
        assert!(o.stdout.is_empty());
    }
    // One region: not with --prior.
    let o = run(&["--prior-polygon", &square(p.x, p.y), "--prior", "1,1,5"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("cannot be used with"), "{}", text(&o));
    // It belongs to one map.
    let o = mapc(
        &[
            "localize",
            db,
            db,
            input,
            "--prior-polygon",
            &square(p.x, p.y),
        ],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("belong to one map"), "{}", text(&o));
}

#[test]
fn eval_check_passes_on_own_baseline_and_fails_on_a_worse_map() {
    let dir = tempfile::tempdir().unwrap();
    let good = built(dir.path(), &[]);
    let out = dir.path().join("eval");
    let o = eval_static(&good, &out, None, dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let baseline = dir.path().join("baseline.json");
    std::fs::copy(out.join("report.json"), &baseline).unwrap();
    let o = eval_static(&good, &out, Some(&baseline), dir.path());
    assert!(o.status.success(), "own baseline must pass: {}", text(&o));
    // A deliberately worse database: one candidate and no refinement.
    let worse = dir.path().join("worse.refdb");
    let map = demo_map();
    let o = mapc(
        &[
            "build",
            map.to_str().unwrap(),
            "-o",
            worse.to_str().unwrap(),
            "--fit-queries",
            "40",
            "--nc-max",
            "1",
            "--refine-iters",
            "0",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let o = eval_static(&worse, &out, Some(&baseline), dir.path());
    assert_eq!(
        o.status.code(),
        Some(1),
        "a worse map must fail the check: {}",
        text(&o)
    );
    assert!(text(&o).contains("REGRESSION"));
}

#[test]
fn bad_inputs_exit_2_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out.refdb");
    let o_str = out.to_str().unwrap();
    // Malformed YAML.
    std::fs::write(d.join("bad.yaml"), "image: [unclosed\nresolution: 0.05\n").unwrap();
    let o = mapc(&["build", "bad.yaml", "-o", o_str], d);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("bad.yaml"));
    // Missing image.
    std::fs::write(d.join("noimg.yaml"), "image: nothere.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n").unwrap();
    let o = mapc(&["build", "noimg.yaml", "-o", o_str], d);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("nothere.pgm"), "{}", text(&o));
    // Zero resolution.
    std::fs::copy(
        repo().join("maps/office-demo/office-demo.pgm"),
        d.join("m.pgm"),
    )
    .unwrap();
    std::fs::write(d.join("zero.yaml"), "image: m.pgm\nresolution: 0\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n").unwrap();
    let o = mapc(&["build", "zero.yaml", "-o", o_str], d);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("resolution"), "{}", text(&o));
    // An image with no YAML beside it and no --resolution.
    let o = mapc(&["build", "m.pgm", "-o", o_str], d);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("--resolution"), "{}", text(&o));
    // ... works with --resolution.
    let o = mapc(
        &[
            "build",
            "m.pgm",
            "-o",
            o_str,
            "--resolution",
            "0.05",
            "--fit-queries",
            "0",
        ],
        d,
    );
    assert!(o.status.success(), "{}", text(&o));
    std::fs::remove_file(&out).unwrap();
    // No free cell.
    std::fs::write(
        d.join("black.pgm"),
        [b"P5\n8 8\n255\n".as_slice(), &[0u8; 64]].concat(),
    )
    .unwrap();
    let o = mapc(
        &["build", "black.pgm", "-o", o_str, "--resolution", "0.05"],
        d,
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(!out.exists(), "nothing may be written on error");
    // Bad usage.
    let o = mapc(&["build"], d);
    assert_eq!(o.status.code(), Some(2));
    // Not a database.
    let o = mapc(&["verify", "m.pgm"], d);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
}

#[test]
fn demo_runs_from_the_repository_root() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let o = mapc(
        &["demo", "--poses", "30", "--out", out.to_str().unwrap()],
        &repo(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("static") && t.contains("dynamic"), "{t}");
    assert!(out.join("static-poses.png").exists());
    assert!(out.join("report.json").exists());
}

#[test]
fn a_coarse_index_is_built_on_request_verified_and_as_good_as_exhaustive_ranking() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("plain.refdb");
    std::fs::rename(built(dir.path(), &[]), &plain).unwrap();
    // The demo map has ~130 sites, below the default threshold: force a
    // narrow index so it really prunes.
    let indexed = dir.path().join("indexed.refdb");
    let db = built(
        dir.path(),
        &[
            "--index-min-sites",
            "1",
            "--index-leaf-size",
            "4",
            "--index-leaves",
            "16",
            "--index-beam",
            "4",
        ],
    );
    std::fs::rename(db, &indexed).unwrap();
    let o = mapc(&["verify", indexed.to_str().unwrap()], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let o = mapc(&["info", "--json", indexed.to_str().unwrap()], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(info["index"]["nodes"].as_u64().unwrap() > 3, "{info}");
    assert_eq!(
        info["index"]["views"].as_array().unwrap().len(),
        3,
        "{info}"
    );
    // The search scores only part of the sites.
    let bytes = std::fs::read(&indexed).unwrap();
    let mut al = vec![0u32; bytes.len().div_ceil(4)];
    zerocopy::IntoBytes::as_mut_bytes(&mut al[..])[..bytes.len()].copy_from_slice(&bytes);
    let db = refloc::RefDb::new(&zerocopy::IntoBytes::as_bytes(&al[..])[..bytes.len()]).unwrap();
    let index = db.index().expect("an index was requested");
    let mut visited = 0;
    index
        .search(refloc::index::ViewKind::Full, db.hist(0), |_| visited += 1)
        .unwrap();
    assert!(
        visited > 0 && visited < db.site_count(),
        "{visited} of {}",
        db.site_count()
    );
    // Same localization quality as the exhaustive ranking, by eval --check.
    let base = dir.path().join("base");
    let o = eval_static(&plain, &base, None, dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let report = base.join("report.json");
    let o = eval_static(&indexed, &dir.path().join("idx"), Some(&report), dir.path());
    assert!(
        o.status.success(),
        "indexed database regressed: {}",
        text(&o)
    );
    // Bad index options are bad usage.
    let o = mapc(
        &[
            "build",
            demo_map().to_str().unwrap(),
            "-o",
            dir.path().join("x.refdb").to_str().unwrap(),
            "--index-beam",
            "0",
        ],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("index beam"), "{}", text(&o));
}

#[test]
fn eval_runs_the_disturbance_suite() {
    let dir = tempfile::tempdir().unwrap();
    let db = built(dir.path(), &[]);
    let out = dir.path().join("eval");
    let o = mapc(
        &[
            "eval",
            db.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--poses",
            "30",
            "--experiments",
            "disturbances",
            "--no-figures",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    for class in mapc::tools::disturb::Class::ALL {
        let s = &report["summaries"][class.name()];
        let (n, correct) = (s["n"].as_u64().unwrap(), s["correct"].as_u64().unwrap());
        assert_eq!(n, 30, "{}", class.name());
        // The synthetic office is easy: most disturbed poses are found.
        assert!(correct * 10 >= n * 8, "{}: {correct} of {n}", class.name());
    }
    let o = mapc(
        &["eval", db.to_str().unwrap(), "--experiments", "windows"],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("people"), "{}", text(&o));
}

/// Scans of a sensor that reaches much less than the database's reference
/// scans (4 m against 30 m) are localized on reference scans made again
/// for their reach from the database (`mapc::compiler::reach`), with every
/// candidate examined: the answers are those of a database built for that
/// sensor with `--range-max 4 --early-accept 0`, and more of them are
/// right than with the database's own reference scans (`--database-reach`).
#[test]
fn short_reach_scans_use_reference_scans_made_for_their_reach() {
    let dir = tempfile::tempdir().unwrap();
    let dbp = built(dir.path(), &[]);
    let map = demo_map();
    let db4 = dir.path().join("demo-4m.refdb");
    let o = mapc(
        &[
            "build",
            map.to_str().unwrap(),
            "-o",
            db4.to_str().unwrap(),
            "--range-max",
            "4",
            "--early-accept",
            "0",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let dump = dir.path().join("dump");
    let o = eval_static_with(
        &dbp,
        &dump.join("report"),
        None,
        &["--range-max", "4", "--dump", dump.to_str().unwrap()],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let scans = dump.join("static-scans.jsonl");
    let truth = dump.join("static-truth.txt");
    let run = |extra: &[&str], db: &Path| {
        let mut args = vec!["localize", "--no-candidates"];
        args.extend_from_slice(extra);
        args.extend([
            db.to_str().unwrap(),
            scans.to_str().unwrap(),
            "--truth",
            truth.to_str().unwrap(),
        ]);
        let o = mapc(&args, dir.path());
        assert!(o.status.success(), "{}", text(&o));
        let answers: Vec<serde_json::Value> = String::from_utf8_lossy(&o.stdout)
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        (answers, String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let right = |answers: &[serde_json::Value]| {
        answers
            .iter()
            .filter(|r| {
                r["accepted"] == true
                    && r["error_m"].as_f64().unwrap() <= 0.3
                    && r["error_rad"].as_f64().unwrap() <= 5f64.to_radians()
            })
            .count()
    };
    let (derived, note) = run(&[], &dbp);
    assert!(note.contains("made again for their reach"), "{note}");
    let (own, note) = run(&["--database-reach"], &dbp);
    assert!(note.contains("every candidate is examined"), "{note}");
    let (built4, _) = run(&[], &db4);
    assert_eq!(derived.len(), 60);
    for (a, b) in derived.iter().zip(&built4) {
        assert_eq!(a["accepted"], b["accepted"], "{a} / {b}");
        let d = (a["x"].as_f64().unwrap() - b["x"].as_f64().unwrap())
            .hypot(a["y"].as_f64().unwrap() - b["y"].as_f64().unwrap());
        assert!(d < 0.05, "{a} / {b}");
    }
    // 47 against 43 when set.
    assert!(
        right(&derived) > right(&own),
        "{} <= {}",
        right(&derived),
        right(&own)
    );
}
