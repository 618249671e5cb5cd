//! Golden `.refdb` files of every format version (tests/golden/v*/): the
//! current reader must read, verify and localize against its own version's
//! file, and reject every other version's with a `Version` error whose
//! message names both versions.

use std::path::Path;

use refloc::{DbErrorKind, RefDb};

fn aligned(bytes: &[u8]) -> Vec<u32> {
    let mut w = vec![0u32; bytes.len().div_ceil(4)];
    zerocopy::IntoBytes::as_mut_bytes(&mut w[..])[..bytes.len()].copy_from_slice(bytes);
    w
}

#[test]
fn every_golden_version_is_read_or_rejected_clearly() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/golden");
    let mut seen_current = false;
    for entry in std::fs::read_dir(&root).unwrap() {
        let dir = entry.unwrap().path();
        let Some(v) = dir
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix('v'))
            .and_then(|n| n.parse::<u32>().ok())
        else {
            continue;
        };
        let bytes = std::fs::read(dir.join("tiny.refdb")).unwrap();
        let words = aligned(&bytes);
        let buf = &zerocopy::IntoBytes::as_bytes(&words[..])[..bytes.len()];
        match RefDb::new(buf) {
            Ok(db) => {
                assert_eq!(
                    v,
                    refloc::format::FORMAT_VERSION,
                    "{} read by a reader of another version",
                    dir.display()
                );
                seen_current = true;
                db.verify().unwrap();
                // Localize a scan simulated at the first site with a 30 degree heading.
                let p = db.site_xy(0);
                let truth = refloc::Pose2::new(p[0] + 0.3, p[1] - 0.2, 0.5);
                let lidar = mapc::compiler::sim::Lidar::new(362, 2.0 * std::f32::consts::PI, 30.0);
                let ranges =
                    mapc::compiler::sim::virtual_scan(&db.grid(), &db.frame(), &truth, &lidar);
                let mut scratch = vec![0u8; refloc::scratch_size(db.params(), ranges.len())];
                let scan = refloc::Scan::Ranges(refloc::RangeScan {
                    angle_min: lidar.angle_min,
                    angle_increment: lidar.angle_increment,
                    range_min: 0.0,
                    range_max: 30.0,
                    ranges: &ranges,
                });
                let fix = refloc::localize(&db, &scan, &mut scratch).unwrap();
                assert!(fix.accepted);
                assert!(
                    (fix.pose.x - truth.x).abs() < 0.05 && (fix.pose.y - truth.y).abs() < 0.05,
                    "{:?}",
                    fix.pose
                );
            }
            Err(e) => {
                assert_eq!(e.kind, DbErrorKind::Version, "{}: {e}", dir.display());
                let msg = e.to_string();
                assert!(
                    msg.contains(&v.to_string())
                        && msg.contains(&refloc::format::FORMAT_VERSION.to_string()),
                    "{msg}"
                );
            }
        }
    }
    assert!(
        seen_current,
        "no golden file for the current format version {}",
        refloc::format::FORMAT_VERSION
    );
}

#[test]
fn other_versions_of_the_current_golden_are_rejected_with_a_clear_message() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!(
        "../../tests/golden/v{}",
        refloc::format::FORMAT_VERSION
    ));
    let bytes = std::fs::read(dir.join("tiny.refdb")).unwrap();
    for other in [0u32, refloc::format::FORMAT_VERSION + 1, 999] {
        let mut b = bytes.clone();
        b[12..16].copy_from_slice(&other.to_le_bytes());
        let words = aligned(&b);
        let e = RefDb::new(&zerocopy::IntoBytes::as_bytes(&words[..])[..b.len()])
            .err()
            .expect("must be rejected");
        assert_eq!(e.kind, DbErrorKind::Version);
        let msg = e.to_string();
        assert!(
            msg.contains(&format!("format version {other}")) && msg.contains("rebuild"),
            "{msg}"
        );
    }
}
